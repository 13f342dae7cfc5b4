"""planner_node as a separate process (.venv/bin/planner_node), reached the way a real client reaches it."""
import signal
from pathlib import Path

import pytest
from rcl_interfaces.srv import GetParameters
from shape_msgs.msg import SolidPrimitive

from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS
from humanoid_planner_interfaces.msg import CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from plan_helpers import STARTUP_TIMEOUT, wait_for_services

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]


def wait_ready(ros, client_node, proc):
    cli = client_node.create_client(GetPlanningScene, "get_planning_scene")
    wait_for_services(proc, cli)
    return cli


def assert_clean_exit(proc, sig):
    proc.send_signal(sig)
    code = proc.wait(timeout=15)
    out = proc.output()
    assert code == 0, f"exit code {code} after {sig.name}; output:\n{out}"
    assert "Traceback" not in out, out


def test_scene_roundtrip_parameters_and_sigint(ros, start_planner_process):
    from conftest import TEST_SRDF

    # a MoveIt SRDF's virtual joint: its parent frame `world` coincides with the planning frame (the root)
    srdf = TEST_SRDF.replace("</robot>", '<virtual_joint name="virtual_joint" type="fixed" parent_frame="world" '
                                         'child_link="base_link"/></robot>')
    proc = start_planner_process(params={"robot_description_semantic": srdf})
    node = ros.node("process_client")
    cli = wait_ready(ros, node, proc)

    # parameters come from config/planner.yaml (+ the test robot file)
    pcli = node.create_client(GetParameters, "humanoid_planner/get_parameters")
    names = ["f_extend", "max_cycles", "goal_tolerance_rot", "num_workers", "robot", "planning_frame"]
    values = ros.call(pcli, GetParameters.Request(names=names)).values
    assert [values[0].double_value, values[1].integer_value, values[2].double_value, values[3].integer_value,
            values[4].string_value, values[5].string_value] == [0.3, 40000, 0.0174, 0, "", ""]

    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    ros.wait_for_subscribers(pub, timeout=STARTUP_TIMEOUT)
    msg = CollisionObject(id="box", operation=CollisionObject.ADD)
    msg.header.frame_id = "base_link"
    msg.pose.position.x = 0.4
    msg.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.2, 0.3])]
    msg.primitive_poses = [msg.pose.__class__()]
    pub.publish(msg)
    bad = CollisionObject(id="bad", operation=CollisionObject.MOVE)  # MOVE of a missing object: rejected
    pub.publish(bad)
    pub.publish(CollisionObject(id="box", operation=CollisionObject.MOVE, pose=msg.pose.__class__()))
    in_world = CollisionObject(id="box_in_world", operation=CollisionObject.ADD, primitives=msg.primitives,
                               primitive_poses=msg.primitive_poses)
    in_world.header.frame_id = "world"
    in_world.pose.position.y = 0.5
    pub.publish(in_world)
    resp = ros.wait_until(lambda: (r := ros.call(cli, GetPlanningScene.Request())).version >= 3 and r,
                          what="three applied updates")
    assert resp.version == 3 and resp.planning_frame == "base_link"
    assert [o.id for o in resp.objects] == ["box", "box_in_world"]
    assert resp.objects[0].pose.position.x == 0.0 and list(resp.objects[0].primitives[0].dimensions) == [0.1, 0.2, 0.3]
    assert resp.objects[1].pose.position.y == 0.5 and resp.objects[1].header.frame_id == "base_link"
    assert "planning frame 'base_link' (also 'world')" in proc.output()

    assert_clean_exit(proc, signal.SIGINT)
    assert "collision_object rejected" in proc.output()


def test_sigterm_during_a_collision_object_flood_exits_promptly_and_cleanly(ros, start_planner_process):
    """One client publishes collision_object ADDs as fast as it can (a backlog queued in the node) and
    subscribes to the markers; SIGTERM in the middle of the flood: exit 0 within 2 s, no FATAL line and
    no traceback (the queued updates are dropped at shutdown, not applied first)."""
    import threading
    import time

    from rclpy._rclpy_pybind11 import RCLError
    from visualization_msgs.msg import MarkerArray

    from humanoid_planner.ros.qos import MARKERS_QOS

    proc = start_planner_process()
    node = ros.node("flood_client")
    wait_ready(ros, node, proc)
    node.create_subscription(MarkerArray, "humanoid_planner/markers", lambda m: None, MARKERS_QOS)
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    ros.wait_for_subscribers(pub, timeout=STARTUP_TIMEOUT)
    stop = threading.Event()

    def flood():
        k = 0
        while not stop.is_set():
            msg = CollisionObject(id=f"box{k % 2000}", operation=CollisionObject.ADD)
            msg.header.frame_id = "base_link"
            msg.pose.position.x = 2.0 + 0.001 * (k % 1000)
            msg.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.05, 0.05, 0.05])]
            msg.primitive_poses = [msg.pose.__class__()]
            try:
                pub.publish(msg)
            except RCLError:  # keep-all: publish gives up while the exiting node's full reader acknowledges nothing
                continue
            k += 1

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        time.sleep(1.5)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=15)
        elapsed = time.monotonic() - t0
    finally:
        stop.set()
        flooder.join(5.0)
    out = proc.output()
    assert code == 0, f"exit code {code}; output:\n{out}"
    assert elapsed <= 2.0, f"exited {elapsed:.2f} s after SIGTERM"
    assert "FATAL" not in out and "Traceback" not in out, out


