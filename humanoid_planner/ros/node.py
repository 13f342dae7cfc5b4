"""The `humanoid_planner` node: robot, planning scene, joint states, and the services on top.

Threading (see docs/ARCHITECTURE.md and the ROS 2 callback-group guide):
- the `collision_object` subscription has its own MutuallyExclusive group, so scene updates are
  applied one at a time, in order, and never wait behind a plan;
- `joint_states` has its own MutuallyExclusive group;
- services share one Reentrant group: several requests may run at once. The plan services answer
  later (deferred responses): the callback checks the request in the executor thread (fast) against
  the current scene, hands the planning to a bounded worker pool (`num_workers` threads; the worker
  plans on a frozen snapshot of the scene taken when it starts) and returns a `PendingResponse`;
  the worker that finishes the plan fills the response and sends it itself. No executor thread is
  ever blocked by a plan — scene updates, `get_planning_scene` and further requests keep being
  served however many plans are queued or running — and the answer does not wait for the executor
  to wake up and resume anything.
- markers are republished by a slow timer (own group) when the scene has changed.
No callback blocks, so any executor works: `node_main.main` spins rclpy's EventsExecutor (C++;
parameter `executor`, fallback SingleThreadedExecutor; measurements there). The groups keep it
correct on a MultiThreadedExecutor too (e.g. when composed with other nodes). The node has no guard
condition and no coroutine callback (rclpy 7.1's EventsExecutor supports neither).

Deferred responses: rclpy, unlike rclcpp, has no API to answer a request outside its callback, but
every rclpy executor (the Python ones and the EventsExecutor) answers through the service object's
`send_response(response, header)`. `_defer_responses` wraps that method on the node's plan services:
given a `PendingResponse` it only records the request header, and the pending response is sent by
whichever of the two sides (executor: header, worker: response) comes second.

Deadlines: a request's timeout counts from its arrival (time spent queued for a worker included);
the core stops itself at the deadline, and a watchdog answers TIMED_OUT (and cancels the plan) if
it has not answered `timeout + max(1 s, timeout / 2)` after arrival (one thread checks every plan's
deadline every 0.1 s). On shutdown (context shutdown or destroy_node) every running plan is cancelled.

Every callback catches its exceptions: an exception escaping a callback would stop the executor.
"""
from __future__ import annotations

import heapq
import itertools
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from humanoid_planner.core.pipeline.planner import GraspPlan, GraspPlanner
from humanoid_planner.core.planners.common import PlannerOptions, PlanStatus
from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner_interfaces.msg import CollisionObject, ErrorCode
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp

from humanoid_planner.ros.conversions import collision_object_to_update, scene_object_to_msg
from humanoid_planner.ros.markers import marker_array, plan_markers, scene_markers
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS, MARKERS_QOS, PLANNED_TRAJECTORY_QOS, SERVICE_QOS
from humanoid_planner.ros.requests import (ERROR_NAMES, PreparedRequest, RequestDefaults, RequestError, fail_response, fill_response,
                       prepare_plan_dual_grasp, prepare_plan_grasp)

NODE_NAME = "humanoid_planner"
OPERATION_NAMES = {0: "ADD", 1: "REMOVE", 2: "APPEND", 3: "MOVE"}
MARKER_PERIOD = 0.5  # s: the scene markers are refreshed at most this often
EXECUTOR_KINDS = ("events", "single")  # values of the `executor` parameter (node_main spins the node with it)
WATCHDOG_GRACE = 1.0  # s: at least this long past a request's deadline before the watchdog answers
WATCHDOG_PERIOD = 0.1  # s: how often the watchdog thread looks at the deadlines (it fires up to this late)


class RobotLoadError(RuntimeError):
    """The robot description could not be loaded; the node cannot start."""


