"""Completing the grasp: straight approach onto it, retreat with the object in hand (issue 15).

Every plan here is checked by core.verification with the generic FK and exact FCL, independently
of the planners' compiled kinematics and checkers."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlanStatus, Verdict
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach
from humanoid_planner.core.verification import verify_plan, verify_retreat, verify_straight
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

GROUP = "left_arm_torso"
UP = (0.0, 0.0, 1.0)


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def planner(armar3) -> GraspPlanner:
    return GraspPlanner(armar3)


def _request(robot, sc, seed, approach=None, retreat=None, grasps=None, scene_object=True, **kw) -> GraspPlanRequest:
    return GraspPlanRequest(GROUP, robot.home.copy(), sc.object_pose, grasps or sc.left_grasps,
                            object_id=OBJECT_ID if scene_object else "", seed=seed, timeout=10.0,
                            approach=approach, retreat=retreat, **kw)


def free_postures(prob, pre, starts: int) -> np.ndarray:
    """Collision-free IK solutions of target `pre` from `starts` seeded random starts: postures a search
    may reach it in."""
    from humanoid_planner.core.ik.solver import solve_ik_batch

    q0 = np.random.default_rng(0).uniform(prob.lower, prob.upper, size=(starts, len(prob.lower)))
    q, ok, _ = solve_ik_batch(prob.kin, np.repeat(pre.T_target[None], starts, axis=0), q0, prob.lower, prob.upper)
    return q[ok][prob.motion.check_configs(q[ok])]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_girrt_approaches_along_the_hand_axis_and_lifts_the_object(armar3, planner, seed):
    r = armar3
    sc = make_scenario(r, "boxes6", seed, hand="left")
    ax = approach_axis(r, GROUP)
    req = _request(r, sc, seed + 1, GripperTranslation(tuple(ax), 0.10, 0.05), GripperTranslation(UP, 0.10, 0.05))
    plan = planner.plan_grasp(sc.scene, req)
    assert plan.ok, plan.message
    (g,) = plan.grasps
    T_grasp = sc.object_pose @ g.tcp_in_object
    # the whole trajectory: starts at the start, limits, ends on the grasp, collision-free with the
    # object allowed to touch the hand only
    assert verify_plan(r, sc.scene, (GROUP,), r.home, plan, (T_grasp,), object_id=OBJECT_ID) == []
    # the approach: the trajectory's last part, straight along the hand axis onto the grasp
    assert 0.05 - 1e-9 <= plan.approach_distance <= 0.10 + 1e-9
    approach = plan.trajectory.positions[plan.trajectory.times >= plan.approach_time - 1e-12]
    assert verify_straight(r, (GROUP,), r.home, approach, T_grasp[:3, :3] @ ax,
                           min_distance=plan.approach_distance - 0.002) == []
    assert np.allclose(plan.approach_path[-1], plan.trajectory.positions[-1])
    # the retreat: straight up with the box in the hand, collision-free
    assert plan.retreat_distance >= 0.05 - 1e-9
    assert verify_retreat(r, sc.scene, (GROUP,), r.home, plan, UP, object_id=OBJECT_ID,
                          min_distance=plan.retreat_distance - 0.002) == []


def test_blocked_approach_at_every_grasp_fails_with_a_reason(armar3, planner):
    """A small ball on every approach line, 2 cm before the grasp: no grasp can be approached straight."""
    r = armar3
    sc = make_scenario(r, "empty", 0, hand="left")
    ax = approach_axis(r, GROUP)
    balls = []
    for k, g in enumerate(sc.left_grasps):
        T = sc.object_pose @ g.tcp_in_object
        T[:3, 3] -= 0.02 * (T[:3, :3] @ ax)  # the fingers reach 6 cm past the TCP: clear of it at 10 cm
        balls.append(SceneObject(f"ball{k}", T, (Shape("sphere", np.eye(4), (0.005,)),)))
    scene = SceneSnapshot(2, sc.scene.frame, sc.scene.objects + tuple(balls))
    req = _request(r, sc, 3, GripperTranslation(tuple(ax), 0.10, 0.10))
    plan = planner.plan_grasp(scene, req)
    assert plan.status is PlanStatus.PLANNING_FAILED
    assert "approach" in plan.message and "every grasp" in plan.message


def test_invalid_translations_are_refused(armar3, planner):
    sc = make_scenario(armar3, "empty", 0, hand="left")
    for gt, words, status in ((GripperTranslation((0, 0, 0), 0.1), "direction", PlanStatus.INVALID_GOAL),
                              (GripperTranslation(UP, 0.1, 0.2), "min_distance", PlanStatus.INVALID_GOAL),
                              (GripperTranslation(UP, -0.1), ">= 0", PlanStatus.INVALID_GOAL),
                              (GripperTranslation(UP, 0.1, frame="moon"), "'moon' is neither", PlanStatus.INVALID_FRAME)):
        plan = planner.plan_grasp(sc.scene, _request(armar3, sc, 1, retreat=gt))
        assert plan.status is status and words in plan.message and "post_grasp_retreat" in plan.message


def test_a_held_object_changes_later_plans(armar3, planner):
    """With a plate held in the left hand, plans keep the plate clear of the clutter; the same plan
    made without knowing about the plate would hit something with it."""
    r = armar3
    tip = r.group(GROUP).tip_link
    T_tip = r.link_poses(r.home, [tip])[0]
    plate = SceneObject("plate", T_tip, (Shape("box", np.eye(4), (0.30, 0.30, 0.01)),))
    held = attach(plate, tip, T_tip, r.hand_links(GROUP))
    hits = 0
    for seed in range(4):
        sc = make_scenario(r, "boxes6", seed, hand="left")
        holding = SceneSnapshot(3, sc.scene.frame, sc.scene.objects, attached=(held,))
        bare_plan = planner.plan_grasp(sc.scene, _request(r, sc, seed + 1))
        assert bare_plan.ok
        T_grasp = sc.object_pose @ bare_plan.grasps[0].tcp_in_object
        if not verify_plan(r, holding, (GROUP,), r.home, bare_plan, (T_grasp,), object_id=OBJECT_ID):
            continue
        hits += 1
        plan = planner.plan_grasp(holding, _request(r, sc, seed + 1))
        if plan.ok:  # (a plate this size may leave no way to the grasps at all)
            T_grasp = sc.object_pose @ plan.grasps[0].tcp_in_object
            assert verify_plan(r, holding, (GROUP,), r.home, plan, (T_grasp,), object_id=OBJECT_ID) == []
        else:
            assert plan.status in (PlanStatus.PLANNING_FAILED, PlanStatus.TIMED_OUT, PlanStatus.START_IN_COLLISION)
    assert hits >= 1, "no seed where the plate would have hit something: the test proves nothing"


@pytest.mark.parametrize("parallel", ["thread", "process"])
def test_dagrrt_lifts_the_box_with_both_hands(parallel):
    """Both arm searches drop grasps whose approach fails (in the planning thread and in the arm
    process); the pair approaches together and lifts the box by the same displacement."""
    r = RobotModel.preset("dual_arm")
    gp = GraspPlanner(r, parallel=parallel)
    sc = make_scenario(r, "empty", 0, hand="both")
    ax = approach_axis(r, "left_arm")
    assert np.allclose(ax, approach_axis(r, "right_arm"))
    req = DualGraspPlanRequest("left_arm", "right_arm", r.home.copy(), sc.object_pose, sc.left_grasps, sc.right_grasps,
                               object_id=OBJECT_ID, seed=1, timeout=20.0,
                               approach=GripperTranslation(tuple(ax), 0.05, 0.05),
                               retreat=GripperTranslation(UP, 0.10, 0.05))
    try:
        plan = gp.plan_dual_grasp(sc.scene, req)
    finally:
        gp.close()
    assert plan.ok, plan.message
    gl, gr = plan.grasps
    targets = (sc.object_pose @ gl.tcp_in_object, sc.object_pose @ gr.tcp_in_object)
    groups = ("left_arm", "right_arm")
    assert verify_plan(r, sc.scene, groups, r.home, plan, targets, object_id=OBJECT_ID) == []
    assert plan.approach_distance == pytest.approx(0.05)
    assert plan.retreat_distance >= 0.05 - 1e-9
    # both TCPs up by the same displacement at every instant (relative pose within 2 mm / 1°)
    assert verify_retreat(r, sc.scene, groups, r.home, plan, UP, object_id=OBJECT_ID,
                          min_distance=plan.retreat_distance - 0.002) == []


def _pick_request(r, sc, seed, timeout=5.0) -> GraspPlanRequest:
    """The benchmark's girrt_pick request: 10 cm approach along the hand axis, 10 cm lift, 5 cm minimum each."""
    return GraspPlanRequest(GROUP, r.home.copy(), sc.object_pose, sc.grasps, OBJECT_ID, "girrt", timeout, seed=seed,
                            approach=GripperTranslation(tuple(approach_axis(r, GROUP)), 0.10, 0.05),
                            retreat=GripperTranslation(UP, 0.10, 0.05))


