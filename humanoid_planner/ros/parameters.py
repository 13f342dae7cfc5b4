"""The node's parameters: one table (`PARAMETERS`) of names, defaults, ranges and descriptions.

The planner's own tunables (f_extend, max_cycles, steps, tolerances, min_grasp_score, friction,
collision_padding, edge_resolution)
take their default, range and description from `PlannerOptions` (core); the node's own parameters
are written here once. From the table come the declarations (a ParameterDescriptor per parameter,
with its range and read_only flag), `PlannerParameters()`'s defaults, and the checks of
config/planner.yaml and the README's parameter table (test/unit/test_parameters.py).

Validation: rclpy refuses a value outside its declared range or of another type, at start (the node
turns that into a StartupError: planner_node exits 1 with one line) and at `ros2 param set` (the set
fails with rclpy's reason; read-only parameters cannot be set). Accepted run-time values apply from
the next request (`PlannerNode._on_parameters_set`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from humanoid_planner.core.planners.common import OptionRange, PlannerOptions, option_ranges
from humanoid_planner.core.scene.planning_scene import SceneLimits
from humanoid_planner.core.scene.voxels import CloudSettings

EXECUTOR_KINDS = ("events", "single")  # values of the `executor` parameter (node_main spins the node with it)


class StartupError(RuntimeError):
    """The node cannot start (bad parameter, robot that cannot be loaded); the message says why."""


@dataclass(frozen=True)
class ParameterSpec:
    """One node parameter: its default, range (None: any value of the type) and description."""

    name: str
    default: bool | int | float | str
    description: str
    range: OptionRange | None = None
    read_only: bool = False
    choices: tuple[str, ...] = ()  # the values a string parameter accepts (empty: any)

    def descriptor(self) -> ParameterDescriptor:
        """A new descriptor for this parameter (never shared: rclpy stores it per name)."""
        d = ParameterDescriptor(name=self.name, description=self.description, read_only=self.read_only)
        if self.range is not None:
            if isinstance(self.default, int) and not isinstance(self.default, bool):
                d.integer_range = [IntegerRange(from_value=int(self.range.lo), to_value=int(self.range.hi), step=0)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(self.range.lo),
                                                             to_value=float(self.range.hi), step=0.0)]
        return d

    def range_text(self) -> str:
        """The accepted values as the README writes them."""
        if self.range is not None:
            if isinstance(self.default, int) and not isinstance(self.default, bool):
                return f"[{int(self.range.lo)}, {int(self.range.hi)}]"
            return f"[{self.range.lo:g}, {self.range.hi:g}]"
        if self.choices:
            return " or ".join(self.choices)
        return "true / false" if isinstance(self.default, bool) else "any string"


def _node(name, default, lo=None, hi=None, description="", read_only=False, choices=()) -> ParameterSpec:
    rng = None if lo is None else OptionRange(lo, hi, description)
    return ParameterSpec(name, default, description, rng, read_only, tuple(choices))


_OPTIONS = PlannerOptions()
_CLOUD = CloudSettings()
_LIMITS = SceneLimits()
PLANNER_OPTION_NAMES = tuple(option_ranges())
"""PlannerOptions fields that are node parameters of the same name."""

PARAMETERS: tuple[ParameterSpec, ...] = (
    _node("robot", "", description="robot preset (config/robots/<robot>.urdf + .srdf: armar3, dual_arm, maru1), "
          "used when robot_description is empty; both empty: the robot comes from the robot_description "
          "topics", read_only=True),
    _node("robot_description", "", description="URDF XML; when set, used instead of `robot` and the topics",
          read_only=True),
    _node("robot_description_semantic", "", description="SRDF XML that goes with the robot_description "
          "parameter or topic (empty: the robot_description_semantic topic, when the URDF comes from a topic)",
          read_only=True),
    _node("planning_frame", "", description='"" = the URDF root link; else a frame outside the URDF that the '
          "root is fixed to (e.g. world)", read_only=True),
    _node("executor", "events", description="the executor planner_node spins: events (rclpy's "
          "EventsExecutor) or single (SingleThreadedExecutor)", read_only=True, choices=EXECUTOR_KINDS),
    _node("num_workers", 0, 0, 64, "plans run at once, each in a worker process (planning_processes) or a "
          "planning thread; 0 = one per core the node may use", read_only=True),
    _node("planning_processes", True, description="plans run in worker processes, one per num_workers, fed the "
          "scene incrementally (true: plans/s grows with the cores), or in threads of the node's process, which "
          "share one core (false)", read_only=True),
    _node("default_timeout", 5.0, 0.001, 3600.0, "s, a plan's time limit when the request's timeout is 0"),
    _node("joint_states_max_age", 1.0, 0.001, 86400.0, "s, a joint_states message older than this (by receive "
          "time) is not used as the start state: the request gets INVALID_ROBOT_STATE"),
    *(ParameterSpec(n, getattr(_OPTIONS, n), r.description, r) for n, r in option_ranges().items()),
    _node("dual_arm_processes", True, description="DAGRRT: right arm in an arm process, left in the planning "
          "thread (true), or both in threads (false)"),
    _node("voxel_size", _CLOUD.voxel_size, 0.001, 1.0, "m, edge of the occupied cells of the point-cloud layer"),
    _node("pointcloud_max_range", _CLOUD.max_range, 0.01, 100.0,
          "m, points farther than this from the cloud's sensor are dropped"),
    _node("pointcloud_self_padding", _CLOUD.self_padding, 0.0, 1.0,
          "m, points this close to the robot's collision geometry are dropped (self-filter)"),
    _node("pointcloud_object_padding", _CLOUD.object_padding, 0.0, 1.0,
          "m, points this close to a scene object are dropped (its own points)"),
    # limits (README "Limits"): what one client may ask of the node
    _node("max_timeout", 60.0, 0.001, 3600.0, "s, longest a plan may run: a request's larger timeout is clamped "
          "to it (the response's message says so)"),
    _node("max_grasps_per_request", 20_000, 1, 10_000_000, "grasps in one list of a plan request; a longer "
          "list is refused (FAILURE)"),
    _node("max_queued_plans", 64, 1, 100_000, "plan requests waiting for a planning thread (run earliest "
          "deadline first); more are refused (FAILURE)", read_only=True),
    _node("max_queued_scene_updates", 10_000, 1, 10_000_000, "collision_object / attached_collision_object "
          "updates waiting for the scene thread (MOVEs of one object that wait together count once); one that "
          "arrives while that many wait is dropped, counted (~/dropped_scene_updates) and logged", read_only=True),
    _node("max_triangles_per_message", _LIMITS.max_triangles_per_message, 1, 100_000_000,
          "mesh triangles in one collision_object message; more is rejected", read_only=True),
    _node("max_triangles_per_scene", _LIMITS.max_triangles_per_scene, 1, 1_000_000_000,
          "mesh triangles in the whole scene; an update that would exceed it is rejected", read_only=True),
    _node("max_primitives_per_object", _LIMITS.max_primitives_per_object, 1, 10_000_000,
          "primitives of one scene object; more is rejected", read_only=True),
    _node("max_grasps_per_object", _LIMITS.max_grasps_per_object, 1, 10_000_000,
          "grasps of one scene object; more is rejected", read_only=True),
)
SPECS: dict[str, ParameterSpec] = {s.name: s for s in PARAMETERS}
START_ONLY = tuple(s.name for s in PARAMETERS if s.read_only)


def _default(name: str):
    return field(default=SPECS[name].default)


@dataclass(frozen=True)
class PlannerParameters:
    """The parameters a request is planned with (defaults from `PARAMETERS`); replaced as a whole
    when a parameter is set at run time."""

    default_timeout: float = _default("default_timeout")
    joint_states_max_age: float = _default("joint_states_max_age")
    num_workers: int = _default("num_workers")  # 0 at declaration: one per core (declare_parameters)
    planning_processes: bool = _default("planning_processes")
    dual_arm_processes: bool = _default("dual_arm_processes")
    voxel_size: float = _default("voxel_size")
    pointcloud_max_range: float = _default("pointcloud_max_range")
    pointcloud_self_padding: float = _default("pointcloud_self_padding")
    pointcloud_object_padding: float = _default("pointcloud_object_padding")
    max_timeout: float = _default("max_timeout")
    max_grasps_per_request: int = _default("max_grasps_per_request")
    max_queued_plans: int = _default("max_queued_plans")
    max_queued_scene_updates: int = _default("max_queued_scene_updates")
    max_triangles_per_message: int = _default("max_triangles_per_message")
    max_triangles_per_scene: int = _default("max_triangles_per_scene")
    max_primitives_per_object: int = _default("max_primitives_per_object")
    max_grasps_per_object: int = _default("max_grasps_per_object")
    options: PlannerOptions = field(default_factory=PlannerOptions)

    @property
    def min_grasp_score(self) -> float:
        return self.options.min_grasp_score

    def with_values(self, values: dict) -> "PlannerParameters":
        """A copy with some parameters (node or planner option names) replaced."""
        own = {f.name for f in fields(self)} - {"options"}
        opts = {k: v for k, v in values.items() if k in PLANNER_OPTION_NAMES}
        return replace(self, **{k: v for k, v in values.items() if k in own},
                       options=replace(self.options, **opts) if opts else self.options)


@dataclass(frozen=True)
class StartParameters:
    """Read-only parameters the node is built from."""

    robot: str
    robot_description: str
    robot_description_semantic: str
    planning_frame: str
    executor: str


def _refusal(spec: ParameterSpec, value, reason: str = "") -> str:
    """One line naming the parameter, the value and what it accepts."""
    kind = {bool: "bool", int: "integer", float: "float", str: "string"}[type(spec.default)]
    if spec.choices:
        accepts = "one of " + ", ".join(spec.choices)
    elif spec.range is not None:
        accepts = f"a {kind} in {spec.range_text()}"
    else:
        accepts = f"a {kind}"
    return f"parameter {spec.name}={value!r} refused: must be {accepts} ({spec.description})" + (
        f"; {reason}" if reason else "")


def declare_parameters(node: Node) -> tuple[StartParameters, PlannerParameters]:
    """Declare every parameter of `PARAMETERS` on `node`; return the values it starts with.
    Raises StartupError (one line) for a value the node cannot start with."""
    values = {}
    for spec in PARAMETERS:
        try:
            value = node.declare_parameter(spec.name, spec.default, spec.descriptor()).value
        except (InvalidParameterTypeException, InvalidParameterValueException):
            raise StartupError(_refusal(spec, _override(node, spec.name))) from None
        if spec.choices and value not in spec.choices:
            raise StartupError(_refusal(spec, value))
        values[spec.name] = value
    start = StartParameters(**{f.name: values[f.name] for f in fields(StartParameters)})
    values["num_workers"] = values["num_workers"] or usable_cores()
    return start, PlannerParameters().with_values(values)


JOINT_LIMITS_PREFIX = "robot_description_planning.joint_limits."
"""Where move_group reads a MoveIt configuration's joint_limits.yaml (moveit_configs_utils loads the file
under `robot_description_planning`): parameters <prefix><joint>.<key>, e.g.
robot_description_planning.joint_limits.panda_joint1.max_acceleration."""


def joint_limit_parameters(node: Node) -> dict[str, dict[str, object]]:
    """The joint_limits.yaml entries the node was started with (joint -> {key: value}; RobotModel's
    joint_limits), each declared read-only so that `ros2 param` lists it."""
    out: dict[str, dict[str, object]] = {}
    for name, p in sorted(node._parameter_overrides.items()):  # noqa: SLF001 - names given at start, undeclared
        if not name.startswith(JOINT_LIMITS_PREFIX):
            continue
        joint, _, key = name[len(JOINT_LIMITS_PREFIX):].rpartition(".")
        if not joint or not key:
            raise StartupError(f"parameter {name}: expected {JOINT_LIMITS_PREFIX}<joint>.<key> (MoveIt's "
                               "joint_limits.yaml: has_velocity_limits, max_velocity, has_acceleration_limits, ...)")
        value = p.value if isinstance(p, Parameter) else p
        node.declare_parameter(name, value, ParameterDescriptor(
            read_only=True, description=f"joint_limits.yaml of the MoveIt configuration: {key} of {joint}"))
        out.setdefault(joint, {})[key] = value
    return out


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity, e.g. a container's or taskset's share)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def _override(node: Node, name: str):
    """The value given for `name` at start (--ros-args / parameter_overrides), for the message."""
    p = node._parameter_overrides.get(name)  # noqa: SLF001 - rclpy keeps no public accessor for them
    return p.value if isinstance(p, Parameter) else p


def cloud_settings(p: PlannerParameters) -> CloudSettings:
    """The point-cloud layer's settings from the node parameters."""
    return CloudSettings(p.voxel_size, p.pointcloud_max_range, p.pointcloud_self_padding, p.pointcloud_object_padding)


def scene_limits(p: PlannerParameters) -> SceneLimits:
    """The planning scene's limits from the node parameters."""
    return SceneLimits(max_triangles_per_message=p.max_triangles_per_message,
                       max_triangles_per_scene=p.max_triangles_per_scene,
                       max_primitives_per_object=p.max_primitives_per_object,
                       max_grasps_per_object=p.max_grasps_per_object)
