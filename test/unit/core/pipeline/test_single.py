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


def test_the_deadline_stops_the_search_between_two_batches_of_checks(setup, monkeypatch):
    """Slow checks (50 ms a batch; a cycle takes several): no batch starts after the plan's deadline,
    the answer is TIMED_OUT within about one batch of it, and the checker is left without a stop."""
    import time

    from humanoid_planner.core.collision.checker import CollisionChecker
    from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape

    gp = setup[0]
    r = gp.robot
    sc = make_scenario(r, "empty", 1)
    cage = SceneObject("cage", sc.object_pose, tuple(  # every grasp reachable by IK, none approachable
        Shape("box", np.array([[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]]), d)
        for (x, y, z), d in [((0.13, 0, 0), (0.02, 0.28, 0.3)), ((-0.13, 0, 0), (0.02, 0.28, 0.3)),
                             ((0, 0.13, 0), (0.28, 0.02, 0.3)), ((0, -0.13, 0), (0.28, 0.02, 0.3)),
                             ((0, 0, 0.15), (0.28, 0.28, 0.02))]))
    scene = SceneSnapshot(3, r.root_link, sc.scene.objects + (cage,))
    starts, checkers = [], []
    valid_all = CollisionChecker._valid_all

    def slow(self, q, w):
        starts.append(time.perf_counter())
        checkers.append(self)
        time.sleep(0.05)
        return valid_all(self, q, w)

    monkeypatch.setattr(CollisionChecker, "_valid_all", slow)
    timeout = 0.8
    t0 = time.perf_counter()
    plan = gp.plan_grasp(scene, GraspPlanRequest("left_arm", r.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID,
                                                 "girrt", timeout, seed=1))
    elapsed = time.perf_counter() - t0
    assert plan.status is PlanStatus.TIMED_OUT, plan.message
    assert len(starts) > 5 and max(starts) <= t0 + timeout + 0.01
    assert elapsed <= timeout + 0.05 + 0.1
    assert all(c.stop is None for c in checkers)
