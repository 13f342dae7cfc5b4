"""planners/kernels.py: the compiled points and samples of a motion are numpy's to the bit (a search on
them is the same search), the nearest-neighbour loops are the matrix form's, and each kernel compiles
once for the types its callers pass."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.planners import kernels
from humanoid_planner.core.planners.common import Tree, interpolate_steps
from humanoid_planner.core.planners.motion import MotionValidator


def _numpy_steps(q0: np.ndarray, q1: np.ndarray, step: float) -> np.ndarray:
    d = q1 - q0
    k = max(1, int(np.ceil(np.max(np.abs(d)) / step))) if np.any(d) else 1
    return q0 + np.outer(np.arange(1, k + 1) / k, d)


def test_interpolate_steps_gives_numpys_points_to_the_bit():
    rng = np.random.default_rng(0)
    for trial in range(2000):
        n = int(rng.integers(1, 10))
        q0 = rng.uniform(-3, 3, n)
        q1 = q0 if trial % 11 == 0 else q0 + rng.normal(scale=rng.choice([1e-9, 0.05, 1.0, 3.0]), size=n)
        step = float(rng.choice([0.1, 0.02, 0.37]))
        expect = _numpy_steps(q0, q1, step)
        got = interpolate_steps(q0, q1, step)
        assert got.shape == expect.shape and np.array_equal(got, expect)
        assert np.max(np.abs(np.diff(np.vstack([q0, got]), axis=0))) <= step + 1e-12


def _numpy_polyline(v: MotionValidator, q_from: np.ndarray, waypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples in numpy: MotionValidator.steps per segment, evenly spaced."""
    prev = np.empty_like(waypoints)
    prev[0], prev[1:] = q_from, waypoints[:-1]
    d = waypoints - prev
    counts = v.steps(d)
    total = int(counts.sum())
    seg = np.full(total + 1, -1, dtype=np.int64)
    seg[1:] = np.repeat(np.arange(len(waypoints)), counts)
    s = seg[1:]
    frac = (np.arange(1, total + 1) - (np.cumsum(counts) - counts)[s]) / counts[s]
    pts = np.empty((total + 1, len(q_from)))
    pts[0], pts[1:] = q_from, prev[s] + frac[:, None] * d[s]
    return pts, seg


def test_polyline_gives_the_validators_numpy_samples_to_the_bit():
    rng = np.random.default_rng(1)
    for trial in range(500):
        n, U, M = int(rng.integers(1, 10)), int(rng.integers(0, 12)), int(rng.integers(1, 12))
        v = MotionValidator.__new__(MotionValidator)  # the sampling only: levers, resolution, point motion
        v.levers = rng.uniform(0, 1.5, (n, U))
        v._levers_rows = np.ascontiguousarray(v.levers)
        v.resolution, v.max_point_motion = 0.02, 0.015
        q0 = rng.uniform(-3, 3, n)
        W = q0 + np.cumsum(rng.normal(scale=rng.choice([1e-3, 0.05, 0.3]), size=(M, n)), axis=0)
        if trial % 7 == 0:
            W[0] = q0  # a segment that does not move
        pts, seg = _numpy_polyline(v, q0, W)
        got_pts, got_seg = v.samples(q0, W)
        assert np.array_equal(got_pts, pts) and np.array_equal(got_seg, seg)


def test_first_in_domain_queries_draws_in_order_and_compiles_once():
    rng = np.random.default_rng(2)
    tree = Tree(np.zeros(4))
    tree.add(rng.normal(size=(500, 4)), 0)
    tree.domain[:tree.size] = rng.uniform(0.1, 1.0, tree.size)
    Q = rng.normal(size=(20, 4))
    near = np.argmin(tree.sq[:tree.size][None] - 2.0 * Q @ tree.q[:tree.size].T, axis=1)
    inside = np.linalg.norm(Q - tree.q[near], axis=1) <= tree.domain[near]
    k, i = kernels.first_in_domain(tree.qT, tree.sq, tree.domain, tree.size, Q)
    assert k == (int(np.argmax(inside)) if inside.any() else len(Q) - 1) and i == near[k]
    tree.nearest(Q[0])
    interpolate_steps(Q[0], Q[1], 0.1)
    kernels.warm()
    for f in (kernels.first_in_domain, kernels.nearest_rows, kernels.interpolate_steps, kernels.polyline):
        assert len(f.signatures) == 1, f  # one compilation: a second one would compile inside a plan
