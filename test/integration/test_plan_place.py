"""plan_place and plan_dual_place (services and actions) against planner_node in its own process
(armar3): an object held by the left hand put on a shelf (one of 5 candidate placements, a straight
5 cm descent, clear of everything but its support), a box held by both hands carried to the other side
of a table (their relative pose kept), cancels ending PREEMPTED, hostile requests refused with clear
codes. The pick before each place is planned in this process (core) and given to the node as
joint_states + attach, as a robot that executed it would. One node for the module."""
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
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.ros.conversions import scene_object_to_msg
from humanoid_planner.ros.executors import wait_for_server
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS
from humanoid_planner.scenarios import OBJECT_ID, make_scenario
from humanoid_planner_interfaces.action import PlanDualPlace as DualPlaceAction, PlanPlace as PlaceAction
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject, ErrorCode
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualPlace, PlanPlace

from ros_messages import attached_msg, translation  # test/ros_messages.py
from plan_helpers import FRAME, STARTUP_TIMEOUT, SUCCESS, ResponsePlan, armar3, box_object, pose_stamped, trajectory_arrays

pytestmark = pytest.mark.integration

LEFT = "left_arm_torso"
DUAL = ("left_arm", "right_arm")
TOP = 1.0  # m: the shelf board's top
DOWN5 = translation((0, 0, 0), 0.05, 0.05)  # zero direction: the default, the planning frame's -z
BACK = translation((-1, 0, 0), 0.10, 0.05)  # TCP frame: back along the hand's axis (ARMAR-III's TCP +x)
CANCEL_LIMIT = 0.5  # s, client side: the node stops a plan within 0.2 s; slack for a loaded machine


