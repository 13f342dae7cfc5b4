"""Placing a held object (core/pipeline/place.py) on ARMAR-III: one hand onto a shelf (the object clear
of everything but its support, a straight descent, the retreat of the hand alone), two hands carrying a
box (relative pose kept), the support found under a placement, and the refusals."""
from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.pipeline.place import PlaceRequest, plan_place, supports
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlanStatus, Verdict
from humanoid_planner.core.postprocess.timing import TimedTrajectory
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach
from humanoid_planner.core.verification import verify_place, verify_plan
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

from .test_completion import free_postures

LEFT = "left_arm_torso"
DUAL = ("left_arm", "right_arm")
TOP = 1.0  # m: the shelf board's top
DOWN5 = GripperTranslation((0.0, 0.0, 0.0), 0.05, 0.05)  # zero direction: the default, planning frame -z
BACK = GripperTranslation((-1.0, 0.0, 0.0), 0.10, 0.05)  # TCP frame: ARMAR-III's hands point along their TCP's +x
SIDEWAYS = GripperTranslation((0.0, 0.0, 0.0), 0.08, 0.03)  # zero direction: the default, TCP -z (across the hand)


def box(oid: str, center, size) -> SceneObject:
    T = np.eye(4)
    T[:3, 3] = center
    return SceneObject(oid, T, (Shape("box", np.eye(4), tuple(float(s) for s in size)),))


def at(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


@pytest.fixture(scope="module")
def planner(armar3) -> GraspPlanner:
    return GraspPlanner(armar3, workers=1)


@pytest.fixture(scope="module")
def held(armar3, planner):
    """After a pick and a 10 cm lift (boxes6 seed 0): the lifted start and the object attached to the hand."""
    r = armar3
    sc = make_scenario(r, "boxes6", 0, hand="left")
    # the hand across the box's top (its 0° grasp): the sideways retreat test needs a hand that slides
    # along the box it let go of; which grasp of the set a search reaches first is not the fixture's business
    grasp = [g for g in sc.grasps if g.id == "left_arm_0_0"]
    pick = planner.plan_grasp(sc.scene, GraspPlanRequest(
        LEFT, r.home.copy(), sc.object_pose, grasp, object_id=OBJECT_ID, seed=1, timeout=10.0,
        approach=GripperTranslation(tuple(approach_axis(r, LEFT)), 0.10, 0.05),
        retreat=GripperTranslation((0.0, 0.0, 1.0), 0.10, 0.05, "base_link")))
    assert pick.ok, pick.message
    idx = r.group_joint_indices(LEFT)
    q_grasp, q_up = r.home.copy(), r.home.copy()
    q_grasp[idx], q_up[idx] = pick.trajectory.positions[-1], pick.retreat_trajectory.positions[-1]
    tip = r.group(LEFT).tip_link
    return q_up, attach(sc.scene.get(OBJECT_ID), tip, r.link_poses(q_grasp, [tip])[0], r.hand_links(LEFT))


def shelf() -> tuple[SceneObject, ...]:
    """A board (top at TOP) under a second one, and a jar where the last placement is."""
    return (box("board", (0.45, 0.30, TOP - 0.01), (0.30, 0.50, 0.02)),
            box("upper", (0.45, 0.30, TOP + 0.40), (0.30, 0.50, 0.02)),
            box("jar", (0.45, 0.50, TOP + 0.06), (0.08, 0.08, 0.12)))


PLACES = [at(0.45, y, TOP + 0.10) for y in (0.10, 0.20, 0.30, 0.40, 0.50)]  # the 20 cm box stands on the board


def test_supports_are_what_the_object_rests_on(held):
    _, att = held
    scene = SceneSnapshot(1, "base_link", shelf())
    assert supports(scene, att, PLACES[1]) == (frozenset({"board"}), ())
    assert supports(scene, att, PLACES[4]) == (frozenset({"board"}), ("jar",))
    sunk = PLACES[1].copy()
    sunk[2, 3] -= 0.02  # 2 cm into the board: a collision, not a support
    assert supports(scene, att, sunk) == (frozenset(), ("board",))
    assert supports(scene, att, at(0.45, 0.2, TOP + 0.2)) == (frozenset(), ())  # in the air


def test_place_on_a_shelf_one_hand(armar3, planner, held):
    r = armar3
    q_up, att = held
    assert np.allclose(approach_axis(r, LEFT), (1.0, 0.0, 0.0))  # BACK backs the hand out along its axis
    scene = SceneSnapshot(1, "base_link", shelf(), attached=(att,))
    plan = plan_place(planner, scene, PlaceRequest(LEFT, q_up, OBJECT_ID, PLACES, seed=1, timeout=10.0,
                                                   approach=DOWN5, retreat=BACK))
    assert plan.ok, plan.message
    assert plan.place_index in (0, 1, 2, 3)  # the jar stands on the last one
    assert plan.approach_distance == pytest.approx(0.05) and plan.retreat_distance >= 0.05
    # the search's validator (whose checker the set-down's derives from) does not leave plan_place
    assert plan.search_validator is None and pickle.loads(pickle.dumps(plan)).place_index == plan.place_index
    idx, tip = r.group_joint_indices(LEFT), r.group(LEFT).tip_link
    q = q_up.copy()
    q[idx] = plan.trajectory.positions[-1]
    T_obj = r.link_poses(q, [tip])[0] @ att.pose
    assert np.allclose(T_obj, PLACES[plan.place_index], atol=1e-3)
    # the last 5 cm: the object straight down
    q[idx] = plan.approach_path[0]
    assert np.allclose((r.link_poses(q, [tip])[0] @ att.pose)[:3, 3], T_obj[:3, 3] + (0, 0, 0.05), atol=1e-3)
    # clear of everything but its support: verified without the board, and never below the board's top
    no_board = SceneSnapshot(1, "base_link", shelf()[1:], attached=(att,))
    assert verify_plan(r, no_board, (LEFT,), q_up, plan, ()) == []
    for qi in plan.trajectory.positions:
        q[idx] = qi
        bottom = (r.link_poses(q, [tip])[0] @ att.pose)[2, 3] - 0.10
        assert bottom > TOP - 1e-3
    # the retreat: the hand alone, the object standing where it was placed: the hand may touch it while
    # it leaves it, then never again, and it ends clear of it (where the next plan starts)
    released = SceneSnapshot(1, "base_link", shelf() + (SceneObject(OBJECT_ID, PLACES[plan.place_index], att.shapes),))
    check = CollisionChecker(r, released, LEFT, q_up,
                             CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=r.hand_links(LEFT)))
    strict = CollisionChecker(r, released, LEFT, q_up)
    Q = plan.retreat_trajectory.positions
    assert np.allclose(Q[0], plan.trajectory.positions[-1])
    assert check.check_configs(Q).all()
    off = strict.check_configs(Q)
    assert not off[0] and off[-1] and off[np.argmax(off):].all(), off


