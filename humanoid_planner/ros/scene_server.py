"""The node's view of the world: the `collision_object` and `attached_collision_object` topics into
the planning scene, the latest `joint_states` message, and the `get_planning_scene` service (objects,
attached objects, version, and the number of cells of the point-cloud layer, which ros/pointcloud.py fills;
each group's TCP has no field there: the node logs it at startup, robot_description.tcp_lines).

The scene topics never go through an executor. `collision_object` (raw) and `attached_collision_object`
are subscribed by a node of their own (`<name>_scene`) that no executor spins: one thread (`scene-ingest`)
waits on them, takes what has arrived (at most `max_queued_scene_updates` per turn), reads the
serialized collision objects with numpy (`collision_object_cdr`: sizes checked against the limits before
any array is built), validates and applies them in arrival order. rclpy's own deserialization builds a
Python object per mesh vertex and triangle; a 10^6-triangle mesh held the executor for 29 s.

Backpressure: the node takes messages only as fast as it applies them; the rest wait in the DDS reader
(reliable, keep all). A keep-all publisher then waits (flow control), nothing is lost; a keep-last
publisher overwrites its oldest samples, which never arrive: DDS reports them (the subscription's
message-lost status), and that count is the node's drop count, published on `~/dropped_scene_updates`
and logged at most once a second. So applied + dropped = sent (a sample still in a publisher that exits
before delivering it is lost to everyone, uncounted). Under a sustained backlog the scene thread works at
most half of the time (FLOOD_DUTY), so that services and plans keep the interpreter; MOVEs of one object
that wait together collapse into the last of them (its pose is the one the object ends with), which
advances the version by the number of messages it stands for: each counts as applied.

`get_planning_scene` answers with the parts its request's `components` asks for (object names and
poses, shapes, grasps, attached objects, voxel count), from the scene's last snapshot (never waiting for
updates): an object with a mesh or many grasps gets its full message built by the scene thread when it
changes; the answer's lists are assembled once per scene version and part set, when asked.

`joint_states` belongs to the node's topic node (executors.TopicThread: its own executor thread);
`get_planning_scene` is served in the node's shared Reentrant service group. Every callback catches its
exceptions.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from rclpy.event_handler import (EventHandler, QoSSubscriptionEventType, SubscriptionEventCallbacks,
                                 UnsupportedEventTypeError)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_policy_name_from_kind
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt64

from humanoid_planner.core.scene.planning_scene import Operation, PlanningScene, SceneUpdate, SceneUpdateError
from humanoid_planner.core.scene.types import SceneObject
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from humanoid_planner.ros.collision_object_cdr import parse_collision_object
from humanoid_planner.ros.executors import TopicThread
from humanoid_planner.ros.conversions import (RawObject, attached_object_to_msg, attached_object_to_update,
                                              moved_message, raw_object_to_update, scene_object_to_msg)
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, DROPPED_QOS, JOINT_STATES_QOS, SERVICE_QOS

OPERATION_NAMES = {0: "ADD", 1: "REMOVE", 2: "APPEND", 3: "MOVE"}
DROP_REPORT_PERIOD = 1.0  # s: the drop count is published and logged at most this often
INGEST_WAIT = 0.2  # s: the scene thread's longest wait for a message before it looks at close()
FLOOD_GRACE = 0.1  # s of uninterrupted backlog (a burst) the scene thread works through at full speed
FLOOD_DUTY = 0.5  # past FLOOD_GRACE: the share of the time the scene thread may work (it sleeps the rest)
EAGER_GRASPS = 16  # an object with more grasps (or any mesh) gets its full message built when it changes
_R = GetPlanningScene.Request
OBJECT_COMPONENTS = _R.OBJECT_NAMES | _R.OBJECT_GEOMETRY | _R.OBJECT_GRASPS
ALL_OBJECT_PARTS = _R.OBJECT_GEOMETRY | _R.OBJECT_GRASPS
ALL_COMPONENTS = OBJECT_COMPONENTS | _R.ATTACHED_OBJECTS | _R.VOXELS


def _ignore(_msg) -> None:
    """The callback of subscriptions no executor spins (the scene thread takes their messages)."""


def _message_lost_counter(sub):
    """The DDS message-lost status of `sub` (a handle polled for its running total), or None when the
    middleware has none."""
    try:
        with sub.handle:
            return _rclpy.EventHandle(sub.handle, QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)
    except UnsupportedEventTypeError:
        return None


class SceneServer:
    """Subscriptions `collision_object`, `attached_collision_object` and `joint_states` and the service
    `get_planning_scene` of `node`."""

    def __init__(self, node: Node, scene: PlanningScene, frame_aliases: tuple[str, ...],
                 service_group: CallbackGroup, max_queued: int = 256, executor_kind: str = "events"):
        """max_queued: scene messages the scene thread takes per turn (the rest wait in DDS).
        executor_kind: what the joint_states executor thread (executors.TopicThread) spins."""
        self._node = node
        self.scene = scene
        self._frame_aliases = frame_aliases  # other names of the planning frame accepted in object headers
        self._joint_state_lock = threading.Lock()
        self._joint_state: JointState | None = None
        self._joint_state_time = 0.0  # time.monotonic() when it was received
        self.state_group = MutuallyExclusiveCallbackGroup()
        self._closing = threading.Event()
        self._batch = max(1, int(max_queued))
        self.applied = 0  # scene messages applied (a MOVE collapsed into a later one of its object included)
        self.superseded = 0  # of these: MOVEs collapsed into a later MOVE of the same object
        self.dropped = 0  # scene messages lost before the node could take them (DDS message-lost status)
        self._dropped_reported = 0
        self._lost_lock = threading.Lock()
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
        # the scene topics' node: never spun (no services of its own), the scene thread takes its messages
        self._scene_node = Node(f"{node.get_name()}_scene", namespace=node.get_namespace(), context=node.context,
                                start_parameter_services=False,
                                parameter_overrides=[Parameter("start_type_description_service", value=False)])
        quiet = SubscriptionEventCallbacks(use_default_callbacks=False)
        self.collision_object_sub = self._scene_node.create_subscription(
            CollisionObject, "collision_object", _ignore, COLLISION_OBJECT_QOS, raw=True, event_callbacks=quiet)
        # attach/detach change the same scene: taken by the same thread, applied in arrival order
        self.attached_object_sub = self._scene_node.create_subscription(
            AttachedCollisionObject, "attached_collision_object", _ignore, COLLISION_OBJECT_QOS, event_callbacks=quiet)
        self._lost = [_message_lost_counter(sub) for sub in (self.collision_object_sub, self.attached_object_sub)]
        self._lost_totals = [0, 0]
        for sub in (self.collision_object_sub, self.attached_object_sub):
            self._warn_incompatible_qos(sub)
        self.joint_states_sub = self.topics.node.create_subscription(
            JointState, "joint_states", self._on_joint_state, JOINT_STATES_QOS, callback_group=self.state_group)
        self._ingest = threading.Thread(target=self._ingest_loop, name="scene-ingest", daemon=True)
        self._ingest.start()
        self.get_planning_scene_srv = node.create_service(
            GetPlanningScene, "get_planning_scene", self._on_get_planning_scene, qos_profile=SERVICE_QOS,
            callback_group=service_group)

    def _warn_incompatible_qos(self, sub) -> None:
        """rclpy's warning for a publisher whose QoS cannot reach `sub` (e.g. best effort), served by the
        topic thread's executor (the scene node is not spun)."""
        topic, log = sub.topic_name, self._node.get_logger()

        def warn(event) -> None:
            log.warning(f"a publisher on {topic!r} offers incompatible QoS ({qos_policy_name_from_kind(event.last_policy_kind)}): "
                        "none of its messages will be received")

        try:
            handler = EventHandler(callback_group=self.topics.node.default_callback_group, callback=warn,
                                   event_type=QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS,
                                   parent_impl=sub.handle)
        except UnsupportedEventTypeError:
            return
        self.topics.node.add_waitable(handler)

    def latest_joint_state(self) -> JointState | None:
        """The last message received on joint_states (None before the first)."""
        with self._joint_state_lock:
            return self._joint_state

    def joint_state_and_age(self) -> tuple[JointState | None, float]:
        """The last joint_states message and how many seconds ago it was received (None, 0.0 before the first)."""
        with self._joint_state_lock:
            msg, received = self._joint_state, self._joint_state_time
        return msg, (time.monotonic() - received if msg is not None else 0.0)

    def count_dropped(self) -> int:
        """Scene messages lost so far before the node could take them: the running totals of the
        subscriptions' DDS message-lost status (samples a keep-last publisher overwrote while the
        node's reader was full). Also sets `dropped`."""
        with self._lost_lock:
            for i, handle in enumerate(self._lost):
                if handle is None:
                    continue
                with handle:
                    info = handle.take_event()
                if info is not None:
                    self._lost_totals[i] = int(info.total_count)
            self.dropped = sum(self._lost_totals)
            return self.dropped

    def _report_drops(self) -> None:
        """At most once a period: publish and log the drop count when it grew."""
        try:
            if self._closing.is_set():
                return
            n = self.count_dropped()
            if n == self._dropped_reported:
                return
            self.dropped_pub.publish(UInt64(data=n))
            self._node.get_logger().warning(
                f"{n - self._dropped_reported} scene message(s) lost before the node could apply them: their "
                f"publisher (keep-last QoS) overwrote them while the node's reader was full; {n} in all")
            self._dropped_reported = n
        except Exception as e:  # noqa: BLE001 - never let a timer callback die
            self._node.get_logger().error(f"dropped scene updates not reported: {e!r}")

    def close(self) -> None:
        """Stop the scene thread after the turn it is in (messages not yet taken are not applied: a node
        shutting down does not need them), then the topics' thread and the scene node."""
        self._closing.set()
        self._ingest.join(timeout=2.0)
        self.topics.close()
        for handle in self._lost:
            if handle is not None:
                handle.destroy_when_not_in_use()
        self._scene_node.destroy_node()

    # ------------------------------------------------------------------ the scene thread
    def _ingest_loop(self) -> None:
        """Wait for scene messages, take a turn's worth, apply them; under a sustained backlog sleep
        between turns (FLOOD_DUTY)."""
        co, att = self.collision_object_sub, self.attached_object_sub
        wait_set = _rclpy.WaitSet(2, 0, 0, 0, 0, 0, self._scene_node.context.handle)
        held: list[tuple[int, bytes]] = []  # collision objects taken but not yet due (see _take)
        backlog_since: float | None = None
        while not self._closing.is_set():
            try:
                if not held:
                    with co.handle, att.handle:
                        wait_set.clear_entities()
                        wait_set.add_subscription(co.handle)
                        wait_set.add_subscription(att.handle)
                        wait_set.wait(int(INGEST_WAIT * 1e9))
                start = time.monotonic()
                batch, more = self._take(held)
                if batch and not self._closing.is_set():
                    self._apply_batch(batch)
                if not more:
                    backlog_since = None
                elif backlog_since is None:
                    backlog_since = start
                elif start - backlog_since > FLOOD_GRACE:
                    self._closing.wait((time.monotonic() - start) * (1.0 - FLOOD_DUTY) / FLOOD_DUTY)
            except Exception as e:  # noqa: BLE001 - never let the scene thread die
                if self._closing.is_set():
                    return
                self._node.get_logger().error(f"scene thread: {e!r}")
                self._closing.wait(0.05)

    def _take(self, held: list[tuple[int, bytes]]) -> tuple[list, bool]:
        """(this turn's messages in arrival order, whether more are waiting). The attached objects are
        taken first, then the collision objects; a collision object received after that (held for the
        next turn) may have an attached object before it that the next turn takes."""
        co, att = self.collision_object_sub, self.attached_object_sub
        attached: list[tuple[int, AttachedCollisionObject]] = []
        with att.handle:
            while len(attached) < self._batch and (taken := att.handle.take_message(AttachedCollisionObject, False)):
                attached.append((int(taken[1].get("received_timestamp") or 0), taken[0]))
        cut = time.time_ns()  # received_timestamp: the DDS reception time, system clock
        with co.handle:
            while len(held) < self._batch and (taken := co.handle.take_message(CollisionObject, True)):
                held.append((int(taken[1].get("received_timestamp") or 0), taken[0]))
        more = len(held) >= self._batch or len(attached) >= self._batch
        due = 0
        while due < len(held) and held[due][0] <= cut:
            due += 1
        batch = held[:due]
        del held[:due]
        if attached:
            batch = sorted(batch + attached, key=lambda m: m[0])  # stable: each topic keeps its order
        return [m for _, m in batch], more or bool(held)

    def _apply_batch(self, batch: list) -> None:
        """Apply one turn's messages in order; a MOVE followed in the turn by another valid MOVE of the same
        object, with nothing else about that object between them, is not applied on its own: the later
        one stands for it (the object ends where the last MOVE puts it)."""
        items: list = []  # AttachedCollisionObject, (RawObject, SceneUpdate), or None (refused)
        for m in batch:
            items.append(m if isinstance(m, AttachedCollisionObject) else self._read(m))
        stands_for = [1] * len(items)  # messages each item applies
        later_move: dict[str, int] = {}  # object id -> the index of its next message, when that is a MOVE
        for i in range(len(items) - 1, -1, -1):
            item = items[i]
            if item is None:
                continue
            if isinstance(item, AttachedCollisionObject):
                later_move.clear()
                continue
            raw = item[0]
            if raw.operation == Operation.MOVE:
                j = later_move.get(raw.id)
                if j is not None:
                    stands_for[j] += stands_for[i]
                    stands_for[i] = 0
                later_move[raw.id] = i
            elif raw.operation == Operation.REMOVE and not raw.id:
                later_move.clear()
            else:
                later_move.pop(raw.id, None)
        for item, n in zip(items, stands_for):
            if item is None or n == 0:
                continue
            if isinstance(item, AttachedCollisionObject):
                self._on_attached_object(item)
            else:
                self._apply(item[0], item[1], n)

    def _read(self, data: bytes) -> tuple[RawObject, SceneUpdate] | None:
        """A serialized CollisionObject read and checked on its own (None: refused, logged)."""
        log = self._node.get_logger()
        try:
            raw = parse_collision_object(data, self.scene.limits)
            return raw, raw_object_to_update(raw, self.scene.frame, self._frame_aliases, self.scene.limits,
                                             self._node.frames.pose)
        except SceneUpdateError as e:
            log.warning(f"collision_object rejected, scene unchanged: {e}")
        except Exception as e:  # noqa: BLE001 - never let the scene thread die
            log.error(f"collision_object ({len(data)} bytes) failed, scene unchanged: {e!r}")
        return None

    def _apply(self, raw: RawObject, update: SceneUpdate, messages: int = 1) -> int | None:
        """Apply one checked update standing for `messages` messages; the new version, or None when it was
        refused (logged; the scene is unchanged)."""
        log = self._node.get_logger()
        op = OPERATION_NAMES.get(raw.operation, str(raw.operation))
        also = f" (and {messages - 1} earlier MOVE(s) of it)" if messages > 1 else ""
        try:
            version = self.scene.apply(update, messages)
        except SceneUpdateError as e:
            log.warning(f"collision_object rejected{also}, scene unchanged: {e}")
            return None
        except Exception as e:  # noqa: BLE001 - never let the scene thread die
            log.error(f"collision_object {op} {raw.id!r}{also} failed, scene unchanged: {e!r}")
            return None
        self.applied += messages
        self.superseded += messages - 1
        if raw.operation != CollisionObject.REMOVE:  # nothing left to convert
            self._prepare_object_message(raw.id)
        return version

    def apply_serialized(self, data: bytes) -> int | None:
        """Read, check and apply one serialized CollisionObject; the new version, or None when it
        was refused (logged; the scene is unchanged). Never raises."""
        read = self._read(data)
        return None if read is None else self._apply(*read)

    def _prepare_object_message(self, object_id: str) -> None:
        """Convert the object just changed into its full message here, in the scene thread, when that is
        costly (a mesh, many grasps), so that no get_planning_scene pays for it; a cheap object's message
        is built when an answer asks for it. A moved object's message shares the shapes and grasps of
        the one it had (only the pose is new)."""
        try:
            obj = self.scene.get(object_id)
            with self._cache_lock:
                cache = self._object_msgs[ALL_OBJECT_PARTS]
                before = cache.get(object_id)
            if obj is None or (len(obj.grasps) <= EAGER_GRASPS and not any(s.kind == "mesh" for s in obj.shapes)):
                return
            if before is not None and before[0].shapes is obj.shapes and before[0].grasps is obj.grasps:
                msg = moved_message(before[1], obj)
            else:
                msg = scene_object_to_msg(obj, self.scene.frame)
            with self._cache_lock:
                cache[object_id] = (obj, msg)
                if len(cache) > 2 * len(self.scene) + 64:  # objects removed since the last answer
                    live = {o.id for o in self.scene.snapshot().objects}
                    for oid in [k for k in cache if k not in live]:
                        del cache[oid]
        except Exception as e:  # noqa: BLE001 - never let the scene thread die
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
                    msgs: dict[str, tuple[SceneObject, CollisionObject]] = {}
                    for o in snap.objects:
                        hit = cached.get(o.id)
                        msgs[o.id] = hit if hit is not None and hit[0] is o else (o, scene_object_to_msg(
                            o, snap.frame, geometry=bool(parts & GetPlanningScene.Request.OBJECT_GEOMETRY),
                            grasps=bool(parts & GetPlanningScene.Request.OBJECT_GRASPS)))
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
            (response.version, response.objects, response.attached_objects,
             response.occupied_voxels) = self.scene_messages(int(request.components))
            response.planning_frame = self.scene.frame
        except Exception as e:
            self._node.get_logger().error(f"get_planning_scene failed: {e!r}")
            response.planning_frame = self.scene.frame
        return response
