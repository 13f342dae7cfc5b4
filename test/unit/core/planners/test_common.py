"""What every planner shares (planners.common): seeds, termination, the search tree, interpolation,
option ranges."""
from __future__ import annotations

import threading

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humanoid_planner.core.planners.common import (PlannerOptions, PlanResult, PlanStatus, Termination, Tree,
                                                   interpolate_steps, option_ranges, substream)


def test_substream_is_reproducible_and_independent():
    assert substream(None, 3) is None  # fresh entropy stays fresh
    a = np.random.default_rng(substream(42, 1)).random(5)
    np.testing.assert_array_equal(a, np.random.default_rng(substream(42, 1)).random(5))
    assert not np.allclose(a, np.random.default_rng(substream(42, 2)).random(5))
    assert not np.allclose(a, np.random.default_rng(42).random(5))
    assert substream(substream(7, 1), 2) == [7, 1, 2]  # streams of streams: seeds nest


def test_termination_cycles_cancel_and_deadline():
    t = Termination(60.0, max_cycles=10)
    assert not t.should_stop(9) and t.should_stop(10)
    assert t.stop_status() is PlanStatus.PLANNING_FAILED  # the budget, not the clock
    assert 0.0 <= t.elapsed() < 60.0 and 0.0 < t.remaining() <= 60.0
    cancel = threading.Event()
    t = Termination(60.0, cancel)
    assert not t.should_stop(10**9)  # no cycle budget
    cancel.set()
    assert t.should_stop() and t.stop_status() is PlanStatus.CANCELLED
    t = Termination(0.0)
    assert t.expired() and t.should_stop() and t.remaining() <= 0.0
    assert t.stop_status() is PlanStatus.TIMED_OUT


def test_tree_nearest_equals_brute_force_and_grows():
    rng = np.random.default_rng(0)
    tree = Tree(np.zeros(4), capacity=2)
    parent = 0
    for _ in range(50):  # chains of 1-5 nodes; capacity doubles as needed
        chain = rng.normal(size=(int(rng.integers(1, 6)), 4))
        parent = tree.add(chain, int(rng.integers(tree.size)))
    assert tree.size == parent + 1 and len(tree.q) >= tree.size
    Q = tree.q[:tree.size]
    for q in rng.normal(size=(200, 4)):
        assert np.linalg.norm(Q[tree.nearest(q)] - q) == pytest.approx(np.linalg.norm(Q - q, axis=1).min())
    samples = rng.normal(size=(200, 4))
    many = np.array([tree.nearest(q) for q in samples])
    np.testing.assert_allclose(np.linalg.norm(Q[many] - samples, axis=1),
                               np.linalg.norm(Q[None] - samples[:, None], axis=2).min(1))
    assert tree.add(np.empty((0, 4)), 3) == 3  # an empty chain adds nothing


def test_nearest_in_domain_takes_the_first_draw_inside_its_nodes_domain():
    rng = np.random.default_rng(1)
    tree = Tree(np.zeros(3), capacity=4)
    tree.add(rng.normal(size=(300, 3)), 0)
    tree.domain[:tree.size] = rng.uniform(0.05, 0.6, tree.size)
    tree.domain[rng.random(tree.size) < 0.3] = np.inf
    tree.cut(7)  # cut nodes are never nearest
    for _ in range(100):
        Q = rng.normal(size=(20, 3))
        near = np.argmin(tree.sq[:tree.size][None] - 2.0 * Q @ tree.q[:tree.size].T, axis=1)  # the matrix form
        inside = np.flatnonzero(np.linalg.norm(Q - tree.q[near], axis=1) <= tree.domain[near])
        k = int(inside[0]) if len(inside) else len(Q) - 1
        assert tree.nearest_in_domain(Q) == (k, int(near[k]))
        np.testing.assert_array_equal([tree.nearest(q) for q in Q], near)
    tree.domain[:] = 0.0  # no draw inside: the last one is taken
    assert tree.nearest_in_domain(Q)[0] == len(Q) - 1