def test_robot_that_cannot_be_loaded_exits_nonzero_without_traceback(start_planner_process):
    proc = start_planner_process(params={"robot_description": "<robot name='broken'><link name='a'/>",
                                         "robot_description_semantic": ""})
    code = proc.wait(timeout=STARTUP_TIMEOUT)
    out = proc.output()
    assert code == 1, out
    assert "cannot load the robot" in out and "Traceback" not in out


def test_unknown_preset_exits_nonzero(start_planner_process):
    proc = start_planner_process(params={"robot": "no_such_robot"}, robot=False)
    assert proc.wait(timeout=STARTUP_TIMEOUT) == 1
    out = proc.output()
    assert "no_such_robot" in out and "Traceback" not in out


@pytest.mark.skipif(not (REPO_ROOT / "config" / "robots" / "armar3.urdf").exists(),
                    reason="preset config/robots/armar3.urdf not in the tree yet")
def test_preset_starts_with_moveit_joint_limits(ros, start_planner_process):
    """A MoveIt configuration's joint_limits.yaml, as move_group gets it (robot_description_planning.
    joint_limits.<joint>.*): the trajectories keep its velocity and acceleration limits, which the URDF
    (1.5 rad/s, no acceleration) does not have; a joint the URDF does not move is named in the log."""
    import numpy as np
    from sensor_msgs.msg import JointState

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner_interfaces.srv import PlanToState
    from plan_helpers import SUCCESS, trajectory_arrays

    slow = {"left_shoulder_1_joint": (0.3, 0.6), "left_elbow_joint": (0.4, 0.5)}
    limits = {j: {"has_velocity_limits": True, "max_velocity": v, "has_acceleration_limits": True,
                  "max_acceleration": a, "has_jerk_limits": False} for j, (v, a) in slow.items()}
    limits["left_gripper_joint"] = {"has_velocity_limits": True, "max_velocity": 1.0}
    proc = start_planner_process(params={"robot": "armar3", "robot_description_planning": {"joint_limits": limits}},
                                 robot=False)
    node = ros.node("process_client")
    cli = wait_ready(ros, node, proc)
    resp = ros.call(cli, GetPlanningScene.Request())
    assert resp.version == 0 and resp.planning_frame
    out = proc.output()
    assert "joint limits of 2 joint(s) from robot_description_planning.joint_limits.*" in out, out
    assert "left out: left_gripper_joint" in out

    robot = RobotModel.preset("armar3")
    names = list(robot.group("left_arm").joint_names)
    goal = robot.home[robot.group_joint_indices("left_arm")].copy()
    for j in slow:
        goal[names.index(j)] += 0.8 if robot.home[robot.joint_names.index(j)] + 0.8 < robot.upper[
            robot.joint_names.index(j)] else -0.8
    to_state = node.create_client(PlanToState, "plan_to_state")
    wait_for_services(proc, to_state)
    resp = ros.call(to_state, PlanToState.Request(group="left_arm", goal_state=JointState(name=names,
                                                  position=goal.tolist()), seed=1, timeout=10.0))
    assert resp.error_code.val == SUCCESS, resp.message
    _, pos, vel, acc = trajectory_arrays(resp.trajectory)
    assert np.allclose(pos[-1], goal, atol=1e-9)
    for j, (v, a) in slow.items():
        k = names.index(j)
        assert np.max(np.abs(vel[:, k])) <= v * (1 + 1e-6) and np.max(np.abs(acc[:, k])) <= a * (1 + 1e-6)
        assert np.max(np.abs(vel[:, k])) > 0.5 * v  # long enough to reach it (past it at the URDF's 1.5 rad/s)
    assert_clean_exit(proc, signal.SIGINT)


def test_a_bad_moveit_joint_limit_exits_1_naming_it(start_planner_process):
    proc = start_planner_process(params={"robot": "armar3", "robot_description_planning": {"joint_limits": {
        "left_elbow_joint": {"has_acceleration_limits": True, "max_acceleration": -2.0}}}}, robot=False)
    assert proc.wait(timeout=STARTUP_TIMEOUT) == 1
    out = proc.output()
    assert "joint_limits of left_elbow_joint: max_acceleration=-2 must be > 0" in out and "Traceback" not in out


def test_ros2_run_finds_the_node_in_the_venv(monkeypatch):
    """What `ros2 run humanoid_planner planner_node` looks up (ros2run: the package prefix from the
    ament index, then an executable lib/<package>/<name> under it), with AMENT_PREFIX_PATH=.venv."""
    import os
    import sys
    from pathlib import Path

    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    monkeypatch.setenv("AMENT_PREFIX_PATH", sys.prefix)
    prefix = Path(get_package_prefix("humanoid_planner"))
    assert prefix.resolve() == Path(sys.prefix).resolve()
    for exe in ("planner_node", "grasp_client"):
        path = prefix / "lib" / "humanoid_planner" / exe
        assert path.is_file() and os.access(path, os.X_OK), f"{path}: run `make setup`"
        assert path.resolve() == (Path(sys.executable).parent / exe).resolve()
    assert (Path(get_package_share_directory("humanoid_planner")) / "config" / "planner.yaml").is_file()

