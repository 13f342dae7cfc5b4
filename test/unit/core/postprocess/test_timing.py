"""Time parameterization: limits (sampled and by finite differences), endpoints, rest, scaling,
path deviation, degenerate paths and bad input."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_planner.core.postprocess import timing
from humanoid_planner.core.postprocess.timing import TimedTrajectory, time_parameterize

TOL = 1e-3  # relative slack on the limits


def random_walk(seed: int, m: int = 20, n: int = 10, step: float = 0.3) -> np.ndarray:
    return np.cumsum(np.random.default_rng(seed).uniform(-step, step, (m, n)), axis=0)


def polyline_distance(points: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Euclidean distance of each point (P, n) to the polyline through w (M, n)."""
    a, d = w[:-1], np.diff(w, axis=0)
    t = np.einsum("pmn,mn->pm", points[:, None] - a[None], d) / np.maximum((d * d).sum(1), 1e-300)
    closest = a[None] + np.clip(t, 0, 1)[..., None] * d[None]
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


def assert_valid(tr: TimedTrajectory, w: np.ndarray, vlim: np.ndarray, alim: np.ndarray) -> None:
    """Everything a JointTrajectory consumer relies on, limits checked two ways."""
    t, q, qd, qdd = tr.times, tr.positions, tr.velocities, tr.accelerations
    k, n = q.shape
    assert t.shape == (k,) and qd.shape == qdd.shape == (k, n)
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(qd)) and np.all(np.isfinite(qdd))
    np.testing.assert_array_equal(q[0], w[0])
    np.testing.assert_array_equal(q[-1], w[-1])
    assert np.all(qd[0] == 0) and np.all(qd[-1] == 0)
    assert np.all(np.abs(qd) <= vlim * (1 + TOL))
    assert np.all(np.abs(qdd) <= alim * (1 + TOL))
    if k > 2:
        h = np.diff(t)[:, None]
        v_fd = np.diff(q, axis=0) / h
        assert np.all(np.abs(v_fd) <= vlim * (1 + TOL))
        # second divided difference = a weighted mean of q'' over [t_i-1, t_i+1]
        a_fd = 2 * (v_fd[1:] - v_fd[:-1]) / (h[1:] + h[:-1])
        assert np.all(np.abs(a_fd) <= alim * (1 + TOL))
    # the motion stays within the reported distance of the piecewise-linear path
    assert np.all(polyline_distance(q, w) <= tr.max_deviation + 1e-9)


