"""The `humanoid_planner` node: robot, planning scene and joint states, and the services on top.

The node composes its parts, one module per concern:
- `parameters`: declarations and the values the node starts with;
- `scene_server`: `collision_object` -> planning scene, `joint_states`, `get_planning_scene`;
- `plan_server`: `plan_grasp` / `plan_dual_grasp` (deferred responses from a planning thread pool,
  deadlines by `watchdog`);
- `markers`: `~/markers` for RViz;
- `pointcloud`: the `pointcloud` topic -> the scene's point-cloud layer, converted on a thread of its
  own (the callback only hands the newest cloud over).

Threading (see docs/ARCHITECTURE.md): joint_states is subscribed by the node's topic node `<name>_topics`,
spun on its own executor thread (ros/executors.py), and collision_object / attached_collision_object by
`<name>_scene`, whose messages the scene thread takes itself (ros/scene_intake.py; request handlers first
apply what has arrived), so that no flood on them queues a service request; the services share one Reentrant group,
the marker timer has its own group. No callback blocks, so any executor works: `node_main.main` spins
rclpy's EventsExecutor (C++; parameter `executor`, fallback SingleThreadedExecutor). The groups keep it correct on a MultiThreadedExecutor
too (e.g. when composed with other nodes). The node has no guard condition and no coroutine callback
(rclpy 7.1's EventsExecutor supports neither). Every callback catches its exceptions: an exception
escaping a callback would stop the executor.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from humanoid_planner.core import compiled
from humanoid_planner.core.collision.geometry import prepare_scene_meshes
from humanoid_planner.core.pipeline.plan_process import START_TIMEOUT, PlanRunner, PlanWorkerPool
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.scene.planning_scene import PlanningScene

from humanoid_planner.ros.frames import Frames
from humanoid_planner.ros.markers import MarkerPublisher
from humanoid_planner.ros.parameters import SPECS, PlannerParameters, cloud_settings, declare_parameters, scene_limits
from humanoid_planner.ros.plan_server import PlanServer
from humanoid_planner.ros.pointcloud import PointCloudLayer
from humanoid_planner.ros.robot_description import RobotLoadError, load_robot, tcp_lines
from humanoid_planner.ros.scene_server import SceneServer

NODE_NAME = "humanoid_planner"
NAME_CHECK_PERIOD = 2.0  # s: the graph is looked up for another node of the same name this often ...
NAME_CHECKS = 5  # ... this many times after start (discovery can take seconds on a loaded machine)
WARM_UP_JOIN = 0.5  # s a shutdown waits for a warm-up thread (its arm-process start stops at once on close)


class PlannerNode(Node):
    """Planning scene, joint states and the plan services for one robot.

    Keyword arguments go to rclpy's Node (context, parameter_overrides, namespace, cli_args, ...).
    Raises StartupError (RobotLoadError when the robot cannot be loaded) when the node cannot start.
    With neither `robot_description` nor `robot` set, the constructor waits for the robot on the
    description topics (ros/robot_description.py), spinning the node on its own meanwhile.
    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        start, self.params = declare_parameters(self)
        self.executor_kind = start.executor  # read by node_main: the executor the node is spun with

        self.robot, source = load_robot(self, start)
        self.planning_frame = self._resolve_planning_frame(start.planning_frame)
        # meshes get their collision geometry on the scene thread, before they are visible to plans
        self.scene = PlanningScene(self.planning_frame, scene_limits(self.params), prepare_scene_meshes)
        # the URDF root and the SRDF's virtual joint's parent frame (MoveIt's model frame, e.g. world)
        # coincide with the planning frame: object poses may be given in either
        aliases = tuple(f for f in dict.fromkeys((self.robot.root_link, *self.robot.virtual_frames))
                        if f != self.planning_frame)
        self.frames = Frames(self.robot, self.planning_frame, aliases, lambda: self.latest_joint_state())
        # logged before any service exists: a client that sees the services also sees these lines
        self.get_logger().info(
            f"robot {self.robot.name!r} from {source}: {len(self.robot.joint_names)} joints, "
            f"groups {sorted(self.robot.groups)}; planning frame {self.planning_frame!r}"
            f"{' (also ' + ', '.join(repr(a) for a in aliases) + ')' if aliases else ''}; "
            f"{self.params.num_workers} planning worker {'process' if self.params.planning_processes else 'thread'}"
            f"{'es' if self.params.planning_processes and self.params.num_workers > 1 else ''}"
            f"{'s' if not self.params.planning_processes and self.params.num_workers > 1 else ''}")
        # which link each group's grasps are asked of: no message field carries it
        for line in tcp_lines(self.robot):
            self.get_logger().info(line)

        # the collision checker's compiled kernels, before any plan or worker process needs them: loaded
        # from numba's cache (~0.5 s), or compiled once on a new install (~7 s, which a first plan's
        # deadline could not absorb); the worker processes started later load the cache
        t0 = time.monotonic()
        compiled.warm_all()
        if time.monotonic() - t0 > 2.0:
            self.get_logger().info(f"compiled the collision kernels in {time.monotonic() - t0:.1f} s "
                                   "(cached for the next start)")

        self._planner_lock = threading.Lock()
        self._planner_users: dict[GraspPlanner, int] = {}  # planners with plans running -> how many
        self._retired: list[GraspPlanner] = []  # replaced planners that still have plans running
        self._warm_threads: list[threading.Thread] = []
        self._destroying = False
        self.planner = self._make_planner(self.params)
        # where plans run: worker processes (started by warm_up_in_background, or by the first plan),
        # or the planning threads themselves; the planning threads queue and deadline both alike
        pool = (PlanWorkerPool(self.robot, self.params.num_workers, self.params.options,
                               "process" if self.params.dual_arm_processes else "thread", scene=self.scene.snapshot)
                if self.params.planning_processes else None)
        self.runner = PlanRunner(self.use_planner, pool)

        self.service_group = ReentrantCallbackGroup()
        self.scene_server = SceneServer(self, self.scene, aliases, self.service_group,
                                        max_queued=self.params.max_queued_scene_updates,
                                        executor_kind=self.executor_kind)
        self.markers = MarkerPublisher(self, self.robot, self.scene, link_pose=self.scene_server.link_pose)
        self.pointcloud = PointCloudLayer(self, self.robot, self.scene, self.frames, lambda: cloud_settings(self.params))
        self.plan_server = PlanServer(self, self.service_group, self.markers)
        self.context.on_shutdown(self.cancel_plans)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        # while discovery settles: a second node of this name would share the clients' calls
        self._name_checks_left = NAME_CHECKS
        self._name_check = self.create_timer(NAME_CHECK_PERIOD, self._check_name_unique,
                                             callback_group=MutuallyExclusiveCallbackGroup())

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

    def same_name_nodes(self) -> int:
        """Nodes in the ROS graph (this one included) with this node's name and namespace."""
        me = (self.get_name(), self.get_namespace())
        return sum(1 for n in self.get_node_names_and_namespaces() if n == me)

    def _check_name_unique(self) -> None:
        """Warn (once, in the first NAME_CHECKS * NAME_CHECK_PERIOD s) when another node has this node's name."""
        self._name_checks_left -= 1
        try:
            n = self.same_name_nodes()
            if n > 1 or self._name_checks_left <= 0:
                self._name_check.cancel()
            if n > 1:
                self.get_logger().warning(
                    f"{n} nodes named {self.get_fully_qualified_name()!r} on this ROS domain: clients reach either one "
                    "(give each planner its own namespace, e.g. --ros-args -r __ns:=/robot1, or another ROS_DOMAIN_ID)")
        except Exception as e:  # noqa: BLE001 - a check, never a reason to stop
            self.get_logger().debug(f"node name check failed: {e!r}")

    def latest_joint_state(self) -> JointState | None:
        """The last message received on joint_states (None before the first)."""
        return self.scene_server.latest_joint_state()

    def cancel_plans(self) -> None:
        """Stop every queued and running plan (they answer FAILURE "cancelled"); refuse new ones."""
        self.plan_server.cancel_plans()

    # ------------------------------------------------------------------ planner and parameters
    def _make_planner(self, p: PlannerParameters) -> GraspPlanner:
        return GraspPlanner(self.robot, p.options, parallel="process" if p.dual_arm_processes else "thread")

    @contextmanager
    def use_planner(self) -> Iterator[GraspPlanner]:
        """The current planner, for one plan: a planner replaced meanwhile is closed after its last plan."""
        with self._planner_lock:
            planner = self.planner
            self._planner_users[planner] = self._planner_users.get(planner, 0) + 1
        try:
            yield planner
        finally:
            with self._planner_lock:
                left = self._planner_users.pop(planner) - 1
                if left:
                    self._planner_users[planner] = left
                done = not left and planner in self._retired
                if done:
                    self._retired.remove(planner)
            if done:
                planner.close()

    def _on_parameters_set(self, parameters: list[Parameter]) -> None:
        """Accepted run-time values (rclpy has checked ranges, types and read_only): the next request
        plans with them. The planner is rebuilt (its arm process restarted in the background); plans
        running keep the planner they started with."""
        try:
            changed = {p.name: p.value for p in parameters if p.name in SPECS}
            if not changed:
                return
            params = self.params.with_values(changed)
            rebuild = (params.options != self.params.options
                       or params.dual_arm_processes != self.params.dual_arm_processes)
            self.params = params
            if rebuild:
                planner = self._make_planner(params)
                with self._planner_lock:
                    old, self.planner = self.planner, planner
                    busy = old in self._planner_users
                    if busy:
                        self._retired.append(old)
                if not busy:
                    threading.Thread(target=old.close, name="planner-close", daemon=True).start()
                self.warm_up_in_background()
            self.get_logger().info("parameters set, used from the next request: "
                                   + ", ".join(f"{k}={v!r}" for k, v in changed.items()))
        except Exception as e:  # noqa: BLE001 - never let a callback die
            self.get_logger().error(f"applying parameters {[p.name for p in parameters]} failed: {e!r}")

    def warm_up_in_background(self) -> None:
        """Start the planning worker processes, or (planning in threads) the planner's collision model
        and DAGRRT's arm process, now (a second or two), off the executor, not in the first request."""
        planner, pool = self.planner, self.runner.pool

        def run() -> None:
            if pool is not None:  # each worker builds its own planner and collision model
                if pool.wait_ready(START_TIMEOUT):
                    self.get_logger().info(f"planning worker processes ready (pids {pool.pids()})")
                elif not self._destroying:
                    self.get_logger().warning("the planning worker processes did not all start; plans run in "
                                              "the node's threads meanwhile, and their start is retried")
                return
            try:
                planner.warm_up()
            except Exception as e:  # noqa: BLE001 - a dual-arm plan retries the start and reports
                if not self._destroying:  # closed by shutdown: nothing to report
                    self.get_logger().warning(f"could not start the dual-arm worker processes: {e}")

        thread = threading.Thread(target=run, name="planner-warm-up", daemon=True)
        self._warm_threads.append(thread)
        thread.start()

    def destroy_node(self):
        self._destroying = True
        self.markers.close()  # first: its timer and thread publish on this node
        self.plan_server.close()
        self.runner.close()
        self.pointcloud.close()
        self.scene_server.close()
        with self._planner_lock:
            planners = [self.planner, *self._retired]
        for planner in planners:  # a warm-up still starting the arm processes gives up and stops them
            planner.close()
        for thread in self._warm_threads:  # daemons: one still building the collision model is not waited for
            thread.join(timeout=WARM_UP_JOIN)
        return super().destroy_node()