def test_a_blocked_lift_of_the_reached_posture_is_completed_by_another_posture(armar3, planner):
    """boxes6 seed 18: a box over the forearm blocks the lift of the posture the search reaches grasp 0
    with (2.5 cm), not of every posture of that grasp. accept must not give the grasp up (it did)."""
    from humanoid_planner.core.pipeline.completion import Completion

    r = armar3
    sc = make_scenario(r, "boxes6", 18, hand="left")
    req = _pick_request(r, sc, 18)
    prob = planner.single.problem(sc.scene, req)

    def completion() -> Completion:
        return Completion(prob, req.approach, req.retreat)

    probe = completion()
    pre = probe.pre_targets(list(prob.targets))[0]
    blocked = [qn for qn in free_postures(prob, pre, 24) if probe.accept_here(qn, pre).verdict is Verdict.REJECTED
               and "retreat" in probe.dropped[pre.index]]
    assert blocked, "no reached posture of grasp 0 with a blocked lift: the scene no longer tests this"
    done = completion()
    done.pre_targets(list(prob.targets))
    assert done.accept(blocked[0], pre).ok, done.dropped
    c = done.lines[pre.index]
    assert c.retreat_distance >= 0.05 - 1e-9 and c.approach_distance >= 0.05 - 1e-9
    assert prob.motion.check_edge(blocked[0], c.settle[-1])  # the reached posture joins the other one


