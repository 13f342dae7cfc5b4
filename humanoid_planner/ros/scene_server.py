"""The node's view of the world: the `collision_object` and `attached_collision_object` topics into
the planning scene, the latest `joint_states` message, and the `get_planning_scene` service (objects,
attached objects, version, and the number of cells of the point-cloud layer, which ros/pointcloud.py fills).

Callback groups: `collision_object` has its own MutuallyExclusive group (scene updates are applied
one at a time, in order, and never wait behind a plan), `joint_states` another; `get_planning_scene`
is served in the node's shared Reentrant service group. Every callback catches its exceptions.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState

from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from humanoid_planner.ros.conversions import (attached_object_to_msg, attached_object_to_update,
                                              collision_object_to_update, scene_object_to_msg)
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS, SERVICE_QOS

OPERATION_NAMES = {0: "ADD", 1: "REMOVE", 2: "APPEND", 3: "MOVE"}


class SceneServer:
    """Subscriptions `collision_object` and `joint_states` and the service `get_planning_scene` of `node`."""

    def __init__(self, node: Node, scene: PlanningScene, frame_aliases: tuple[str, ...],
                 service_group: CallbackGroup):
        self._node = node
        self.scene = scene
        self._frame_aliases = frame_aliases  # other names of the planning frame accepted in object headers
        self._joint_state_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._joint_state_time = 0.0  # time.monotonic() when it was received
        self.scene_group = MutuallyExclusiveCallbackGroup()
        self.state_group = MutuallyExclusiveCallbackGroup()
        self.collision_object_sub = node.create_subscription(
            CollisionObject, "collision_object", self._on_collision_object, COLLISION_OBJECT_QOS,
            callback_group=self.scene_group)
        # attach/detach change the same scene: applied in order with collision_object
        self.attached_object_sub = node.create_subscription(
            AttachedCollisionObject, "attached_collision_object", self._on_attached_object, COLLISION_OBJECT_QOS,
            callback_group=self.scene_group)
        self.joint_states_sub = node.create_subscription(
            JointState, "joint_states", self._on_joint_state, JOINT_STATES_QOS, callback_group=self.state_group)
        self.get_planning_scene_srv = node.create_service(
            GetPlanningScene, "get_planning_scene", self._on_get_planning_scene, qos_profile=SERVICE_QOS,
            callback_group=service_group)

    def latest_joint_state(self) -> JointState | None:
        """The last message received on joint_states (None before the first)."""
        with self._joint_state_lock:
            return self._joint_state

    def joint_state_and_age(self) -> tuple[JointState | None, float]:
        """The last joint_states message and how many seconds ago it was received (None, 0.0 before the first)."""
        with self._joint_state_lock:
            msg, received = self._joint_state, self._joint_state_time
        return msg, (time.monotonic() - received if msg is not None else 0.0)

    def _on_collision_object(self, msg: CollisionObject) -> None:
        log = self._node.get_logger()
        op = OPERATION_NAMES.get(msg.operation, str(msg.operation))
        try:
            version = self.scene.apply(collision_object_to_update(msg, self.scene.frame, self._frame_aliases))
        except SceneUpdateError as e:
            log.warning(f"collision_object rejected, scene unchanged: {e}")
            return
        except Exception as e:  # never let a callback kill the executor
            log.error(f"collision_object {op} {msg.id!r} failed, scene unchanged: {e!r}")
            return
        log.debug(f"collision_object {op} {msg.id!r} applied; scene version {version}")

    def current_configuration(self) -> np.ndarray:
        """The robot's configuration now: home, overwritten by the latest joint_states (within the limits)."""
        robot = self._node.robot
        q = np.array(robot.home, dtype=float)
        latest = self.latest_joint_state()
        if latest is not None:
            index = {n: i for i, n in enumerate(robot.joint_names)}
            for n, p in zip(latest.name, latest.position):
                if n in index and np.isfinite(p):
                    q[index[n]] = p
        return np.clip(q, robot.lower, robot.upper)

    def link_pose(self, link: str, q: np.ndarray | None = None) -> np.ndarray:
        """A robot link's pose in the planning frame at q (default: the current configuration)."""
        robot = self._node.robot
        return robot.link_poses(self.current_configuration() if q is None else q, [link])[0]

    def _on_attached_object(self, msg: AttachedCollisionObject) -> None:
        log = self._node.get_logger()
        op = OPERATION_NAMES.get(msg.object.operation, str(msg.object.operation))
        try:
            update = attached_object_to_update(msg, self.scene.frame, self._frame_aliases, self.scene.limits)
            q = self.current_configuration()
            version = self.scene.apply_attach(update, lambda link: self.link_pose(link, q), self._node.robot.link_names)
        except SceneUpdateError as e:
            log.warning(f"attached_collision_object rejected, scene unchanged: {e}")
            return
        except Exception as e:  # never let a callback kill the executor
            log.error(f"attached_collision_object {op} {msg.object.id!r} failed, scene unchanged: {e!r}")
            return
        log.debug(f"attached_collision_object {op} {msg.object.id!r} on {msg.link_name!r}; scene version {version}")

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            now = time.monotonic()
            with self._joint_state_lock:
                self._joint_state, self._joint_state_time = msg, now
        except Exception as e:  # pragma: no cover - defensive
            self._node.get_logger().error(f"joint_states callback failed: {e!r}")

    def _on_get_planning_scene(self, request, response):
        try:
            snap = self.scene.snapshot()
            response.objects = [scene_object_to_msg(o, snap.frame) for o in snap.objects]
            response.attached_objects = [attached_object_to_msg(a) for a in snap.attached]
            response.version = snap.version
            response.planning_frame = snap.frame
            response.occupied_voxels = len(snap.voxels) if snap.voxels is not None else 0
        except Exception as e:
            self._node.get_logger().error(f"get_planning_scene failed: {e!r}")
            response.planning_frame = self.scene.frame
        return response
