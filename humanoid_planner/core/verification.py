"""Independent checks of a finished plan: what the tests, the benchmark and the demo assert.

Deliberately slow and simple: exact FCL on every pair (no sphere prefilter) at a fine resolution,
FK from the generic RobotModel path (not the planners' compiled kinematics), limits from the model.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, attach
from humanoid_planner.core.transforms import pose_distance


def dense(path: np.ndarray, resolution: float) -> np.ndarray:
    """Every segment of a path interpolated so that no joint moves more than `resolution`."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.max(np.abs(b - a)) / resolution)))
        out.append(a + np.outer(np.arange(1, k + 1) / k, b - a))
    return np.vstack(out)


def _leaves_limits(robot: RobotModel, idx: np.ndarray, pos: np.ndarray) -> bool:
    """Does any position leave its joint's limits? Continuous joints have none (angles wrap)."""
    bounded = ~robot.continuous[idx]
    p = pos[:, bounded]
    return bool(np.any(p < robot.lower[idx][bounded] - 1e-9) or np.any(p > robot.upper[idx][bounded] + 1e-9))


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
    if _leaves_limits(robot, idx, pos):
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
    exact = CollisionChecker(robot, scene, groups, start,
                             CheckerSettings(grasp_object_id=object_id or None, hand_links=hands))
    for q in dense(pos, resolution):
        if not exact.exact_check(q):
            problems.append(f"collision at configuration {np.round(q, 3).tolist()}")
            break
    return problems


