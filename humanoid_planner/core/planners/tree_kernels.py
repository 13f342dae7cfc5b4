"""Compiled (numba) nearest-neighbour queries of the search trees (common.Tree).

A tree's nearest node is argmin_j |x_j|² - 2 x_j·q over its nodes, brute force. As a numpy matrix
product that is a BLAS call, and OpenBLAS spreads products of a few thousand rows over its threads:
on a loaded 2-core machine the spinning threads made a dynamic-domain draw (20 samples against a
4k-node tree) cost ~1.5 ms of CPU, most of Fetch's MotionBenchMaker cage fallback, against ~60 µs
single-threaded. These loops take one thread and stop the draws at the first sample inside its
node's domain, as ConnectSearch._sample takes it, so most cycles query one sample, not twenty.
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


def warm() -> None:
    """Compile (or load from the cache) the kernels for the argument types Tree passes."""
    XT, sq, Q = np.zeros((3, 2)), np.zeros(2), np.zeros((1, 3))
    nearest_rows(XT, sq, 2, Q)
    first_in_domain(XT, sq, np.full(2, np.inf), 2, Q)


if __name__ == "__main__":
    warm()