VMAX = np.full(10, 1.5)
AMAX = np.full(10, 3.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_walk_respects_limits_and_tolerance(seed):
    w = random_walk(seed)
    tr = time_parameterize(w, VMAX, AMAX)
    assert tr.method == "toppra"
    assert 0 < tr.max_deviation <= timing.DEFAULT_PATH_TOLERANCE + 1e-12
    assert len(tr.times) <= timing.DEFAULT_MAX_POINTS
    assert_valid(tr, w, VMAX, AMAX)


@pytest.mark.parametrize("seed", [0, 3])
def test_blends_cover_every_part_of_the_motion_off_the_path(seed):
    """Planners re-check only TimedTrajectory.blends, so every sample off the input path must lie on
    one of them (within the chord error of their 2-degree points)."""
    w = random_walk(seed)
    tr = time_parameterize(w, VMAX, AMAX)
    assert tr.blends and all(b.ndim == 2 and b.shape[1] == w.shape[1] and len(b) >= 3 for b in tr.blends)
    for b in tr.blends:  # a blend leaves and rejoins the path, and stays within max_deviation of it
        assert polyline_distance(b[[0, -1]], w).max() <= 1e-9
        assert polyline_distance(b, w).max() <= tr.max_deviation + 1e-9
    off = tr.positions[polyline_distance(tr.positions, w) > 1e-7]
    assert len(off) > 0
    nearest_blend = np.min([polyline_distance(off, b) for b in tr.blends], axis=0)
    assert nearest_blend.max() <= 1e-3 * timing.DEFAULT_PATH_TOLERANCE


def test_exact_paths_have_no_blends():
    w = random_walk(1)
    assert time_parameterize(w, VMAX, AMAX, path_tolerance=0.0).blends == ()
    assert time_parameterize(w[:2], VMAX, AMAX).blends == ()


def test_blends_are_faster_than_stopping_at_every_waypoint():
    w = random_walk(0)
    blended = time_parameterize(w, VMAX, AMAX, path_tolerance=0.1)
    exact = time_parameterize(w, VMAX, AMAX, path_tolerance=0.0)
    assert blended.duration < 0.9 * exact.duration


def test_zero_tolerance_follows_the_path_exactly_and_stops_at_each_waypoint():
    w = random_walk(3, m=6, n=4, step=0.8)
    tr = time_parameterize(w, VMAX[:4], AMAX[:4], path_tolerance=0.0)
    assert tr.method == "trapezoidal" and tr.max_deviation == 0.0
    assert_valid(tr, w, VMAX[:4], AMAX[:4])
    for wp in w:  # every waypoint is a sample, reached at rest
        i = np.flatnonzero(np.all(tr.positions == wp, axis=1))
        assert len(i) >= 1 and np.all(tr.velocities[i] == 0)


@pytest.mark.parametrize("vs, as_", [(0.5, 1.0), (1.0, 0.5), (0.5, 0.5), (0.1, 0.1)])
def test_scaling_slows_down_and_tightens_the_limits(vs, as_):
    w = random_walk(4, m=8, n=6, step=0.6)
    full = time_parameterize(w, VMAX[:6], AMAX[:6])
    scaled = time_parameterize(w, VMAX[:6], AMAX[:6], velocity_scaling=vs, acceleration_scaling=as_)
    assert scaled.duration > full.duration
    assert_valid(scaled, w, vs * VMAX[:6], as_ * AMAX[:6])


def test_two_points_trapezoid_and_triangle_durations():
    # 4 rad at 1 rad/s, 1 rad/s^2: 1 s up, 3 s cruise, 1 s down
    tr = time_parameterize([[0.0], [4.0]], [1.0], [1.0])
    assert tr.method == "trapezoidal" and tr.duration == pytest.approx(5.0)
    assert_valid(tr, np.array([[0.0], [4.0]]), np.ones(1), np.ones(1))
    # 1 rad never reaches cruise speed: triangle of 2 s
    assert time_parameterize([[0.0], [1.0]], [1.0], [1.0]).duration == pytest.approx(2.0)
    # the slowest joint (relative to its limits) sets the pace; both arrive together
    tr2 = time_parameterize([[0.0, 0.0], [4.0, 1.0]], [1.0, 10.0], [1.0, 10.0])
    assert tr2.duration == pytest.approx(5.0)


def test_single_point_and_all_duplicates_are_static():
    for w in ([[0.1, 0.2, 0.3]], [[0.1, 0.2, 0.3]] * 4):
        tr = time_parameterize(w, VMAX[:3], AMAX[:3])
        assert tr.method == "static" and tr.duration == 0.0
        assert tr.times.shape == (1,) and tr.positions.shape == (1, 3)
        np.testing.assert_array_equal(tr.positions[0], w[0])
        assert np.all(tr.velocities == 0) and np.all(tr.accelerations == 0)


def test_duplicated_waypoints_are_merged():
    w = np.array([[0, 0], [0, 0], [1, 0], [1, 0], [1, 1], [1, 1 + 1e-12]], dtype=float)
    tr = time_parameterize(w, VMAX[:2], AMAX[:2])
    assert_valid(tr, w, VMAX[:2], AMAX[:2])


def test_reversal_stops_at_the_turning_point():
    w = np.array([[0.0, 0.0], [1.0, 0.5], [0.0, 0.0]])
    tr = time_parameterize(w, VMAX[:2], AMAX[:2])
    assert_valid(tr, w, VMAX[:2], AMAX[:2])
    i = np.flatnonzero(np.all(tr.positions == w[1], axis=1))
    assert len(i) == 1 and np.all(tr.velocities[i] == 0)


def test_collinear_waypoints_move_as_one_segment():
    w = np.array([[0.0, 0.0], [0.5, 1.0], [1.0, 2.0], [2.0, 4.0]])
    tr = time_parameterize(w, [1.0, 1.0], [2.0, 2.0])
    one = time_parameterize(w[[0, -1]], [1.0, 1.0], [2.0, 2.0])
    assert tr.max_deviation == 0.0
    assert tr.duration == pytest.approx(one.duration, rel=0.03)
    assert_valid(tr, w, np.ones(2), np.full(2, 2.0))


def test_motion_stays_within_position_limits_the_waypoints_respect():
    # a sharp corner pressed against the upper limit of both joints
    w = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]])
    lower, upper = np.zeros(2), np.ones(2)
    tr = time_parameterize(w, [1.0, 1.0], [2.0, 2.0], path_tolerance=0.2,
                           position_limits=(lower, upper))
    assert tr.method == "toppra"
    assert np.all(tr.positions >= lower) and np.all(tr.positions <= upper)
    assert_valid(tr, w, np.ones(2), np.full(2, 2.0))


