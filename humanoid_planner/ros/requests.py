"""plan_grasp / plan_dual_grasp / plan_to_state / plan_place / plan_dual_place: request messages -> checked core requests, plans -> responses.

Everything a request can get wrong is found before the request is queued for planning, and reported
as a `RequestError` carrying the ErrorCode value and a message that names the field: what only a
message can get wrong here (conversion), the rest by the core's own checks of the converted request
(`core/pipeline/validation.py`: groups, planner, start limits, usable grasps, approach / retreat),
whose PlanStatus maps to the ErrorCode through `ERROR_CODES`:

- INVALID_GROUP_NAME (-15): unknown group, a group without joints, dual groups sharing a joint;
- INVALID_ROBOT_STATE (-17): start_state with an unknown or duplicate joint name, names/positions
  of different lengths, NaN/inf, or (merged) outside the joint limits;
- INVALID_OBJECT_NAME (-19): object_id not in the scene;
- FRAME_TRANSFORM_FAILURE (-21): object_pose's or a place_poses[i]'s header.frame_id neither "", the planning frame nor a robot link; a
  pre_grasp_approach / post_grasp_retreat direction frame that is neither "", the planning frame nor
  a robot link;
- INVALID_GOAL_CONSTRAINTS (-16): object_pose NaN/inf or a zero / clearly non-unit quaternion; a
  malformed grasp; no grasp at all, or none the group's hand may use; an approach / retreat with a
  zero or non-finite direction, a negative or non-finite distance, or min_distance > desired_distance;
  plan_to_state: both or neither of named_state and goal_state, an unknown group_state, a goal_state
  with names and positions of different lengths, a duplicate, unknown, missing or other group's
  joint, NaN/inf or a value outside the limits (and, when planned, a goal in collision: the pairs);
  plan_place / plan_dual_place: place_poses empty, NaN/inf or a malformed quaternion, or every
  placement putting the object in collision (the pairs);
- INVALID_OBJECT_NAME (-19), place: object_id empty, not attached, or not held by the group's hand
  (dual: by both hands);
- FAILURE (99999): unknown planner; timeout < 0, NaN or inf; a velocity/acceleration scaling
  outside (0, 1] (0 means 1; below 1e-4 refused) or NaN; min_grasp_score NaN or inf; more grasps
  than `max_grasps_per_request`.

A timeout above `max_timeout` is clamped to it and the response's message says so (a plan never
holds a planning thread longer than that). Grasps without an id are named "#<k>" (their position in
the list), so the grasp a response reports is never ambiguous; two grasps with the same id are
INVALID_GOAL_CONSTRAINTS.

ErrorCode has no value for "a request parameter is out of its range" (MoveIt has none either), so
those return FAILURE with a message naming the field. Outcomes of planning map from
`PlanStatus` through `ERROR_CODES` (one table); CANCELLED (the node is shutting down) is FAILURE.

Defaults: timeout 0 -> the `default_timeout` parameter; scaling 0 -> 1; min_grasp_score <= 0 ->
the `min_grasp_score` parameter; planner "" -> girrt / dagrrt / rrt_connect; seed 0 -> nondeterministic.
Start state: the request's joints merged over the latest `joint_states` (its unknown joints and
non-finite values ignored), else over the robot's home pose.
"""
from __future__ import annotations

import array
import math
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from humanoid_planner.core.pipeline.place import DUAL_PLACE_PLANNERS, PLACE_PLANNERS, PlacePlan, PlaceRequest, check_place_request
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlan, GraspPlanRequest, StatePlanRequest
from humanoid_planner.core.pipeline.validation import (DUAL_ARM_PLANNERS, SINGLE_ARM_PLANNERS, STATE_PLANNERS,
                                                     RequestRefused, check_dual_request, check_grasp_request, check_request_grasps,
                                                     check_state_request)
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.scene.planning_scene import SceneUpdateError
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot
from humanoid_planner_interfaces.msg import ErrorCode

from humanoid_planner.ros.frames import FrameError, Frames
from humanoid_planner.ros.conversions import grasp_from_msg, grasp_to_msg, matrix_to_pose_msg, pose_to_matrix_checked

MIN_SCALING = 1e-4
"""Smallest velocity/acceleration scaling accepted: below it a motion lasts over 10^4 times as long
as the fastest one (an accidental value, and soon beyond builtin_interfaces/Duration)."""