class PendingResponse:
    """A plan service's answer, sent later from a planning worker (see the module docstring).

    The service callback returns it instead of a response; the executor then hands it, with the
    request header, to the service's `send_response`, which `_defer_responses` routes to `attach`.
    `complete(response)` comes from the thread that finished the plan (worker or watchdog). The
    response goes out once both are known, exactly once, from whichever thread came second.
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


def _defer_responses(service):
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


class Watchdog:
    """The deadlines of all plans, on one daemon thread that looks at them every `period` seconds.

    A threading.Timer per request started a thread on the request's path: about 0.5 ms, measured in
    the node between taking a request and handing it to a worker. `add` only pushes onto a heap and
    does not wake the thread, so a deadline fires up to `period` late: the watchdog is a last resort,
    `max(1 s, timeout / 2)` after the planner's own deadline.
    """

    def __init__(self, on_error, period: float = WATCHDOG_PERIOD):
        self._period = period
        self._on_error = on_error  # called with an exception a deadline's function raised
        self._lock = threading.Lock()
        self._heap: list[list] = []  # [when, sequence number, fn or None once cancelled]
        self._count = itertools.count()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="planner-watchdog", daemon=True)
        self._thread.start()

    def add(self, delay: float, fn) -> list:
        """Call fn() in `delay` seconds (up to `period` later) unless cancelled; returns the entry."""
        entry = [time.monotonic() + delay, next(self._count), fn]
        with self._lock:
            heapq.heappush(self._heap, entry)
        return entry

    @staticmethod
    def cancel(entry: list) -> None:
        entry[2] = None  # dropped when it comes due; its function (and what it holds) is released now

    def close(self, timeout: float = 1.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            now = time.monotonic()
            with self._lock:
                due = []
                while self._heap and self._heap[0][0] <= now:
                    due.append(heapq.heappop(self._heap)[2])
            for fn in due:
                if fn is None:
                    continue
                try:
                    fn()
                except Exception as e:  # noqa: BLE001 - the watchdog must outlive a failing deadline
                    self._on_error(e)


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
    "dual_arm_processes": "DAGRRT: right arm in a worker process, left in the planning thread (true), or both in threads (false)",
}


def load_robot(preset: str, urdf: str, srdf: str):
    """RobotModel from URDF/SRDF strings (when the URDF is non-empty) or from a preset name."""
    from humanoid_planner.core.model.robot import RobotModel

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


def planner_options(p: PlannerParameters) -> PlannerOptions:
    """The core's options from the node parameters (the rest keep the core's defaults)."""
    return PlannerOptions(f_extend=p.f_extend, max_cycles=p.max_cycles, joint_step=p.joint_step,
                          tcp_step_pos=p.tcp_step_pos, tcp_step_rot=p.tcp_step_rot,
                          goal_tolerance_pos=p.goal_tolerance_pos, goal_tolerance_rot=p.goal_tolerance_rot,
                          min_grasp_score=p.min_grasp_score, friction=p.friction)


class PlannerNode(Node):
    """Planning scene, joint states and the plan services for one robot.

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
        # read by node_main (the executor the node is spun with); declared here with the other parameters
        self.executor_kind = self.declare_parameter(
            "executor", "events", ParameterDescriptor(
                read_only=True, description="events (rclpy's EventsExecutor) or single (SingleThreadedExecutor)")).value
        if self.executor_kind not in EXECUTOR_KINDS:
            raise RobotLoadError(f"executor must be one of {', '.join(EXECUTOR_KINDS)}, got {self.executor_kind!r}")
        values = {}
        for f in fields(PlannerParameters):
            values[f.name] = self.declare_parameter(
                f.name, f.default, ParameterDescriptor(description=_PARAM_DOCS[f.name])).value
        self.params = PlannerParameters(**values)
        if self.params.num_workers < 1:
            raise RobotLoadError(f"num_workers must be >= 1, got {self.params.num_workers}")

        self.robot = load_robot(robot, urdf, srdf)
        self.planning_frame = self._resolve_planning_frame(frame)
        self.scene = PlanningScene(self.planning_frame)
        # the URDF root coincides with the planning frame, so object poses may also be given in it
        self._frame_aliases = (self.robot.root_link,) if self.planning_frame != self.robot.root_link else ()

        self._frames = (self.planning_frame,) + self._frame_aliases

        self._joint_state_lock = threading.Lock()
        self._joint_state: JointState | None = None

        self.planner = GraspPlanner(self.robot, planner_options(self.params), padding=self.params.collision_padding,
                                    edge_resolution=self.params.edge_resolution,
                                    parallel="process" if self.params.dual_arm_processes else "thread")
        self._defaults = RequestDefaults(self.params.default_timeout, self.params.min_grasp_score)
        self._pool = ThreadPoolExecutor(max_workers=self.params.num_workers, thread_name_prefix="planner")
        self._marker_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="markers")
        self._watchdog = Watchdog(lambda e: self.get_logger().error(f"watchdog: {e!r}"))
        self._plans_lock = threading.Lock()
        self._active: set[threading.Event] = set()  # cancel events of queued and running plans
        self._shutting_down = threading.Event()
        self._warm_thread: threading.Thread | None = None
        self._markers_lock = threading.Lock()
        self._last_plan_markers: list = []
        self._last_plan_object = ""
        self._markers_version = -1

        self.scene_group = MutuallyExclusiveCallbackGroup()
        self.state_group = MutuallyExclusiveCallbackGroup()
        self.service_group = ReentrantCallbackGroup()
        self.marker_group = MutuallyExclusiveCallbackGroup()

        self.collision_object_sub = self.create_subscription(
            CollisionObject, "collision_object", self._on_collision_object, COLLISION_OBJECT_QOS,
            callback_group=self.scene_group)
        self.joint_states_sub = self.create_subscription(
            JointState, "joint_states", self._on_joint_state, JOINT_STATES_QOS, callback_group=self.state_group)
        self.get_planning_scene_srv = self.create_service(
            GetPlanningScene, "get_planning_scene", self._on_get_planning_scene, qos_profile=SERVICE_QOS,
            callback_group=self.service_group)
        self.planned_trajectory_pub = self.create_publisher(
            JointTrajectory, "planned_trajectory", PLANNED_TRAJECTORY_QOS)
        self.markers_pub = self.create_publisher(MarkerArray, "~/markers", MARKERS_QOS)
        self.plan_grasp_srv = self.create_service(
            PlanGrasp, "plan_grasp", self._on_plan_grasp, qos_profile=SERVICE_QOS, callback_group=self.service_group)
        self.plan_dual_grasp_srv = self.create_service(
            PlanDualGrasp, "plan_dual_grasp", self._on_plan_dual_grasp, qos_profile=SERVICE_QOS,
            callback_group=self.service_group)
        self._send = {"plan_grasp": _defer_responses(self.plan_grasp_srv),
                      "plan_dual_grasp": _defer_responses(self.plan_dual_grasp_srv)}
        self.marker_timer = self.create_timer(MARKER_PERIOD, self._on_marker_timer, callback_group=self.marker_group)
        self.context.on_shutdown(self.cancel_plans)

        source = "robot_description" if urdf.strip() else f"preset {robot!r}"
        self.get_logger().info(
            f"robot {self.robot.name!r} from {source}: {len(self.robot.joint_names)} joints, "
            f"groups {sorted(self.robot.groups)}; planning frame {self.planning_frame!r}; "
            f"{self.params.num_workers} planning worker(s)")

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

    def cancel_plans(self) -> None:
        """Stop every queued and running plan (they answer FAILURE "cancelled"); refuse new ones."""
        self._shutting_down.set()
        with self._plans_lock:
            active = list(self._active)
        for ev in active:
            ev.set()

    def warm_up_in_background(self) -> None:
        """Start DAGRRT's arm process (a second or two) now, off the executor, not in the first request."""
        def run() -> None:
            try:
                self.planner.warm_up()
            except Exception as e:  # noqa: BLE001 - a dual-arm plan retries the start and reports
                self.get_logger().warning(f"could not start the dual-arm worker processes: {e}")

        self._warm_thread = threading.Thread(target=run, name="planner-warm-up")
        self._warm_thread.start()

    def destroy_node(self):
        self.cancel_plans()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._marker_pool.shutdown(wait=True, cancel_futures=True)
        if self._warm_thread is not None:  # a signal during start-up: let the processes finish starting first
            self._warm_thread.join(timeout=60.0)
        self.planner.close()
        self._watchdog.close()
        return super().destroy_node()

    # ------------------------------------------------------------------ planning
    def _on_plan_grasp(self, request, response):
        return self._serve("plan_grasp", request, response)

    def _on_plan_dual_grasp(self, request, response):
        return self._serve("plan_dual_grasp", request, response)

    def _serve(self, kind: str, request, response):
        """One plan request: the response now (refused) or a PendingResponse. Never raises.

        The request is checked at once against the current scene (bad requests never queue); when
        a worker starts it, the scene is snapshotted again and, if it changed meanwhile, the request
        is re-resolved against that snapshot (object pose and grasp set), which is then the one the
        plan uses and reports. The worker that finishes sends the answer (`_answer`).
        """
        arrival = time.monotonic()
        dual = kind == "plan_dual_grasp"
        prepare = prepare_plan_dual_grasp if dual else prepare_plan_grasp
        version = 0
        try:
            snap = self.scene.snapshot()
            version = snap.version
            joint_state = self.latest_joint_state()
            prep = prepare(self.robot, request, snap, joint_state, self._defaults, self._frames)
        except RequestError as e:
            self.get_logger().warning(f"{kind} refused ({ERROR_NAMES.get(e.code, e.code)}): {e.message}")
            return fail_response(response, e.code, e.message, version)
        except Exception as e:  # noqa: BLE001 - never let a callback die
            self.get_logger().error(f"{kind}: checking the request failed: {e!r}")
            return fail_response(response, ErrorCode.FAILURE, f"internal error while checking the request: {e!r}",
                                 version)
        if self._shutting_down.is_set():
            return fail_response(response, ErrorCode.FAILURE, "the node is shutting down", version)
        pending = PendingResponse(self._send[kind],
                                  lambda e: self._log_late_failure(f"{kind}: the answer was not sent", e))

        def refresh(s):
            return prepare(self.robot, request, s, joint_state, self._defaults, self._frames)

        def done(result) -> None:
            self._answer(kind, pending, response, result, version)

        self._plan_in_worker(prep, refresh, arrival, done)
        return pending

    def _answer(self, kind: str, pending: PendingResponse, response, result, version: int) -> None:
        """In the thread that finished the plan: fill and send the response, then (no longer on the
        caller's path) log, publish the trajectory and start the markers. Never raises."""
        plan = prep = None
        try:
            if isinstance(result, RequestError):
                self.get_logger().warning(f"{kind} refused when it started ({ERROR_NAMES.get(result.code)}): "
                                          f"{result.message}")
                response = fail_response(response, result.code, result.message,
                                         getattr(result, "scene_version", version))
            elif isinstance(result, BaseException):
                raise result
            else:
                prep, plan = result
                fill_response(response, plan, self.planning_frame, kind == "plan_dual_grasp")
        except Exception as e:  # noqa: BLE001
            self.get_logger().error(f"{kind}: planning failed with an internal error: {e!r}")
            plan = None
            response = fail_response(type(response)(), ErrorCode.FAILURE, f"internal error while planning: {e!r}",
                                     version)
        pending.complete(response)
        if plan is None:
            return
        try:
            code = response.error_code.val
            self.get_logger().info(
                f"{kind} {'+'.join(prep.groups)}: {ERROR_NAMES.get(code, code)} in {plan.planning_time:.3f} s, "
                f"{plan.iterations} iterations, scene version {plan.scene_version}"
                + ("" if plan.ok else f": {plan.message}"))
            if plan.ok:
                # after the answer: the caller has its trajectory; subscribers get the same one right after
                self.planned_trajectory_pub.publish(response.trajectory)
                # markers (FK along the path, the scene) are built on their own thread: RViz can wait
                self._marker_pool.submit(self._update_plan_markers_safely, prep, plan)
        except Exception as e:  # noqa: BLE001 - e.g. the node is being destroyed; the answer is out
            self._log_late_failure(f"{kind}: the plan was not published", e)

    def _log_late_failure(self, what: str, e: Exception) -> None:
        """An error after planning: expected while the node shuts down (debug), an error otherwise."""
        if self._shutting_down.is_set():
            self.get_logger().debug(f"{what} (shutting down): {e!r}")
        else:
            self.get_logger().error(f"{what}: {e!r}")

    def _update_plan_markers_safely(self, prep: PreparedRequest, plan: GraspPlan) -> None:
        try:
            self._update_plan_markers(prep, plan)
        except Exception as e:  # noqa: BLE001 - markers are a view, never a reason to fail a plan
            self.get_logger().warning(f"markers of the last plan not published: {e!r}")

    def _plan_in_worker(self, prep: PreparedRequest, refresh, arrival: float, done) -> None:
        """Run the plan in the worker pool; `done` is called once, in the thread that finishes, with
        (PreparedRequest used, GraspPlan), a RequestError (the request no longer fits the scene when
        it starts) or an exception."""
        cancel = threading.Event()
        lock = threading.Lock()
        finished = False
        timeout = prep.core.timeout
        version = prep.snapshot.version

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
            try:
                if cancel.is_set():
                    return finish((prep, GraspPlan(PlanStatus.CANCELLED, "cancelled before planning started: "
                                                   + ("the node is shutting down" if self._shutting_down.is_set()
                                                      else "the deadline passed"), scene_version=version)))
                waited = time.monotonic() - arrival
                remaining = timeout - waited
                if remaining <= 0.0:
                    return finish((prep, GraspPlan(
                        PlanStatus.TIMED_OUT, f"timed out after waiting {waited:.2f} s for a free planning worker "
                        f"({self.params.num_workers} busy); raise the timeout or num_workers",
                        scene_version=version)))
                used = prep
                snap = self.scene.snapshot()
                if snap.version != prep.snapshot.version:
                    try:
                        used = refresh(snap)
                    except RequestError as e:
                        e.scene_version = snap.version
                        return finish(e)
                core = replace(used.core, timeout=remaining)
                if used.kind == "plan_dual_grasp":
                    plan = self.planner.plan_dual_grasp(used.snapshot, core, cancel)
                else:
                    plan = self.planner.plan_grasp(used.snapshot, core, cancel)
                if plan.status is PlanStatus.CANCELLED and self._shutting_down.is_set():
                    plan.message = "cancelled: the node is shutting down"
                finish((used, plan))
            except BaseException as e:  # noqa: BLE001 - reported to the caller as FAILURE
                finish(e)

        def expire() -> None:
            cancel.set()
            finish((prep, GraspPlan(PlanStatus.TIMED_OUT, f"the planner did not stop by its {timeout:.3f} s "
                                    "deadline; cancelled", scene_version=version,
                                    planning_time=time.monotonic() - arrival)))

        deadline = self._watchdog.add(timeout + max(WATCHDOG_GRACE, 0.5 * timeout), expire)
        with self._plans_lock:
            self._active.add(cancel)
        if self._shutting_down.is_set():
            cancel.set()
        try:
            self._pool.submit(work)
        except RuntimeError:  # pool shut down
            finish((prep, GraspPlan(PlanStatus.CANCELLED, "the node is shutting down", scene_version=version)))

    # ------------------------------------------------------------------ markers
    def _update_plan_markers(self, prep: PreparedRequest, plan: GraspPlan) -> None:
        targets = tuple(prep.core.object_pose @ g.tcp_in_object for g in plan.grasps)
        markers = plan_markers(self.robot, plan, prep.groups, prep.start, targets, self.planning_frame)
        with self._markers_lock:
            self._last_plan_markers = markers
            self._last_plan_object = prep.core.object_id
            self._publish_markers(prep.snapshot)

    def _publish_markers(self, snap) -> None:
        """Scene + last plan markers (call with _markers_lock held)."""
        scene = scene_markers(snap, self.planning_frame, highlight=self._last_plan_object)
        self.markers_pub.publish(marker_array(scene + self._last_plan_markers))
        self._markers_version = snap.version

    def _on_marker_timer(self) -> None:
        try:
            if self.scene.version == self._markers_version:
                return
            with self._markers_lock:
                self._publish_markers(self.scene.snapshot())
        except Exception as e:  # noqa: BLE001
            self.get_logger().warning(f"scene markers not published: {e!r}")

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