def test_position_limits_are_widened_to_the_waypoints_and_guard_the_blends():
    w = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])
    # a start state slightly outside its limits must not forbid the blends
    tr = time_parameterize(w, [1.0, 1.0], [2.0, 2.0], path_tolerance=0.2,
                           position_limits=([0.1, 0.0], [2.0, 1.0]))
    assert tr.method == "toppra"
    # the guard itself: the blend tops out 0.2 below the corner; a box below that rejects it
    path = timing._BlendedPath(w, 0.2)
    ok = timing._toppra_piece(path, np.ones(2), np.full(2, 2.0), 60, (np.zeros(2), np.array([2.0, 1.0])))
    assert ok is not None
    assert timing._toppra_piece(path, np.ones(2), np.full(2, 2.0), 60,
                                (np.zeros(2), np.array([2.0, 0.7]))) is None


def test_long_trajectory_respects_max_points():
    w = np.array([[0.0], [50.0]])
    tr = time_parameterize(w, [0.5], [1.0], sample_dt=0.01, max_points=200)
    assert len(tr.times) <= 200 and tr.duration > 100
    assert_valid(tr, w, np.full(1, 0.5), np.ones(1))


def test_toppra_failure_falls_back_to_exact_stops(monkeypatch):
    def broken(*args, **kwargs):
        raise ValueError("simulated toppra failure")

    monkeypatch.setattr(timing.algorithm, "TOPPRA", broken)
    w = random_walk(5, m=5, n=3)
    tr = time_parameterize(w, VMAX[:3], AMAX[:3])
    assert tr.method == "trapezoidal" and tr.max_deviation == 0.0
    assert_valid(tr, w, VMAX[:3], AMAX[:3])


@pytest.mark.parametrize(
    "w, v, a, kwargs",
    [
        ([[0.0, np.nan], [1.0, 1.0]], [1, 1], [1, 1], {}),
        ([[0.0, np.inf], [1.0, 1.0]], [1, 1], [1, 1], {}),
        ([0.0, 1.0], [1, 1], [1, 1], {}),  # 1-D
        (np.zeros((0, 2)), [1, 1], [1, 1], {}),
        ([[0.0, 0.0], [1.0, 1.0]], [1], [1, 1], {}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 0], [1, 1], {}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, -1], {}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, np.nan], [1, 1], {}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, 1], {"velocity_scaling": 0.0}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, 1], {"acceleration_scaling": 1.5}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, 1], {"path_tolerance": -0.1}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, 1], {"sample_dt": 0.0}),
        ([[0.0, 0.0], [1.0, 1.0]], [1, 1], [1, 1], {"position_limits": ([0, 0], [1])}),
    ],
)
def test_bad_input_raises_value_error(w, v, a, kwargs):
    with pytest.raises(ValueError):
        time_parameterize(w, v, a, **kwargs)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    m=st.integers(2, 6),
    n=st.integers(1, 4),
    scale=st.floats(0.05, 1.0),
    tol=st.sampled_from([0.0, 0.01, 0.05, 0.2]),
)
def test_property_any_path_is_valid(seed, m, n, scale, tol):
    rng = np.random.default_rng(seed)
    w = rng.uniform(-2, 2, (m, n))
    vmax, amax = rng.uniform(0.2, 3.0, n), rng.uniform(0.5, 10.0, n)
    tr = time_parameterize(w, vmax, amax, velocity_scaling=scale, acceleration_scaling=scale,
                           path_tolerance=tol)
    assert tr.max_deviation <= tol + 1e-12
    assert_valid(tr, w, scale * vmax, scale * amax)
