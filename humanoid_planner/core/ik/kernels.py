"""Compiled (numba) inverse kinematics: a group's TCP pose and geometric Jacobian for one configuration, the
pose error, and the batched damped-least-squares loop of `solver.solve_ik_batch`.

Why compiled: a plan's IK is many small problems (up to a few hundred seeds × grasps, ≤ 120 iterations
each), and in numpy every iteration is some 20 calls on (S, 6, n) arrays whose overhead is most of the cost:
a batch of the Panda's hints took ~24 ms, a third of a plan into an open shelf. Here each seed runs its own
loop on scalars and 6×6 systems, and stops the moment it converges.

The chain is `KinematicTree.kernel_arrays` (frames W_k = W_parent · L_k(q), L_k = u·A_k + v·B_k + C_k with
(u, v) = (cos, sin), or (q, 0) when prismatic) and the TCP's constant offset from the last frame, as
`kinematics.GroupKinematics` computes them in numpy (same formulas: the two agree to rounding).
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True)
def chain_pose_jacobian(q, cols, parents, prismatic, basis, Ktip, W, T, J) -> None:
    """TCP pose T (4, 4) and 6×n geometric Jacobian J (linear rows first) of one group configuration q (n,).
    W (F, 3, 4): scratch for the frames (their top three rows). A group column without a frame keeps a zero
    Jacobian column."""
    F = cols.shape[0]
    L = np.empty((3, 4))
    for k in range(F):
        x = q[cols[k]]
        if prismatic[k]:
            u, v = x, 0.0
        else:
            u, v = math.cos(x), math.sin(x)
        for i in range(12):
            L[i // 4, i % 4] = u * basis[k, i, 0] + v * basis[k, i, 1] + basis[k, i, 2]
        p = parents[k]
        if p < 0:
            W[k] = L
        else:
            for i in range(3):
                for j in range(4):
                    W[k, i, j] = W[p, i, 0] * L[0, j] + W[p, i, 1] * L[1, j] + W[p, i, 2] * L[2, j]
                W[k, i, 3] += W[p, i, 3]
    last = F - 1
    for i in range(3):
        for j in range(4):
            T[i, j] = W[last, i, 0] * Ktip[0, j] + W[last, i, 1] * Ktip[1, j] + W[last, i, 2] * Ktip[2, j]
        T[i, 3] += W[last, i, 3]
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0
    J[:, :] = 0.0
    for k in range(F):
        c = cols[k]
        zx, zy, zz = W[k, 0, 2], W[k, 1, 2], W[k, 2, 2]
        if prismatic[k]:
            J[0, c], J[1, c], J[2, c] = zx, zy, zz
        else:
            dx, dy, dz = T[0, 3] - W[k, 0, 3], T[1, 3] - W[k, 1, 3], T[2, 3] - W[k, 2, 3]
            J[0, c] = zy * dz - zz * dy
            J[1, c] = zz * dx - zx * dz
            J[2, c] = zx * dy - zy * dx
            J[3, c], J[4, c], J[5, c] = zx, zy, zz


@nb.njit(cache=True, nogil=True)
def pose_error(T, Tt, e) -> None:
    """e (6,) = position difference and rotation vector taking T's orientation to Tt's, root frame:
    `transforms.pose_error`'s formulas (atan2 of |v|/2 and the trace; the axis from (R + I)/2 near π)."""
    for i in range(3):
        e[i] = Tt[i, 3] - T[i, 3]
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = Tt[i, 0] * T[j, 0] + Tt[i, 1] * T[j, 1] + Tt[i, 2] * T[j, 2]  # Rt · Rᵀ
    cos = min(max((R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0, -1.0), 1.0)
    vx, vy, vz = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    s = min(math.sqrt(vx * vx + vy * vy + vz * vz) / 2.0, 1.0)
    angle = math.atan2(s, cos)
    if s > 1e-6:
        scale = angle / (2.0 * s)
    elif not cos < 0:
        scale = 0.5
    else:  # angle ≈ π: the axis is the row of (R + I)/2 with the largest diagonal entry (the first maximum)
        r = 0
        for i in range(1, 3):
            if R[i, i] > R[r, r]:
                r = i
        ax = (R[r, 0] + (1.0 if r == 0 else 0.0)) / 2.0
        ay = (R[r, 1] + (1.0 if r == 1 else 0.0)) / 2.0
        az = (R[r, 2] + (1.0 if r == 2 else 0.0)) / 2.0
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        e[3], e[4], e[5] = ax / norm * angle, ay / norm * angle, az / norm * angle
        return
    e[3], e[4], e[5] = vx * scale, vy * scale, vz * scale


@nb.njit(cache=True, nogil=True)
def _solve_spd6(A, b, x) -> None:
    """x = A⁻¹ b for a symmetric positive definite 6×6 A (J Jᵀ + λ² I), by Cholesky; A is overwritten."""
    for j in range(6):
        d = A[j, j]
        for k in range(j):
            d -= A[j, k] * A[j, k]
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, 6):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / d
    for i in range(6):  # L y = b
        s = b[i]
        for k in range(i):
            s -= A[i, k] * x[k]
        x[i] = s / A[i, i]
    for i in range(5, -1, -1):  # Lᵀ x = y
        s = x[i]
        for k in range(i + 1, 6):
            s -= A[k, i] * x[k]
        x[i] = s / A[i, i]


