"""Compiled (numba) inverse kinematics: a group's TCP pose and geometric Jacobian for one configuration, the
pose error, the batched damped-least-squares loop of `solver.solve_ik_batch`, and the generalized inverses
with the Jacobian-steered loop of `geninv.steer_to_pose` (`steer`) and a straight line's waypoints
(`line`, `line_deviation`: cartesian.straight_line).

Why compiled: a plan's IK is many small problems (up to a few hundred seeds × grasps, ≤ 120 iterations
each), and in numpy every iteration is some 20 calls on (S, 6, n) arrays whose overhead is most of the cost:
a batch of the Panda's hints took ~24 ms, a third of a plan into an open shelf. Here each seed runs its own
loop on scalars and 6×6 systems, and stops the moment it converges. The steering loop likewise: a step in
numpy costs ~40 µs of call overhead (FK, Jacobian, SVD, weights, pose error), ~5 µs here, and a plan's approach
and exit lines take hundreds of them.

The chain is `KinematicTree.kernel_arrays` (frames W_k = W_parent · L_k(q), L_k = u·A_k + v·B_k + C_k with
(u, v) = (cos, sin), or (q, 0) when prismatic) and the TCP's constant offset from the last frame, as
`kinematics.GroupKinematics` computes them in numpy (same formulas: the two agree to rounding).
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from humanoid_planner.core.collision.kernels import local_transform


@nb.njit(cache=True, nogil=True)
def chain_pose(q, cols, parents, prismatic, basis, Ktip, W, T) -> None:
    """TCP pose T (4, 4) of one group configuration q (n,); W (F, 3, 4) gets the frames (their top three rows).
    A frame's local transform goes into W[k] first and is read back as scalars: no scratch array per call
    (IK calls this once per iteration, hundreds of thousands of times per plan)."""
    F = cols.shape[0]
    for k in range(F):
        local_transform(basis, k, q[cols[k]], prismatic[k], W[k])
        p = parents[k]
        if p >= 0:
            a0, a1, a2, a3 = W[k, 0, 0], W[k, 0, 1], W[k, 0, 2], W[k, 0, 3]
            b0, b1, b2, b3 = W[k, 1, 0], W[k, 1, 1], W[k, 1, 2], W[k, 1, 3]
            c0, c1, c2, c3 = W[k, 2, 0], W[k, 2, 1], W[k, 2, 2], W[k, 2, 3]
            for i in range(3):
                x, y, z = W[p, i, 0], W[p, i, 1], W[p, i, 2]
                W[k, i, 0] = x * a0 + y * b0 + z * c0
                W[k, i, 1] = x * a1 + y * b1 + z * c1
                W[k, i, 2] = x * a2 + y * b2 + z * c2
                W[k, i, 3] = x * a3 + y * b3 + z * c3 + W[p, i, 3]
    last = F - 1
    for i in range(3):
        for j in range(4):
            T[i, j] = W[last, i, 0] * Ktip[0, j] + W[last, i, 1] * Ktip[1, j] + W[last, i, 2] * Ktip[2, j]
        T[i, 3] += W[last, i, 3]
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0


@nb.njit(cache=True, nogil=True)
def chain_pose_jacobian(q, cols, parents, prismatic, basis, Ktip, W, T, J) -> None:
    """TCP pose T (4, 4) and 6×n geometric Jacobian J (linear rows first) of one group configuration q (n,).
    W (F, 3, 4): scratch for the frames (their top three rows). A group column without a frame keeps a zero
    Jacobian column."""
    F = cols.shape[0]
    chain_pose(q, cols, parents, prismatic, basis, Ktip, W, T)
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
def dls_batch(T_targets, seeds, lower, upper, tol_pos, tol_rot, iterations, damping, max_step, stall, stall_gain,
              cols, parents, prismatic, basis, Ktip):
    """solver.solve_ik_batch's loop, each seed on its own: q clipped to the limits, then per iteration the
    pose error, a stop once within (tol_pos, tol_rot), else Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e scaled so that no
    joint moves more than max_step, clipped. stall > 0: a seed is given up once its error, in tolerances
    (ep / tol_pos + er / tol_rot), has not shrunk by the share stall_gain over the last `stall` iterations.
    Returns (q (S, n), converged (S,), error (S, 2))."""
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
    hist = np.empty(max(stall, 1))
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
            if stall > 0:
                togo = ep / tol_pos + er / tol_rot
                if it >= stall and togo > (1.0 - stall_gain) * hist[it % stall]:
                    break
                hist[it % stall] = togo
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


# steer's status codes (geninv.STEER_STATUS names them)
STEER_REACHED, STEER_MAX_ITERS, STEER_JOINT_LIMIT, STEER_STALLED = 0, 1, 2, 3


@nb.njit(cache=True, nogil=True, error_model="numpy")
def limit_gradient(q, lo, hi, g) -> None:
    """g (n,) = ∂H/∂θ of the joint-limit cost H (the GIRRT paper eq. 26): (θmax − θmin)² (2θ − θmax − θmin) /
    (4 (θmax − θ)² (θ − θmin)²); ±∞ at or beyond a limit, 0 for a joint without a finite range."""
    for i in range(q.shape[0]):
        lo_i, hi_i = lo[i], hi[i]
        if not (math.isfinite(lo_i) and math.isfinite(hi_i) and hi_i > lo_i):
            g[i] = 0.0
            continue
        x = q[i]
        a, b = hi_i - x, x - lo_i
        if a > 0.0 and b > 0.0:
            ab = a * b  # (ab)² may underflow to 0 right at a limit: ±∞ then, as there
            g[i] = (hi_i - lo_i) * (hi_i - lo_i) / 4.0 * (b - a) / (ab * ab)
        else:
            g[i] = math.inf if x >= hi_i else -math.inf


@nb.njit(cache=True, nogil=True, error_model="numpy")
def limit_weights(q, lo, hi, prev, has_prev, w, g) -> None:
    """Eq. 28: w (n,) = 1 + |∂H/∂θ_i| while joint i moves toward a limit (Δ|∂H/∂θ_i| ≥ 0 against prev, the
    previous step's gradient, or always when has_prev is False), else 1; g (n,) = ∂H/∂θ at q. At a limit on
    both steps Δ is ∞ − ∞ = nan, which is not ≥ 0: w = 1, and the joint may leave the limit."""
    limit_gradient(q, lo, hi, g)
    for i in range(q.shape[0]):
        mag = abs(g[i])
        w[i] = 1.0 + mag if not has_prev or mag - abs(prev[i]) >= 0.0 else 1.0


@nb.njit(cache=True, nogil=True, error_model="numpy")
def damped_pinv(A, eps, lam_max, P) -> None:
    """P (n, m) = damped pseudo-inverse of A (m, n), the DAGRRT paper eq. 9–12 (Maciejewski & Klein):
    Σ σ_i / (σ_i² + λ²) v_i u_iᵀ with λ² = (1 − (σ_min/ε)²) λ_max² when σ_min < ε, else 0 (a term whose
    σ_i² + λ² is 0 is left out)."""
    m, n = A.shape
    P[:, :] = 0.0
    if m == 0 or n == 0:
        return
    U, S, Vt = np.linalg.svd(A, full_matrices=False)
    r = S.shape[0]
    smin = S[r - 1]
    lam2 = (1.0 - (smin / eps) ** 2) * lam_max ** 2 if smin < eps else 0.0
    for k in range(r):
        den = S[k] * S[k] + lam2
        if not den > 0.0:
            continue
        inv = S[k] / den
        for c in range(n):
            v = Vt[k, c] * inv
            for i in range(m):
                P[c, i] += v * U[i, k]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def wln_pinv(J, q, lo, hi, prev, has_prev, eps, lam_max, P, g) -> None:
    """P (n, m) = the weighted least-norm inverse of J (m, n), the GIRRT paper eq. 27 with eq. 28's weights
    (limit_weights: prev, has_prev; g gets ∂H/∂θ at q, the next step's prev), as W^-½ · pinv(J W^-½) with
    the damped pseudo-inverse: eq. 27 while J W⁻¹ Jᵀ is well conditioned, bounded near a singularity. A
    joint pushed into its limit has w = ∞, i.e. a zero row: it does not move."""
    m, n = J.shape
    w = np.empty(n)
    limit_weights(q, lo, hi, prev, has_prev, w, g)
    Jw = np.empty((m, n))
    for c in range(n):
        w[c] = 1.0 / math.sqrt(w[c])  # W^-½; w ≥ 1, and w = ∞ gives exactly 0
        for i in range(m):
            Jw[i, c] = J[i, c] * w[c]
    damped_pinv(Jw, eps, lam_max, P)
    for c in range(n):
        for i in range(m):
            P[c, i] *= w[c]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def steer(q0, T_target, wln, max_step_pos, max_step_rot, max_joint_step, tol_pos, tol_rot, max_iters, lo, hi,
          eps, lam_max, stall_iters, nullspace_gain, has_start, T, J, steps, errs,
          cols, parents, prismatic, basis, Ktip):
    """geninv.steer_to_pose's loop (see there) without its is_valid callback: the steps into steps
    (max_iters, n), each iteration's (position, rotation) error into errs (max_iters + 1, 2), and T, J
    (4x4, 6×n) left at the last configuration's pose and Jacobian; on entry they hold q0's when has_start.
    wln: the weighted least-norm inverse (eq. 27 with eq. 28's weights), else the damped SVD one.
    Returns (steps taken, status code, iterations, position error, rotation error)."""
    n = q0.shape[0]
    W = np.empty((cols.shape[0], 3, 4))
    e = np.empty(6)
    q = np.empty(n)
    qn = np.empty(n)
    dq = np.empty(n)
    g = np.empty(n)
    prev = np.empty(n)
    z = np.empty(n)
    Jz = np.empty(6)
    P = np.empty((n, 6))
    history = np.empty(max_iters + 1)
    for c in range(n):
        q[c] = min(max(q0[c], lo[c]), hi[c])
    k = 0
    for it in range(max_iters + 1):
        if it > 0 or not has_start:
            chain_pose_jacobian(q, cols, parents, prismatic, basis, Ktip, W, T, J)
        pose_error(T, T_target, e)
        ep = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        er = math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
        errs[it, 0], errs[it, 1] = ep, er
        if ep <= tol_pos and er <= tol_rot:
            return k, STEER_REACHED, it, ep, er
        if it == max_iters:
            return k, STEER_MAX_ITERS, it, ep, er
        # progress in "full steps still to go"; stalled = no net progress over the last stall_iters steps
        history[it] = ep / max_step_pos + er / max_step_rot
        if it >= stall_iters and history[it] >= history[it - stall_iters] * (1.0 - 1e-3):
            return k, _blocked(q, lo, hi), it, ep, er
        scale = min(1.0, max_step_pos / ep if ep > 0 else math.inf, max_step_rot / er if er > 0 else math.inf)
        if scale < 1.0:
            for i in range(6):
                e[i] *= scale
        if wln:
            wln_pinv(J, q, lo, hi, prev, it > 0, eps, lam_max, P, g)
            prev[:] = g
        else:
            damped_pinv(J, eps, lam_max, P)
        for c in range(n):
            d = 0.0
            for i in range(6):
                d += P[c, i] * e[i]
            dq[c] = d
        if nullspace_gain > 0.0:  # the GIRRT paper eq. 24 (Liégeois): descend H(θ) without moving the TCP
            if not wln:
                limit_gradient(q, lo, hi, g)
            zmax = 0.0
            for c in range(n):
                z[c] = -nullspace_gain * min(max(g[c], -1e6), 1e6)
                zmax = max(zmax, abs(z[c]))
            if zmax > 0.5 * max_joint_step:
                f = 0.5 * max_joint_step / zmax
                for c in range(n):
                    z[c] *= f
            for i in range(6):
                s = 0.0
                for c in range(n):
                    s += J[i, c] * z[c]
                Jz[i] = s
            for c in range(n):
                s = 0.0
                for i in range(6):
                    s += P[c, i] * Jz[i]
                dq[c] += z[c] - s
        m = 0.0
        for c in range(n):
            m = max(m, abs(dq[c]))
        f = max_joint_step / m if m > max_joint_step else 1.0
        moved = 0.0
        for c in range(n):
            qn[c] = min(max(q[c] + (dq[c] * f if f < 1.0 else dq[c]), lo[c]), hi[c])
            moved = max(moved, abs(qn[c] - q[c]))
        if moved < 1e-12:  # clipping left no motion
            return k, _blocked(q, lo, hi), it, ep, er
        steps[k] = qn
        q[:] = qn
        k += 1
    return k, STEER_MAX_ITERS, max_iters, math.nan, math.nan  # not reached: the loop returns at max_iters


@nb.njit(cache=True, nogil=True)
def _blocked(q, lo, hi) -> int:
    for c in range(q.shape[0]):
        if q[c] <= lo[c] + 1e-9 or q[c] >= hi[c] - 1e-9:
            return STEER_JOINT_LIMIT
    return STEER_STALLED


@nb.njit(cache=True, nogil=True)
def line_deviation(q_path, T0, d, samples, cols, parents, prismatic, basis, Ktip):
    """Per segment of q_path (M, n), sampled `samples` times (joint-space interpolation, the far end
    included): the largest TCP distance from the line through T0 along the unit d, the largest rotation
    away from T0's orientation, and the largest advance along the line. Returns three (M − 1,) arrays."""
    M, n = q_path.shape
    m = max(M - 1, 0)
    off, ang, along = np.empty(m), np.empty(m), np.empty(m)
    W = np.empty((cols.shape[0], 3, 4))
    T = np.empty((4, 4))
    e = np.empty(6)
    q = np.empty(n)
    for i in range(m):
        o, a, t = -math.inf, -math.inf, -math.inf
        for k in range(1, samples + 1):
            f = k / samples
            for c in range(n):
                q[c] = q_path[i, c] + f * (q_path[i + 1, c] - q_path[i, c])
            chain_pose(q, cols, parents, prismatic, basis, Ktip, W, T)
            pose_error(T, T0, e)  # position T0 − T, and the rotation between the two orientations
            rx, ry, rz = -e[0], -e[1], -e[2]
            s = rx * d[0] + ry * d[1] + rz * d[2]
            ox, oy, oz = rx - s * d[0], ry - s * d[1], rz - s * d[2]
            o = max(o, math.sqrt(ox * ox + oy * oy + oz * oz))
            a = max(a, math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5]))
            t = max(t, s)
        off[i], ang[i], along[i] = o, a, t
    return off, ang, along


# line's reason codes (cartesian.LINE_REASONS names them)
LINE_COMPLETE, LINE_IK, LINE_DEVIATION = 0, 1, 2


@nb.njit(cache=True, nogil=True, error_model="numpy")
def line(q0, T0, d, s, wln, max_step_pos, max_step_rot, max_joint_step, tol_pos, tol_end, tol_rot, max_iters,
         lo, hi, eps, lam_max, stall_iters, line_tol_pos, line_tol_rot, samples,
         cols, parents, prismatic, basis, Ktip):
    """cartesian.straight_line's waypoints: steer from q0 onto T0 moved s[j] along the unit direction d
    (orientation held), each from where the previous one ended and with its pose and Jacobian, the last one
    to tol_end, up to the first waypoint not reached (LINE_IK); then cut before the first segment whose TCP
    leaves the line by more than (line_tol_pos, line_tol_rot) at one of its `samples` samples
    (line_deviation; LINE_DEVIATION). Returns (waypoints (len(s), n), how many are kept, reason code)."""
    K, n = s.shape[0], q0.shape[0]
    path = np.empty((K + 1, n))  # q0, then the waypoints
    path[0] = q0
    q = q0.copy()
    Tt = np.empty((4, 4))
    T = np.empty((4, 4))
    J = np.empty((6, n))
    steps = np.empty((max_iters, n))
    errs = np.empty((max_iters + 1, 2))
    m, reason = K, LINE_COMPLETE
    for j in range(K):
        Tt[:, :] = T0
        for i in range(3):
            Tt[i, 3] += s[j] * d[i]
        k, status, _, _, _ = steer(q, Tt, wln, max_step_pos, max_step_rot, max_joint_step,
                                   tol_end if j == K - 1 else tol_pos, tol_rot, max_iters, lo, hi, eps, lam_max,
                                   stall_iters, 0.0, j > 0, T, J, steps, errs, cols, parents, prismatic, basis, Ktip)
        if status != STEER_REACHED:
            m, reason = j, LINE_IK
            break
        if k > 0:
            q[:] = steps[k - 1]
        path[j + 1] = q
    off, ang, _ = line_deviation(path[:m + 1], T0, d, samples, cols, parents, prismatic, basis, Ktip)
    for i in range(m):
        if off[i] > line_tol_pos or ang[i] > line_tol_rot:
            m, reason = i, LINE_DEVIATION
            break
    return path[1:], m, reason


def c_array(a) -> np.ndarray:
    """a as the kernels are compiled for: float64, C-contiguous and writeable (numba compiles a read-only
    array, e.g. a broadcast view, as another type: a second compilation on first use)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def warm() -> None:
    """Compile (or load from the cache) the kernels for the argument types GroupKinematics passes."""
    i, b = np.int64, np.bool_
    cols, parents, prismatic = np.zeros(1, i), np.full(1, -1, i), np.zeros(1, b)
    basis, Ktip = np.zeros((1, 16, 3)), np.eye(4)
    dls_batch(np.eye(4)[None], np.zeros((1, 1)), np.full(1, -1.0), np.ones(1), 0.002, 0.0174, 1, 0.05, 0.4, 10, 0.05,
              cols, parents, prismatic, basis, Ktip)
    n = 1
    T, J = np.empty((4, 4)), np.empty((6, n))
    lo, hi = np.full(n, -1.0), np.ones(n)
    steer(np.zeros(n), np.eye(4), True, 0.02, 0.1, 0.1, 1e-3, 0.01, 2, lo, hi, 0.05, 0.05, 15, 0.0, False, T, J,
          np.empty((2, n)), np.empty((3, 2)), cols, parents, prismatic, basis, Ktip)
    line(np.zeros(n), np.eye(4), np.array([1.0, 0.0, 0.0]), np.array([0.01]), True, 0.02, 0.05, 0.1, 2e-4, 1e-5,
         0.002, 2, lo, hi, 0.05, 0.05, 15, 0.002, 0.0175, 4, cols, parents, prismatic, basis, Ktip)
    line_deviation(np.zeros((2, n)), np.eye(4), np.array([1.0, 0.0, 0.0]), 4, cols, parents, prismatic, basis, Ktip)
    wln_pinv(np.ones((6, n)), np.zeros(n), lo, hi, np.zeros(n), True, 0.05, 0.05, np.empty((n, 6)), np.empty(n))
    limit_gradient(np.zeros(n), lo, hi, np.empty(n))
    limit_weights(np.zeros(n), lo, hi, np.zeros(n), False, np.empty(n), np.empty(n))
    damped_pinv(np.ones((6, n)), 0.05, 0.05, np.empty((n, 6)))


if __name__ == "__main__":
    warm()
