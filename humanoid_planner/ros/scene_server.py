"""The node's view of the world: the `collision_object` and `attached_collision_object` topics into
the planning scene, the latest `joint_states` message, and the `get_planning_scene` service (objects,
attached objects, version, and the number of cells of the point-cloud layer, which ros/pointcloud.py fills;
each group's TCP has no field there: the node logs it at startup, robot_description.tcp_lines).

The scene topics go through no executor: ros/scene_intake.py takes and applies them on the scene thread
(in arrival order; MOVEs of an object that wait together collapse into the last; what is not applied is
counted exactly, published on `~/dropped_scene_updates` and logged at most once a second), and every
request handler first calls `sync()`: the updates received before the request are in the scene it reads.
`get_planning_scene` answers with the parts its request's `components` asks for (object names and poses,
shapes, grasps, attached objects, voxel count): a big object's full message is built by the scene thread
when the object changes (EAGER_MESSAGE_ITEMS), a small one's when an answer first needs it, the answer's
lists once per scene version and part set, when asked.

`joint_states` belongs to the node's topic node (executors.TopicThread: its own executor thread, with
its own MutuallyExclusive group); `get_planning_scene` is served in the node's shared Reentrant service
group. Every callback catches its exceptions.
"""
from __future__ import annotations

import gc
import threading
import time

import numpy as np
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt64

from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner.core.scene.types import SceneObject
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from humanoid_planner.ros.executors import TopicThread
from humanoid_planner.ros.conversions import (RawObject, attached_object_to_msg, attached_object_to_update,
                                              moved_message, scene_object_to_msg)
from humanoid_planner.ros.qos import DROPPED_QOS, JOINT_STATES_QOS, SERVICE_QOS
from humanoid_planner.ros.scene_intake import OPERATION_NAMES, SceneIntake

DROP_REPORT_PERIOD = 1.0  # s: the drop count is published and logged at most this often
_R = GetPlanningScene.Request
OBJECT_COMPONENTS = _R.OBJECT_NAMES | _R.OBJECT_GEOMETRY | _R.OBJECT_GRASPS
ALL_OBJECT_PARTS = _R.OBJECT_GEOMETRY | _R.OBJECT_GRASPS
ALL_COMPONENTS = OBJECT_COMPONENTS | _R.ATTACHED_OBJECTS | _R.VOXELS
FREEZE_TRIANGLES = 20_000
"""A prepared message of a mesh this big is moved out of the garbage collector's sight (gc.freeze): a
10^6-triangle mesh's message is 1.5 million Python objects, which every full collection then walked
(~150 ms each, measured in-process, wherever it fell). Messages hold no reference cycles, so a frozen one
is still freed when its object goes."""


EAGER_MESSAGE_ITEMS = 2_000
"""An object whose full message holds this many items (shapes, mesh vertices and triangles, grasps and
their contacts) is converted when it changes, in the ingest thread, so that no get_planning_scene pays
for it; a smaller one (a box: ~15 µs) when an answer first needs it: a stream of updates then costs no
conversion until someone asks, and one per object changed since the last answer when they do."""


def message_items(obj: SceneObject) -> int:
    """What an object's full message holds, counted as EAGER_MESSAGE_ITEMS counts it."""
    return (len(obj.shapes) + sum(len(s.vertices) + len(s.triangles) for s in obj.shapes if s.kind == "mesh")
            + sum(1 + len(g.contacts) for g in obj.grasps))