def test_girrt_pick_finds_the_posture_whose_lift_is_clear(armar3, planner):
    """The same problem planned: every grasp the search reaches first has a blocked lift in the
    posture it is reached with; before, the search gave each up and timed out."""
    r = armar3
    sc = make_scenario(r, "boxes6", 18, hand="left")
    plan = planner.plan_grasp(sc.scene, _pick_request(r, sc, 18))
    assert plan.ok, plan.message
    (g,) = plan.grasps
    T_grasp = sc.object_pose @ g.tcp_in_object
    assert verify_plan(r, sc.scene, (GROUP,), r.home, plan, (T_grasp,), object_id=OBJECT_ID) == []
    # the other posture's approach (its backward line, reversed) is straight along the hand axis too
    assert plan.approach_distance >= 0.05 - 1e-9
    approach = plan.trajectory.positions[plan.trajectory.times >= plan.approach_time - 1e-12]
    assert verify_straight(r, (GROUP,), r.home, approach, T_grasp[:3, :3] @ approach_axis(r, GROUP),
                           min_distance=plan.approach_distance - 0.002) == []
    assert plan.retreat_distance >= 0.05 - 1e-9
    assert verify_retreat(r, sc.scene, (GROUP,), r.home, plan, UP, object_id=OBJECT_ID,
                          min_distance=plan.retreat_distance - 0.002) == []
