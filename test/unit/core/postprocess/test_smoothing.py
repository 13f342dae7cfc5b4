"""Shortcutting (postprocess.smoothing) on a 2-D joint space with a square obstacle: endpoints kept,
every new edge checked, never longer, the same result for the same seed."""
from __future__ import annotations

import time

import numpy as np
import pytest

from humanoid_planner.core.postprocess.smoothing import greedy_shortcut, path_length, random_shortcut, smooth_path

HALF = 0.5
"""The obstacle: the square |q0|, |q1| <= HALF."""


def free_edge(a: np.ndarray, b: np.ndarray) -> bool:
    """Exact: the straight segment a -> b misses the closed square (slab test)."""
    t0, t1 = 0.0, 1.0
    for k in range(2):
        d = b[k] - a[k]
        if abs(d) < 1e-15:
            if abs(a[k]) > HALF:
                return True
            continue
        lo, hi = sorted(((-HALF - a[k]) / d, (HALF - a[k]) / d))
        t0, t1 = max(t0, lo), min(t1, hi)
        if t0 > t1:
            return True
    return False


def detour(seed: int) -> np.ndarray:
    """A jittery collision-free path from (-2, 0) over the square to (2, 0)."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-2.0, 2.0, 25)
    y = np.where(np.abs(x) <= 1.0, 1.0, 0.5 * np.abs(2.0 - np.abs(x)) + 0.5) + rng.uniform(0.0, 0.3, len(x))
    path = np.column_stack([x, y])
    path[0], path[-1] = (-2.0, 0.0), (2.0, 0.0)
    assert all(free_edge(a, b) for a, b in zip(path[:-1], path[1:]))
    return path


def counting(check):
    calls = []

    def wrapped(a, b):
        calls.append((a.copy(), b.copy()))
        return check(a, b)
    return wrapped, calls


def test_path_length():
    assert path_length(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 5.0]])) == pytest.approx(6.0)
    assert path_length(np.zeros((1, 3))) == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smoothing_keeps_endpoints_shortens_and_every_edge_is_free(seed):
    path = detour(seed)
    out = smooth_path(path, free_edge, np.random.default_rng(seed), time_budget=5.0, max_iterations=200)
    np.testing.assert_array_equal(out[0], path[0])
    np.testing.assert_array_equal(out[-1], path[-1])
    assert all(free_edge(a, b) for a, b in zip(out[:-1], out[1:]))
    assert len(out) < len(path)
    assert path_length(out) < 0.9 * path_length(path)
    # the best path over the square's top corners is 2 * sqrt(1.5^2 + 0.5^2) + 1 = 4.16
    assert path_length(out) >= 2 * np.hypot(1.5, HALF) + 2 * HALF - 1e-9


def test_same_seed_same_path_other_seed_may_differ():
    path = detour(4)
    a = smooth_path(path, free_edge, np.random.default_rng(7), time_budget=5.0, max_iterations=50)
    b = smooth_path(path, free_edge, np.random.default_rng(7), time_budget=5.0, max_iterations=50)
    np.testing.assert_array_equal(a, b)


def test_free_space_becomes_one_segment():
    path = detour(5)
    check, calls = counting(lambda a, b: True)
    out = greedy_shortcut(path, check, time.perf_counter() + 5.0)
    np.testing.assert_array_equal(out, path[[0, -1]])
    assert len(calls) == 1  # the first jump, start -> goal, is free


def on_segment(a: np.ndarray, b: np.ndarray, p: np.ndarray, q: np.ndarray) -> bool:
    """Whether a and b both lie on the segment p -> q."""
    d = q - p
    for x in (a, b):
        t = float((x - p) @ d / (d @ d))
        if not (-1e-9 <= t <= 1 + 1e-9 and np.linalg.norm(p + t * d - x) <= 1e-9):
            return False
    return True


def test_every_kept_edge_was_checked_and_passed():
    """An output edge is an edge the check passed, or a piece of one (or of an input edge)."""
    path = detour(6)
    check, calls = counting(free_edge)
    out = smooth_path(path, check, np.random.default_rng(0), time_budget=5.0)
    trusted = [(a, b) for a, b in calls if free_edge(a, b)] + list(zip(path[:-1], path[1:]))
    assert len(calls) > 5
    for a, b in zip(out[:-1], out[1:]):
        assert any(on_segment(a, b, p, q) for p, q in trusted), (a, b)


def test_out_of_time_returns_the_path_unchanged():
    path = detour(7)
    check, calls = counting(free_edge)
    np.testing.assert_array_equal(greedy_shortcut(path, check, time.perf_counter() - 1.0), path)
    np.testing.assert_array_equal(random_shortcut(path, check, np.random.default_rng(0), time.perf_counter() - 1.0,
                                                  100), path)
    np.testing.assert_array_equal(smooth_path(path, check, np.random.default_rng(0), time_budget=0.0), path)
    assert calls == []


def test_short_paths_and_blocked_space_are_left_alone():
    two = np.array([[0.0, 0.0], [1.0, 1.0]])
    np.testing.assert_array_equal(smooth_path(two, lambda a, b: False, np.random.default_rng(0), 1.0), two)
    path = detour(8)
    out = smooth_path(path, lambda a, b: False, np.random.default_rng(0), time_budget=1.0)
    np.testing.assert_array_equal(out, path)  # nothing is free: no new edge, no dropped waypoint