ERROR_CODES: dict[PlanStatus, int] = {
    PlanStatus.SUCCESS: ErrorCode.SUCCESS,
    PlanStatus.PLANNING_FAILED: ErrorCode.PLANNING_FAILED,
    PlanStatus.TIMED_OUT: ErrorCode.TIMED_OUT,
    PlanStatus.CANCELLED: ErrorCode.FAILURE,
    PlanStatus.START_IN_COLLISION: ErrorCode.START_STATE_IN_COLLISION,
    PlanStatus.NO_IK_SOLUTION: ErrorCode.NO_IK_SOLUTION,
    PlanStatus.GRASP_QUALITY_TOO_LOW: ErrorCode.GRASP_QUALITY_TOO_LOW,
    PlanStatus.INVALID_REQUEST: ErrorCode.FAILURE,
    PlanStatus.INVALID_GROUP: ErrorCode.INVALID_GROUP_NAME,
    PlanStatus.INVALID_START: ErrorCode.INVALID_ROBOT_STATE,
    PlanStatus.INVALID_GOAL: ErrorCode.INVALID_GOAL_CONSTRAINTS,
    PlanStatus.INVALID_OBJECT: ErrorCode.INVALID_OBJECT_NAME,
    PlanStatus.INVALID_FRAME: ErrorCode.FRAME_TRANSFORM_FAILURE,
    PlanStatus.INTERNAL_ERROR: ErrorCode.FAILURE,
}
"""The core's outcome classes -> ErrorCode values (the only place this mapping lives)."""

ERROR_NAMES: dict[int, str] = {v: k for k, v in vars(ErrorCode).items()
                               if k.isupper() and isinstance(v, int) and not k.startswith("_")}
"""ErrorCode value -> constant name (for logs and the client)."""


class RequestError(Exception):
    """A request that cannot be planned: the ErrorCode value and a message for the caller."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = int(code)
        self.message = message


@dataclass(frozen=True)
class RequestDefaults:
    """Node parameters that fill a request's zero fields."""

    default_timeout: float = 5.0
    min_grasp_score: float = 0.001
    max_timeout: float = 60.0  # s: longer timeouts are clamped to it (and the message says so)
    max_grasps_per_request: int = 20_000  # in one grasp list of a request; more is refused


@dataclass
class PreparedRequest:
    """A checked request, ready for the worker pool."""

    kind: str  # "plan_grasp" | "plan_dual_grasp" | "plan_to_state" | "plan_place" | "plan_dual_place"
    core: GraspPlanRequest | DualGraspPlanRequest | StatePlanRequest | PlaceRequest
    snapshot: SceneSnapshot
    groups: tuple[str, ...]
    start: np.ndarray  # full configuration (RobotModel.joint_names order)
    notes: tuple[str, ...] = ()  # said to the caller in the response's message (e.g. a clamped timeout)


# ---------------------------------------------------------------------------------------- fields
GRASP_LISTS = ("grasps", "left_grasps", "right_grasps")
"""The grasp-list fields of the plan requests."""


def request_timeout(value: float, defaults: RequestDefaults) -> tuple[float, tuple[str, ...]]:
    """(timeout in s, notes for the caller): 0 -> default_timeout; above max_timeout -> clamped, said so."""
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise RequestError(ErrorCode.FAILURE, f"timeout must be a finite number of seconds >= 0 (0 = node default), "
                                              f"got {value}")
    v = v if v > 0.0 else float(defaults.default_timeout)
    if v > defaults.max_timeout:
        return float(defaults.max_timeout), (f"timeout {value:g} s clamped to max_timeout {defaults.max_timeout:g} s",)
    return v, ()


def _scaling(value: float, field: str) -> float:
    v = float(value)
    if v == 0.0:
        return 1.0
    if not (MIN_SCALING <= v <= 1.0):  # also catches NaN
        raise RequestError(ErrorCode.FAILURE, f"{field} must be in (0, 1] (0 = 1; at least {MIN_SCALING:g}), "
                                              f"got {value}")
    return v


