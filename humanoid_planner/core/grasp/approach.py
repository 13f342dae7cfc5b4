"""The hand's approach axis: the direction, in the TCP frame, along which a hand closes in on a grasp."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import invert


def approach_axis(robot: RobotModel, group: str) -> np.ndarray:
    """Unit vector, in the TCP frame, along which the hand points (last joint → TCP); z if they coincide."""
    g = robot.group(group)
    wrist = robot.joints[g.joint_names[-1]].child
    P = robot.link_poses(robot.home, [wrist, g.tip_link])
    v = (invert(P[1]) @ np.append(P[0, :3, 3], 1.0))[:3]
    n = np.linalg.norm(v)
    return -v / n if n > 1e-6 else np.array([0.0, 0.0, 1.0])