def test_a_retreat_that_would_end_touching_the_released_object_is_refused(planner, held):
    """Sideways (the TCP's -z for ARMAR-III's hands) the hand slides along the object it let go of and
    ends still touching it (its collision model reaches into what it held): refused, not planned."""
    q_up, att = held
    scene = SceneSnapshot(1, "base_link", shelf(), attached=(att,))
    out = plan_place(planner, scene, PlaceRequest(LEFT, q_up, OBJECT_ID, PLACES[1:2], seed=1, timeout=10.0,
                                                  approach=DOWN5, retreat=SIDEWAYS))
    assert out.status is PlanStatus.PLANNING_FAILED
    assert "the hand still touches the released object" in out.message and "'target'" in out.message


def test_two_hands_carry_a_box_keeping_its_pose_between_them(armar3, planner):
    r = armar3
    sc = make_scenario(r, "empty", 0, hand="both")
    pick = planner.plan_dual_grasp(sc.scene, DualGraspPlanRequest(
        *DUAL, r.home.copy(), sc.object_pose, sc.left_grasps, sc.right_grasps, object_id=OBJECT_ID, seed=1,
        timeout=10.0, retreat=GripperTranslation((0.0, 0.0, 1.0), 0.10, 0.05, "base_link")))
    assert pick.ok, pick.message
    idx = np.concatenate([r.group_joint_indices(g) for g in DUAL])
    q_grasp, q_up = r.home.copy(), r.home.copy()
    q_grasp[idx], q_up[idx] = pick.trajectory.positions[-1], pick.retreat_trajectory.positions[-1]
    tips = [r.group(g).tip_link for g in DUAL]
    att = attach(sc.scene.get(OBJECT_ID), tips[0], r.link_poses(q_grasp, [tips[0]])[0],
                 r.hand_links(DUAL[0]) + r.hand_links(DUAL[1]))
    half_h = sc.scene.get(OBJECT_ID).shapes[0].dims[2] / 2
    top = sc.object_pose[2, 3] - half_h - 0.10  # a table 10 cm under where the box was
    x, y = sc.object_pose[0, 3], sc.object_pose[1, 3]
    table = box("table", (x + 0.1, y, top - 0.01), (0.3, 0.9, 0.02))
    places = [sc.object_pose @ at(0.0, dy, 0.0) for dy in (0.15, -0.15, 0.10, -0.10)]
    for P in places:
        P[2, 3] = top + half_h
    scene = SceneSnapshot(1, "base_link", (table,), attached=(att,))
    plan = plan_place(planner, scene, PlaceRequest(DUAL[0], q_up, OBJECT_ID, places, right_group=DUAL[1],
                                                   planner="parallel_lines", approach=DOWN5, retreat=BACK))
    assert plan.ok, plan.message
    rel0 = None
    for qi in plan.trajectory.positions:
        q = q_up.copy()
        q[idx] = qi
        TL, TR = r.link_poses(q, tips)
        rel = np.linalg.inv(TL) @ TR
        rel0 = rel if rel0 is None else rel0
        d = np.linalg.inv(rel0) @ rel
        assert np.linalg.norm(d[:3, 3]) < 0.002
        assert np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)) < np.radians(1.0)
    q[idx] = plan.trajectory.positions[-1]
    assert np.allclose(r.link_poses(q, [tips[0]])[0] @ att.pose, places[plan.place_index], atol=1e-3)
    no_table = SceneSnapshot(1, "base_link", (), attached=(att,))
    assert verify_plan(r, no_table, DUAL, q_up, plan, ()) == []
    # both hands leave the released box and end clear of it
    released = SceneSnapshot(1, "base_link", (table, SceneObject(OBJECT_ID, places[plan.place_index], att.shapes)))
    off = CollisionChecker(r, released, DUAL, q_up).check_configs(plan.retreat_trajectory.positions)
    assert plan.retreat_distance >= 0.05 and off[-1] and off[np.argmax(off):].all(), off
    # a placement that turns the object is refused by the two-handed carry, with the reason
    turned = places[0] @ np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    out = plan_place(planner, scene, PlaceRequest(DUAL[0], q_up, OBJECT_ID, [turned], right_group=DUAL[1],
                                                  planner="parallel_lines"))
    assert out.status is PlanStatus.PLANNING_FAILED and "turns the object by 90.0 deg" in out.message