def _min_grasp_score(value: float, default: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise RequestError(ErrorCode.FAILURE, f"min_grasp_score must be finite (<= 0 = node default), got {value}")
    return v if v > 0.0 else float(default)


def _seed(value: int) -> int | None:
    return int(value) or None


def joint_state_values(robot: RobotModel, msg: JointState) -> dict[str, float]:
    """The usable entries of a joint_states message: known joints with finite positions."""
    known = set(robot.joint_names)
    return {n: float(p) for n, p in zip(msg.name, msg.position) if n in known and math.isfinite(float(p))}


def fresh_joint_state(robot: RobotModel, start: JointState, latest: JointState | None, age: float,
                      max_age: float) -> JointState | None:
    """`latest` (the last joint_states message, received `age` s ago) when it may fill the request's
    start state; RequestError INVALID_ROBOT_STATE when it is older than `max_age` and the request's
    start_state does not give every joint itself."""
    if latest is None or age <= max_age or set(robot.joint_names) <= set(start.name):
        return latest
    raise RequestError(ErrorCode.INVALID_ROBOT_STATE,
                       f"the latest joint_states message was received {age:.2f} s ago, more than joint_states_max_age "
                       f"({max_age:g} s): it is not used as the start state; publish joint_states, or give every joint "
                       "in start_state")


def start_state(robot: RobotModel, msg: JointState, latest: JointState | None) -> np.ndarray:
    """The full start configuration: the request's joints over the latest joint_states, else home
    (its limits are checked with the rest of the request: validation.check_start)."""
    names, positions = list(msg.name), [float(p) for p in msg.position]
    if len(names) != len(positions):
        raise RequestError(ErrorCode.INVALID_ROBOT_STATE,
                           f"start_state: {len(names)} names but {len(positions)} positions (must be the same)")
    unknown = [n for n in names if n not in robot.joints or robot.joints[n].index < 0]
    if unknown:
        raise RequestError(ErrorCode.INVALID_ROBOT_STATE,
                           f"start_state: unknown joint(s) {unknown[:5]}; the robot's joints are "
                           f"{', '.join(robot.joint_names)}")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RequestError(ErrorCode.INVALID_ROBOT_STATE, f"start_state: joint(s) {dup} given more than once")
    bad = [f"{n}={p}" for n, p in zip(names, positions) if not math.isfinite(p)]
    if bad:
        raise RequestError(ErrorCode.INVALID_ROBOT_STATE, f"start_state: NaN or inf position(s): {', '.join(bad[:5])}")
    q = np.array(robot.home, dtype=float)
    index = {n: i for i, n in enumerate(robot.joint_names)}
    if latest is not None:
        for n, p in joint_state_values(robot, latest).items():
            q[index[n]] = p
    for n, p in zip(names, positions):
        q[index[n]] = p
    return q


def check_grasp_count(msgs, field: str, defaults: RequestDefaults) -> None:
    """Refuse a grasp list longer than max_grasps_per_request (by its length only: cheap)."""
    if len(msgs) > defaults.max_grasps_per_request:
        raise RequestError(ErrorCode.FAILURE, f"{field}: {len(msgs)} grasps, more than max_grasps_per_request = "
                                              f"{defaults.max_grasps_per_request}")


def _grasps(msgs, field: str, defaults: RequestDefaults) -> tuple[GraspSpec, ...]:
    check_grasp_count(msgs, field, defaults)
    try:
        grasps = [grasp_from_msg(g, f"{field}[{i}] ({g.id!r})") for i, g in enumerate(msgs)]
        return check_request_grasps(grasps, field)
    except SceneUpdateError as e:  # a message field that is no grasp at all (grasp_from_msg)
        raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS, str(e)) from None
    except RequestRefused as e:
        raise RequestError(ERROR_CODES[e.status], e.message) from None


def _object(snapshot: SceneSnapshot, object_id: str, object_pose: PoseStamped, frames: Frames,
            ) -> tuple[np.ndarray, tuple[GraspSpec, ...]]:
    """(T_world_object, the object's grasp set): the scene object's, or object_pose's (no grasps;
    its frame: the planning frame or a robot link, at the latest joint_states)."""
    if object_id:
        obj = snapshot.get(object_id)
        if obj is None:
            known = ", ".join(repr(o.id) for o in snapshot.objects) or "none"
            raise RequestError(ErrorCode.INVALID_OBJECT_NAME,
                               f"object_id {object_id!r} is not in the planning scene (version {snapshot.version}; "
                               f"objects: {known})")
        return obj.pose, obj.grasps
    try:
        T_frame = frames.pose(object_pose.header.frame_id)
    except FrameError as e:
        raise RequestError(ErrorCode.FRAME_TRANSFORM_FAILURE, f"object_pose.header.frame_id: {e}") from None
    try:
        return T_frame @ pose_to_matrix_checked(object_pose.pose, "object_pose"), ()
    except SceneUpdateError as e:
        raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS, str(e)) from None