def at(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


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
        self.node = self.ros.node("place_client")
        self.place = self.node.create_client(PlanPlace, "plan_place")
        self.dual = self.node.create_client(PlanDualPlace, "plan_dual_place")
        self.scene_cli = self.node.create_client(GetPlanningScene, "get_planning_scene")
        self.place_action = ActionClient(self.node, PlaceAction, "plan_place")
        self.dual_action = ActionClient(self.node, DualPlaceAction, "plan_dual_place")
        for cli in (self.place, self.dual, self.scene_cli):
            if not wait_for_server(cli, STARTUP_TIMEOUT):
                raise AssertionError(f"planner_node did not come up; its output:\n{self.proc.output()}")
        for a in (self.place_action, self.dual_action):
            assert wait_for_server(a, STARTUP_TIMEOUT), self.proc.output()
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
        target = self.version() + len(msgs)
        for m in msgs:
            publisher.publish(m)
        wait_until(lambda: self.version() >= target, timeout=10.0, what=f"scene version {target}")
        return target

    def hold(self, q: np.ndarray, obj: SceneObject, link: str, touch) -> JointState:
        """The robot at q (joint_states) holding obj (added where it is, then attached to `link`); the
        start state, given in full."""
        robot = armar3()
        js = JointState(name=list(robot.joint_names), position=q.tolist())
        for _ in range(3):  # best effort: one message may be lost; the attach takes the hand where the
            self.joints.publish(js)  # latest joint_states puts it
            time.sleep(0.1)
        self.apply(self.objects, scene_object_to_msg(obj, FRAME))
        self.apply(self.attached, attached_msg(obj.id, link, touch=touch))
        return js

    def clear(self) -> None:
        self.apply(self.attached, attached_msg("", op=CollisionObject.REMOVE))
        self.apply(self.objects, CollisionObject(id="", operation=CollisionObject.REMOVE))

    def close(self) -> None:
        self.proc.stop()
        self.ros.close()


@pytest.fixture(scope="module")
def node(ros_domain_id, tmp_path_factory):
    n = Node(ros_domain_id, tmp_path_factory.mktemp("place"))
    try:
        yield n
    finally:
        n.close()


@pytest.fixture(scope="module")
def lifted():
    """After a one-hand pick and a 10 cm lift (boxes6 seed 0): the start and the object where it is then."""
    r = armar3()
    sc = make_scenario(r, "boxes6", 0, hand="left")
    pick = GraspPlanner(r, workers=1).plan_grasp(sc.scene, GraspPlanRequest(
        LEFT, r.home.copy(), sc.object_pose, sc.grasps, object_id=OBJECT_ID, seed=1, timeout=10.0,
        approach=GripperTranslation(tuple(approach_axis(r, LEFT)), 0.10, 0.05),
        retreat=GripperTranslation((0.0, 0.0, 1.0), 0.10, 0.05, FRAME)))
    assert pick.ok, pick.message
    return _after_lift(sc, (LEFT,), pick)


def _after_lift(sc, groups, pick) -> tuple[np.ndarray, SceneObject]:
    """The configuration at the end of the pick's lift, and the object where the hand has taken it."""
    r = armar3()
    idx = np.concatenate([r.group_joint_indices(g) for g in groups])
    q_grasp, q_up = r.home.copy(), r.home.copy()
    q_grasp[idx], q_up[idx] = pick.trajectory.positions[-1], pick.retreat_trajectory.positions[-1]
    tip = r.group(groups[0]).tip_link
    T_lift = r.link_poses(q_up, [tip])[0] @ np.linalg.inv(r.link_poses(q_grasp, [tip])[0])
    return q_up, SceneObject(OBJECT_ID, T_lift @ sc.object_pose, sc.scene.get(OBJECT_ID).shapes)


def shelf() -> tuple[SceneObject, ...]:
    """A board (top at TOP) under a second one, and a jar where the last placement is."""
    return (box_object("board", (0.45, 0.30, TOP - 0.01), (0.30, 0.50, 0.02)),
            box_object("upper", (0.45, 0.30, TOP + 0.40), (0.30, 0.50, 0.02)),
            box_object("jar", (0.45, 0.50, TOP + 0.06), (0.08, 0.08, 0.12)))


PLACES = [at(0.45, y, TOP + 0.10) for y in (0.10, 0.20, 0.30, 0.40, 0.50)]  # the 20 cm box stands on the board


def object_poses(q_start: np.ndarray, group_names, positions, T_link_obj: np.ndarray, link: str) -> np.ndarray:
    robot = armar3()
    idx = [robot.joint_names.index(n) for n in group_names]
    q = np.repeat(q_start[None], len(positions), axis=0)
    q[:, idx] = positions
    return robot.link_poses(q, [link])[:, 0] @ T_link_obj


def test_place_on_a_shelf(node, lifted):
    r = armar3()
    q_up, obj = lifted
    tip, hands = r.group(LEFT).tip_link, r.hand_links(LEFT)
    start = node.hold(q_up, obj, tip, hands)
    try:
        node.apply(node.objects, *(scene_object_to_msg(o, FRAME) for o in shelf()))
        req = PlanPlace.Request(group=LEFT, start_state=start, object_id=OBJECT_ID, seed=1, timeout=10.0,
                                place_poses=[pose_stamped(P) for P in PLACES], pre_place_approach=DOWN5,
                                post_place_retreat=BACK)
        resp = node.call(node.place, req)
        assert resp.error_code.val == SUCCESS, resp.message
        assert resp.place_index in (0, 1, 2, 3)  # the jar stands on the last one
        assert resp.approach_distance == pytest.approx(0.05) and resp.retreat_distance >= 0.05
        names = list(r.group(LEFT).joint_names)
        assert list(resp.trajectory.joint_names) == names
        T_tip_obj = np.linalg.inv(r.link_poses(q_up, [tip])[0]) @ obj.pose
        _, pos, _, _ = trajectory_arrays(resp.trajectory)
        poses = object_poses(q_up, names, pos, T_tip_obj, tip)
        P = PLACES[resp.place_index]
        assert np.allclose(poses[-1], P, atol=1e-3)
        # the descent: every point within 5 cm above the placement is on the vertical through it
        low = poses[:, 2, 3] < P[2, 3] + 0.05 - 1e-3
        assert low.sum() >= 2 and np.abs(poses[low, :2, 3] - P[:2, 3]).max() < 2e-3
        # clear of everything but its support, which it never enters
        held = attach(obj, tip, r.link_poses(q_up, [tip])[0], hands)
        no_board = SceneSnapshot(resp.scene_version, FRAME, shelf()[1:], attached=(held,))
        assert verify_plan(r, no_board, (LEFT,), q_up, ResponsePlan(resp.trajectory), ()) == []
        assert (poses[:, 2, 3] - 0.10 > TOP - 1e-3).all()
        # the retreat: the hand alone, the object left standing at the placement
        _, back, _, _ = trajectory_arrays(resp.retreat_trajectory)
        assert np.allclose(back[0], pos[-1])
        released = SceneSnapshot(1, FRAME, shelf() + (SceneObject(OBJECT_ID, P, obj.shapes),))
        check = CollisionChecker(r, released, LEFT, q_up, CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=hands))
        assert check.check_configs(back).all()
        assert CollisionChecker(r, released, LEFT, q_up).check_configs(back[-1:]).all()  # it ends clear of it
        # planning did not detach it
        scene = node.call(node.scene_cli, GetPlanningScene.Request())
        assert [a.object.id for a in scene.attached_objects] == [OBJECT_ID]
        # the action plans the same request the same way
        handle = wait_for(node.place_action.send_goal_async(PlaceAction.Goal(
            **{f: getattr(req, f) for f in req.get_fields_and_field_types()})), 10.0)
        res = wait_for(handle.get_result_async(), 30.0)
        assert res.status == 4, res.result.message
        assert res.result.trajectory == resp.trajectory and res.result.place_index == resp.place_index
    finally:
        node.clear()


