"""Completing the grasp over ROS (issue 15): plan_grasp with a straight approach and a retreat, and
attached objects through the `attached_collision_object` topic (attach, shown by get_planning_scene
and the markers, carried by later plans, detached back into the world). One armar3 node for the module."""
from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.scene.types import SceneSnapshot, attach
from humanoid_planner.core.verification import verify_plan, verify_straight
from humanoid_planner.ros.conversions import grasp_from_msg, grasp_to_msg, matrix_to_pose_msg, pose_to_matrix_checked
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS, MARKERS_QOS, SERVICE_QOS
from humanoid_planner.scenarios import OBJECT_ID
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject, ErrorCode
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp

from ros_messages import attached_msg, translation  # test/ros_messages.py
from plan_helpers import SUCCESS, ResponsePlan, armar3, publish_scene, scenario, trajectory_arrays, verify_response

pytestmark = pytest.mark.integration

LEFT = "left_arm_torso"




@pytest.fixture
def graph(ros):
    planner = ros.planner(urdf="", srdf="", robot="armar3")
    node = ros.node("completion_client")
    plan = node.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
    scene = node.create_client(GetPlanningScene, "get_planning_scene", qos_profile=SERVICE_QOS)
    attach_pub = node.create_publisher(AttachedCollisionObject, "attached_collision_object", COLLISION_OBJECT_QOS)
    markers: list[MarkerArray] = []
    node.create_subscription(MarkerArray, "humanoid_planner/markers", markers.append, MARKERS_QOS)
    ros.wait_for_subscribers(attach_pub)
    return ros, planner, node, plan, scene, attach_pub, markers