def _grasp_set(requested: tuple[GraspSpec, ...], own: tuple[GraspSpec, ...], object_id: str,
               field: str) -> tuple[GraspSpec, ...]:
    """The request's grasps, else the scene object's grasp set; refused when both are empty."""
    grasps = requested or own
    if not grasps:
        why = (f"object {object_id!r} has no grasp set and {field} is empty" if object_id
               else f"object_id is empty, so {field} must give the grasps (with object_pose)")
        raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS, f"no grasps: {why}")
    return grasps


def _translation(msg, frames: Frames) -> GripperTranslation | None:
    """A GripperTranslation message -> core (None when desired_distance is 0: no such segment).
    The planning frame's aliases become the planning frame; other frames stay as given (checked with
    the rest of the request: validation.check_translation)."""
    desired, least = float(msg.desired_distance), float(msg.min_distance)
    if desired == 0.0 and least == 0.0:
        return None
    frame = msg.direction.header.frame_id
    if frame in frames.names:
        frame = frames.planning_frame
    v = msg.direction.vector
    return GripperTranslation((float(v.x), float(v.y), float(v.z)), desired, least, frame)


def _checked(check, robot: RobotModel, frames: Frames, core, given: JointState):
    """Run the core's checks of a converted request (validation.py): the clipped start, or RequestError
    with the refusal's ErrorCode."""
    try:
        return check(robot, frames.planning_frame, core, set(given.name))
    except RequestRefused as e:
        raise RequestError(ERROR_CODES[e.status], e.message) from None


# ---------------------------------------------------------------------------------------- requests
def prepare_plan_grasp(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                       defaults: RequestDefaults, frames: Frames) -> PreparedRequest:
    """PlanGrasp.Request -> PreparedRequest; raises RequestError. frames: the node's (ros/frames.py)."""
    group = req.group
    planner = req.planner or SINGLE_ARM_PLANNERS[0]
    timeout, notes = request_timeout(req.timeout, defaults)
    vs = _scaling(req.max_velocity_scaling, "max_velocity_scaling")
    acc = _scaling(req.max_acceleration_scaling, "max_acceleration_scaling")
    start = start_state(robot, req.start_state, latest)
    pose, own = _object(snapshot, req.object_id, req.object_pose, frames)
    grasps = _grasp_set(_grasps(req.grasps, "grasps", defaults), own, req.object_id, "grasps")
    core = GraspPlanRequest(group=group, start=start, object_pose=pose, grasps=grasps, object_id=req.object_id,
                            planner=planner, timeout=timeout, velocity_scaling=vs, acceleration_scaling=acc,
                            seed=_seed(req.seed),
                            approach=_translation(req.pre_grasp_approach, frames),
                            retreat=_translation(req.post_grasp_retreat, frames))
    core.start = start = _checked(check_grasp_request, robot, frames, core, req.start_state)
    return PreparedRequest("plan_grasp", core, snapshot, (group,), start, notes)


def prepare_plan_dual_grasp(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                            defaults: RequestDefaults, frames: Frames) -> PreparedRequest:
    """PlanDualGrasp.Request -> PreparedRequest; raises RequestError."""
    left, right = req.left_group, req.right_group
    planner = req.planner or DUAL_ARM_PLANNERS[0]
    timeout, notes = request_timeout(req.timeout, defaults)
    vs = _scaling(req.max_velocity_scaling, "max_velocity_scaling")
    acc = _scaling(req.max_acceleration_scaling, "max_acceleration_scaling")
    gs_min = _min_grasp_score(req.min_grasp_score, defaults.min_grasp_score)
    start = start_state(robot, req.start_state, latest)
    pose, own = _object(snapshot, req.object_id, req.object_pose, frames)
    lg = _grasp_set(_grasps(req.left_grasps, "left_grasps", defaults), own, req.object_id, "left_grasps")
    rg = _grasp_set(_grasps(req.right_grasps, "right_grasps", defaults), own, req.object_id, "right_grasps")
    core = DualGraspPlanRequest(left_group=left, right_group=right, start=start, object_pose=pose, left_grasps=lg,
                                right_grasps=rg, object_id=req.object_id, planner=planner, min_grasp_score=gs_min,
                                timeout=timeout, velocity_scaling=vs, acceleration_scaling=acc, seed=_seed(req.seed),
                                approach=_translation(req.pre_grasp_approach, frames),
                                retreat=_translation(req.post_grasp_retreat, frames))
    core.start = start = _checked(check_dual_request, robot, frames, core, req.start_state)
    return PreparedRequest("plan_dual_grasp", core, snapshot, (left, right), start, notes)


