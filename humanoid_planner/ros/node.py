"""The `humanoid_planner` node: robot, planning scene, joint states, and the services on top.

Threading (see docs/ARCHITECTURE.md and the ROS 2 callback-group guide):
- the `collision_object` subscription has its own MutuallyExclusive group, so scene updates are
  applied one at a time, in order, and never wait behind a plan;
- `joint_states` has its own MutuallyExclusive group;
- services share one Reentrant group: several requests may run at once (plan services run planning
  in worker threads on frozen scene snapshots).
Run it on a MultiThreadedExecutor (`node_main.main` does).

Every callback catches its exceptions: an exception escaping a callback would stop the executor.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, fields

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState

from humanoid_planner.core.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner_interfaces.msg import CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from .conversions import collision_object_to_update, scene_object_to_msg
from .qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS

NODE_NAME = "humanoid_planner"
OPERATION_NAMES = {0: "ADD", 1: "REMOVE", 2: "APPEND", 3: "MOVE"}


class RobotLoadError(RuntimeError):
    """The robot description could not be loaded; the node cannot start."""


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


_PARAM_DOCS = {
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
}


def load_robot(preset: str, urdf: str, srdf: str):
    """RobotModel from URDF/SRDF strings (when the URDF is non-empty) or from a preset name."""
    from humanoid_planner.core.robot_model import RobotModel

    try:
        if urdf.strip():
            return RobotModel.from_urdf_srdf(urdf, srdf if srdf.strip() else None)
        if not preset:
            raise RobotLoadError("no robot: set `robot` (a preset name) or `robot_description`")
        return RobotModel.preset(preset)
    except RobotLoadError:
        raise
    except Exception as e:  # file, XML and model errors of every kind
        source = "robot_description" if urdf.strip() else f"preset {preset!r}"
        raise RobotLoadError(f"cannot load the robot from {source}: {e}") from e


class PlannerNode(Node):
    """Planning scene and (later) plan services for one robot.

    Keyword arguments go to rclpy's Node (context, parameter_overrides, namespace, cli_args, ...).
    Raises RobotLoadError when the robot cannot be loaded.
    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        ro = ParameterDescriptor(read_only=True)
        robot = self.declare_parameter(
            "robot", "armar3", ParameterDescriptor(read_only=True, description="preset name")).value
        urdf = self.declare_parameter("robot_description", "", ro).value
        srdf = self.declare_parameter("robot_description_semantic", "", ro).value
        frame = self.declare_parameter(
            "planning_frame", "", ParameterDescriptor(read_only=True, description='"" = URDF root link')).value
        values = {}
        for f in fields(PlannerParameters):
            values[f.name] = self.declare_parameter(
                f.name, f.default, ParameterDescriptor(description=_PARAM_DOCS[f.name])).value
        self.params = PlannerParameters(**values)

        self.robot = load_robot(robot, urdf, srdf)
        self.planning_frame = self._resolve_planning_frame(frame)
        self.scene = PlanningScene(self.planning_frame)
        # the URDF root coincides with the planning frame, so object poses may also be given in it
        self._frame_aliases = (self.robot.root_link,) if self.planning_frame != self.robot.root_link else ()

        self._joint_state_lock = threading.Lock()
        self._joint_state: JointState | None = None

        self.scene_group = MutuallyExclusiveCallbackGroup()
        self.state_group = MutuallyExclusiveCallbackGroup()
        self.service_group = ReentrantCallbackGroup()

        self.collision_object_sub = self.create_subscription(
            CollisionObject, "collision_object", self._on_collision_object, COLLISION_OBJECT_QOS,
            callback_group=self.scene_group)
        self.joint_states_sub = self.create_subscription(
            JointState, "joint_states", self._on_joint_state, JOINT_STATES_QOS, callback_group=self.state_group)
        self.get_planning_scene_srv = self.create_service(
            GetPlanningScene, "get_planning_scene", self._on_get_planning_scene, callback_group=self.service_group)

        source = "robot_description" if urdf.strip() else f"preset {robot!r}"
        self.get_logger().info(
            f"robot {self.robot.name!r} from {source}: {len(self.robot.joint_names)} joints, "
            f"groups {sorted(self.robot.groups)}; planning frame {self.planning_frame!r}")

    def _resolve_planning_frame(self, frame: str) -> str:
        root = self.robot.root_link
        if not frame or frame == root:
            return root
        if frame in self.robot.link_names:
            raise RobotLoadError(
                f"planning_frame {frame!r} is a link of the robot but not its root {root!r}; the planner works in "
                "the root frame: leave planning_frame empty, or name the frame the root is fixed to (e.g. 'world')")
        # A frame outside the URDF (e.g. the parent of an SRDF virtual joint): taken to coincide with the root.
        self.get_logger().info(f"planning frame {frame!r} is taken to coincide with the URDF root {root!r}")
        return frame

    # ------------------------------------------------------------------ state
    def latest_joint_state(self) -> JointState | None:
        """The last message received on joint_states (None before the first)."""
        with self._joint_state_lock:
            return self._joint_state

    # ------------------------------------------------------------------ callbacks
    def _on_collision_object(self, msg: CollisionObject) -> None:
        op = OPERATION_NAMES.get(msg.operation, str(msg.operation))
        try:
            version = self.scene.apply(collision_object_to_update(msg, self.planning_frame, self._frame_aliases))
        except SceneUpdateError as e:
            self.get_logger().warning(f"collision_object rejected, scene unchanged: {e}")
            return
        except Exception as e:  # never let a callback kill the executor
            self.get_logger().error(f"collision_object {op} {msg.id!r} failed, scene unchanged: {e!r}")
            return
        self.get_logger().debug(f"collision_object {op} {msg.id!r} applied; scene version {version}")

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            with self._joint_state_lock:
                self._joint_state = msg
        except Exception as e:  # pragma: no cover - defensive
            self.get_logger().error(f"joint_states callback failed: {e!r}")

    def _on_get_planning_scene(self, request, response):
        try:
            snap = self.scene.snapshot()
            response.objects = [scene_object_to_msg(o, snap.frame) for o in snap.objects]
            response.version = snap.version
            response.planning_frame = snap.frame
        except Exception as e:
            self.get_logger().error(f"get_planning_scene failed: {e!r}")
            response.planning_frame = self.planning_frame
        return response
