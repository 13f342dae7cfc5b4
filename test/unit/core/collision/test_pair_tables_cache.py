"""The pair-table cache (RobotCollisionModel.pair_tables) stays bounded on a live robot: its keys hold q_ref
values, which noisy joint_states change with every plan."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.collision.geometry import RobotCollisionModel
from humanoid_planner.core.model.robot import RobotModel


def test_noisy_joint_states_reuse_one_pair_selection():
    robot = RobotModel.preset("dual_arm")
    cache = RobotCollisionModel.for_robot(robot).pair_tables
    rng = np.random.default_rng(3)
    idx = robot.group_joint_indices("left_arm")
    Q = rng.uniform(robot.lower[idx], robot.upper[idx], (32, len(idx)))

    def selections() -> int:
        return sum(1 for k in cache if k[0] in ("selection", "env-selection"))

    before = selections()
    for _ in range(25):
        q_ref = np.clip(robot.home + rng.normal(0.0, 0.002, robot.dof), robot.lower, robot.upper)
        CollisionChecker(robot, None, "left_arm", q_ref).check_configs(Q)
    # one per rounding cell of q_ref the noise reaches (two where a joint sits on a cell border), not one per plan
    assert 1 <= selections() - before <= 2