def goal_state_values(msg: JointState) -> dict[str, float] | None:
    """A goal_state message -> joint name -> value (None: no goal_state given); the values are checked
    by the core with the rest of the goal (validation.state_goal)."""
    names, positions = list(msg.name), [float(p) for p in msg.position]
    if not names and not positions:
        return None
    if len(names) != len(positions):
        raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS,
                           f"goal_state: {len(names)} names but {len(positions)} positions (must be the same; "
                           "names are required)")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS, f"goal_state: joint(s) {dup} given more than once")
    return dict(zip(names, positions))


def prepare_plan_to_state(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                          defaults: RequestDefaults, frames: Frames) -> PreparedRequest:
    """PlanToState.Request -> PreparedRequest; raises RequestError."""
    planner = req.planner or STATE_PLANNERS[0]
    timeout, notes = request_timeout(req.timeout, defaults)
    vs = _scaling(req.max_velocity_scaling, "max_velocity_scaling")
    acc = _scaling(req.max_acceleration_scaling, "max_acceleration_scaling")
    start = start_state(robot, req.start_state, latest)
    core = StatePlanRequest(group=req.group, right_group=req.right_group, start=start, named_state=req.named_state,
                            goal=goal_state_values(req.goal_state), planner=planner, timeout=timeout,
                            velocity_scaling=vs, acceleration_scaling=acc, seed=_seed(req.seed))
    core.start, _ = _checked(check_state_request, robot, frames, core, req.start_state)
    return PreparedRequest("plan_to_state", core, snapshot, core.groups, core.start, notes)


def place_poses(msgs, frames: Frames, defaults: RequestDefaults) -> list[np.ndarray]:
    """place_poses -> T_world_object candidates (each in its header's frame: the planning frame or a robot
    link, at the latest joint_states); at most max_grasps_per_request of them."""
    if len(msgs) > defaults.max_grasps_per_request:
        raise RequestError(ErrorCode.FAILURE, f"place_poses: {len(msgs)} poses, more than max_grasps_per_request = "
                                              f"{defaults.max_grasps_per_request}")
    out = []
    for i, m in enumerate(msgs):
        try:
            T_frame = frames.pose(m.header.frame_id)
        except FrameError as e:
            raise RequestError(ErrorCode.FRAME_TRANSFORM_FAILURE, f"place_poses[{i}].header.frame_id: {e}") from None
        try:
            out.append(T_frame @ pose_to_matrix_checked(m.pose, f"place_poses[{i}]"))
        except SceneUpdateError as e:
            raise RequestError(ErrorCode.INVALID_GOAL_CONSTRAINTS, str(e)) from None
    return out


def _prepare_place(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                   defaults: RequestDefaults, frames: Frames, dual: bool) -> PreparedRequest:
    group, right = (req.left_group, req.right_group) if dual else (req.group, "")
    timeout, notes = request_timeout(req.timeout, defaults)
    vs = _scaling(req.max_velocity_scaling, "max_velocity_scaling")
    acc = _scaling(req.max_acceleration_scaling, "max_acceleration_scaling")
    start = start_state(robot, req.start_state, latest)
    core = PlaceRequest(group=group, right_group=right, start=start, object_id=req.object_id,
                        placements=place_poses(req.place_poses, frames, defaults),
                        planner=req.planner or (DUAL_PLACE_PLANNERS if dual else PLACE_PLANNERS)[0], timeout=timeout,
                        velocity_scaling=vs, acceleration_scaling=acc, seed=_seed(req.seed),
                        approach=_translation(req.pre_place_approach, frames),
                        retreat=_translation(req.post_place_retreat, frames))
    core.start = _checked(check_place_request, robot, frames, core, req.start_state)
    return PreparedRequest("plan_dual_place" if dual else "plan_place", core, snapshot, core.groups, core.start, notes)


