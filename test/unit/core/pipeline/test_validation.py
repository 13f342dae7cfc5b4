"""Request checks (pipeline.validation), the one place a plan request is validated: each refusal's
status and the field its message names, the start's slack and clipping, hands, translations — and
GraspPlanner refusing through the same checks. On ARMAR-III."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.pipeline.validation import (START_LIMIT_SLACK, RequestRefused, check_dual_request, check_request_grasps,
                                                     check_grasp_request, check_start)
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.scene.types import GraspSpec
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

UP = (0.0, 0.0, 1.0)


@pytest.fixture(scope="module")
def scenario(armar3):
    return make_scenario(armar3, "empty", 1)


@pytest.fixture(scope="module")
def single(armar3, scenario) -> GraspPlanRequest:
    return GraspPlanRequest("left_arm", armar3.home.copy(), scenario.object_pose, scenario.left_grasps, OBJECT_ID)


def test_start_within_the_slack_is_clipped(armar3):
    q = armar3.home.copy()
    q[0], q[1] = armar3.upper[0] + 0.5 * START_LIMIT_SLACK, armar3.lower[1] - 0.5 * START_LIMIT_SLACK
    clipped = check_start(armar3, q)
    assert clipped[0] == armar3.upper[0] and clipped[1] == armar3.lower[1]
    np.testing.assert_array_equal(clipped[2:], q[2:])
    assert check_start(armar3, list(armar3.home)) is not None  # any sequence of numbers


@pytest.mark.parametrize("change,words", [
    (lambda q, r: np.append(q, 0.0), "finite joint values"),
    (lambda q, r: np.where(np.arange(len(q)) == 3, np.nan, q), "finite joint values"),
    (lambda q, r: np.where(np.arange(len(q)) == 2, r.upper + 2 * START_LIMIT_SLACK, q), "outside the joint limits"),
])
def test_start_outside_the_slack_or_malformed_is_refused(armar3, change, words):
    with pytest.raises(RequestRefused) as e:
        check_start(armar3, change(armar3.home.copy(), armar3))
    assert e.value.status is PlanStatus.INVALID_START and words in e.value.message
    if "limits" in e.value.message:
        assert armar3.joint_names[2] in e.value.message and "joint_states" not in e.value.message


def test_start_names_the_joints_that_came_from_joint_states(armar3):
    q = armar3.home.copy()
    q[2] = armar3.upper[2] + 0.1
    q[4] = armar3.lower[4] - 0.1
    with pytest.raises(RequestRefused) as e:
        check_start(armar3, q, given={armar3.joint_names[2]})
    m = e.value.message
    assert f"{armar3.joint_names[4]}=" in m and m.count("(from joint_states)") == 1
    assert m.index("(from joint_states)") > m.index(armar3.joint_names[4])


@pytest.mark.parametrize("change,status,words", [
    (dict(group="nope"), PlanStatus.INVALID_GROUP, "group: unknown planning group 'nope'"),
    (dict(group="left_hand_links"), PlanStatus.INVALID_GROUP, "no joints"),
    (dict(planner="prm"), PlanStatus.INVALID_REQUEST, "unknown planner 'prm'"),
    (dict(planner="dagrrt"), PlanStatus.INVALID_REQUEST, "unknown planner"),
    (dict(start=np.full(17, 9.0)), PlanStatus.INVALID_START, "outside the joint limits"),
    (dict(grasps=()), PlanStatus.INVALID_GOAL, "no grasps"),
    (dict(grasps=(GraspSpec("g", "right_arm", np.eye(4)),)), PlanStatus.INVALID_GOAL,
     "may be used by group 'left_arm'"),
    (dict(approach=GripperTranslation((0, 0, 0), 0.1)), PlanStatus.INVALID_GOAL, "pre_grasp_approach: direction"),
    (dict(retreat=GripperTranslation(UP, 0.1, 0.2)), PlanStatus.INVALID_GOAL, "post_grasp_retreat: min_distance"),
    (dict(retreat=GripperTranslation(UP, 0.1, frame="moon")), PlanStatus.INVALID_FRAME, "'moon' is neither"),
])
def test_single_arm_refusals(armar3, single, scenario, change, status, words):
    req = replace(single, **change)
    with pytest.raises(RequestRefused) as e:
        check_grasp_request(armar3, scenario.scene.frame, req)
    assert e.value.status is status and words in e.value.message
    plan = GraspPlanner(armar3).plan_grasp(scenario.scene, req)  # the planner refuses through the same checks
    assert plan.status is status and plan.message == e.value.message


def test_valid_requests_pass_with_the_clipped_start(armar3, single, scenario):
    q = armar3.home.copy()
    q[0] = armar3.upper[0] + 0.5 * START_LIMIT_SLACK
    start = check_grasp_request(armar3, scenario.scene.frame, replace(single, start=q))
    assert start[0] == armar3.upper[0]
    dual = DualGraspPlanRequest("left_arm", "right_arm", armar3.home.copy(), scenario.object_pose,
                                scenario.left_grasps, scenario.right_grasps, OBJECT_ID)
    np.testing.assert_array_equal(check_dual_request(armar3, scenario.scene.frame, dual), armar3.home)


@pytest.mark.parametrize("change,words", [
    (dict(left_group="left_arm_torso", right_group="right_arm_torso"), "share joint"),
    (dict(right_group="nope"), "right_group: unknown planning group"),
])
def test_dual_group_refusals(armar3, scenario, change, words):
    dual = replace(DualGraspPlanRequest("left_arm", "right_arm", armar3.home.copy(), scenario.object_pose,
                                        scenario.left_grasps, scenario.right_grasps, OBJECT_ID), **change)
    with pytest.raises(RequestRefused) as e:
        check_dual_request(armar3, scenario.scene.frame, dual)
    assert e.value.status is PlanStatus.INVALID_GROUP and words in e.value.message


def test_dual_grasps_are_checked_per_side(armar3, scenario):
    dual = DualGraspPlanRequest("left_arm", "right_arm", armar3.home.copy(), scenario.object_pose,
                                scenario.left_grasps, scenario.left_grasps, OBJECT_ID)
    with pytest.raises(RequestRefused) as e:
        check_dual_request(armar3, scenario.scene.frame, dual)
    assert e.value.status is PlanStatus.INVALID_GOAL and "group 'right_arm'" in e.value.message


def test_a_requests_own_grasps_are_checked_named_and_refused_as_an_invalid_goal():
    ok = check_request_grasps([GraspSpec("", "", np.eye(4)), GraspSpec("b", "", np.eye(4))], "grasps")
    assert [g.id for g in ok] == ["#0", "b"] and not ok[0].tcp_in_object.flags.writeable
    skewed = np.eye(4)
    skewed[0, 1] = 0.5
    for grasps, words in (([GraspSpec("a", "", skewed)], "grasps[0] ('a') tcp_in_object: not a rigid"),
                          ([GraspSpec("a", "", np.eye(4))] * 2, "grasp id 'a' appears more than once")):
        with pytest.raises(RequestRefused) as e:
            check_request_grasps(grasps, "grasps")
        assert e.value.status == PlanStatus.INVALID_GOAL and words in e.value.message
