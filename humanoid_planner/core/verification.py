"""Independent checks of a finished plan: what the tests, the benchmark and the demo assert.

Deliberately slow and simple: exact FCL on every pair (no sphere prefilter) at a fine resolution,
FK from the generic RobotModel path (not the planners' compiled kinematics), limits from the model.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneSnapshot
from humanoid_planner.core.transforms import pose_distance


def dense(path: np.ndarray, resolution: float) -> np.ndarray:
    """Every segment of a path interpolated so that no joint moves more than `resolution`."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.max(np.abs(b - a)) / resolution)))
        out.append(a + np.outer(np.arange(1, k + 1) / k, b - a))
    return np.vstack(out)


def verify_plan(robot: RobotModel, scene: SceneSnapshot, groups: tuple[str, ...], start: np.ndarray,
                plan, targets: tuple[np.ndarray, ...], *, object_id: str = "", resolution: float = 0.01,
                tol_pos: float = 0.002, tol_rot: float = np.radians(1.0)) -> list[str]:
    """Problems found in a successful GraspPlan (empty list = all good).

    targets: the TCP target pose of each group's reached grasp (T_world_object @ tcp_in_object).
    """
    problems: list[str] = []
    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    traj = plan.trajectory
    pos = traj.positions
    if not np.allclose(pos[0], start[idx], atol=1e-9):
        problems.append("trajectory does not start at the start state")
    if not np.allclose(plan.path[0], start[idx], atol=1e-9):
        problems.append("path does not start at the start state")
    lo, hi = robot.lower[idx] - 1e-9, robot.upper[idx] + 1e-9
    if np.any(pos < lo) or np.any(pos > hi):
        problems.append("trajectory leaves the joint limits")
    t = traj.times
    if np.any(np.diff(t) <= 0) or t[0] != 0.0:
        problems.append("times are not strictly increasing from 0")
    vmax = robot.max_velocity[idx] * (1 + 1e-6)
    amax = robot.max_acceleration[idx] * (1 + 1e-3)
    if np.any(np.abs(traj.velocities) > vmax):
        problems.append(f"velocity limit exceeded: {np.max(np.abs(traj.velocities) / vmax):.3f}x")
    if np.any(np.abs(traj.accelerations) > amax):
        problems.append(f"acceleration limit exceeded: {np.max(np.abs(traj.accelerations) / amax):.3f}x")
    # TCP at the end, through the generic FK
    q_end = start.copy()
    q_end[idx] = pos[-1]
    for g, T_target in zip(groups, targets):
        T = robot.link_poses(q_end, [robot.group(g).tip_link])[0]
        dp, dr = pose_distance(T, T_target)
        if dp > tol_pos or dr > tol_rot:
            problems.append(f"{g}: TCP misses the grasp by {dp * 1000:.2f} mm / {np.degrees(dr):.2f} deg")
    # collision-free, exact, at fine resolution, along the timed samples
    hands: tuple[str, ...] = ()
    for g in groups:
        hands += robot.hand_links(g)
    exact = CollisionChecker(robot, scene, groups, start, grasp_object_id=object_id or None, hand_links=hands)
    for q in dense(pos, resolution):
        if not exact.exact_check(q):
            problems.append(f"collision at configuration {np.round(q, 3).tolist()}")
            break
    return problems