def prepare_plan_place(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                       defaults: RequestDefaults, frames: Frames) -> PreparedRequest:
    """PlanPlace.Request -> PreparedRequest; raises RequestError (the attached object is checked when planned)."""
    return _prepare_place(robot, req, snapshot, latest, defaults, frames, dual=False)


def prepare_plan_dual_place(robot: RobotModel, req, snapshot: SceneSnapshot, latest: JointState | None,
                            defaults: RequestDefaults, frames: Frames) -> PreparedRequest:
    """PlanDualPlace.Request -> PreparedRequest; raises RequestError."""
    return _prepare_place(robot, req, snapshot, latest, defaults, frames, dual=True)


# ---------------------------------------------------------------------------------------- responses
def _points_by_constructor(ns: list[int], P: list, V: list, A: list) -> list[JointTrajectoryPoint]:
    return [JointTrajectoryPoint(positions=p, velocities=v, accelerations=a,
                                 time_from_start=Duration(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000))
            for t, p, v, a in zip(ns, P, V, A)]


def _points_direct(ns: list[int], P: list, V: list, A: list) -> list[JointTrajectoryPoint]:
    """The same points as _points_by_constructor, about 2.5x faster: the objects are made without
    the generated __init__ (which builds four empty arrays and a Duration for every point, then
    replaces them) and their fields are set as the generated setters store them (array('d'),
    checks off). Used only when _direct_points_match() holds for this rosidl's classes."""
    new_point, new_duration, double = JointTrajectoryPoint.__new__, Duration.__new__, array.array
    points = []
    for t, p, v, a in zip(ns, P, V, A):
        d = new_duration(Duration)
        d._check_fields, d._sec, d._nanosec = False, t // 1_000_000_000, t % 1_000_000_000
        pt = new_point(JointTrajectoryPoint)
        pt._check_fields = False
        pt._positions, pt._velocities, pt._accelerations = double("d", p), double("d", v), double("d", a)
        pt._effort, pt._time_from_start = double("d"), d
        points.append(pt)
    return points


def _direct_points_match() -> bool:
    """Whether _points_direct builds exactly what the generated constructors build (same slots, equal
    messages, serializable): checked once at import, so another rosidl falls back to the constructors."""
    try:
        from rclpy.serialization import serialize_message

        if (set(JointTrajectoryPoint.__slots__) != {"_positions", "_velocities", "_accelerations", "_effort",
                                                    "_time_from_start", "_check_fields"}
                or set(Duration.__slots__) != {"_sec", "_nanosec", "_check_fields"}):
            return False
        sample = ([0, 1_500_000_001], [[0.5, -1.25], [1.0, 2.0]], [[0.0, 0.1], [0.2, 0.3]], [[1e-3, -1e3], [0.0, 0.0]])
        direct, made = _points_direct(*sample), _points_by_constructor(*sample)
        serialize_message(JointTrajectory(points=direct))
        return direct == made and [p.time_from_start.sec for p in direct] == [0, 1]
    except Exception:  # noqa: BLE001 - any difference: use the constructors
        return False


_make_points = _points_direct if _direct_points_match() else _points_by_constructor


def trajectory_to_msg(plan: GraspPlan, frame: str, retreat: bool = False) -> JointTrajectory:
    """The plan's timed trajectory (or its retreat) as a JointTrajectory (header stamp 0 = start on receipt)."""
    msg = JointTrajectory()
    msg.header.frame_id = frame
    msg.joint_names = list(plan.joint_names)
    traj = plan.retreat_trajectory if retreat else plan.trajectory
    if traj is None:
        return msg
    times = np.asarray(traj.times, dtype=np.float64).reshape(-1)
    if not (np.all(np.isfinite(times)) and np.all(times >= 0.0) and np.all(times < 2**31 - 1)):
        raise ValueError("trajectory times do not fit builtin_interfaces/Duration")
    n = len(times)
    if n == 0:
        return msg
    rows = [np.asarray(x, dtype=np.float64).reshape(n, -1).tolist()
            for x in (traj.positions, traj.velocities, traj.accelerations)]
    msg.points = _make_points(np.round(times * 1e9).astype(np.int64).tolist(), *rows)
    return msg


