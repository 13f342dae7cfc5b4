"""Shared pytest fixtures: a small test robot and launch-less ROS 2 graphs.

Isolation: one ROS domain per test run (`ros_domain_id`, session scope: honours ROS_DOMAIN_ID when
set, else reserves one with domain_coordinator) and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, so
parallel runs on one machine never see each other. Each test gets its own rclpy Context and a
MultiThreadedExecutor spinning in a background thread (`ros` fixture); everything is shut down at
teardown.

Typical use in a test:

    def test_something(ros):
        planner = ros.planner()                       # PlannerNode on the test robot
        client_node = ros.node("client")
        cli = client_node.create_client(GetPlanningScene, "get_planning_scene")
        resp = ros.call(cli, GetPlanningScene.Request())
"""
from __future__ import annotations

import functools
import os
import sys
import threading
import time
from pathlib import Path

import pytest
from humanoid_planner.child_env import child_environment

REPO_ROOT = Path(__file__).resolve().parents[1]

TEST_URDF = """<?xml version="1.0"?>
<robot name="test_arm">
  <link name="base_link">
    <collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision>
  </link>
  <link name="upper_arm">
    <collision><origin xyz="0 0 0.15"/><geometry><cylinder radius="0.03" length="0.3"/></geometry></collision>
  </link>
  <link name="forearm">
    <collision><origin xyz="0 0 0.125"/><geometry><cylinder radius="0.025" length="0.25"/></geometry></collision>
  </link>
  <link name="hand">
    <collision><geometry><sphere radius="0.04"/></geometry></collision>
  </link>
  <link name="tcp"/>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="upper_arm"/><origin xyz="0 0 0.05"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" velocity="1.5" effort="10"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper_arm"/><child link="forearm"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" velocity="1.5" effort="10"/>
  </joint>
  <joint name="wrist" type="revolute">
    <parent link="forearm"/><child link="hand"/><origin xyz="0 0 0.25"/><axis xyz="0 0 1"/>
    <limit lower="-3.0" upper="3.0" velocity="2.0" effort="5"/>
  </joint>
  <joint name="tcp_joint" type="fixed">
    <parent link="hand"/><child link="tcp"/><origin xyz="0 0 0.06"/>
  </joint>
</robot>
"""
"""A 3-DoF arm (shoulder, elbow, wrist) on base_link, TCP 6 cm beyond the hand."""

TEST_SRDF = """<?xml version="1.0"?>
<robot name="test_arm">
  <group name="arm"><chain base_link="base_link" tip_link="tcp"/></group>
  <group name="hand"><link name="hand"/><link name="tcp"/></group>
  <end_effector name="gripper" parent_link="tcp" group="hand" parent_group="arm"/>
  <disable_collisions link1="base_link" link2="upper_arm" reason="Adjacent"/>
  <disable_collisions link1="upper_arm" link2="forearm" reason="Adjacent"/>
  <disable_collisions link1="forearm" link2="hand" reason="Adjacent"/>
</robot>
"""


@pytest.fixture(scope="session")
def test_robot_description() -> tuple[str, str]:
    """(URDF, SRDF) strings of the small test robot."""
    return TEST_URDF, TEST_SRDF


@pytest.fixture(scope="session")
def ros_domain_id():
    """The ROS domain of this test run (also exported, so child processes share it; under pytest-xdist one
    per worker, a preset ROS_DOMAIN_ID then ignored). Its participants
    announce themselves as often as planner_node's (ros/discovery.py): a test's client then finds a
    node in this process within ~0.5 s, not up to 3 s."""
    from humanoid_planner.ros.discovery import apply_node_profile, forget_profile

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    profile = apply_node_profile()
    try:
        preset = os.environ.get("ROS_DOMAIN_ID", "").strip()
        # pytest-xdist (make test's PYTEST_WORKERS): every worker is a run of its own, in its own domain
        if preset and int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) <= 1:
            yield int(preset)
            return
        import domain_coordinator

        with domain_coordinator.domain_id() as domain:
            os.environ["ROS_DOMAIN_ID"] = str(domain)
            try:
                yield domain
            finally:
                os.environ.pop("ROS_DOMAIN_ID", None)
    finally:
        forget_profile(profile)


