"""One ARMAR-III problem shared by the planner tests: a seeded clutter scene (boxes6) with an object in
front of the left shoulder, set up the way the planning thread sets it up (ProblemBuilder)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.scenarios import OBJECT_ID, Scenario, make_scenario


@dataclass
class ArmProblem:
    robot: RobotModel
    planner: GraspPlanner
    scenario: Scenario
    group: str
    q0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    kin: GroupKinematics
    motion: MotionValidator
    targets: list[GraspTarget]

    @property
    def options(self) -> PlannerOptions:
        return self.planner.options


def arm_problem(robot: RobotModel, scenario: Scenario, group: str, grasps) -> ArmProblem:
    planner = GraspPlanner(robot)
    idx = robot.group_joint_indices(group)
    motion = planner.problems.motion(scenario.scene, group, robot.home, OBJECT_ID, robot.hand_links(group))
    return ArmProblem(robot, planner, scenario, group, robot.home[idx], robot.lower[idx], robot.upper[idx],
                      GroupKinematics(robot, group, robot.home), motion,
                      planner.targets(scenario.object_pose, grasps, group))


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def left_problem(armar3) -> ArmProblem:
    sc = make_scenario(armar3, "boxes6", 2, hand="left")
    return arm_problem(armar3, sc, "left_arm", sc.left_grasps)
