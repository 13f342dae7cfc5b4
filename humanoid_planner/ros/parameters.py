"""The node's parameters: declarations, descriptions and the values the node starts with.

Start-up parameters (robot, robot_description*, planning_frame, executor) are read once; the planner
parameters (`PlannerParameters`) become the core's `PlannerOptions` (`planner_options`).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from humanoid_planner.core.planners.common import PlannerOptions
from humanoid_planner.core.scene.voxels import CloudError, CloudSettings

EXECUTOR_KINDS = ("events", "single")  # values of the `executor` parameter (node_main spins the node with it)


class StartupError(RuntimeError):
    """The node cannot start (bad parameter, robot that cannot be loaded); the message says why."""


@dataclass(frozen=True)
class PlannerParameters:
    """Planner constants (node parameters, defaults as config/planner.yaml)."""

    default_timeout: float = 5.0
    f_extend: float = 0.3
    max_cycles: int = 40000
    joint_step: float = 0.1
    tcp_step_pos: float = 0.02
    tcp_step_rot: float = 0.1
    goal_tolerance_pos: float = 0.002
    goal_tolerance_rot: float = 0.0174
    min_grasp_score: float = 0.001
    friction: float = 0.5
    num_workers: int = 2
    collision_padding: float = 0.0
    edge_resolution: float = 0.02
    dual_arm_processes: bool = True
    voxel_size: float = 0.02
    pointcloud_max_range: float = 3.0
    pointcloud_self_padding: float = 0.05
    pointcloud_object_padding: float = 0.02


PARAM_DOCS = {
    "default_timeout": "seconds a plan may take when the request's timeout is 0",
    "f_extend": "probability of extending towards a grasp (GIRRT/DAGRRT)",
    "max_cycles": "RRT iterations before a plan gives up",
    "joint_step": "rad, joint-space step of the trees",
    "tcp_step_pos": "m, TCP translation step when extending to a grasp",
    "tcp_step_rot": "rad, TCP rotation step when extending to a grasp",
    "goal_tolerance_pos": "m, position tolerance of a reached grasp",
    "goal_tolerance_rot": "rad, orientation tolerance of a reached grasp",
    "min_grasp_score": "dual-arm gs_min when a request gives <= 0",
    "friction": "Coulomb friction when a grasp gives 0",
    "num_workers": "planning worker threads",
    "collision_padding": "m, added around the robot's collision geometry",
    "edge_resolution": "rad, largest joint step between collision checks along an edge",
    "dual_arm_processes": "DAGRRT: right arm in a worker process, left in the planning thread (true), or both in threads (false)",
    "voxel_size": "m, edge of the occupied cells of the point-cloud layer",
    "pointcloud_max_range": "m, points farther than this from the cloud's sensor are dropped",
    "pointcloud_self_padding": "m, points this close to the robot's collision geometry are dropped (self-filter)",
    "pointcloud_object_padding": "m, points this close to a scene object are dropped (its own points)",
}


@dataclass(frozen=True)
class StartParameters:
    """Read-only parameters the node is built from."""

    robot: str
    robot_description: str
    robot_description_semantic: str
    planning_frame: str
    executor: str


def declare_parameters(node: Node) -> tuple[StartParameters, PlannerParameters]:
    """Declare every node parameter on `node`; return the values it starts with.
    Raises StartupError for a value the node cannot start with."""
    ro = ParameterDescriptor(read_only=True)
    start = StartParameters(
        robot=node.declare_parameter(
            "robot", "armar3", ParameterDescriptor(read_only=True, description="preset name")).value,
        robot_description=node.declare_parameter("robot_description", "", ro).value,
        robot_description_semantic=node.declare_parameter("robot_description_semantic", "", ro).value,
        planning_frame=node.declare_parameter(
            "planning_frame", "", ParameterDescriptor(read_only=True, description='"" = URDF root link')).value,
        # read by node_main (the executor the node is spun with); declared here with the other parameters
        executor=node.declare_parameter(
            "executor", "events", ParameterDescriptor(
                read_only=True, description="events (rclpy's EventsExecutor) or single (SingleThreadedExecutor)")).value,
    )
    if start.executor not in EXECUTOR_KINDS:
        raise StartupError(f"executor must be one of {', '.join(EXECUTOR_KINDS)}, got {start.executor!r}")
    values = {}
    for f in fields(PlannerParameters):
        values[f.name] = node.declare_parameter(
            f.name, f.default, ParameterDescriptor(description=PARAM_DOCS[f.name])).value
    params = PlannerParameters(**values)
    if params.num_workers < 1:
        raise StartupError(f"num_workers must be >= 1, got {params.num_workers}")
    try:
        cloud_settings(params)
    except CloudError as e:
        raise StartupError(f"point-cloud parameters: {e}") from None
    return start, params


def cloud_settings(p: PlannerParameters) -> CloudSettings:
    """The point-cloud layer's settings from the node parameters (raises CloudError when out of range)."""
    return CloudSettings(p.voxel_size, p.pointcloud_max_range, p.pointcloud_self_padding, p.pointcloud_object_padding)


def planner_options(p: PlannerParameters) -> PlannerOptions:
    """The core's options from the node parameters (the rest keep the core's defaults)."""
    return PlannerOptions(f_extend=p.f_extend, max_cycles=p.max_cycles, joint_step=p.joint_step,
                          tcp_step_pos=p.tcp_step_pos, tcp_step_rot=p.tcp_step_rot,
                          goal_tolerance_pos=p.goal_tolerance_pos, goal_tolerance_rot=p.goal_tolerance_rot,
                          min_grasp_score=p.min_grasp_score, friction=p.friction)