def _fill_status(response, plan: GraspPlan) -> None:
    """The fields every plan response has: error code, message, planning time, iterations, scene version."""
    response.error_code.val = ERROR_CODES.get(plan.status, ErrorCode.FAILURE)
    response.message = plan.message
    response.planning_time = float(plan.planning_time)
    response.iterations = int(max(0, min(plan.iterations, 2**32 - 1)))
    response.scene_version = int(plan.scene_version)


def fill_response(response, plan: GraspPlan, frame: str, dual: bool, notes: tuple[str, ...] = ()):
    """Copy a core GraspPlan into a PlanGrasp / PlanDualGrasp response (every field); `notes` (what
    the node changed in the request, e.g. a clamped timeout) go in front of the message."""
    _fill_status(response, plan)
    if not plan.ok:
        return _with_notes(response, notes)
    response.trajectory = trajectory_to_msg(plan, frame)
    if plan.retreat_trajectory is not None:
        response.retreat_trajectory = trajectory_to_msg(plan, frame, retreat=True)
    response.approach_distance = float(plan.approach_distance)
    response.retreat_distance = float(plan.retreat_distance)
    if not response.message:
        ids = " + ".join(repr(g.id) for g in plan.grasps)
        response.message = (f"reached grasp {ids} after {plan.iterations} iterations; trajectory "
                            f"{plan.trajectory.duration:.2f} s, {len(plan.trajectory.times)} points")
    if dual:
        response.left_grasp, response.right_grasp = (grasp_to_msg(g) for g in plan.grasps)
        response.left_tcp_pose, response.right_tcp_pose = (matrix_to_pose_msg(T) for T in plan.tcp_poses)
        response.grasp_score = float(plan.grasp_score)
    else:
        response.grasp = grasp_to_msg(plan.grasps[0])
        response.tcp_pose = matrix_to_pose_msg(plan.tcp_poses[0])
    return _with_notes(response, notes)


def fill_state_response(response, plan: GraspPlan, frame: str, notes: tuple[str, ...] = ()):
    """Copy a core plan to a joint-space goal into a PlanToState response; `notes` as fill_response's."""
    _fill_status(response, plan)
    if plan.ok:
        response.trajectory = trajectory_to_msg(plan, frame)
        if not response.message:
            response.message = (f"goal reached after {plan.iterations} iterations; trajectory "
                                f"{plan.trajectory.duration:.2f} s, {len(plan.trajectory.times)} points")
    return _with_notes(response, notes)


def fill_place_response(response, plan: PlacePlan, frame: str, dual: bool, notes: tuple[str, ...] = ()):
    """Copy a core place plan into a PlanPlace / PlanDualPlace response; `notes` as fill_response's."""
    _fill_status(response, plan)
    if not plan.ok:
        return _with_notes(response, notes)
    response.trajectory = trajectory_to_msg(plan, frame)
    if plan.retreat_trajectory is not None:
        response.retreat_trajectory = trajectory_to_msg(plan, frame, retreat=True)
    response.place_index = int(plan.place_index)
    response.approach_distance = float(plan.approach_distance)
    response.retreat_distance = float(plan.retreat_distance)
    if dual:
        response.left_tcp_pose, response.right_tcp_pose = (matrix_to_pose_msg(T) for T in plan.tcp_poses)
    else:
        response.tcp_pose = matrix_to_pose_msg(plan.tcp_poses[0])
    if not response.message:
        response.message = (f"reached place_poses[{plan.place_index}] after {plan.iterations} iterations; trajectory "
                            f"{plan.trajectory.duration:.2f} s, {len(plan.trajectory.times)} points")
    return _with_notes(response, notes)


def _with_notes(response, notes: tuple[str, ...]):
    if notes:
        response.message = "; ".join(notes) + ("; " + response.message if response.message else "")
    return response


def fail_response(response, code: int, message: str, scene_version: int = 0, planning_time: float = 0.0):
    response.error_code.val = int(code)
    response.message = message
    response.scene_version = int(scene_version)
    response.planning_time = float(planning_time)
    return response