def wait_for(future, timeout: float = 5.0):
    """Block the calling (test) thread until an rclpy Future is done; return its result.

    The executor spins in another thread; raises TimeoutError if the future is not done in time.
    """
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout):
        raise TimeoutError(f"future not done after {timeout} s")
    return future.result()


def wait_until(predicate, timeout: float = 5.0, period: float = 0.01, what: str = "condition"):
    """Poll predicate() until it is truthy; return its value or raise TimeoutError."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what} not met after {timeout} s")
        time.sleep(period)


@functools.cache
def _race_free_action_client() -> type:
    from rclpy.action import ActionClient as Base

    class RaceFreeActionClient(Base):
        """rclpy's ActionClient, race-free when goals are sent from a thread other than the executor's.

        Jazzy's client sends a request and only then records its sequence number; an answer the
        executor takes in between is dropped ("Ignoring unexpected goal response", ros2/rclpy#1123)
        and the test's future never completes. As upstream's fix does, one lock spans each send +
        record and the executor's handling of the answers."""

        def __init__(self, *a, **kw):
            self._race_lock = threading.RLock()
            super().__init__(*a, **kw)

        def send_goal_async(self, *a, **kw):
            with self._race_lock:
                return super().send_goal_async(*a, **kw)

        def _cancel_goal_async(self, *a, **kw):
            with self._race_lock:
                return super()._cancel_goal_async(*a, **kw)

        def _get_result_async(self, *a, **kw):
            with self._race_lock:
                return super()._get_result_async(*a, **kw)

        async def execute(self, taken_data):
            with self._race_lock:
                return await super().execute(taken_data)

    return RaceFreeActionClient


def ActionClient(node, action_type, name: str, **kwargs):  # noqa: N802 - stands in for rclpy's class
    """An action client for tests that send goals from the test thread (see _race_free_action_client);
    rclpy is imported only when a test makes one."""
    return _race_free_action_client()(node, action_type, name, **kwargs)


class RosGraph:
    """One isolated rclpy Context with a background MultiThreadedExecutor, and the nodes of a test."""

    def __init__(self, domain_id: int, num_threads: int = 4):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import MultiThreadedExecutor

        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.executor = MultiThreadedExecutor(num_threads=num_threads, context=self.context)
        self.nodes = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="ros-test-executor", daemon=True)
        self._spin_error: BaseException | None = None
        self._thread.start()

    def _spin(self):
        """Spin until close() asks to stop. Not executor.spin() + executor.shutdown(): Jazzy's
        Executor.shutdown sets its shutdown flag and then skips its own wait for running callbacks
        (`if not self._is_shutdown` is never true there), so it destroyed the guard condition while a
        pool thread was about to trigger it (InvalidHandle at teardown, seen in CI)."""
        try:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)
        except BaseException as e:  # noqa: BLE001 - recorded and reported at teardown
            self._spin_error = e

    def add(self, node):
        """Spin an existing node (created with context=self.context); it is destroyed at teardown."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def node(self, name: str, **kwargs):
        """A plain helper node in this graph (e.g. a client or a publisher)."""
        from rclpy.node import Node

        return self.add(Node(name, context=self.context, **kwargs))

    def planner(self, urdf: str = TEST_URDF, srdf: str = TEST_SRDF, **params):
        """A PlannerNode on the test robot (or the given URDF/SRDF); params override node parameters."""
        from rclpy.parameter import Parameter

        from humanoid_planner.ros.node import PlannerNode

        # plans in the node's threads unless a test asks for worker processes: a test node that plans
        # would otherwise start num_workers processes (a second or two of CPU each) it hardly uses
        params.setdefault("planning_processes", False)
        overrides = [Parameter("robot_description", value=urdf), Parameter("robot_description_semantic", value=srdf)]
        overrides += [Parameter(k, value=v) for k, v in params.items()]
        return self.add(PlannerNode(context=self.context, parameter_overrides=overrides))

    def call(self, client, request, timeout: float = 5.0):
        """Wait for the service, call it, and return the response (TimeoutError otherwise)."""
        from humanoid_planner.ros.executors import wait_for_server

        if not wait_for_server(client, timeout):
            raise TimeoutError(f"service {client.srv_name} not available after {timeout} s")
        return wait_for(client.call_async(request), timeout)

    @staticmethod
    def wait_for(future, timeout: float = 5.0):
        return wait_for(future, timeout)

    @staticmethod
    def wait_until(predicate, timeout: float = 5.0, what: str = "condition"):
        return wait_until(predicate, timeout, what=what)

    def wait_for_subscribers(self, publisher, count: int = 1, timeout: float = 5.0):
        """Block until `publisher` is matched with at least `count` subscriptions (so nothing is lost)."""
        wait_until(lambda: publisher.get_subscription_count() >= count, timeout,
                   what=f"{count} subscriber(s) on {publisher.topic_name}")

    @staticmethod
    def publish_until(publisher, msg, predicate, timeout: float = 10.0, what: str = "condition"):
        """Publish `msg` until predicate() holds: on a best-effort topic (joint_states, clouds) a
        message may be lost even to a matched subscriber, so one publish proves nothing."""
        def again():
            if predicate():
                return True
            publisher.publish(msg)
            time.sleep(0.05)
            return predicate()
        return wait_until(again, timeout, what=what)

    def close(self):
        self._stop.set()
        self._thread.join(timeout=5.0)
        pool = getattr(self.executor, "_executor", None)  # its thread pool: let handed-out callbacks end
        if pool is not None:
            drain = threading.Thread(target=pool.shutdown, name="ros-test-drain", daemon=True)
            drain.start()
            drain.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=5.0)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()
        assert not self._thread.is_alive(), "executor thread did not stop"
        if self._spin_error is not None:
            raise self._spin_error


@pytest.fixture
def ros(ros_domain_id):
    """A fresh RosGraph (own Context, background executor) for one test."""
    graph = RosGraph(ros_domain_id)
    try:
        yield graph
    finally:
        graph.close()


@pytest.fixture(scope="session")
def planner_node_exe() -> Path:
    """The console script installed by `make setup` (next to this venv's python)."""
    exe = Path(sys.executable).parent / "planner_node"
    if not exe.exists():
        pytest.fail(f"{exe} not found: run `make setup` (pip install -e . into the venv)")
    return exe


class PlannerProcess:
    """`planner_node` running in its own process, as a real client would reach it."""

    STOP_GRACE = 5.0  # s from SIGINT to SIGKILL at teardown (the node exits within ~1 s)

    def __init__(self, exe: Path, params_files: list[Path], log_dir: Path, extra_args: list[str] = (),
                 env: dict[str, str] | None = None, cwd: Path = REPO_ROOT):
        import subprocess

        self.stdout_path = log_dir / "planner_node.stdout"
        self.stderr_path = log_dir / "planner_node.stderr"
        args = [str(exe), "--ros-args"]
        for f in params_files:
            args += ["--params-file", str(f)]
        args += list(extra_args)
        self._out = open(self.stdout_path, "wb")
        self._err = open(self.stderr_path, "wb")
        env = child_environment(env)
        self.proc = subprocess.Popen(args, stdout=self._out, stderr=self._err, stdin=subprocess.DEVNULL,
                                     env=env, cwd=str(cwd))

    @property
    def pid(self) -> int:
        return self.proc.pid

    def send_signal(self, sig) -> None:
        self.proc.send_signal(sig)

    def wait(self, timeout: float = 10.0) -> int:
        return self.proc.wait(timeout=timeout)

    def output(self) -> str:
        self._out.flush()
        self._err.flush()
        return self.stdout_path.read_text(errors="replace") + self.stderr_path.read_text(errors="replace")

    def stop(self) -> None:
        """SIGINT first (the node's own shutdown), SIGKILL only if it is still running STOP_GRACE s later:
        a participant killed outright leaves its Fast DDS shared-memory port to the next ones of the domain."""
        import signal
        import subprocess

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=self.STOP_GRACE)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)
        self._out.close()
        self._err.close()


