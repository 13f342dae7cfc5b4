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
    proc = start_planner_process()
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
    resp = ros.wait_until(lambda: (r := ros.call(cli, GetPlanningScene.Request())).version >= 2 and r,
                          what="two applied updates")
    assert resp.version == 2 and resp.planning_frame == "base_link"
    assert [o.id for o in resp.objects] == ["box"]
    assert resp.objects[0].pose.position.x == 0.0 and list(resp.objects[0].primitives[0].dimensions) == [0.1, 0.2, 0.3]

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
def test_preset_starts(ros, start_planner_process):
    proc = start_planner_process(params={"robot": "armar3"}, robot=False)
    cli = wait_ready(ros, ros.node("process_client"), proc)
    resp = ros.call(cli, GetPlanningScene.Request())
    assert resp.version == 0 and resp.planning_frame
    assert_clean_exit(proc, signal.SIGINT)


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