def _tcp_poses(robot: RobotModel, groups: tuple[str, ...], start: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(K, G, 4, 4) TCP poses of each group along group-joint positions (K, n), generic FK."""
    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    Q = np.repeat(np.asarray(start, float)[None], len(positions), axis=0)
    Q[:, idx] = positions
    return robot.link_poses(Q, [robot.group(g).tip_link for g in groups])


def verify_straight(robot: RobotModel, groups: tuple[str, ...], start: np.ndarray, positions: np.ndarray,
                    direction: np.ndarray, *, min_distance: float = 0.0, resolution: float = 0.005,
                    tol_pos: float = 0.002, tol_rot: float = np.radians(1.0)) -> list[str]:
    """Problems of a straight-line TCP segment (empty list = all good): along `positions` (densified
    to `resolution` rad) each group's TCP stays within tol_pos of the line from its first pose along
    the world `direction`, keeps its orientation within tol_rot, never moves backwards along it by
    more than tol_pos, and advances at least min_distance. Several groups: also their TCPs' relative
    pose stays within the tolerances (a rigid object between the hands)."""
    problems: list[str] = []
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    P = _tcp_poses(robot, groups, start, dense(np.atleast_2d(positions), resolution))
    for k, g in enumerate(groups):
        T = P[:, k]
        rel = T[:, :3, 3] - T[0, :3, 3]
        along = rel @ d
        off = np.linalg.norm(rel - along[:, None] * d, axis=1)
        rot = np.array([pose_distance(T[0], Ti)[1] for Ti in T])
        if off.max() > tol_pos:
            problems.append(f"{g}: TCP leaves the line by {off.max() * 1000:.2f} mm")
        if rot.max() > tol_rot:
            problems.append(f"{g}: TCP turns by {np.degrees(rot.max()):.2f} deg along the line")
        if np.any(along < np.maximum.accumulate(along) - tol_pos):
            problems.append(f"{g}: TCP moves backwards along the line")
        if along[-1] < min_distance - 1e-6:
            problems.append(f"{g}: line is {along[-1] * 1000:.1f} mm long, less than {min_distance * 1000:.1f} mm")
    if len(groups) > 1:
        for k in range(1, len(groups)):
            R0 = np.linalg.inv(P[0, 0]) @ P[0, k]
            errs = [pose_distance(np.linalg.inv(P[i, 0]) @ P[i, k], R0) for i in range(len(P))]
            dp, dr = max(e[0] for e in errs), max(e[1] for e in errs)
            if dp > tol_pos or dr > tol_rot:
                problems.append(f"{groups[0]} and {groups[k]}: relative TCP pose drifts by {dp * 1000:.2f} mm / "
                                f"{np.degrees(dr):.2f} deg")
    return problems


def verify_retreat(robot: RobotModel, scene: SceneSnapshot, groups: tuple[str, ...], start: np.ndarray, plan,
                   direction: np.ndarray, *, object_id: str = "", min_distance: float = 0.0,
                   resolution: float = 0.01) -> list[str]:
    """Problems of a plan's retreat (empty list = all good): it starts where `trajectory` ends, stays
    within the joint limits, is a straight line (verify_straight, both TCPs by the same displacement),
    and is collision-free — exact FCL at `resolution` — with the object `object_id` attached to the
    first group's TCP link where the trajectory leaves it, allowed to touch only the hands' links."""
    problems: list[str] = []
    traj = plan.retreat_trajectory
    if traj is None or len(traj.positions) == 0:
        return ["no retreat trajectory"]
    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    pos = traj.positions
    if not np.allclose(pos[0], plan.trajectory.positions[-1], atol=1e-9):
        problems.append("retreat does not start where the trajectory ends")
    if _leaves_limits(robot, idx, pos):
        problems.append("retreat leaves the joint limits")
    if np.any(np.diff(traj.times) <= 0):
        problems.append("retreat times are not strictly increasing")
    problems += verify_straight(robot, groups, start, pos, direction, min_distance=min_distance)
    hands: tuple[str, ...] = ()
    for g in groups:
        hands += robot.hand_links(g)
    held_scene = scene
    obj = scene.get(object_id) if object_id else None
    if obj is not None:
        tip = robot.group(groups[0]).tip_link
        T_tip = _tcp_poses(robot, groups, start, pos[:1])[0, 0]
        held_scene = replace(scene, objects=tuple(o for o in scene.objects if o.id != object_id),
                             attached=scene.attached + (attach(obj, tip, T_tip, hands),))
    exact = CollisionChecker(robot, held_scene, groups, start)
    for q in dense(pos, resolution):
        if not exact.exact_check(q):
            problems.append(f"retreat collides (object in hand) at configuration {np.round(q, 3).tolist()}")
            break
    return problems


def _first_collision(checker: CollisionChecker, positions: np.ndarray, resolution: float) -> np.ndarray | None:
    for q in dense(positions, resolution):
        if not checker.exact_check(q):
            return q
    return None


def verify_place(robot: RobotModel, scene: SceneSnapshot, group: str, start: np.ndarray, plan, object_id: str,
                 placement: np.ndarray, support: Sequence[str], approach_direction: np.ndarray, *,
                 approach_min: float = 0.0, retreat_direction: np.ndarray | None = None, retreat_min: float = 0.0,
                 retreat_in_tcp: bool = False, resolution: float = 0.01) -> list[str]:
    """Problems of a one-arm place plan (empty list = all good). scene: as planned from, `object_id`
    attached to the hand; placement: the object's pose it must end at; support: the scene objects it
    may touch there (what it stands on). Checked here, without the planner's support logic:
    verify_plan against the scene without the supports (object carried, it ends exactly at
    `placement`); the robot never touches a support, the object only during the straight descent
    (the trajectory from plan.approach_time on), which goes along `approach_direction` for at least
    approach_min; the retreat (plan.retreat_trajectory, when there is one) starts where the descent
    ends, goes straight along retreat_direction (world, or with retreat_in_tcp the TCP frame at the
    descent's end; None: the TCP's -z there) for at least retreat_min, and is collision-free with the
    object released at the placement, which the hand may touch only until it is first clear of it
    (it ends clear of it, where a next plan starts)."""
    att = next((a for a in scene.attached if a.id == object_id), None)
    if att is None:
        return [f"{object_id!r} is not attached in the scene"]
    idx = robot.group_joint_indices(group)
    tip = robot.group(group).tip_link
    T_tip, T_link = robot.link_poses(start, [tip, att.link])
    T_tcp_obj = np.linalg.inv(T_tip) @ T_link @ att.pose
    placement = np.asarray(placement, float)
    others = tuple(o for o in scene.objects if o.id not in support)
    problems = verify_plan(robot, replace(scene, objects=others), (group,), start, plan,
                           (placement @ np.linalg.inv(T_tcp_obj),), resolution=resolution)
    supports = tuple(o for o in scene.objects if o.id in support)
    traj = plan.trajectory
    pos, t = traj.positions, traj.times
    if supports:
        bare = CollisionChecker(robot, replace(scene, objects=supports, attached=()), group, start)
        if (q := _first_collision(bare, pos, resolution)) is not None:
            problems.append(f"the robot touches a support at {np.round(q, 3).tolist()}")
        carry = t < plan.approach_time - 1e-9
        held = CollisionChecker(robot, replace(scene, objects=supports, attached=(att,)), group, start)
        if carry.sum() > 1 and (q := _first_collision(held, pos[carry], resolution)) is not None:
            problems.append(f"the object touches a support before the descent at {np.round(q, 3).tolist()}")
    descent = pos[t >= plan.approach_time - 1e-9]
    if len(descent) < 2:
        problems.append("no straight descent at the end of the trajectory")
    else:
        problems += [f"descent: {p}" for p in verify_straight(robot, (group,), start, descent, approach_direction,
                                                              min_distance=approach_min)]
    back = getattr(plan, "retreat_trajectory", None)
    if back is None or len(back.positions) == 0:
        return problems + (["no retreat trajectory"] if retreat_min > 0 else [])
    if not np.allclose(back.positions[0], pos[-1], atol=1e-9):
        problems.append("retreat does not start where the descent ends")
    if _leaves_limits(robot, idx, back.positions):
        problems.append("retreat leaves the joint limits")
    q_end = np.asarray(start, float).copy()
    q_end[idx] = pos[-1]
    T_end = robot.link_poses(q_end, [tip])[0]
    if retreat_direction is None:
        d = -T_end[:3, 2]
    elif retreat_in_tcp:
        d = T_end[:3, :3] @ np.asarray(retreat_direction, float)
    else:
        d = np.asarray(retreat_direction, float)
    problems += [f"retreat: {p}" for p in verify_straight(robot, (group,), start, back.positions, d,
                                                          min_distance=retreat_min)]
    placed = SceneObject(object_id, placement, att.shapes)
    released = replace(scene, objects=scene.objects + (placed,), attached=tuple(a for a in scene.attached
                                                                                   if a.id != object_id))
    free = CollisionChecker(robot, released, group, start,
                            CheckerSettings(grasp_object_id=object_id, hand_links=robot.hand_links(group)))
    if (q := _first_collision(free, back.positions, resolution)) is not None:
        problems.append(f"retreat collides (object released) at {np.round(q, 3).tolist()}")
    return problems + verify_release(robot, released, (group,), start, back.positions, resolution)


def verify_release(robot: RobotModel, released: SceneSnapshot, groups: Sequence[str], start: np.ndarray,
                   positions: np.ndarray, resolution: float = 0.01) -> list[str]:
    """Problems of a retreat after a release (`released`: the object standing where it was let go,
    nothing exempt): the hand(s) may touch it only until first clear of it, and end clear of it."""
    strict = CollisionChecker(robot, released, tuple(groups), start)
    samples = dense(positions, resolution)
    off = np.array([strict.exact_check(q) for q in samples], dtype=bool)
    if not off[-1]:
        return [f"retreat ends touching the released object: {strict.colliding_pairs(samples[-1])[:4]}"]
    if not off[np.argmax(off):].all():
        q = samples[np.argmax(off) + np.argmin(off[np.argmax(off):])]
        return [f"retreat touches the released object again after leaving it, at {np.round(q, 3).tolist()}"]
    return []