def test_refusals(armar3, planner, held):
    q_up, att = held
    scene = SceneSnapshot(1, "base_link", shelf(), attached=(att,))

    def ask(**kw):
        fields = dict(group=LEFT, start=q_up, object_id=OBJECT_ID, placements=PLACES, seed=1, timeout=2.0)
        fields.update(kw)
        return plan_place(planner, fields.pop("scene", scene), PlaceRequest(**fields))

    cases = [
        (ask(scene=SceneSnapshot(1, "base_link", shelf())), PlanStatus.INVALID_OBJECT, "is not attached to the robot"),
        (ask(object_id=""), PlanStatus.INVALID_OBJECT, "object_id is empty"),
        (ask(group="right_arm"), PlanStatus.INVALID_OBJECT, "not in the hand of 'right_arm'"),
        (ask(placements=[]), PlanStatus.INVALID_GOAL, "place_poses is empty"),
        (ask(placements=[np.full((4, 4), np.nan)]), PlanStatus.INVALID_GOAL, "place_poses[0] is not a finite pose"),
        (ask(placements=[PLACES[4]]), PlanStatus.INVALID_GOAL, "place_poses[0]: 'target' with 'jar'"),
        (ask(planner="dagrrt"), PlanStatus.INVALID_REQUEST, "unknown planner"),
        (ask(right_group="right_arm", group="left_arm", planner="parallel_lines"), PlanStatus.INVALID_OBJECT,
         "held by the hand of 'left_arm' only"),
    ]
    for plan, status, text in cases:
        assert plan.status is status and text in plan.message, (status, text, plan.status, plan.message)


def test_verify_place_accepts_the_plan_and_catches_a_bent_descent(armar3, planner, held):
    """core.verification.verify_place, the bench's and the demo's check of a place plan: a plan passes;
    the same plan whose descent leaves its line, or whose object was lowered into the board, does not."""
    r = armar3
    q_up, att = held
    scene = SceneSnapshot(1, "base_link", shelf()[:2], attached=(att,))
    down = np.array([0.0, 0.0, -1.0])
    plan = plan_place(planner, scene, PlaceRequest(LEFT, q_up, OBJECT_ID, PLACES[:4], seed=1, timeout=10.0,
                                                   approach=DOWN5, retreat=BACK))
    assert plan.ok, plan.message
    P = PLACES[plan.place_index]
    assert verify_place(r, scene, LEFT, q_up, plan, OBJECT_ID, P, ("board",), down, approach_min=0.05 - 1e-3,
                        retreat_direction=BACK.direction, retreat_min=0.03, retreat_in_tcp=True) == []
    rt = plan.retreat_trajectory  # cut where the hand is still in the object it released
    cut = replace(plan, retreat_trajectory=TimedTrajectory(rt.times[:2], rt.positions[:2], rt.velocities[:2],
                                                          rt.accelerations[:2], rt.max_deviation, rt.method))
    assert any("retreat ends touching the released object" in p
               for p in verify_place(r, scene, LEFT, q_up, cut, OBJECT_ID, P, ("board",), down,
                                     retreat_direction=BACK.direction, retreat_in_tcp=True))
    assert any("descent" in p for p in verify_place(r, scene, LEFT, q_up, plan, OBJECT_ID, P, ("board",),
                                                    np.array([0.0, 1.0, -1.0]), approach_min=0.04))
    sunk = P.copy()
    sunk[2, 3] -= 0.02
    assert any("misses" in p for p in verify_place(r, scene, LEFT, q_up, plan, OBJECT_ID, sunk, ("board",), down))
    assert any("support" in p or "collision" in p
               for p in verify_place(r, scene, LEFT, q_up, plan, OBJECT_ID, P, (), down))


