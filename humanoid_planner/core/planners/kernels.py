"""Compiled (numba) loops of the searches: the trees' nearest-neighbour queries (common.Tree), the
points of a step (interpolate_steps) and the samples of a motion (motion.MotionValidator.samples).

A tree's nearest node is argmin_j |x_j|² - 2 x_j·q over its nodes, brute force. As a numpy matrix
product that is a BLAS call, which OpenBLAS spreads over its threads for a few thousand rows: on the
loaded 2-core machine their spinning cost ~1.5 ms of CPU per dynamic-domain draw (20 samples against a
4k-node tree; ~60 µs on one thread), most of Fetch's MotionBenchMaker cage fallback. These loops run on
one thread, along the nodes joint by joint (Tree.qT), and stop the draws at the first sample inside its
node's domain, as ConnectSearch._sample takes it. The points and samples of a lazy extension in numpy
cost ~15 calls (~30 µs), a third of the extension.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True)
def _nearest(XT, sq, size, q, dot) -> int:
    """Index of the node (columns XT[:, :size], |x|² in sq) nearest to q: the first minimum of
    sq - 2 x·q, as numpy's argmin (a node cut from the tree, sq = inf, is never nearer than one kept).
    dot: scratch of at least size."""
    dot[:size] = 0.0
    for c in range(XT.shape[0]):  # joint by joint: each pass runs along the nodes
        qc = q[c]
        for j in range(size):
            dot[j] += XT[c, j] * qc
    best, arg = np.inf, 0
    for j in range(size):
        v = sq[j] - 2.0 * dot[j]
        if v < best or j == 0:
            best, arg = v, j
    return arg


@nb.njit(cache=True, nogil=True)
def nearest_rows(XT, sq, size, Q) -> np.ndarray:
    """The nearest node of each row of Q (M, n); XT (n, capacity): the nodes by joint."""
    out = np.empty(Q.shape[0], dtype=np.int64)
    dot = np.empty(size)
    for k in range(Q.shape[0]):
        out[k] = _nearest(XT, sq, size, Q[k], dot)
    return out


@nb.njit(cache=True, nogil=True)
def first_in_domain(XT, sq, domain, size, Q) -> tuple[int, int]:
    """(k, i): the first row k of Q whose nearest node i holds it within its domain radius
    (|Q[k] - x_i| <= domain[i]), else the last row and its nearest node."""
    dot = np.empty(size)
    i = 0
    for k in range(Q.shape[0]):
        i = _nearest(XT, sq, size, Q[k], dot)
        d2 = 0.0
        for c in range(XT.shape[0]):
            x = Q[k, c] - XT[c, i]
            d2 += x * x
        if np.sqrt(d2) <= domain[i]:
            return k, i
    return Q.shape[0] - 1, i


@nb.njit(cache=True, nogil=True)
def polyline(q_from, waypoints, levers, resolution, max_point_motion):
    """q_from and the samples of q_from → waypoints (K+1, n), and the segment each ends (q_from: -1):
    per segment d, ceil(max(max|d| / resolution, max_u Σ_j |d_j| levers[j, u] / max_point_motion))
    samples (at least 1), evenly spaced — MotionValidator.steps' arithmetic in the same order (the same
    counts to the bit)."""
    M, n = waypoints.shape
    U = levers.shape[1]
    counts = np.empty(M, dtype=np.int64)
    d = np.empty((M, n))
    moved = np.empty(U)
    for m in range(M):
        big = 0.0
        moved[:] = 0.0
        for j in range(n):
            d[m, j] = waypoints[m, j] - (q_from[j] if m == 0 else waypoints[m - 1, j])
            a = abs(d[m, j])
            big = max(big, a)
            for u in range(U):
                moved[u] += a * levers[j, u]
        far = moved.max() if U else 0.0
        k = max(big / resolution, far / max_point_motion)
        counts[m] = max(1, int(np.ceil(k - 1e-9)))
    total = counts.sum()
    pts = np.empty((total + 1, n))
    seg = np.empty(total + 1, dtype=np.int64)
    pts[0] = q_from
    seg[0] = -1
    at = 1
    for m in range(M):
        for i in range(1, counts[m] + 1):
            frac = i / counts[m]
            for j in range(n):
                pts[at, j] = (q_from[j] if m == 0 else waypoints[m - 1, j]) + frac * d[m, j]
            seg[at] = m
            at += 1
    return pts, seg


@nb.njit(cache=True, nogil=True)
def interpolate_steps(q0, q1, step):
    """Points from q0 (excluded) to q1 (included) no farther apart than step (max-norm): common.interpolate_steps,
    the same arithmetic (the same points to the bit)."""
    n = q0.shape[0]
    d = np.empty(n)
    big = 0.0
    moves = False
    for j in range(n):
        d[j] = q1[j] - q0[j]
        big = max(big, abs(d[j]))
        moves = moves or d[j] != 0.0
    k = max(1, int(np.ceil(big / step))) if moves else 1
    out = np.empty((k, n))
    for i in range(k):
        a = (i + 1) / k
        for j in range(n):
            out[i, j] = q0[j] + a * d[j]
    return out


def warm() -> None:
    """Compile (or load from the cache) the kernels for the argument types Tree and the motions pass."""
    XT, sq, Q = np.zeros((3, 2)), np.zeros(2), np.zeros((1, 3))
    nearest_rows(XT, sq, 2, Q)
    first_in_domain(XT, sq, np.full(2, np.inf), 2, Q)
    polyline(np.zeros(3), np.ones((2, 3)), np.ones((3, 2)), 0.1, 0.1)
    interpolate_steps(np.zeros(3), np.ones(3), 0.1)


if __name__ == "__main__":
    warm()
