"""The robot as a ROS robot hands it over (ros/robot_description.py): URDF + SRDF on the
`robot_description` / `robot_description_semantic` topics (transient local), `package://` meshes
through the ament index; load errors name the mesh URI."""
from __future__ import annotations

import signal
import time

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.model.srdf_setup import generate_srdf
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.ros.qos import ROBOT_DESCRIPTION_QOS
from humanoid_planner_interfaces.msg import ErrorCode
from humanoid_planner.scenarios import OBJECT_ID, make_scenario
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp, PlanToState

from plan_helpers import (STARTUP_TIMEOUT, SUCCESS, ResponsePlan, publish_scene, remote_version, trajectory_arrays,
                          verify_response, wait_for_services)

TALOS = "share/example-robot-data/robots/talos_data"
MISSING = "package://example-robot-data/robots/talos_data/meshes/torso/no_such_mesh.STL"


def _ament_prefix(tmp_path, example_robot_data):
    """A temporary ament prefix holding only example-robot-data (symlinked), as a colcon install would."""
    index = tmp_path / "prefix" / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True)
    (index / "example-robot-data").touch()
    (tmp_path / "prefix" / "share" / "example-robot-data").symlink_to(
        example_robot_data / "share" / "example-robot-data")
    return tmp_path / "prefix"


def test_missing_mesh_in_the_parameter_exits_1_naming_the_uri(start_planner_process, tmp_path):
    urdf = f"""<robot name="r"><link name="a"><collision><geometry><mesh filename="{MISSING}"/></geometry>
        </collision></link></robot>"""
    proc = start_planner_process(params={"robot_description": urdf, "robot_description_semantic": ""}, robot=False,
                                 env={"AMENT_PREFIX_PATH": str(tmp_path)})
    code = proc.wait(timeout=STARTUP_TIMEOUT)
    out = proc.output()
    assert code == 1, out
    assert f"mesh not found: {MISSING}" in out and "Traceback" not in out


def test_talos_from_the_topics_with_package_meshes_plans(ros, start_planner_process, example_robot_data, tmp_path):
    """No `robot`, no `robot_description` parameter: the node waits on the topics (and says so), logs a
    description it cannot load and keeps waiting, then loads TALOS (with the SRDF planner_setup writes)
    and plans a verified grasp."""
    prefix = _ament_prefix(tmp_path, example_robot_data)
    urdf_path = example_robot_data / TALOS / "robots/talos_reduced.urdf"
    urdf = urdf_path.read_text()
    assert "package://example-robot-data/" in urdf
    # the node starts in its own process while this one writes the SRDF (the client side's work is done
    # while the node's is: the test waits for the slower of the two, not for their sum)
    proc = start_planner_process(robot=False, env={"AMENT_PREFIX_PATH": str(prefix)})
    # the SRDF planner_setup writes from TALOS's own (groups left_arm/..., home = its half_sitting)
    srdf = generate_srdf(urdf_path, example_robot_data / TALOS / "srdf/talos.srdf", samples=100).srdf
    node = ros.node("description_publisher")
    scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
    ros.wait_until(lambda: "waiting for the robot description on /robot_description, /robot_description_semantic"
                   in proc.output(), timeout=STARTUP_TIMEOUT, what="the node saying what it waits for")
    assert not scene_cli.service_is_ready()  # nothing is served before the robot is loaded

    urdf_pub = node.create_publisher(String, "robot_description", ROBOT_DESCRIPTION_QOS)
    srdf_pub = node.create_publisher(String, "robot_description_semantic", ROBOT_DESCRIPTION_QOS)
    srdf_pub.publish(String(data=srdf))
    urdf_pub.publish(String(data=urdf.replace("package://example-robot-data/robots/talos_data/meshes/torso/"
                                              "torso_2_collision.STL", MISSING)))
    ros.wait_until(lambda: f"mesh not found: {MISSING}" in proc.output(), timeout=STARTUP_TIMEOUT,
                   what="the load error naming the missing mesh")
    assert proc.proc.poll() is None, proc.output()  # still waiting for a better description
    urdf_pub.publish(String(data=urdf))  # transient local: the node also gets it if it subscribed late
    # the client's own copy of the robot (the same files) and the scenario, while the node loads TALOS
    robot = RobotModel.from_urdf_srdf(urdf_path, srdf)
    np.testing.assert_allclose(robot.home, robot.state("half_sitting"))  # all-zero has the hands in the thighs
    sc = make_scenario(robot, "empty", 1, hand="left", left_group="left_arm", right_group="right_arm")
    wait_for_services(proc, scene_cli)
    assert "robot 'talos' from the robot_description topic" in proc.output()

    # the scene and the plan
    publish_scene(ros, node, sc.scene.objects, remote_version(ros, node))
    plan_cli = node.create_client(PlanGrasp, "plan_grasp")
    wait_for_services(proc, plan_cli)
    # a plan while the worker processes start: this process's collision model is not built yet (seconds);
    # the plan takes whichever comes first, a worker or the model, and answers by its deadline (a plan
    # that built the model first answered 4.6 s after its 3 s deadline)
    t0 = time.monotonic()
    early = ros.call(plan_cli, PlanGrasp.Request(group="left_arm", object_id=OBJECT_ID, timeout=1.0, seed=1),
                     timeout=40.0)
    took = time.monotonic() - t0
    assert early.error_code.val in (SUCCESS, ErrorCode.TIMED_OUT), early.message
    assert took < 2.0, (took, early.message)  # the deadline, and the answer's trip through a node that is busy building
    # the first plan of the group in a worker process: its pair tables (seconds on TALOS) are built off its
    # path, so a short timeout holds (0.2 s here; building them in the plan took 2.7 s)
    ros.wait_until(lambda: "planning worker processes ready" in proc.output(), timeout=STARTUP_TIMEOUT,
                   what="the worker processes")
    req = PlanGrasp.Request(group="left_arm", object_id=OBJECT_ID, timeout=1.5, seed=1)  # start: the SRDF's home
    resp = ros.call(plan_cli, req, timeout=40.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert verify_response(resp, sc.scene, ("left_arm",), robot.home, sc.object_pose, robot=robot) == []
    assert np.allclose(resp.trajectory.points[0].positions, robot.home[robot.group_joint_indices("left_arm")])

    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=STARTUP_TIMEOUT) == 0
    assert "Traceback" not in proc.output(), proc.output()  # whole, not pytest's truncated diff