@pytest.fixture
def start_planner_process(planner_node_exe, ros_domain_id, tmp_path):
    """Factory: start `planner_node` with the test robot (or other parameters) in a separate process.

    start_planner_process(params={...}, robot=True) writes a --params-file (node key `humanoid_planner`)
    after config/planner.yaml; with robot=True the test robot's URDF/SRDF are included (robot=False and
    no `robot` in params: the node waits for the robot_description topics); `env` adds environment
    variables (e.g. AMENT_PREFIX_PATH). Every process
    started is killed at teardown if it is still running.
    """
    import yaml

    procs: list[PlannerProcess] = []

    def start(params: dict | None = None, robot: bool = True, extra_args: list[str] = (),
              env: dict[str, str] | None = None) -> PlannerProcess:
        values = dict(params or {})
        if robot:
            values.setdefault("robot_description", TEST_URDF)
            values.setdefault("robot_description_semantic", TEST_SRDF)
        n = len(procs)
        params_file = tmp_path / f"params_{n}.yaml"
        params_file.write_text(yaml.safe_dump({"humanoid_planner": {"ros__parameters": values}}))
        log_dir = tmp_path / f"proc_{n}"
        log_dir.mkdir()
        p = PlannerProcess(planner_node_exe, [REPO_ROOT / "config" / "planner.yaml", params_file], log_dir,
                           list(extra_args), env)
        procs.append(p)
        return p

    try:
        yield start
    finally:
        for p in procs:
            p.stop()


