"""Path shortcutting (DAGRRT paper, Fig. 7): fewer, straighter segments, every new edge collision-checked.

The first and last configurations never change, so the path still starts at the start state and
still ends on the reached grasp.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

EdgeCheck = Callable[[np.ndarray, np.ndarray], bool]

SHORTCUT_FIRST_BATCH = 16
"""Samples in the first batch of a shortcut's edge check (MotionValidator.check_edge(first=...)): most
candidate shortcuts are blocked, and a collision on them shows among the first coarse-to-fine samples,
so checking 96 at once (the default batch when checks are cheap) paid mostly for samples past it. Panda,
MotionBenchMaker (bookshelf_small, box, table_pick, table_under_pick, cage, problems 1-10, each plan's
own path and checker replayed): shortcutting CPU median 17.8 -> 13.0 ms, the same paths."""


def path_length(path: np.ndarray) -> float:
    """Joint-space length (sum of Euclidean segment lengths)."""
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))) if len(path) > 1 else 0.0


def greedy_shortcut(path: np.ndarray, check_edge: EdgeCheck, deadline: float) -> np.ndarray:
    """From each kept waypoint jump to the farthest waypoint it sees directly (binary search, then step)."""
    out = [path[0]]
    i, last = 0, len(path) - 1
    while i < last and time.perf_counter() < deadline:
        j = last
        while j > i + 1 and not check_edge(path[i], path[j]):
            j = i + 1 + (j - i - 1) // 2  # halve the jump until it is free
        out.append(path[j])
        i = j
    if i < last:  # out of time: keep the rest as it was
        out.extend(path[i + 1:])
    return np.array(out)


def random_shortcut(path: np.ndarray, check_edge: EdgeCheck, rng: np.random.Generator, deadline: float,
                    max_iterations: int) -> np.ndarray:
    """Classic random shortcutting between points on two random segments."""
    path = np.array(path, dtype=float)
    for _ in range(max_iterations):
        if len(path) < 3 or time.perf_counter() >= deadline:
            break
        a, b = sorted(rng.choice(len(path) - 1, size=2, replace=False))
        if b - a < 1:
            continue
        ta, tb = rng.random(), rng.random()
        qa = path[a] + ta * (path[a + 1] - path[a])
        qb = path[b] + tb * (path[b + 1] - path[b])
        if check_edge(qa, qb):
            path = np.vstack([path[: a + 1], qa[None], qb[None], path[b + 1:]])
            # drop zero-length segments that the insertion may create
            keep = np.concatenate([[True], np.any(np.abs(np.diff(path, axis=0)) > 1e-9, axis=1)])
            keep[-1] = True
            path = path[keep]
    return path


def smooth_path(path: np.ndarray, check_edge: EdgeCheck, rng: np.random.Generator, time_budget: float,
                max_iterations: int = 60) -> np.ndarray:
    """Greedy then random shortcutting within a time budget; never longer than the input."""
    if len(path) <= 2:
        return np.array(path, dtype=float)
    deadline = time.perf_counter() + max(0.0, time_budget)
    p = greedy_shortcut(np.asarray(path, dtype=float), check_edge, deadline)
    p = random_shortcut(p, check_edge, rng, deadline, max_iterations)
    return p if path_length(p) <= path_length(path) + 1e-12 else np.asarray(path, dtype=float)
