"""One ARMAR-III problem shared by the planner tests: a seeded clutter scene (boxes6) with an object in
front of the left shoulder, set up the way the planning thread sets it up (ProblemBuilder.arm)."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.scenarios import OBJECT_ID, Scenario, make_scenario


def arm_problem(planner: GraspPlanner, scenario: Scenario, group: str, grasps, seed: int = 0) -> ArmProblem:
    """The arm's problem at home: its grasp targets, a stream seeded with `seed`."""
    robot = planner.robot
    targets = planner.targets(scenario.object_pose, grasps, group)
    return planner.problems.arm(scenario.scene, group, robot.home, targets, np.random.default_rng(seed),
                                object_id=OBJECT_ID)


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def armar3_planner(armar3) -> GraspPlanner:
    return GraspPlanner(armar3)


@pytest.fixture(scope="module")
def left_problem(armar3_planner) -> ArmProblem:
    sc = make_scenario(armar3_planner.robot, "boxes6", 2, hand="left")
    return arm_problem(armar3_planner, sc, "left_arm", sc.left_grasps)