class SceneServer:
    """Subscriptions `collision_object`, `attached_collision_object` and `joint_states` and the service
    `get_planning_scene` of `node`."""

    def __init__(self, node: Node, scene: PlanningScene, frame_aliases: tuple[str, ...],
                 service_group: CallbackGroup, max_queued: int = 10_000, executor_kind: str = "events"):
        """max_queued: scene updates that may wait for the scene thread; more are dropped and counted.
        executor_kind: what the joint_states executor thread (executors.TopicThread) spins."""
        self._node = node
        self.scene = scene
        self._frame_aliases = frame_aliases  # other names of the planning frame accepted in object headers
        self._joint_state_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._joint_state_time = 0.0  # time.monotonic() when it was received
        self.state_group = MutuallyExclusiveCallbackGroup()
        self._closing = threading.Event()
        self._max_queued = max_queued
        self._dropped_reported = 0
        self.dropped_pub = node.create_publisher(UInt64, "~/dropped_scene_updates", DROPPED_QOS)
        self.dropped_pub.publish(UInt64(data=0))
        self._drop_timer = node.create_timer(DROP_REPORT_PERIOD, self._report_drops,
                                             callback_group=MutuallyExclusiveCallbackGroup())
        self._cache_lock = threading.Lock()
        # per part set (OBJECT_GEOMETRY | OBJECT_GRASPS bits): id -> (object, its message), and the list of
        # a scene version
        self._object_msgs: dict[int, dict[str, tuple[SceneObject, CollisionObject]]] = {ALL_OBJECT_PARTS: {}}
        self._object_lists: dict[int, tuple[int, list[CollisionObject]]] = {}
        self._attached: tuple[int, list[AttachedCollisionObject]] = (-1, [])
        self.topics = TopicThread(node, executor_kind)
        self.intake = SceneIntake(node, scene, frame_aliases, max_queued, self._applied, self._on_attached_object,
                                  self.topics.node)
        self.joint_states_sub = self.topics.node.create_subscription(
            JointState, "joint_states", self._on_joint_state, JOINT_STATES_QOS, callback_group=self.state_group)
        self.get_planning_scene_srv = node.create_service(
            GetPlanningScene, "get_planning_scene", self._on_get_planning_scene, qos_profile=SERVICE_QOS,
            callback_group=service_group)
        self._send_scene = self.get_planning_scene_srv.send_response
        self.get_planning_scene_srv.send_response = self._send_scene_answer

    def _send_scene_answer(self, response, header) -> None:
        """get_planning_scene's send_response: the answer's conversion and sending are part of answering
        (the scene thread waits until it is sent; _on_get_planning_scene began it)."""
        try:
            self._send_scene(response, header)
        finally:
            self.intake.end_answer()

    def latest_joint_state(self) -> JointState | None:
        """The last message received on joint_states (None before the first)."""
        with self._joint_state_lock:
            return self._joint_state

    def joint_state_and_age(self) -> tuple[JointState | None, float]:
        """The last joint_states message and how many seconds ago it was received (None, 0.0 before the first)."""
        with self._joint_state_lock:
            msg, received = self._joint_state, self._joint_state_time
        return msg, (time.monotonic() - received if msg is not None else 0.0)

    @property
    def dropped(self) -> int:
        """Scene messages not applied nor refused so far (scene_intake.SceneIntake.dropped)."""
        return self.intake.dropped()

    def sync(self) -> bool:
        """Apply the scene messages received before this call (SceneIntake.sync): request handlers call
        it before they read the scene."""
        return self.intake.sync()

    def answering(self):
        """Context manager around a request handler's work: the scene thread waits meanwhile
        (SceneIntake.answering)."""
        return self.intake.answering()

    def _report_drops(self) -> None:
        """At most once a period: publish and log the drop count when it grew."""
        try:
            n = self.dropped
            if n == self._dropped_reported or self._closing.is_set():
                return
            self.dropped_pub.publish(UInt64(data=n))
            self._node.get_logger().warning(
                f"{n - self._dropped_reported} scene message(s) not applied: {self._max_queued} updates were waiting "
                f"(max_queued_scene_updates), or a keep-last publisher overwrote them before the node took them; "
                f"{n} in all")
            self._dropped_reported = n
        except Exception as e:  # noqa: BLE001 - never let a timer callback die
            self._node.get_logger().error(f"dropped scene updates not reported: {e!r}")

    def close(self) -> None:
        """Stop the scene thread after its turn (what is still waiting is not applied: a node shutting
        down does not need it; after a flood, applying the backlog first took seconds), then the topics'
        thread."""
        self._closing.set()
        self.intake.close()
        self.topics.close()

    def _applied(self, raw: RawObject) -> None:
        """A collision object was applied (scene thread)."""
        if raw.operation != CollisionObject.REMOVE:  # nothing left to convert
            self._prepare_object_message(raw.id)

    def _prepare_object_message(self, object_id: str) -> None:
        """Convert the big object just changed (EAGER_MESSAGE_ITEMS) into its full message here, in the
        ingest thread, so that no get_planning_scene pays for a big mesh; the answer's list is assembled
        only when asked. A moved object's message shares the shapes and grasps of the one it had (only
        the pose is new)."""
        try:
            obj = self.scene.get(object_id)
            if obj is not None and message_items(obj) >= EAGER_MESSAGE_ITEMS:
                with self._cache_lock:
                    before = self._object_msgs[ALL_OBJECT_PARTS].get(object_id)
                if before is not None and before[0].shapes is obj.shapes and before[0].grasps is obj.grasps:
                    msg = moved_message(before[1], obj)
                else:
                    msg = scene_object_to_msg(obj, self.scene.frame)
                    if sum(len(s.triangles) for s in obj.shapes if s.kind == "mesh") >= FREEZE_TRIANGLES:
                        gc.collect()  # what is garbage now is collected, not frozen
                        gc.freeze()
                with self._cache_lock:
                    cache = self._object_msgs[ALL_OBJECT_PARTS]
                    cache[object_id] = (obj, msg)
                    if len(cache) > 2 * len(self.scene) + 64:  # objects removed since the last answer
                        live = {o.id for o in self.scene.snapshot().objects}
                        for oid in [k for k in cache if k not in live]:
                            del cache[oid]
        except Exception as e:  # noqa: BLE001 - never let the ingest thread die
            self._node.get_logger().error(f"get_planning_scene message of {object_id!r} not prepared: {e!r}")

    def scene_messages(self, components: int = 0) -> tuple[int, list[CollisionObject], list[AttachedCollisionObject], int]:
        """(version, one CollisionObject per scene object, the attached objects, occupied voxels) of the
        scene now, holding only the parts `components` asks for (GetPlanningScene's bit mask; 0 = all).
        Each object's message is built once per change of the object and per part set; the lists once
        per scene version and part set."""
        if components == 0:
            components = ALL_COMPONENTS
        parts = components & (GetPlanningScene.Request.OBJECT_GEOMETRY | GetPlanningScene.Request.OBJECT_GRASPS)
        want_objects = bool(components & OBJECT_COMPONENTS)
        snap = self.scene.snapshot()
        with self._cache_lock:
            objects: list[CollisionObject] = []
            if want_objects:
                ready = self._object_lists.get(parts)
                if ready is not None and ready[0] == snap.version:
                    objects = ready[1]
                else:
                    cached = self._object_msgs.setdefault(parts, {})
                    geometry = bool(parts & GetPlanningScene.Request.OBJECT_GEOMETRY)
                    grasps = bool(parts & GetPlanningScene.Request.OBJECT_GRASPS)
                    msgs: dict[str, tuple[SceneObject, CollisionObject]] = {}
                    for o in snap.objects:
                        hit = cached.get(o.id)
                        if hit is not None and hit[0] is o:
                            msgs[o.id] = hit
                        elif hit is not None and hit[0].shapes is o.shapes and hit[0].grasps is o.grasps:
                            msgs[o.id] = (o, moved_message(hit[1], o))  # moved: only the pose is new
                        else:
                            msgs[o.id] = (o, scene_object_to_msg(o, snap.frame, geometry=geometry, grasps=grasps))
                    self._object_msgs[parts] = msgs
                    objects = [m for _, m in msgs.values()]
                    self._object_lists[parts] = (snap.version, objects)
            attached: list[AttachedCollisionObject] = []
            if components & GetPlanningScene.Request.ATTACHED_OBJECTS:
                if self._attached[0] != snap.version:
                    self._attached = (snap.version, [attached_object_to_msg(a) for a in snap.attached])
                attached = self._attached[1]
        voxels = len(snap.voxels) if snap.voxels is not None and components & GetPlanningScene.Request.VOXELS else 0
        return snap.version, objects, attached, voxels

    def current_configuration(self) -> np.ndarray:
        """The robot's configuration now (ros/frames.py: the latest joint_states over home)."""
        return self._node.frames.configuration()

    def link_pose(self, link: str, q: np.ndarray | None = None) -> np.ndarray:
        """A robot link's pose in the planning frame at q (default: the current configuration)."""
        return self._node.frames.pose(link, q)

    def _on_attached_object(self, msg: AttachedCollisionObject) -> None:
        """Apply an attach / detach (scene thread); a refusal is logged, the scene unchanged."""
        log = self._node.get_logger()
        op = OPERATION_NAMES.get(msg.object.operation, str(msg.object.operation))
        try:
            update = attached_object_to_update(msg, self.scene.frame, self._frame_aliases, self.scene.limits)
            q = self.current_configuration()
            version = self.scene.apply_attach(update, lambda link: self.link_pose(link, q), self._node.robot.link_names)
        except SceneUpdateError as e:
            log.warning(f"attached_collision_object rejected, scene unchanged: {e}")
            return
        except Exception as e:  # noqa: BLE001 - never let the scene thread die
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
        self.intake.begin_answer()  # ended once the answer is sent (_send_scene_answer)
        try:
            self.sync()
            (response.version, response.objects, response.attached_objects,
             response.occupied_voxels) = self.scene_messages(int(request.components))
            response.planning_frame = self.scene.frame
        except Exception as e:
            self._node.get_logger().error(f"get_planning_scene failed: {e!r}")
            response.planning_frame = self.scene.frame
        return response