def test_tree_path_to_follows_parents_back_to_the_root():
    tree = Tree(np.zeros(2))
    a = tree.add(np.array([[1.0, 0.0], [2.0, 0.0]]), 0)
    b = tree.add(np.array([[0.0, 1.0]]), 0)
    c = tree.add(np.array([[3.0, 0.0]]), a)
    np.testing.assert_array_equal(tree.path_to(c), [[0, 0], [1, 0], [2, 0], [3, 0]])
    np.testing.assert_array_equal(tree.path_to(b), [[0, 0], [0, 1]])
    np.testing.assert_array_equal(tree.path_to(0), [[0, 0]])


def test_tree_cut_takes_a_node_and_its_descendants_out_of_nearest():
    tree = Tree(np.zeros(2))
    a = tree.add(np.array([[1.0, 0.0], [2.0, 0.0]]), 0)  # nodes 1, 2
    b = tree.add(np.array([[0.0, 1.0]]), 0)  # node 3
    c = tree.add(np.array([[3.0, 0.0]]), a)  # node 4, below node 2
    tree.cut(a - 1)  # node 1: nodes 1, 2, 4 go; the root and node 3 stay
    assert tree.nearest(np.array([3.0, 0.0])) == 0 and tree.nearest(np.array([0.0, 2.0])) == b
    assert tree.size == 5 and tree.parent[c] == a  # indices and parents stay as they were
    d = tree.add(np.array([[2.5, 0.0]]), 0)
    assert tree.nearest(np.array([3.0, 0.0])) == d


def test_nearest_tcp_weighs_rotation_and_avoids_failing_nodes():
    def T(p, rotvec=(0, 0, 0)):
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = Rotation.from_rotvec(rotvec).as_matrix(), p
        return M

    tree = Tree(np.zeros(1), T([1.0, 0, 0]))
    tree.add(np.ones((1, 1)), 0, T([0.1, 0, 0], [0, 0, np.pi])[None])  # near, but turned half around
    tree.add(np.full((1, 1), 2.0), 0, T([0.2, 0, 0])[None])
    target = T([0.0, 0, 0])
    assert tree.nearest_tcp(target, rot_weight=0.0) == 1
    assert tree.nearest_tcp(target, rot_weight=0.1) == 2  # 0.1 m + 0.1 * pi > 0.2 m
    tree.fails[2] = 20  # every approach from node 2 failed: 20 * 0.05 m
    assert tree.nearest_tcp(target, rot_weight=0.1) == 1


def test_interpolate_steps():
    q0, q1 = np.array([0.0, 0.0]), np.array([0.35, -0.1])
    pts = interpolate_steps(q0, q1, 0.1)
    assert len(pts) == 4
    np.testing.assert_allclose(pts[-1], q1)
    steps = np.diff(np.vstack([q0, pts]), axis=0)
    assert np.all(np.max(np.abs(steps), axis=1) <= 0.1 + 1e-12)
    np.testing.assert_allclose(steps, np.broadcast_to(steps[0], steps.shape), atol=1e-12)  # evenly spaced, on the line
    np.testing.assert_array_equal(interpolate_steps(q0, q0, 0.1), [q0])


def test_plan_result_ok_and_option_ranges():
    assert PlanResult(PlanStatus.SUCCESS).ok and not PlanResult(PlanStatus.TIMED_OUT).ok
    ranges = option_ranges()
    defaults = PlannerOptions()
    assert ranges and all(r.lo <= getattr(defaults, name) <= r.hi for name, r in ranges.items())
    name, r = next(iter(ranges.items()))
    r.check(name, r.lo)
    for bad in (r.hi + 1.0, float("nan"), True, "1"):
        with pytest.raises(ValueError, match=name):
            r.check(name, bad)
    assert defaults.validate() is defaults
    with pytest.raises(ValueError, match=name):
        PlannerOptions(**{name: r.hi + 1.0}).validate()