def test_approach_retreat_then_attach_detach_round_trip(graph):
    ros, planner, node, plan_cli, scene_cli, attach_pub, markers = graph
    robot = armar3()
    sc = scenario("boxes6", 0, "left")
    version = publish_scene(ros, node, sc.scene.objects, lambda: planner.scene.version)
    ax = approach_axis(robot, LEFT)

    # plan: a 10 cm approach along the hand axis (TCP frame), a 10 cm lift (planning frame)
    req = PlanGrasp.Request(group=LEFT, object_id=OBJECT_ID, timeout=10.0, seed=1,
                            pre_grasp_approach=translation(ax, 0.10, 0.05),
                            post_grasp_retreat=translation((0, 0, 1), 0.10, 0.05, frame="base_link"))
    resp = ros.call(plan_cli, req, timeout=30.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert resp.scene_version == version
    assert verify_response(resp, sc.scene, (LEFT,), robot.home, sc.object_pose) == []
    assert 0.05 - 1e-6 <= resp.approach_distance <= 0.10 + 1e-6
    assert 0.05 - 1e-6 <= resp.retreat_distance <= 0.10 + 1e-6
    _, pos, _, _ = trajectory_arrays(resp.trajectory)
    _, back, _, _ = trajectory_arrays(resp.retreat_trajectory)
    assert list(resp.retreat_trajectory.joint_names) == list(resp.trajectory.joint_names)
    assert np.allclose(back[0], pos[-1], atol=1e-9)  # the retreat starts exactly where the trajectory ends
    T_grasp = sc.object_pose @ grasp_from_msg(resp.grasp, "grasp").tcp_in_object
    assert verify_straight(robot, (LEFT,), robot.home, back, (0, 0, 1), min_distance=resp.retreat_distance - 0.002) == []
    # the last points of the trajectory approach along the hand axis
    tail = pos[-3:]
    assert verify_straight(robot, (LEFT,), robot.home, tail, T_grasp[:3, :3] @ ax) == []

    # the robot executed the plan (joint_states at its last point); the client attaches the target
    # to the hand where it is, as MoveIt's pick does once the gripper has closed
    q_grasp = robot.home.copy()
    q_grasp[robot.group_joint_indices(LEFT)] = pos[-1]
    js_pub = node.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
    js_pub.publish(JointState(name=list(robot.joint_names), position=q_grasp.tolist()))
    ros.wait_until(lambda: planner.latest_joint_state() is not None, what="joint_states received")
    tip = robot.group(LEFT).tip_link
    hands = robot.hand_links(LEFT)
    attach_pub.publish(attached_msg(OBJECT_ID, tip, touch=hands))
    ros.wait_until(lambda: planner.scene.version == version + 1, what="attach applied")
    got = ros.call(scene_cli, GetPlanningScene.Request())
    assert got.version == version + 1
    assert OBJECT_ID not in {o.id for o in got.objects}
    (att,) = got.attached_objects
    assert att.link_name == tip and att.object.id == OBJECT_ID and set(att.touch_links) == set(hands)
    assert att.object.header.frame_id == tip
    T_tip = robot.link_poses(q_grasp, [tip])[0]
    assert np.allclose(T_tip @ pose_to_matrix_checked(att.object.pose, "pose"), sc.object_pose, atol=1e-6)
    assert len(att.object.grasps) == len(sc.grasps)  # the grasp set stays with the object
    ros.wait_until(lambda: any(any(m.ns == "attached" for m in a.markers) for a in markers), what="attached markers")

    # a later plan (from where the robot now is) carries it: placing it 15 cm higher, verified in the
    # scene with the box held
    snap = planner.scene.snapshot()
    place = sc.object_pose.copy()
    place[2, 3] += 0.15
    req2 = PlanGrasp.Request(group=LEFT, object_pose=_stamped(place), grasps=[grasp_to_msg(grasp_from_msg(resp.grasp, "g"))],
                             timeout=10.0, seed=2)
    resp2 = ros.call(plan_cli, req2, timeout=30.0)
    assert resp2.error_code.val == SUCCESS, resp2.message
    held = SceneSnapshot(snap.version, snap.frame, snap.objects, attached=(attach(sc.scene.get(OBJECT_ID), tip, T_tip, hands),))
    T2 = place @ grasp_from_msg(resp2.grasp, "grasp").tcp_in_object
    assert verify_plan(robot, held, (LEFT,), q_grasp, ResponsePlan(resp2.trajectory), (T2,)) == []

    # the robot lifted it (joint_states at the retreat's end); detaching leaves it where the hand is
    q_up = robot.home.copy()
    q_up[robot.group_joint_indices(LEFT)] = back[-1]
    js_pub.publish(JointState(name=list(robot.joint_names), position=q_up.tolist()))
    ros.wait_until(lambda: np.allclose(planner.latest_joint_state().position, q_up), what="joint_states received")
    v = planner.scene.version
    attach_pub.publish(attached_msg(OBJECT_ID, op=CollisionObject.REMOVE))
    ros.wait_until(lambda: planner.scene.version == v + 1, what="detach applied")
    got = ros.call(scene_cli, GetPlanningScene.Request())
    assert not got.attached_objects
    (back_obj,) = [o for o in got.objects if o.id == OBJECT_ID]
    lifted = sc.object_pose.copy()
    lifted[2, 3] += resp.retreat_distance
    assert np.allclose(pose_to_matrix_checked(back_obj.pose, "pose"), lifted, atol=2e-3)
    assert len(back_obj.grasps) == len(sc.grasps)

    # invalid messages are refused whole (unknown link; unknown object); the version stays
    attach_pub.publish(attached_msg(OBJECT_ID, "no_such_link"))
    attach_pub.publish(attached_msg("ghost", tip))
    attach_pub.publish(attached_msg(OBJECT_ID, tip))  # sentinel: applied after the two above
    ros.wait_until(lambda: planner.scene.version == v + 2, what="sentinel applied")
    got = ros.call(scene_cli, GetPlanningScene.Request())
    assert [a.object.id for a in got.attached_objects] == [OBJECT_ID] and got.version == v + 2


def test_bad_translations_get_their_codes(graph):
    ros, planner, node, plan_cli, *_ = graph
    sc = scenario("empty", 0, "left")
    publish_scene(ros, node, sc.scene.objects, lambda: planner.scene.version)
    cases = [(translation((0, 0, 0), 0.1), ErrorCode.INVALID_GOAL_CONSTRAINTS, "direction"),
             (translation((0, 0, 1), 0.1, 0.2), ErrorCode.INVALID_GOAL_CONSTRAINTS, "min_distance"),
             (translation((0, 0, 1), 0.1, frame="moon"), ErrorCode.FRAME_TRANSFORM_FAILURE, "moon")]
    for gt, code, words in cases:
        for field in ("pre_grasp_approach", "post_grasp_retreat"):
            resp = ros.call(plan_cli, PlanGrasp.Request(group=LEFT, object_id=OBJECT_ID, timeout=5.0, **{field: gt}))
            assert resp.error_code.val == code and words in resp.message and field in resp.message, resp.message


def _stamped(T) -> PoseStamped:
    msg = PoseStamped(pose=matrix_to_pose_msg(T))
    msg.header.frame_id = "base_link"
    return msg
