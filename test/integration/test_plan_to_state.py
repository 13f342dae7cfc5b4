"""plan_to_state (service and action) against planner_node in its own process (armar3): back to the
SRDF `home` after a pick with the object attached (verified with the object in the hand), a joint goal
in collision and malformed goals refused with INVALID_GOAL_CONSTRAINTS naming what is wrong, and a
cancelled goal ending PREEMPTED. One node for the module; every test leaves the scene as it found it."""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from sensor_msgs.msg import JointState

from conftest import ActionClient, PlannerProcess, RosGraph, wait_for, wait_until
from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.ros.conversions import pose_to_matrix_checked, scene_object_to_msg
from humanoid_planner.ros.executors import wait_for_server
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS
from humanoid_planner.scenarios import OBJECT_ID
from humanoid_planner_interfaces.action import PlanToState as PlanToStateAction
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject, ErrorCode
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp, PlanToState

from ros_messages import attached_msg, translation  # test/ros_messages.py
from plan_helpers import FRAME, STARTUP_TIMEOUT, SUCCESS, ResponsePlan, armar3, box_object, scenario, trajectory_arrays

pytestmark = pytest.mark.integration

LEFT = "left_arm_torso"
ARM = "left_arm"
INVALID_GOAL = ErrorCode.INVALID_GOAL_CONSTRAINTS
CANCEL_LIMIT = 0.5  # s, client side: the node stops a plan within 0.2 s; slack for a loaded machine


class Node:
    """The module's planner process and a client graph talking to it."""

    def __init__(self, domain: int, tmp: Path) -> None:
        self.ros = RosGraph(domain)
        params = tmp / "params.yaml"
        params.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"robot": "armar3", "dual_arm_processes": False}}}))
        log = tmp / "proc"
        log.mkdir()
        repo = Path(__file__).resolve().parents[2]
        self.proc = PlannerProcess(Path(sys.executable).parent / "planner_node", [repo / "config" / "planner.yaml", params],
                                   log)
        self.node = self.ros.node("to_state_client")
        self.srv = self.node.create_client(PlanToState, "plan_to_state")
        self.grasp = self.node.create_client(PlanGrasp, "plan_grasp")
        self.scene_cli = self.node.create_client(GetPlanningScene, "get_planning_scene")
        self.action = ActionClient(self.node, PlanToStateAction, "plan_to_state")
        for cli in (self.srv, self.grasp, self.scene_cli):
            if not wait_for_server(cli, STARTUP_TIMEOUT):
                raise AssertionError(f"planner_node did not come up; its output:\n{self.proc.output()}")
        assert wait_for_server(self.action, STARTUP_TIMEOUT), self.proc.output()
        self.objects = self.node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        self.attached = self.node.create_publisher(AttachedCollisionObject, "attached_collision_object",
                                                   COLLISION_OBJECT_QOS)
        self.joints = self.node.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
        for pub in (self.objects, self.attached):
            self.ros.wait_for_subscribers(pub, timeout=STARTUP_TIMEOUT)

    def version(self) -> int:
        return self.call(self.scene_cli, GetPlanningScene.Request()).version

    def call(self, client, request, timeout: float = 30.0):
        return self.ros.call(client, request, timeout)

    def apply(self, publisher, *msgs) -> int:
        """Publish scene messages and wait until the node has applied them all; the new version."""
        target = self.version() + len(msgs)
        for m in msgs:
            publisher.publish(m)
        wait_until(lambda: self.version() >= target, timeout=10.0, what=f"scene version {target}")
        return target

    def close(self) -> None:
        self.proc.stop()
        self.ros.close()


@pytest.fixture(scope="module")
def node(ros_domain_id, tmp_path_factory):
    n = Node(ros_domain_id, tmp_path_factory.mktemp("to_state"))
    try:
        yield n
    finally:
        n.close()


def joint_goal(group: str, q: np.ndarray) -> JointState:
    """goal_state: the group's joints at the full configuration q."""
    robot = armar3()
    idx = robot.group_joint_indices(group)
    return JointState(name=[robot.joint_names[i] for i in idx], position=q[idx].tolist())


def raised_arm() -> np.ndarray:
    """home with the left upper arm lifted sideways (clear of the home pose)."""
    robot = armar3()
    q = robot.home.copy()
    q[robot.joint_names.index("left_shoulder_2_joint")] = -1.2
    return q


