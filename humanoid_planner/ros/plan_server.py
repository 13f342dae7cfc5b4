"""The plan services `plan_grasp`, `plan_dual_grasp`, `plan_to_state`, `plan_place` and
`plan_dual_place` (and the actions of the same names): check a request, plan it in the planning thread pool, answer from the thread that finishes.

Threading (see docs/ARCHITECTURE.md and the ROS 2 callback-group guide): the services share the
node's Reentrant service group, so several requests may run at once. The plan services answer later
(deferred responses): the callback checks the request in the executor thread (fast) against the
current scene, hands the planning to a bounded pool (`num_workers` planning threads; a plan runs on a
frozen snapshot of the scene taken when it starts) and returns a `PendingResponse`; the thread that
finishes the plan fills the response and sends it itself. No executor thread is ever blocked by a
plan — scene updates, `get_planning_scene` and further requests keep being served however many
plans are queued or running — and the answer does not wait for the executor to wake up.

Deferred responses: rclpy, unlike rclcpp, has no API to answer a request outside its callback, but
every rclpy executor (the Python ones and the EventsExecutor) answers through the service object's
`send_response(response, header)`. `defer_responses` wraps that method on the plan services: given a
`PendingResponse` it only records the request header, and the pending response is sent by whichever
of the two sides (executor: header, planning thread: response) comes second.

Deadlines: a request's timeout counts from its arrival (time spent queued included); the core stops
itself at the deadline, and the `Watchdog` answers TIMED_OUT (and cancels the plan) if it has not
answered `timeout + max(1 s, timeout / 2)` after arrival. `cancel_plans` (shutdown) cancels every
queued and running plan.
"""
from __future__ import annotations

import threading
import time
import functools
from dataclasses import dataclass, replace
from typing import Callable

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from trajectory_msgs.msg import JointTrajectory

from humanoid_planner.core.pipeline.planner import GraspPlan
from humanoid_planner.core.planners.common import PlanStatus, Progress
from humanoid_planner_interfaces import action as actions
from humanoid_planner_interfaces.msg import ErrorCode
from humanoid_planner_interfaces.srv import PlanDualGrasp, PlanDualPlace, PlanGrasp, PlanPlace, PlanToState

from humanoid_planner.ros.markers import MarkerPublisher
from humanoid_planner.ros.planning_threads import PlanningThreads, QueueFull
from humanoid_planner.ros.qos import PLANNED_TRAJECTORY_QOS, SERVICE_QOS
from humanoid_planner.ros.requests import (ERROR_NAMES, GRASP_LISTS, PreparedRequest, RequestDefaults, RequestError,
                                           check_grasp_count, fail_response, fill_place_response, fill_response,
                                           fill_state_response, fresh_joint_state, prepare_plan_dual_grasp,
                                           prepare_plan_dual_place, prepare_plan_grasp, prepare_plan_place,
                                           prepare_plan_to_state, request_timeout)
from humanoid_planner.ros.watchdog import WATCHDOG_GRACE, Watchdog


FEEDBACK_PERIOD = 0.1  # s: action feedback of every goal being planned, at this period (10 Hz)
ACTIONS = {"plan_grasp": actions.PlanGrasp, "plan_dual_grasp": actions.PlanDualGrasp,
           "plan_to_state": actions.PlanToState, "plan_place": actions.PlanPlace,
           "plan_dual_place": actions.PlanDualPlace}
PREPARE = {"plan_grasp": prepare_plan_grasp, "plan_dual_grasp": prepare_plan_dual_grasp,
           "plan_to_state": prepare_plan_to_state, "plan_place": prepare_plan_place,
           "plan_dual_place": prepare_plan_dual_place}  # request kind -> its message-to-core conversion
FEEDBACK = {a.Goal: a.Feedback for a in ACTIONS.values()}  # goal type -> its feedback type


def _nothing() -> None:
    """stop() of a request that was refused: nothing runs."""


def _accept_goal(goal) -> GoalResponse:
    """Every goal is accepted: one the checks refuse ends aborted with its error code in the result."""
    return GoalResponse.ACCEPT


