"""pipeline.dual: a dual request's way to DAGRRT, answered without a search where the grasps cannot score."""
from __future__ import annotations

from dataclasses import replace

import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.scenarios import OBJECT_ID, make_scenario


@pytest.fixture(scope="module")
def setup():
    r = RobotModel.preset("dual_arm")
    return GraspPlanner(r, workers=1), make_scenario(r, "empty", 0, hand="both")


def test_grasps_without_enough_contacts_are_refused_before_any_search(setup):
    gp, sc = setup
    bare = [replace(g, contacts=()) for g in sc.left_grasps]
    req = DualGraspPlanRequest("left_arm", "right_arm", gp.robot.home.copy(), sc.object_pose, bare, sc.right_grasps,
                               OBJECT_ID, seed=0)
    plan = gp.plan_dual_grasp(sc.scene, req)
    assert plan.status is PlanStatus.GRASP_QUALITY_TOO_LOW and "left grasp" in plan.message
    assert plan.iterations == 0


def test_the_same_seed_gives_the_same_pair(setup):
    gp, sc = setup
    req = DualGraspPlanRequest("left_arm", "right_arm", gp.robot.home.copy(), sc.object_pose, sc.left_grasps,
                               sc.right_grasps, OBJECT_ID, timeout=20.0, seed=3)
    a, b = gp.plan_dual_grasp(sc.scene, req), gp.plan_dual_grasp(sc.scene, req)
    assert a.ok, a.message
    assert a.grasps == b.grasps and (a.path == b.path).all()