def collar(q: np.ndarray) -> SceneObject:
    """Four plates around the left upper arm at q, 2 cm from it, from 12 to 26 cm below the shoulder:
    the arm at q is free, but the upper arm cannot turn more than a few degrees there (its three
    shoulder joints share one point), so no motion joins q to a pose whose upper arm points elsewhere."""
    T = armar3().link_poses(q, ["left_upper_arm_link"])[0]
    w, t, z0, z1 = 0.07, 0.01, 0.12, 0.26  # inner half-width (arm radius 5 cm + 2), plate thickness, extent
    shapes = []
    for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        P = np.eye(4)
        P[:3, 3] = (sx * (w + t / 2), sy * (w + t / 2), -(z0 + z1) / 2)  # the upper arm runs along -z
        shapes.append(Shape("box", P, (t, 2 * (w + t), z1 - z0) if sx else (2 * (w + t), t, z1 - z0)))
    return SceneObject("collar", T, tuple(shapes))


def removal(oid: str) -> CollisionObject:
    return CollisionObject(id=oid, operation=CollisionObject.REMOVE)




# ------------------------------------------------------------------------------------------ refusals
def _goal_cases():
    robot = armar3()
    idx = robot.group_joint_indices(ARM)
    names = [robot.joint_names[i] for i in idx]
    home = robot.home[idx].tolist()

    def js(n, p):
        return {"goal_state": JointState(name=n, position=p)}

    return [
        (js(names + ["no_such_joint"], home + [0.0]), "unknown joint(s) ['no_such_joint']"),
        (js(names + ["right_elbow_joint"], home + [1.0]), "joint(s) ['right_elbow_joint'] are not in 'left_arm'"),
        (js(names[:-1], home[:-1]), "no value for joint(s) ['left_wrist_2_joint']"),
        (js(names, [math.nan] + home[1:]), "NaN or inf value(s): left_shoulder_1_joint=nan"),
        (js(names, home[:3] + [3.0] + home[4:]), "left_elbow_joint=3.0000 not in [0.0000, 2.5307]"),
        (js(names, home[:-1]), "7 names but 6 positions"),
        (js(names + [names[0]], home + [home[0]]), "joint(s) ['left_shoulder_1_joint'] given more than once"),
        ({"named_state": "home", **js(names, home)}, "not both"),
        ({}, "neither is given"),
        ({"named_state": "stow"}, "no group_state 'stow'; known: home"),
    ]


def test_malformed_goals_are_refused_naming_the_fault(node):
    for fields, expected in _goal_cases():
        resp = node.call(node.srv, PlanToState.Request(group=ARM, **fields))
        assert resp.error_code.val == INVALID_GOAL, (fields, resp.message)
        assert expected in resp.message, (expected, resp.message)
    # the action refuses the same way: the goal ends aborted with the code in its result
    handle = wait_for(node.action.send_goal_async(PlanToStateAction.Goal(group=ARM, named_state="stow")), 10.0)
    res = wait_for(handle.get_result_async(), 10.0)
    assert res.status == 6 and res.result.error_code.val == INVALID_GOAL  # GoalStatus.STATUS_ABORTED


def test_a_goal_in_collision_names_the_colliding_pair(node):
    robot = armar3()
    q = raised_arm()
    tcp = robot.link_poses(q, ["left_tcp"])[0, :3, 3]
    v = node.apply(node.objects, scene_object_to_msg(box_object("block", tcp, (0.06, 0.06, 0.06)), FRAME))
    try:
        resp = node.call(node.srv, PlanToState.Request(group=ARM, goal_state=joint_goal(ARM, q), seed=1))
    finally:
        node.apply(node.objects, removal("block"))
    assert resp.error_code.val == INVALID_GOAL, resp.message
    assert resp.message.startswith("the goal is in collision: ") and "'left_tcp' with 'block'" in resp.message, \
        resp.message
    assert resp.scene_version == v


# ------------------------------------------------------------------------------------------ cancel
def test_cancel_ends_preempted_promptly(node):
    q = raised_arm()
    node.apply(node.objects, scene_object_to_msg(collar(q), FRAME))
    try:
        feedback: list = []
        handle = wait_for(node.action.send_goal_async(
            PlanToStateAction.Goal(group=ARM, goal_state=joint_goal(ARM, q), timeout=30.0, seed=1),
            feedback_callback=lambda m: feedback.append(m.feedback)), 10.0)
        assert handle.accepted
        wait_until(lambda: sum(f.phase == "searching" and f.iterations > 0 for f in feedback) >= 3, timeout=15.0,
                   what="3 feedbacks of a running search")
        t0 = time.monotonic()
        wait_for(handle.cancel_goal_async(), 5.0)
        res = wait_for(handle.get_result_async(), 10.0)
        took = time.monotonic() - t0
    finally:
        node.apply(node.objects, removal("collar"))
    assert res.result.error_code.val == ErrorCode.PREEMPTED, res.result.message
    assert res.status == 5  # GoalStatus.STATUS_CANCELED
    assert took < CANCEL_LIMIT, f"result {took:.3f} s after the cancel request"
    searching = [f.iterations for f in feedback if f.phase == "searching"]
    assert searching == sorted(searching) and searching[-1] > 0