def _unused_execute(goal_handle):
    """Never called: every goal is executed with its own callback once its plan is done (PlanServer)."""
    raise RuntimeError("plan goals are executed by PlanServer._end_goal")


def _queue_story(checking: float, waited: float, threads: int) -> str:
    return (f"{checking:.2f} s checking the request, then {waited:.2f} s waiting for a planning thread "
            f"(all {threads} busy); raise the timeout or num_workers")


CHECK_IN_THREAD_ABOVE = 200
"""Grasps in a request above which it is checked in the planning thread, not in the service callback
(checking 20 000 grasps took 7 s on a loaded machine: the executor would wait that long)."""


class PendingResponse:
    """A plan service's answer, sent later from a planning thread (see the module docstring).

    The service callback returns it instead of a response; the executor then hands it, with the
    request header, to the service's `send_response`, which `defer_responses` routes to `attach`.
    `complete(response)` comes from the thread that finished the plan (planning thread or watchdog).
    The response goes out once both are known, exactly once, from whichever thread came second.
    """

    __slots__ = ("_send", "_on_error", "_lock", "_header", "_response", "_sent")

    def __init__(self, send, on_error):
        self._send = send  # the service's own send_response(response, header)
        self._on_error = on_error  # called with the exception when sending fails
        self._lock = threading.Lock()
        self._header = None
        self._response = None
        self._sent = False

    def attach(self, header) -> None:
        with self._lock:
            self._header = header
        self._send_if_ready()

    def complete(self, response) -> None:
        with self._lock:
            self._response = response
        self._send_if_ready()

    @property
    def sent(self) -> bool:
        return self._sent

    def _send_if_ready(self) -> None:
        with self._lock:
            if self._sent or self._header is None or self._response is None:
                return
            self._sent = True
            response, header = self._response, self._header
        try:
            self._send(response, header)
        except Exception as e:  # noqa: BLE001 - e.g. the node is being destroyed, the context shut down
            self._on_error(e)


def defer_responses(service):
    """Let `service` answer with a PendingResponse: its send_response then records the header instead.
    Returns the service's own send_response (what a PendingResponse sends with)."""
    send = service.send_response

    def send_response(response, header):
        if isinstance(response, PendingResponse):
            response.attach(header)
        else:
            send(response, header)

    service.send_response = send_response
    return send


@dataclass
class _Goal:
    """An action goal being planned: what its feedback reads and how to stop it."""

    handle: ServerGoalHandle
    progress: Progress
    accepted: float  # time.monotonic() when the goal was accepted
    stop: Callable[[], None] = _nothing


