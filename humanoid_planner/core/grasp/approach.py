"""The hand's approach axis: the direction, in the TCP frame, along which a hand closes in on a grasp."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import invert


def approach_axis(robot: RobotModel, group: str) -> np.ndarray:
    """Unit vector, in the TCP frame, along which the hand points: last joint → TCP; where they
    coincide (a TCP on the last joint's link: Fetch's wrist_roll_link, Panda's link7), TCP → the
    mean origin of the hand's other links (Fetch's gripper lies along x); z if there is none."""
    g = robot.group(group)
    wrist = robot.joints[g.joint_names[-1]].child
    P = robot.link_poses(robot.home, [wrist, g.tip_link])
    v = (invert(P[1]) @ np.append(P[0, :3, 3], 1.0))[:3]
    n = np.linalg.norm(v)
    if n > 1e-6:
        return -v / n
    hand = [link for link in robot.hand_links(group) if link != g.tip_link]
    if hand:
        H = robot.link_poses(robot.home, hand)
        m = ((H[:, :3, 3] - P[1, :3, 3]) @ P[1, :3, :3]).mean(0)
        if np.linalg.norm(m) > 1e-6:
            return m / np.linalg.norm(m)
    return np.array([0.0, 0.0, 1.0])
