"""The scene topics' intake: `collision_object` and `attached_collision_object` into the planning scene,
in arrival order, with a barrier for requests and an exact count of what was not applied.

No executor takes these messages. Their subscriptions belong to a node of their own (`<name>_scene`,
sharing the node's DDS participant) that nothing spins; the scene thread (`scene-ingest`) waits on them,
takes what has arrived and applies it. So:

- Ordering: a request handler calls `sync()` before it reads the scene: it takes what the DDS readers
  hold and applies every message received before the request, so an update a client published (and DDS
  delivered) before it called a service is in the scene that call sees, as MoveIt users expect.
- The DDS readers are kept drained (a full reliable reader made the publisher's retransmissions crowd
  the participant: service requests went unanswered for seconds). Taking is cheap (the serialized
  bytes, and for a collision object its id and operation read from them, `peek`).
- A MOVE of an object whose previous message still waiting is also a MOVE takes that message's place
  (it would be overwritten at once): a flood of MOVEs costs one update per object, however fast it
  comes. The update then stands for every message it replaced: the version advances by their number,
  each counts as applied.
- At most `max_queued` updates wait; a message taken while that many wait is discarded. Discarded
  messages, MOVEs replaced by one that is then refused for its content (one refused because its object
  is absent or attached stands for MOVEs that would all have been refused: refused, not dropped), and
  the messages DDS lost before the node took them (a keep-last publisher overwriting samples not yet
  delivered: the subscription's message-lost status) make the drop count: every message received is
  applied, refused (logged) or counted.
- A turn of the scene thread takes only what was received before it began and applies for at most
  TURN_SECONDS; under a backlog lasting longer than FLOOD_GRACE it then rests (FLOOD_DUTY), so that
  services and plans keep the interpreter.
- Requests first: while a request handler is answering (`answering()`: `sync()`, reading the scene,
  building and sending the answer) the scene thread ends its turn after the update it is applying and
  waits (at most QUIET_MAX, then it does a whole turn), so the answer does not share the interpreter
  with it. `sync()` itself takes only the messages received before it began.
"""
from __future__ import annotations

import struct
import threading
import time
from collections import deque
from contextlib import contextmanager
from typing import Callable

from rclpy.event_handler import (EventHandler, QoSSubscriptionEventType, SubscriptionEventCallbacks,
                                 UnsupportedEventTypeError)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_policy_name_from_kind

from humanoid_planner.core.scene.checks import SceneStateError, SceneUpdateError
from humanoid_planner.core.scene.planning_scene import PlanningScene
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject

from humanoid_planner.ros.collision_object_cdr import parse_collision_object
from humanoid_planner.ros.conversions import RawObject, raw_object_to_update
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS

OPERATION_NAMES = {0: "ADD", 1: "REMOVE", 2: "APPEND", 3: "MOVE"}
INGEST_WAIT = 0.2  # s: the scene thread's longest wait for a message before it looks at close()
TURN_SECONDS = 0.02  # s: a turn of the scene thread applies updates for this long at most (one may take longer)
TAKE_LIMIT = 20_000  # messages taken per topic and turn at most (a flood faster than taking still lets turns end)
FLOOD_GRACE = 0.5  # s of uninterrupted work (a burst) the scene thread does at full speed
FLOOD_DUTY = 0.5  # past FLOOD_GRACE: the share of the time the scene thread may work (it rests the rest;
# bench_scale --only-flood, six alternating runs against 0.8: names p95 median 112 vs 131 ms, plan p95 109 vs 127 ms)
SYNC_BUDGET = 1.0  # s: the longest a request waits for the updates received before it (then it goes on)
QUIET_MAX = 0.05  # s the scene thread waits for requests being answered before it does a whole turn anyway
_CDR = 4  # bytes of the encapsulation header: CDR offsets are relative to its end


_U32 = {1: struct.Struct("<I").unpack_from, 0: struct.Struct(">I").unpack_from}
_COUNTS = {1: struct.Struct("<5I").unpack_from, 0: struct.Struct(">5I").unpack_from}


def peek(data: bytes) -> tuple[str, int | None] | None:
    """(id, operation) of a serialized CollisionObject, read without building it: the operation only
    when the message has no shapes and no grasps (a MOVE or REMOVE as sent), else None; None for bytes
    that are not such a message (the full reader refuses them later). A few microseconds: every message
    of a flood goes through it."""
    try:
        if data[0] != 0 or data[1] not in (0, 1):
            return None
        u32 = _U32[data[1]]
        pos = _CDR + 8  # after header.stamp
        pos += 4 + u32(data, pos)[0]  # header.frame_id
        pos += -(pos - _CDR) % 4
        n = u32(data, pos)[0]  # id
        oid = data[pos + 4:pos + 3 + n].decode("utf-8") if n else ""
        pos += 4 + n
        pos += 56 + -(pos - _CDR) % 8  # pose
        if any(_COUNTS[data[1]](data, pos)):  # primitives, primitive_poses, meshes, mesh_poses, grasps
            return oid, None
        pos += 20
        if pos + 1 != len(data) and not (pos + 1 < len(data) <= pos + 4 and not any(data[pos + 1:])):
            return None  # only alignment padding may follow the operation
        op = data[pos]
        return oid, op - 256 if op > 127 else op
    except (IndexError, struct.error, UnicodeDecodeError):
        return None