def _blocked_place_postures(armar3, planner, held):
    """PLACES[0] set up as plan_place searches it: (Completion with plan_place's finish hook, the
    pre-place target, the PlaceLines, the postures at the pre-place pose whose set-down or retreat is blocked)."""
    from humanoid_planner.core.pipeline.completion import Completion
    from humanoid_planner.core.pipeline.place import PlaceLines, object_in_tcp, raised, setup, touch_stretch
    from humanoid_planner.core.scene.types import GraspSpec

    r = armar3
    q_up, att = held
    scene = SceneSnapshot(1, "base_link", shelf()[:2], attached=(att,))
    req = PlaceRequest(LEFT, q_up, OBJECT_ID, PLACES[:1], seed=1, approach=DOWN5, retreat=BACK)
    s = setup(r, scene, req)
    touch, approach, searched = touch_stretch(s, planner.options.collision_padding)
    lines = PlaceLines(planner, s, LEFT, touch)
    T_obj_tcp = np.linalg.inv(object_in_tcp(r, att, LEFT, q_up))
    grasp = GraspSpec("place_poses[0]", "", raised(PLACES[0], s.approach, touch) @ T_obj_tcp)
    prob = planner.single.problem(searched, GraspPlanRequest(LEFT, q_up, np.eye(4), [grasp], seed=1, approach=approach))

    def completion() -> Completion:
        return Completion(prob, approach, None, finish=lambda q, k, motion: lines.blocked(q, 0, motion))

    probe = completion()
    pre = probe.pre_targets(list(prob.targets))[0]
    blocked = [qn for qn in free_postures(prob, pre, 64) if probe.accept_here(qn, pre).verdict is Verdict.REJECTED
               and probe.dropped[0].startswith(("the descent stops", "the retreat stops"))]
    return completion, pre, lines, prob, blocked


def test_a_placement_blocked_in_the_reached_posture_is_finished_in_another(armar3, planner, held):
    """The set-down and the retreat depend on the arm's posture (a joint limit on the way down, the
    elbow behind the hand): plan_place's finish hook makes GIRRT's accept try other postures of the
    placement before giving it up, as a pick's blocked lift does (it gave the placement up)."""
    completion, pre, lines, prob, blocked = _blocked_place_postures(armar3, planner, held)
    assert blocked, "no posture of PLACES[0] with a blocked set-down or retreat: the scene no longer tests this"
    done = completion()
    done.pre_targets([prob.targets[0]])
    assert done.accept(blocked[0], pre).ok, done.dropped
    c = done.lines[0]
    assert c.approach_distance >= DOWN5.min_distance - 0.02  # the searched descent: 5 cm less the set-down
    q_end = c.approach[-1] if len(c.approach) else c.settle[-1]
    assert lines.blocked(q_end, 0, prob.motion) is None
    assert prob.motion.check_edge(blocked[0], c.settle[-1])  # the reached posture joins the other one


def test_a_search_left_with_placements_out_of_reach_ends_early(armar3, planner, held):
    """The one reachable placement is blocked in every posture (the hand would slide along the
    released object) and the others are out of the arm's reach: the search ends once IK has given
    them up, naming both reasons, instead of spinning IK until its timeout."""
    q_up, att = held
    scene = SceneSnapshot(1, "base_link", shelf(), attached=(att,))
    far = [at(1.4, y, TOP + 0.10) for y in (0.1, 0.3)]  # in the air, 1 m beyond the shelf
    out = plan_place(planner, scene, PlaceRequest(LEFT, q_up, OBJECT_ID, PLACES[1:2] + far, seed=1, timeout=20.0,
                                                  approach=DOWN5, retreat=SIDEWAYS))
    assert out.status is PlanStatus.PLANNING_FAILED, out.message
    assert "the hand still touches the released object" in out.message
    assert "the 2 placement(s) left are out of the group's reach" in out.message
    assert out.planning_time < 10.0