# ----------------------------------------------------------------------------- point-cloud layer
CLOUD_GROUP = "left_arm_torso"
WALL_OFFSET = (-0.092, -0.081, -0.044)
"""From the object of armar3's `empty` scenario (seed 1, left hand): where every plan made without
the wall passes (found by sampling boxes on those plans' TCP paths that keep the home pose 6 cm clear)."""
WALL_SIZE = (0.055, 0.23, 0.282)


def wall_problem(robot):
    """(scenario, target object, wall object, snapshot with both): a wall between armar3's left hand
    and the object, for plans around obstacles that are given only as points."""
    import numpy as np

    from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario

    problem = make_scenario(robot, "empty", 1, hand="left", left_group="left_arm_torso", right_group="right_arm_torso")
    target = problem.scene.get(OBJECT_ID)
    pose = np.eye(4)
    pose[:3, 3] = problem.object_pose[:3, 3] + WALL_OFFSET
    wall = SceneObject("wall", pose, (Shape("box", np.eye(4), WALL_SIZE),))
    return problem, target, wall, SceneSnapshot(problem.scene.version + 1, problem.scene.frame, (target, wall))


@pytest.fixture(scope="session")
def example_robot_data() -> Path:
    """The ament prefix that example-robot-data (pip, cmeel) installs: `<prefix>/share/example-robot-data/
    robots/...` with its ament index marker, so `package://example-robot-data/...` resolves once the
    prefix is on AMENT_PREFIX_PATH. Skips the test when example-robot-data is not installed."""
    import importlib.metadata

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    prefix = Path(dist.locate_file("cmeel.prefix"))
    if not (prefix / "share" / "example-robot-data" / "robots").is_dir():
        pytest.skip(f"example-robot-data robots not found under {prefix}")
    return prefix


def cloud_layer(points, robot=None, q=None, objects=(), T_world_sensor=None, **settings):
    """core.scene.voxels.cloud_to_layer with the robot's solids at q (default home; no robot: no
    self-filter) and the objects' solids: (layer, stats)."""
    import numpy as np

    from humanoid_planner.core.scene.voxels import CloudSettings, cloud_to_layer, object_solids, robot_solids

    solids = robot_solids(robot, robot.home if q is None else q) if robot is not None else []
    return cloud_to_layer(np.asarray(points, dtype=np.float32), np.eye(4) if T_world_sensor is None else T_world_sensor,
                          CloudSettings(**settings), solids, object_solids(tuple(objects)))