def test_two_hands_carry_a_box_across_the_table(node):
    r = armar3()
    sc = make_scenario(r, "empty", 0, hand="both")
    pick = GraspPlanner(r, workers=1).plan_dual_grasp(sc.scene, DualGraspPlanRequest(
        *DUAL, r.home.copy(), sc.object_pose, sc.left_grasps, sc.right_grasps, object_id=OBJECT_ID, seed=1,
        timeout=10.0, retreat=GripperTranslation((0.0, 0.0, 1.0), 0.10, 0.05, FRAME)))
    assert pick.ok, pick.message
    q_up, lifted = _after_lift(sc, DUAL, pick)
    idx = np.concatenate([r.group_joint_indices(g) for g in DUAL])
    obj = sc.scene.get(OBJECT_ID)
    tips = [r.group(g).tip_link for g in DUAL]
    start = node.hold(q_up, lifted, tips[0], r.hand_links(DUAL[0]) + r.hand_links(DUAL[1]))
    half_h = obj.shapes[0].dims[2] / 2
    top = sc.object_pose[2, 3] - half_h - 0.10
    x, y = sc.object_pose[0, 3], sc.object_pose[1, 3]
    places = [at(x, y + dy, top + half_h) for dy in (-0.15, -0.10)]  # to the right on the table
    for P in places:
        P[:3, :3] = sc.object_pose[:3, :3]
    try:
        node.apply(node.objects, scene_object_to_msg(box_object("table", (x + 0.1, y, top - 0.01), (0.3, 1.0, 0.02)),
                                                     FRAME))
        resp = node.call(node.dual, PlanDualPlace.Request(
            left_group=DUAL[0], right_group=DUAL[1], start_state=start, object_id=OBJECT_ID, timeout=10.0,
            place_poses=[pose_stamped(P) for P in places], pre_place_approach=DOWN5, post_place_retreat=BACK))
        assert resp.error_code.val == SUCCESS, resp.message
        names = [n for g in DUAL for n in r.group(g).joint_names]
        assert list(resp.trajectory.joint_names) == names
        _, pos, _, _ = trajectory_arrays(resp.trajectory)
        q = np.repeat(q_up[None], len(pos), axis=0)
        q[:, idx] = pos
        TL, TR = r.link_poses(q, tips)[:, 0], r.link_poses(q, tips)[:, 1]
        rel = np.linalg.inv(TL) @ TR
        d = np.linalg.inv(rel[0]) @ rel
        assert np.linalg.norm(d[:, :3, 3], axis=1).max() < 0.002
        turn = np.arccos(np.clip((np.trace(d[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1))
        assert np.degrees(turn).max() < 1.0
        T_tip_obj = np.linalg.inv(r.link_poses(q_up, [tips[0]])[0]) @ lifted.pose
        assert np.allclose(TL[-1] @ T_tip_obj, places[resp.place_index], atol=1e-3)
        assert len(resp.retreat_trajectory.points) >= 2
    finally:
        node.clear()


def cage(oid: str, P: np.ndarray) -> SceneObject:
    """Four walls and a lid around the 6 x 6 x 20 cm object standing at P."""
    parts = [((0.045, 0, 0.01), (0.01, 0.10, 0.22)), ((-0.045, 0, 0.01), (0.01, 0.10, 0.22)),
             ((0, 0.045, 0.01), (0.10, 0.01, 0.22)), ((0, -0.045, 0.01), (0.10, 0.01, 0.22)),
             ((0, 0, 0.125), (0.10, 0.10, 0.01))]
    return SceneObject(oid, at(*P[:3, 3]), tuple(Shape("box", at(*c), size) for c, size in parts))


def _cancelled(action, goal, feedback_needed: int = 2):
    feedback: list = []
    handle = wait_for(action.send_goal_async(goal, feedback_callback=lambda m: feedback.append(m.feedback)), 10.0)
    assert handle.accepted
    wait_until(lambda: sum(f.phase == "searching" and f.iterations > 0 for f in feedback) >= feedback_needed,
               timeout=15.0, what="feedback of a running search")
    t0 = time.monotonic()
    wait_for(handle.cancel_goal_async(), 5.0)
    res = wait_for(handle.get_result_async(), 10.0)
    return res, time.monotonic() - t0


def test_cancel_ends_preempted(node, lifted):
    r = armar3()
    q_up, obj = lifted
    tip, hands = r.group(LEFT).tip_link, r.hand_links(LEFT)
    start = node.hold(q_up, obj, tip, hands)
    try:
        # each placement in a cage 1.5 cm around the object: it fits, the hand does not; the search goes on
        node.apply(node.objects, *(scene_object_to_msg(o, FRAME) for o in (
            box_object("board", (0.45, 0.30, TOP - 0.01), (0.30, 0.50, 0.02)), cage("c1", PLACES[1]),
            cage("c2", PLACES[2]))))
        goal = PlaceAction.Goal(group=LEFT, start_state=start, object_id=OBJECT_ID, timeout=30.0, seed=1,
                                place_poses=[pose_stamped(P) for P in PLACES[1:3]])
        res, took = _cancelled(node.place_action, goal)
        assert res.result.error_code.val == ErrorCode.PREEMPTED and res.status == 5, res.result.message
        assert took < CANCEL_LIMIT, f"result {took:.3f} s after the cancel request"
        # two hands (the left hand's attachment, the right hand's links touching it) into the same slot:
        # the carry tries every placement and height in turn
        node.apply(node.attached, attached_msg(OBJECT_ID, tip, touch=hands + r.hand_links("right_arm")))
        many = [at(0.35 + 0.2 * (k % 7) / 7, 0.1 + 0.4 * (k // 7) / 300, TOP + 0.10) for k in range(2000)]
        goal = DualPlaceAction.Goal(left_group="left_arm", right_group="right_arm", start_state=start,
                                    object_id=OBJECT_ID, timeout=30.0, place_poses=[pose_stamped(P) for P in many])
        res, took = _cancelled(node.dual_action, goal)
        assert res.result.error_code.val == ErrorCode.PREEMPTED and res.status == 5, res.result.message
        assert took < CANCEL_LIMIT, f"result {took:.3f} s after the cancel request"
    finally:
        node.clear()


def test_hostile_requests_get_clear_codes(node, lifted):
    r = armar3()
    q_up, obj = lifted
    start = JointState(name=list(r.joint_names), position=q_up.tolist())
    nan = pose_stamped(PLACES[0])
    nan.pose.position.x = math.nan
    cases = [
        ({}, ErrorCode.INVALID_OBJECT_NAME, "is not attached to the robot"),
        ({"place_poses": [nan]}, ErrorCode.INVALID_GOAL_CONSTRAINTS, "place_poses[0]"),
        ({"place_poses": [pose_stamped(PLACES[0], frame="no_such_frame")]}, ErrorCode.FRAME_TRANSFORM_FAILURE,
         "place_poses[0].header.frame_id"),
        ({"place_poses": []}, ErrorCode.INVALID_GOAL_CONSTRAINTS, "place_poses is empty"),
    ]
    for fields, code, text in cases:
        req = PlanPlace.Request(group=LEFT, start_state=start, object_id=OBJECT_ID,
                                place_poses=[pose_stamped(P) for P in PLACES])
        for k, v in fields.items():
            setattr(req, k, v)
        resp = node.call(node.place, req)
        assert resp.error_code.val == code and text in resp.message, (fields, resp.error_code.val, resp.message)
    resp = node.call(node.dual, PlanDualPlace.Request(left_group="left_arm", right_group="right_arm", start_state=start,
                                                      object_id=OBJECT_ID, place_poses=[pose_stamped(PLACES[0])]))
    assert resp.error_code.val == ErrorCode.INVALID_OBJECT_NAME, resp.message