class _Update:
    """A message waiting to be applied: a serialized CollisionObject (`data`, standing for `n` messages)
    or an AttachedCollisionObject."""

    __slots__ = ("data", "n", "oid")

    def __init__(self, data, oid: str | None = None):
        self.data = data
        self.n = 1
        self.oid = oid  # set while this is the newest waiting message of that object and a MOVE


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


class SceneIntake:
    """The scene topics' subscriptions of `node` and the thread that applies them to `scene`."""

    def __init__(self, node: Node, scene: PlanningScene, frame_aliases: tuple[str, ...], max_queued: int,
                 on_applied: Callable[[RawObject], None], on_attached: Callable[[AttachedCollisionObject], None],
                 warnings_node: Node):
        """on_applied(raw): after a collision object was applied (in the scene thread); on_attached(msg):
        applies an attached collision object (a refusal is logged). warnings_node: a spun node that serves the subscriptions'
        incompatible-QoS warnings."""
        self._node = node
        self.scene = scene
        self._frame_aliases = frame_aliases
        self._max_queued = max(1, int(max_queued))
        self._on_applied = on_applied
        self._on_attached = on_attached
        self._lock = threading.Lock()  # taking and applying: the scene thread's turns and sync()
        self._syncing = 0  # sync() calls waiting for the lock (the scene thread lets them in)
        self._answering = 0  # requests being answered (answering()): the scene thread waits for them
        self._answered = threading.Event()  # set while no request is being answered
        self._answered.set()
        self._answering_lock = threading.Lock()
        self._closing = threading.Event()
        self._closed = False
        self._pending: deque[_Update] = deque()
        self._moves: dict[str, _Update] = {}  # object id -> its waiting MOVE, when that is its newest message
        self._held: list[tuple[int, bytes]] = []  # collision objects received after the last cut (see _take)
        self.discarded = 0  # messages taken while max_queued waited
        self.superseded_refused = 0  # MOVEs replaced by a later one that was then refused for its content
        self._lost_lock = threading.Lock()
        self._lost_totals = [0, 0]
        # It shares the node's DDS participant. A participant of its own keeps a flood out of the receive
        # port the service requests arrive on (bench_scale's flood: get_planning_scene p95 3 s -> 0.5 s, no
        # request waiting for its client's heartbeat), but then updates published right after a new
        # publisher matched went missing (most of test_scene_topic failed). Without the global ROS arguments
        # (a __node remap would rename it too): its topics are the node's, resolved by the node.
        self._scene_node = Node(f"{node.get_name()}_scene", namespace=node.get_namespace(), context=node.context,
                                use_global_arguments=False, start_parameter_services=False,
                                parameter_overrides=[Parameter("start_type_description_service", value=False)])
        quiet = SubscriptionEventCallbacks(use_default_callbacks=False)
        self.collision_object_sub = self._scene_node.create_subscription(
            CollisionObject, node.resolve_topic_name("collision_object"), _ignore, COLLISION_OBJECT_QOS, raw=True,
            event_callbacks=quiet)
        self.attached_object_sub = self._scene_node.create_subscription(
            AttachedCollisionObject, node.resolve_topic_name("attached_collision_object"), _ignore,
            COLLISION_OBJECT_QOS, event_callbacks=quiet)
        self._lost = [_message_lost_counter(s) for s in (self.collision_object_sub, self.attached_object_sub)]
        self._warnings_node = warnings_node
        self._qos_handlers = [h for sub in (self.collision_object_sub, self.attached_object_sub)
                              if (h := self._warn_incompatible_qos(sub, warnings_node)) is not None]
        self._thread = threading.Thread(target=self._run, name="scene-ingest", daemon=True)
        self._thread.start()

    def _warn_incompatible_qos(self, sub, warnings_node: Node) -> EventHandler | None:
        """rclpy's warning for a publisher whose QoS cannot reach `sub` (e.g. best effort), served by
        `warnings_node`'s executor (the scene node is not spun). The handler holds `sub`: close() destroys
        it, or the subscription (and its reader, which keep-all publishers wait for) outlives the node."""
        topic, log = sub.topic_name, self._node.get_logger()

        def warn(event) -> None:
            log.warning(f"a publisher on {topic!r} offers incompatible QoS "
                        f"({qos_policy_name_from_kind(event.last_policy_kind)}): none of its messages will be received")

        try:
            handler = EventHandler(callback_group=warnings_node.default_callback_group, callback=warn,
                                   event_type=QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS,
                                   parent_impl=sub.handle)
        except UnsupportedEventTypeError:
            return None
        warnings_node.add_waitable(handler)
        return handler

    # ------------------------------------------------------------------ counts
    def dropped(self) -> int:
        """Messages received or sent but not applied and not refused, so far: discarded, replaced by a
        MOVE refused for its content, or lost in DDS before the node took them (the subscriptions'
        message-lost totals)."""
        with self._lost_lock:
            if not self._closed:
                for i, handle in enumerate(self._lost):
                    if handle is None:
                        continue
                    with handle:
                        info = handle.take_event()
                    if info is not None:
                        self._lost_totals[i] = int(info.total_count)
            return self.discarded + self.superseded_refused + sum(self._lost_totals)

    def backlog(self) -> int:
        """Updates taken and waiting to be applied."""
        return len(self._pending) + len(self._held)

    # ------------------------------------------------------------------ the barrier
    def sync(self, budget: float = SYNC_BUDGET) -> bool:
        """Take what has arrived and apply every update received before this call, for at most `budget`
        seconds; whether all of them are applied. Called by request handlers before they read the scene."""
        if self._closing.is_set():
            return False
        deadline = time.monotonic() + budget
        self._syncing += 1
        try:
            if not self._lock.acquire(timeout=budget):
                return False
        finally:
            self._syncing -= 1
        try:
            if self._closed:
                return False
            self._take()
            return self._apply_pending(deadline, yield_to_requests=False)
        finally:
            self._lock.release()

    def begin_answer(self) -> None:
        """A request handler starts answering: the scene thread pauses (see answering()); end_answer() once
        the answer is sent."""
        with self._answering_lock:
            self._answering += 1
            self._answered.clear()

    def end_answer(self) -> None:
        with self._answering_lock:
            self._answering = max(0, self._answering - 1)
            if not self._answering:
                self._answered.set()

    @contextmanager
    def answering(self):
        """Around a request's work: the scene thread ends its turn and waits until no request is being
        answered (at most QUIET_MAX at a time), so that the answer does not share the interpreter with
        updates of other clients' topics (a flood: the answer took 2-3 times its CPU time)."""
        self.begin_answer()
        try:
            yield
        finally:
            self.end_answer()

    # ------------------------------------------------------------------ the scene thread
    def close(self) -> None:
        """Stop the scene thread after its turn (updates not yet applied are not: a node shutting down
        does not need them), then the subscriptions."""
        self._closing.set()
        self._thread.join(timeout=2.0)
        got = self._lock.acquire(timeout=1.0)
        try:
            with self._lost_lock:
                self._closed = True
                for handle in self._lost:
                    if handle is not None:
                        handle.destroy_when_not_in_use()
            for handler in self._qos_handlers:
                self._warnings_node.remove_waitable(handler)
                handler.destroy()
            self._scene_node.destroy_node()
        finally:
            if got:
                self._lock.release()

    def _run(self) -> None:
        """Wait for scene messages, take them, apply a turn's worth; rest under a sustained flood."""
        co, att = self.collision_object_sub, self.attached_object_sub
        wait_set = _rclpy.WaitSet(2, 0, 0, 0, 0, 0, self._scene_node.context.handle)
        busy_since: float | None = None
        while not self._closing.is_set():
            try:
                if not self._pending and not self._held:
                    t_wait = time.monotonic()
                    with co.handle, att.handle:
                        wait_set.clear_entities()
                        wait_set.add_subscription(co.handle)
                        wait_set.add_subscription(att.handle)
                        wait_set.wait(int(INGEST_WAIT * 1e9))
                    if time.monotonic() - t_wait > 0.001:  # it had to wait: no flood
                        busy_since = None
                if self._syncing:
                    time.sleep(0)  # a request's sync() takes the lock first
                # requests being answered first; after QUIET_MAX a whole turn all the same (no starving)
                waited_out = not self._answered.wait(QUIET_MAX)
                start = time.monotonic()
                with self._lock:
                    if self._closing.is_set():
                        return
                    took = self._take()
                    self._apply_pending(start + TURN_SECONDS, yield_to_requests=not waited_out)
                if not took and not self._pending:
                    busy_since = None
                elif busy_since is None:
                    busy_since = start
                elif start - busy_since > FLOOD_GRACE:
                    self._closing.wait((time.monotonic() - start) * (1.0 - FLOOD_DUTY) / FLOOD_DUTY)
            except Exception as e:  # noqa: BLE001 - never let the scene thread die
                if self._closing.is_set():
                    return
                self._node.get_logger().error(f"scene thread: {e!r}")
                self._closing.wait(0.05)

    def _take(self) -> int:
        """Take what the readers hold (lock held) into the waiting updates, in arrival order; the number
        taken. Attached objects are taken first, then the collision objects received before that; the
        first one received after it is held for the next take (the rest stay in the reader), which takes
        the attached objects received before it first."""
        co, att = self.collision_object_sub, self.attached_object_sub
        attached: list[tuple[int, AttachedCollisionObject]] = []
        with att.handle:
            while len(attached) < TAKE_LIMIT and (taken := att.handle.take_message(AttachedCollisionObject, False)):
                attached.append((int(taken[1].get("received_timestamp") or 0), taken[0]))
        cut = time.time_ns()  # received_timestamp: the DDS reception time, system clock
        objects, self._held = self._held, []
        with co.handle:
            for _ in range(TAKE_LIMIT):
                if not (taken := co.handle.take_message(CollisionObject, True)):
                    break
                stamp = int(taken[1].get("received_timestamp") or 0)
                if stamp > cut:  # this one and the rest came later: the next take's (a flood cannot stretch a turn)
                    self._held.append((stamp, taken[0]))
                    break
                objects.append((stamp, taken[0]))
        if attached:
            merged = sorted([(s, True, m) for s, m in attached] + [(s, False, m) for s, m in objects],
                            key=lambda x: x[0])  # stable: each topic keeps its order
        else:
            merged = [(s, False, m) for s, m in objects]
        for _, is_attached, m in merged:
            self._enqueue(m, is_attached)
        return len(attached) + len(objects)

    def _enqueue(self, m, is_attached: bool) -> None:
        """One taken message into the waiting updates: a MOVE replaces its object's waiting MOVE."""
        head = None if is_attached else peek(m)
        if head is not None and head[1] == CollisionObject.MOVE:
            waiting = self._moves.get(head[0])
            if waiting is not None:
                waiting.data = m
                waiting.n += 1
                return
        if len(self._pending) >= self._max_queued:
            self.discarded += 1
            return
        update = _Update(m)
        self._pending.append(update)
        if head is None or (head[1] == CollisionObject.REMOVE and not head[0]):
            # an attach / detach, a message not read, or REMOVE of all: no MOVE before it may move past it
            for u in self._moves.values():
                u.oid = None
            self._moves.clear()
        elif head[1] == CollisionObject.MOVE:
            update.oid = head[0]
            self._moves[head[0]] = update
        elif (before := self._moves.pop(head[0], None)) is not None:
            before.oid = None

    def _apply_pending(self, deadline: float, yield_to_requests: bool = True) -> bool:
        """Apply waiting updates in order until none is left (True), `deadline`, or (yield_to_requests:
        the scene thread's turn) a request waits in sync() or is being answered (lock held)."""
        while self._pending:
            if time.monotonic() > deadline or self._closing.is_set():
                return False
            if yield_to_requests and (self._syncing or self._answering):
                return False
            update = self._pending.popleft()
            if update.oid is not None:
                del self._moves[update.oid]
            if isinstance(update.data, AttachedCollisionObject):
                self._on_attached(update.data)
            else:
                self._apply(update.data, update.n)
        return True

    def _apply(self, data: bytes, messages: int = 1) -> None:
        """Read, check and apply one serialized CollisionObject standing for `messages` messages; one
        refused is logged (the scene is unchanged) and the messages it replaced count as dropped."""
        log = self._node.get_logger()
        raw = None
        try:
            raw = parse_collision_object(data, self.scene.limits)
            version = self.scene.apply(raw_object_to_update(raw, self.scene.frame, self._frame_aliases,
                                                            self.scene.limits, self._node.frames.pose), messages)
        except SceneStateError as e:
            # absent or attached: each MOVE it replaced saw the same state (an ADD, REMOVE or attach of the
            # object ends the run of MOVEs: _enqueue), so it would have been refused as well, not lost
            log.warning(f"collision_object rejected, scene unchanged: {e}"
                        f"{f' (and the {messages - 1} MOVEs of it before, for the same reason)' if messages > 1 else ''}")
            return
        except SceneUpdateError as e:
            log.warning(f"collision_object rejected, scene unchanged: {e}")
        except Exception as e:  # noqa: BLE001 - never let the scene thread die
            what = (f"({len(data)} bytes)" if raw is None
                    else f"{OPERATION_NAMES.get(raw.operation, raw.operation)} {raw.id!r}")
            log.error(f"collision_object {what} failed, scene unchanged: {e!r}")
        else:
            log.debug(f"collision_object {OPERATION_NAMES.get(raw.operation, raw.operation)} {raw.id!r} applied"
                      f"{f' (for {messages} messages)' if messages > 1 else ''}; scene version {version}")
            self._on_applied(raw)
            return
        self.superseded_refused += messages - 1
