"""pipeline.single: the single-arm problem as the planning thread and the OMPL peer set it up, and the
"IK first" goal configurations the baselines plan to."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.pipeline.single import closest_target
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.scenarios import OBJECT_ID, make_scenario


@pytest.fixture(scope="module")
def setup():
    r = RobotModel.preset("armar3")
    sc = make_scenario(r, "boxes6", 2, hand="left")
    return GraspPlanner(r), sc


def test_the_problem_is_seeded_by_the_request_and_refusals_come_back_as_plans(setup):
    gp, sc = setup
    r = gp.robot
    req = GraspPlanRequest("left_arm", r.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, seed=4)
    a, b = gp.single.problem(sc.scene, req), gp.single.problem(sc.scene, req)
    assert a.options.seed == 4 and a.rng.random() == b.rng.random()
    assert [t.index for t in a.targets] == [t.index for t in gp.targets(sc.object_pose, sc.left_grasps, "left_arm")]
    refused = gp.single.problem(sc.scene, GraspPlanRequest("no_group", r.home.copy(), sc.object_pose, sc.left_grasps))
    assert refused.status is PlanStatus.INVALID_GROUP


def test_goal_configurations_are_free_distinct_and_hold_a_grasp(setup):
    gp, sc = setup
    r = gp.robot
    p = gp.single.problem(sc.scene, GraspPlanRequest("left_arm", r.home.copy(), sc.object_pose, sc.left_grasps,
                                                     OBJECT_ID, seed=0))
    goals, failed = gp.single.goal_configs(p)
    assert failed is None and 1 < len(goals) <= gp.options.max_goal_configs
    assert np.all(p.motion.check_configs(goals))
    assert len(np.unique(np.round(goals, 3), axis=0)) == len(goals)
    t = closest_target(p.kin.fk(goals[0]), p.targets)
    assert np.linalg.norm(p.kin.fk(goals[0])[:3, 3] - t.T_target[:3, 3]) <= gp.options.goal_tolerance_pos