class PlanServer:
    """The plan services and actions of `node` (a PlannerNode: its robot, scene, planner (use_planner),
    planning_frame, frames, params and scene_server are read when a request comes).

    Services and actions share one path (`_start`): the same checks, the same planning thread pool,
    deadlines and answer (`_answer`). A service answers with a deferred response. An action goal is
    accepted at once, gets feedback (phase, elapsed, iterations, best TCP distance, solutions) every
    FEEDBACK_PERIOD while it is queued or planned, and its result is the service's response: a goal
    the request checks refuse is aborted with the error code in its result; a cancelled goal stops
    its plan (or leaves the queue) and ends canceled with PREEMPTED.

    Executor: the goal's execute step runs only once the plan is done (`goal_handle.execute` from the
    planning thread, with a plain callback that only sets the final state). An execute callback that
    awaited the plan instead kept the EventsExecutor polling its task: 0.40 s of CPU per 1 s goal,
    against 0.026 s this way (0.028 s on the SingleThreadedExecutor); measured with rclpy 7.1.6. The
    goal's status is therefore ACCEPTED while it is queued and planned, EXECUTING only at the end.
    """

    def __init__(self, node, service_group: CallbackGroup, markers: MarkerPublisher):
        self._node = node
        self._markers = markers
        self._threads = PlanningThreads(node.params.num_workers, node.params.max_queued_plans,
                                        on_error=lambda e: node.get_logger().error(f"planning thread: {e!r}"))
        self._watchdog = Watchdog(lambda e: node.get_logger().error(f"watchdog: {e!r}"))
        self._plans_lock = threading.Lock()
        self._active: set[threading.Event] = set()  # cancel events of queued and running plans
        self._shutting_down = threading.Event()
        self._goals: dict[bytes, _Goal] = {}  # goal id -> action goals queued or planned
        self.planned_trajectory_pub = node.create_publisher(JointTrajectory, "planned_trajectory",
                                                            PLANNED_TRAJECTORY_QOS)
        self.plan_grasp_srv = node.create_service(
            PlanGrasp, "plan_grasp", self._on_plan_grasp, qos_profile=SERVICE_QOS, callback_group=service_group)
        self.plan_dual_grasp_srv = node.create_service(
            PlanDualGrasp, "plan_dual_grasp", self._on_plan_dual_grasp, qos_profile=SERVICE_QOS,
            callback_group=service_group)
        self.plan_to_state_srv = node.create_service(
            PlanToState, "plan_to_state", self._on_plan_to_state, qos_profile=SERVICE_QOS, callback_group=service_group)
        self.plan_place_srv = node.create_service(
            PlanPlace, "plan_place", self._on_plan_place, qos_profile=SERVICE_QOS, callback_group=service_group)
        self.plan_dual_place_srv = node.create_service(
            PlanDualPlace, "plan_dual_place", self._on_plan_dual_place, qos_profile=SERVICE_QOS,
            callback_group=service_group)
        self._send = {"plan_grasp": defer_responses(self.plan_grasp_srv),
                      "plan_dual_grasp": defer_responses(self.plan_dual_grasp_srv),
                      "plan_to_state": defer_responses(self.plan_to_state_srv),
                      "plan_place": defer_responses(self.plan_place_srv),
                      "plan_dual_place": defer_responses(self.plan_dual_place_srv)}
        self.action_servers = [
            ActionServer(node, ACTIONS[kind], kind, execute_callback=_unused_execute, callback_group=service_group,
                         handle_accepted_callback=functools.partial(self._on_goal_accepted, kind),
                         goal_callback=_accept_goal, cancel_callback=self._on_cancel_goal)
            for kind in ACTIONS]
        self.feedback_timer = node.create_timer(FEEDBACK_PERIOD, self._on_feedback_timer,
                                                callback_group=MutuallyExclusiveCallbackGroup())

    @property
    def active_plans(self) -> int:
        """Plans queued or running."""
        with self._plans_lock:
            return len(self._active)

    def cancel_plans(self) -> None:
        """Stop every queued and running plan (they answer FAILURE "cancelled"); refuse new ones."""
        self._shutting_down.set()
        with self._plans_lock:
            active = list(self._active)
        for ev in active:
            ev.set()

    def close(self) -> None:
        self.cancel_plans()
        self._threads.shutdown()
        self._watchdog.close()
        for server in self.action_servers:
            server.destroy()

    # ------------------------------------------------------------------ services
    def _on_plan_grasp(self, request, response):
        return self._serve("plan_grasp", request, response)

    def _on_plan_dual_grasp(self, request, response):
        return self._serve("plan_dual_grasp", request, response)

    def _on_plan_to_state(self, request, response):
        return self._serve("plan_to_state", request, response)

    def _on_plan_place(self, request, response):
        return self._serve("plan_place", request, response)

    def _on_plan_dual_place(self, request, response):
        return self._serve("plan_dual_place", request, response)

    def _serve(self, kind: str, request, response):
        """One service request: the response now (refused) or a PendingResponse. Never raises."""
        pending = PendingResponse(self._send[kind],
                                  lambda e: self._log_late_failure(f"{kind}: the answer was not sent", e))
        now, _ = self._start(kind, request, response, pending.complete)
        return pending if now is None else now

    # ------------------------------------------------------------------ actions
    def _on_goal_accepted(self, kind: str, goal_handle: ServerGoalHandle) -> None:
        """Start planning an accepted goal (on the executor; never raises)."""
        def deliver(result) -> None:
            goal_handle.execute(functools.partial(self._end_goal, result=result))

        try:
            goal = _Goal(goal_handle, Progress(), time.monotonic())
            self._goals[bytes(goal_handle.goal_id.uuid)] = goal
            now, goal.stop = self._start(kind, goal_handle.request, ACTIONS[kind].Result(), deliver, goal.progress)
            if now is not None:
                deliver(now)
        except Exception as e:  # noqa: BLE001 - the goal ends aborted; the executor lives on
            self._node.get_logger().error(f"{kind} goal: {e!r}")
            deliver(fail_response(ACTIONS[kind].Result(), ErrorCode.FAILURE, f"internal error: {e!r}"))

    def _end_goal(self, goal_handle: ServerGoalHandle, result):
        """The goal's execute step (once its plan is done): its final state, and the result."""
        self._goals.pop(bytes(goal_handle.goal_id.uuid), None)
        if result.error_code.val == ErrorCode.SUCCESS:
            goal_handle.succeed()
        elif goal_handle.is_cancel_requested:
            result.error_code.val = ErrorCode.PREEMPTED
            result.message = "cancelled by the client" + (f" ({result.message})" if result.message else "")
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return result

    def _on_cancel_goal(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        goal = self._goals.get(bytes(goal_handle.goal_id.uuid))
        if goal is None:
            return CancelResponse.REJECT  # already answered
        goal.stop()
        return CancelResponse.ACCEPT

    def _on_feedback_timer(self) -> None:
        now = time.monotonic()
        for goal in list(self._goals.values()):
            try:
                p, goal_handle = goal.progress, goal.handle
                feedback = FEEDBACK[type(goal_handle.request)](
                    phase=p.phase, elapsed=now - goal.accepted, iterations=min(p.iterations, 2**32 - 1),
                    best_tcp_distance=p.best_tcp_distance, solutions=min(p.solutions, 2**32 - 1))
                goal_handle.publish_feedback(feedback)
            except Exception as e:  # noqa: BLE001 - feedback is a view, never a reason to fail a goal
                self._node.get_logger().debug(f"feedback not published: {e!r}")

    # ------------------------------------------------------------------ the shared path
    def _start(self, kind: str, request, response, deliver: Callable, progress: Progress | None = None
               ) -> tuple[object | None, Callable[[], None]]:
        """_check_and_start, the scene thread waiting meanwhile (SceneServer.answering)."""
        with self._node.scene_server.answering():
            return self._check_and_start(kind, request, response, deliver, progress)

    def _check_and_start(self, kind: str, request, response, deliver: Callable, progress: Progress | None = None
                         ) -> tuple[object | None, Callable[[], None]]:
        """Check a request and start its plan. Returns (the response, filled now, when the request is
        refused; a no-op) or (None, stop: cancels the plan); `deliver(response)` is then called once,
        from the thread that finishes the plan. Never raises.

        The request is checked at once against the current scene (bad requests never queue); when
        a planning thread starts it, the scene is snapshotted again and, if it changed meanwhile, the
        request is re-resolved against that snapshot (object pose and grasp set), which is then the
        one the plan uses and reports.
        """
        node = self._node
        arrival = time.monotonic()
        prepare = PREPARE[kind]
        version = 0
        try:
            params = node.params  # the values of this moment apply to the whole request
            defaults = RequestDefaults(params.default_timeout, params.min_grasp_score, params.max_timeout,
                                       params.max_grasps_per_request)
            node.scene_server.sync()  # the scene updates received before this request are in snap
            snap = node.scene.snapshot()
            version = snap.version
            joint_state = fresh_joint_state(node.robot, request.start_state, *node.scene_server.joint_state_and_age(),
                                            params.joint_states_max_age)
            lists = [f for f in GRASP_LISTS if hasattr(request, f)]
            if sum(len(getattr(request, f)) for f in lists) > CHECK_IN_THREAD_ABOVE:
                # many grasps: only the counts and the timeout here; the rest in the planning thread
                for f in lists:
                    check_grasp_count(getattr(request, f), f, defaults)
                prep, timeout = None, request_timeout(request.timeout, defaults)[0]
            else:
                prep = prepare(node.robot, request, snap, joint_state, defaults, node.frames)
                timeout = prep.core.timeout
        except RequestError as e:
            node.get_logger().warning(f"{kind} refused ({ERROR_NAMES.get(e.code, e.code)}): {e.message}")
            return fail_response(response, e.code, e.message, version), _nothing
        except Exception as e:  # noqa: BLE001 - never let a callback die
            node.get_logger().error(f"{kind}: checking the request failed: {e!r}")
            return fail_response(response, ErrorCode.FAILURE, f"internal error while checking the request: {e!r}",
                                 version), _nothing
        if self._shutting_down.is_set():
            return fail_response(response, ErrorCode.FAILURE, "the node is shutting down", version), _nothing

        def refresh(s):
            return prepare(node.robot, request, s, joint_state, defaults, node.frames)

        def done(result) -> None:
            self._answer(kind, deliver, response, result, version)

        return None, self._plan_in_worker(prep, refresh, arrival, done, progress, timeout, version)

    def _answer(self, kind: str, deliver: Callable, response, result, version: int) -> None:
        """In the thread that finished the plan: fill the response and deliver it, then (no longer on
        the caller's path) log, publish the trajectory and start the markers. Never raises."""
        log = self._node.get_logger()
        with self._node.scene_server.answering():
            plan, prep, response = self._fill(kind, response, result, version)
            deliver(response)
        if plan is None:
            return
        try:
            code = response.error_code.val
            log.info(
                f"{kind} {'+'.join(prep.groups) if prep is not None else ''}: {ERROR_NAMES.get(code, code)} in "
                f"{plan.planning_time:.3f} s, "
                f"{plan.iterations} iterations, scene version {plan.scene_version}"
                + (f", path by the search's {plan.stats['fallback']} fallback" if plan.stats.get("fallback") else "")
                + ("" if plan.ok else f": {plan.message}"))
            if plan.ok:
                # after the answer: the caller has its trajectory; subscribers get the same one right after
                self.planned_trajectory_pub.publish(response.trajectory)
                self._markers.show_plan(prep, plan)
        except Exception as e:  # noqa: BLE001 - e.g. the node is being destroyed; the answer is out
            self._log_late_failure(f"{kind}: the plan was not published", e)

    def _fill(self, kind: str, response, result, version: int) -> tuple:
        """(plan, the PreparedRequest it ran, the response filled from `result`); plan None when there is
        no plan to publish (refused, failed). Never raises."""
        log = self._node.get_logger()
        plan = prep = None
        try:
            if isinstance(result, RequestError):
                log.warning(f"{kind} refused when it started ({ERROR_NAMES.get(result.code)}): {result.message}")
                response = fail_response(response, result.code, result.message,
                                         getattr(result, "scene_version", version))
            elif isinstance(result, BaseException):
                raise result
            else:
                prep, plan = result
                notes = prep.notes if prep is not None else ()
                fixed = getattr(plan, "stats", {}).get("fixed_collisions")
                if fixed:  # planned all the same (GraspPlanner.fixed_collisions): the caller and the log hear of it
                    note = ("links that no joint of the planned groups moves collide at the start (the plan neither "
                            f"makes nor removes it): {', '.join(fixed)}")
                    notes = (*notes, note)
                    log.warning(f"{kind}: {note}")
                if kind == "plan_to_state":
                    fill_state_response(response, plan, self._node.planning_frame, notes)
                elif kind in ("plan_place", "plan_dual_place"):
                    fill_place_response(response, plan, self._node.planning_frame, kind == "plan_dual_place", notes)
                else:
                    fill_response(response, plan, self._node.planning_frame, kind == "plan_dual_grasp", notes)
        except Exception as e:  # noqa: BLE001
            log.error(f"{kind}: planning failed with an internal error: {e!r}")
            plan = None
            response = fail_response(type(response)(), ErrorCode.FAILURE, f"internal error while planning: {e!r}",
                                     version)
        return plan, prep, response

    def _log_late_failure(self, what: str, e: Exception) -> None:
        """An error after planning: expected while the node shuts down (debug), an error otherwise."""
        if self._shutting_down.is_set():
            self._node.get_logger().debug(f"{what} (shutting down): {e!r}")
        else:
            self._node.get_logger().error(f"{what}: {e!r}")

    def _plan_in_worker(self, prep: PreparedRequest | None, refresh: Callable, arrival: float, done: Callable,
                        progress: Progress | None, timeout: float, version: int) -> Callable[[], None]:
        """Run the plan on the planning threads; `done` is called once, in the thread that finishes,
        with (PreparedRequest used, GraspPlan), a RequestError (the request no longer fits the scene
        when it starts, or its client has too many queued) or an exception. Returns `stop`: cancels
        the plan (a plan still queued is answered CANCELLED at once, from the caller's thread).

        Queued plans run earliest deadline first (`PlanningThreads`): a short request never waits
        behind longer ones queued before it; when the queue is full the request is refused.

        Times: `planning_time` is the plan's own time, from when a planning thread started it (never
        the time queued); a request that never left the queue is told so with planning_time 0."""
        node = self._node
        cancel = threading.Event()
        lock = threading.Lock()
        finished = started = False
        queued_at = time.monotonic()  # the request was checked (in the callback) until now
        plan_started: float | None = None

        def finish(result) -> None:
            nonlocal finished
            with lock:
                if finished:
                    return
                finished = True
            Watchdog.cancel(deadline)
            with self._plans_lock:
                self._active.discard(cancel)
            done(result)

        def work() -> None:
            nonlocal started, plan_started
            with lock:
                started = True
            try:
                if cancel.is_set():
                    return finish((prep, GraspPlan(PlanStatus.CANCELLED, "cancelled before planning started: "
                                                   + ("the node is shutting down" if self._shutting_down.is_set()
                                                      else "the deadline passed"), scene_version=version)))
                now = time.monotonic()
                remaining = timeout - (now - arrival)
                if remaining <= 0.0:
                    return finish((prep, GraspPlan(
                        PlanStatus.TIMED_OUT, "timed out before planning started: "
                        + _queue_story(queued_at - arrival, now - queued_at, node.params.num_workers),
                        scene_version=version)))
                used = prep
                snap = node.scene.snapshot()
                if prep is None or snap.version != prep.snapshot.version:  # checked here, or again
                    try:
                        used = refresh(snap)
                    except RequestError as e:
                        e.scene_version = snap.version
                        return finish(e)
                core = replace(used.core, timeout=remaining)
                with lock:
                    plan_started = time.monotonic()
                plan = node.runner.run(used.kind, used.snapshot, core, cancel, progress)
                if plan.status is PlanStatus.CANCELLED and self._shutting_down.is_set():
                    plan.message = "cancelled: the node is shutting down"
                finish((used, plan))
            except BaseException as e:  # noqa: BLE001 - reported to the caller as FAILURE
                finish(e)

        def expire() -> None:
            cancel.set()
            now = time.monotonic()
            with lock:
                queued, began = not started, plan_started
            if queued:  # it never left the queue: say so, and it spent no time planning
                why = "never left the queue: " + _queue_story(queued_at - arrival, now - queued_at,
                                                               node.params.num_workers)
                plan = GraspPlan(PlanStatus.TIMED_OUT, why, scene_version=version)
            elif began is None:
                plan = GraspPlan(PlanStatus.TIMED_OUT, "the deadline passed while the request was being checked "
                                 "against the scene when its plan started; cancelled", scene_version=version)
            else:
                plan = GraspPlan(PlanStatus.TIMED_OUT, f"the planner did not stop by its {timeout:.3f} s deadline; "
                                 "cancelled", scene_version=version, planning_time=now - began)
            finish((prep, plan))

        deadline = self._watchdog.add(timeout + max(WATCHDOG_GRACE, 0.5 * timeout), expire)
        with self._plans_lock:
            self._active.add(cancel)
        if self._shutting_down.is_set():
            cancel.set()
        try:
            self._threads.submit(arrival + timeout, work)
        except QueueFull as e:
            finish(RequestError(ErrorCode.FAILURE, str(e)))
        except RuntimeError:  # shut down
            finish((prep, GraspPlan(PlanStatus.CANCELLED, "the node is shutting down", scene_version=version)))

        def stop() -> None:
            cancel.set()
            with lock:
                queued = not started
            if queued:
                finish((prep, GraspPlan(PlanStatus.CANCELLED, "cancelled while queued", scene_version=version)))

        return stop