@nb.njit(cache=True, nogil=True)
def dls_batch(T_targets, seeds, lower, upper, tol_pos, tol_rot, iterations, damping, max_step,
              cols, parents, prismatic, basis, Ktip):
    """solver.solve_ik_batch's loop, each seed on its own: q clipped to the limits, then per iteration the
    pose error, a stop once within (tol_pos, tol_rot), else Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e scaled so that no
    joint moves more than max_step, clipped. Returns (q (S, n), converged (S,), error (S, 2))."""
    S, n = seeds.shape
    q = np.empty((S, n))
    ok = np.zeros(S, dtype=np.bool_)
    err = np.empty((S, 2))
    W = np.empty((cols.shape[0], 3, 4))
    T = np.empty((4, 4))
    J = np.empty((6, n))
    e = np.empty(6)
    A = np.empty((6, 6))
    x = np.empty(6)
    dq = np.empty(n)
    lam2 = damping * damping
    for s in range(S):
        for i in range(n):
            q[s, i] = min(max(seeds[s, i], lower[i]), upper[i])
        for it in range(iterations + 1):
            chain_pose_jacobian(q[s], cols, parents, prismatic, basis, Ktip, W, T, J)
            pose_error(T, T_targets[s], e)
            ep = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            er = math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
            err[s, 0], err[s, 1] = ep, er
            if ep <= tol_pos and er <= tol_rot:
                ok[s] = True
                break
            if it == iterations:
                break
            for i in range(6):
                for j in range(i + 1):
                    a = 0.0
                    for c in range(n):
                        a += J[i, c] * J[j, c]
                    A[i, j] = a
                    A[j, i] = a
                A[i, i] += lam2
            _solve_spd6(A, e, x)
            m = 1e-12
            for c in range(n):
                d = 0.0
                for i in range(6):
                    d += J[i, c] * x[i]
                dq[c] = d
                m = max(m, abs(d))
            scale = min(1.0, max_step / m)
            for c in range(n):
                q[s, c] = min(max(q[s, c] + dq[c] * scale, lower[c]), upper[c])
    return q, ok, err


def warm() -> None:
    """Compile (or load from the cache) the kernels for the argument types GroupKinematics passes."""
    i, b = np.int64, np.bool_
    cols, parents, prismatic = np.zeros(1, i), np.full(1, -1, i), np.zeros(1, b)
    basis, Ktip = np.zeros((1, 16, 3)), np.eye(4)
    dls_batch(np.eye(4)[None], np.zeros((1, 1)), np.full(1, -1.0), np.ones(1), 0.002, 0.0174, 1, 0.05, 0.4,
              cols, parents, prismatic, basis, Ktip)


if __name__ == "__main__":
    warm()