def test_sigterm_while_waiting_for_the_topics_exits_cleanly(ros, start_planner_process):
    proc = start_planner_process(robot=False)
    ros.wait_until(lambda: "waiting for the robot description" in proc.output(), timeout=STARTUP_TIMEOUT,
                   what="the node waiting for the topics")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=STARTUP_TIMEOUT) == 0
    assert "Traceback" not in proc.output()


def test_baxter_from_the_topics_plans_single_and_dual(ros, start_planner_process, example_robot_data, tmp_path):
    """A robot other than TALOS, as a ROS robot hands it over: Baxter's URDF (Collada meshes through
    `package://`, a temporary ament prefix) and planner_setup's SRDF (merged with Baxter's own, whose
    `whole_body` names a joint its URDF lacks) on the topics; a single and a dual grasp, both verified."""
    from humanoid_planner_interfaces.srv import PlanDualGrasp

    from plan_helpers import dual_request

    baxter = example_robot_data / "share/example-robot-data/robots/baxter_description"
    prefix = _ament_prefix(tmp_path, example_robot_data)
    urdf_path = baxter / "urdf/baxter.urdf"
    srdf = generate_srdf(urdf_path, baxter / "srdf/baxter_manipulation.srdf", samples=100).srdf
    # a MoveIt-style group of both arms (VAMP's and MotionBenchMaker's Baxter SRDF name one): no TCP, but
    # a joint goal for it is planned like any other
    srdf = srdf.replace("</robot>", '<group name="both_arms"><group name="left_arm"/><group name="right_arm"/>'
                                    "</group></robot>")
    assert "package://example-robot-data/robots/baxter_description/meshes/" in urdf_path.read_text()
    proc = start_planner_process(robot=False, env={"AMENT_PREFIX_PATH": str(prefix)})
    node = ros.node("baxter_publisher")
    for topic, text in (("robot_description_semantic", srdf), ("robot_description", urdf_path.read_text())):
        node.create_publisher(String, topic, ROBOT_DESCRIPTION_QOS).publish(String(data=text))
    scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
    wait_for_services(proc, scene_cli)
    assert "robot 'baxter' from the robot_description topic" in proc.output()
    assert "group 'left_arm' (7 joints): TCP link 'left_gripper'" in proc.output()

    robot = RobotModel.from_urdf_srdf(urdf_path, srdf)
    sc = make_scenario(robot, "empty", 0, hand="both")
    publish_scene(ros, node, sc.scene.objects, remote_version(ros, node), frame=robot.root_link)
    dual_cli = node.create_client(PlanDualGrasp, "plan_dual_grasp")
    plan_cli = node.create_client(PlanGrasp, "plan_grasp")
    wait_for_services(proc, dual_cli, plan_cli)
    resp = ros.call(dual_cli, dual_request(timeout=20.0), timeout=40.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert verify_response(resp, sc.scene, ("left_arm", "right_arm"), robot.home, sc.object_pose, robot=robot) == []
    resp = ros.call(plan_cli, PlanGrasp.Request(group="left_arm", object_id=OBJECT_ID,
                                                timeout=20.0, seed=1), timeout=40.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert verify_response(resp, sc.scene, ("left_arm",), robot.home, sc.object_pose, robot=robot) == []

    # both arms to a joint goal: each shoulder turned outwards (away from the object between the hands)
    both = robot.group("both_arms")
    assert both.tip_link == "" and len(both.joint_names) == 14
    goal = robot.home.copy()
    for joint, turn in (("left_s0", 0.5), ("right_s0", -0.5)):
        goal[robot.joint_names.index(joint)] += turn
    idx = robot.group_joint_indices("both_arms")
    to_state_cli = node.create_client(PlanToState, "plan_to_state")
    wait_for_services(proc, to_state_cli)
    resp = ros.call(to_state_cli, PlanToState.Request(
        group="both_arms", goal_state=JointState(name=[robot.joint_names[i] for i in idx],
                                                 position=goal[idx].tolist()), timeout=20.0, seed=1), timeout=40.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert list(resp.trajectory.joint_names) == list(both.joint_names)
    pos = trajectory_arrays(resp.trajectory)[1]
    assert np.allclose(pos[-1], goal[idx], atol=1e-9)
    assert verify_plan(robot, sc.scene, ("both_arms",), robot.home, ResponsePlan(resp.trajectory), ()) == []
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=STARTUP_TIMEOUT) == 0
    assert "Traceback" not in proc.output(), proc.output()  # whole, not pytest's truncated diff
