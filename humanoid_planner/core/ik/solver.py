"""Batched multi-start inverse kinematics (damped least squares), for reachability and goal sampling.

Not the papers' Jacobian approach (that is `geninv.steer_to_pose`, one step-limited branch of the
tree): this one solves many seeds × grasps at once in numpy to answer "is any grasp reachable at
all?" within milliseconds and to give the baseline planners goal configurations.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.transforms import pose_error

DEFAULT_ITERATIONS = 120  # damped least-squares iterations per solve; a start that has not converged by then
# rarely does, and the batch carries other starts


def solve_ik_batch(kin, T_targets: np.ndarray, seeds: np.ndarray, lower: np.ndarray, upper: np.ndarray, *,
                   tol_pos: float = 0.002, tol_rot: float = 0.0174, iterations: int = DEFAULT_ITERATIONS,
                   damping: float = 0.05, max_step: float = 0.4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solve S problems (target S, seed S) at once; joints clipped to limits every iteration.

    Returns (q (S, n), converged (S,), error (S, 2) = position m, rotation rad).
    """
    q = np.clip(np.array(seeds, dtype=float), lower, upper)
    S, n = q.shape
    active = np.ones(S, dtype=bool)
    lam2 = damping ** 2
    eye6 = np.eye(6)
    for _ in range(iterations):
        idx = np.nonzero(active)[0]
        if len(idx) == 0:
            break
        T, J = kin.fk_jacobian(q[idx])
        e = pose_error(T, T_targets[idx])
        ep, er = np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)
        done = (ep <= tol_pos) & (er <= tol_rot)
        active[idx[done]] = False
        keep = ~done
        if not np.any(keep):
            break
        idx, J, e = idx[keep], J[keep], e[keep]
        JJt = J @ np.swapaxes(J, 1, 2) + lam2 * eye6
        dq = (np.swapaxes(J, 1, 2) @ np.linalg.solve(JJt, e[:, :, None]))[:, :, 0]
        scale = np.minimum(1.0, max_step / np.maximum(np.max(np.abs(dq), axis=1), 1e-12))
        q[idx] = np.clip(q[idx] + dq * scale[:, None], lower, upper)
    T = kin.fk(q)
    e = pose_error(T, T_targets)
    err = np.stack([np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)], axis=1)
    ok = (err[:, 0] <= tol_pos) & (err[:, 1] <= tol_rot)
    return q, ok, err