# ------------------------------------------------------------------------------------------ the cycle
def test_home_after_a_pick_with_the_object_attached(node):
    robot = armar3()
    sc = scenario("boxes6", 0, "left")
    node.apply(node.objects, *(scene_object_to_msg(o, FRAME) for o in sc.scene.objects))
    idx = robot.group_joint_indices(LEFT)
    tip, hands = robot.group(LEFT).tip_link, robot.hand_links(LEFT)
    try:
        # pick and lift: the robot executes the reach (joint_states there), the client attaches the
        # object, the robot lifts it (joint_states at the retreat's end)
        pick = node.call(node.grasp, PlanGrasp.Request(
            group=LEFT, object_id=OBJECT_ID, timeout=10.0, seed=1,
            pre_grasp_approach=translation(approach_axis(robot, LEFT), 0.10, 0.05),
            post_grasp_retreat=translation((0, 0, 1), 0.10, 0.05, frame=FRAME)))
        assert pick.error_code.val == SUCCESS, pick.message
        q_grasp, q_up = robot.home.copy(), robot.home.copy()
        q_grasp[idx] = trajectory_arrays(pick.trajectory)[1][-1]
        q_up[idx] = trajectory_arrays(pick.retreat_trajectory)[1][-1]
        for _ in range(3):  # best effort: one may be lost; the attach takes the hand where the latest puts it
            node.joints.publish(JointState(name=list(robot.joint_names), position=q_grasp.tolist()))
            time.sleep(0.1)
        node.apply(node.attached, attached_msg(OBJECT_ID, tip, touch=hands))
        (att,) = node.call(node.scene_cli, GetPlanningScene.Request()).attached_objects
        T_tip = robot.link_poses(q_grasp, [tip])[0]
        assert np.allclose(T_tip @ pose_to_matrix_checked(att.object.pose, "pose"), sc.object_pose, atol=1e-6), \
            "attached where the hand was before the grasp: joint_states not received in time"
        for _ in range(3):  # the request's start state: the latest joint_states
            node.joints.publish(JointState(name=list(robot.joint_names), position=q_up.tolist()))
            time.sleep(0.1)

        req = PlanToState.Request(group=LEFT, named_state="home", seed=3, timeout=10.0)
        resp = node.call(node.srv, req)
        assert resp.error_code.val == SUCCESS, resp.message
        assert list(resp.trajectory.joint_names) == list(robot.group(LEFT).joint_names)
        _, pos, _, _ = trajectory_arrays(resp.trajectory)
        assert np.allclose(pos[0], q_up[idx], atol=1e-9)  # from the latest joint_states
        assert np.allclose(pos[-1], robot.state("home")[idx], atol=1e-9)
        # verified with the object in the hand where it was grasped, and the rest of the scene
        held = SceneSnapshot(resp.scene_version, FRAME, tuple(o for o in sc.scene.objects if o.id != OBJECT_ID),
                             attached=(attach(sc.scene.get(OBJECT_ID), tip, T_tip, hands),))
        assert verify_plan(robot, held, (LEFT,), q_up, ResponsePlan(resp.trajectory), ()) == []

        # the action plans the same request the same way (one code path, same seed); its start state
        # given in full (joint_states may be older than joint_states_max_age by now)
        start = JointState(name=list(robot.joint_names), position=q_up.tolist())
        handle = wait_for(node.action.send_goal_async(PlanToStateAction.Goal(
            group=LEFT, start_state=start, named_state="home", seed=3, timeout=10.0)), 10.0)
        res = wait_for(handle.get_result_async(), 30.0)
        assert res.status == 4, res.result.message  # GoalStatus.STATUS_SUCCEEDED
        assert res.result.trajectory == resp.trajectory

        # the held object is checked at the goal too: a 1 cm marker where its far end would be at home
        T_hand = robot.link_poses(robot.state("home"), [tip])[0]
        T_obj = T_hand @ np.linalg.inv(T_tip) @ sc.object_pose  # the box is 20 cm long along its z
        far = max((T_obj[:3, :3] @ (0.0, 0.0, s * 0.09) + T_obj[:3, 3] for s in (1, -1)),
                  key=lambda p: np.linalg.norm(p - T_hand[:3, 3]))
        node.apply(node.objects, scene_object_to_msg(box_object("marker", far, (0.01, 0.01, 0.01)), FRAME))
        blocked = node.call(node.srv, PlanToState.Request(group=LEFT, start_state=start, named_state="home", seed=3))
        assert blocked.error_code.val == INVALID_GOAL, blocked.message
        assert blocked.message == f"the goal is in collision: '{OBJECT_ID}' with 'marker'", blocked.message
    finally:
        node.apply(node.attached, attached_msg(OBJECT_ID, op=CollisionObject.REMOVE))
        node.apply(node.objects, removal(""))
