"""The checker's frame kinematics (collision.frame_kinematics): every link frame equals the generic
FK of RobotModel.link_poses, for one or several groups, on ARMAR-III and TALOS."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.frame_kinematics import FrameKinematics


@pytest.mark.parametrize("which,groups", [("armar3", ("right_arm_torso",)), ("armar3", ("left_arm", "right_arm")),
                                          ("talos", ("all_arms_torso",)), ("talos", ("r_leg", "head"))])
def test_frame_kinematics_matches_robot_model(which, groups, request):
    robot = request.getfixturevalue(which)
    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    rng = np.random.default_rng(1)
    q_ref = rng.uniform(robot.lower, robot.upper)
    fk = FrameKinematics(robot, idx, q_ref)
    Q = rng.uniform(robot.lower[idx], robot.upper[idx], (50, len(idx)))
    full = np.repeat(q_ref[None], 50, 0)
    full[:, idx] = Q
    P = robot.link_poses(full)
    R, t = fk(Q)
    for li, link in enumerate(robot.link_names):
        f, T = fk.anchors[link]
        if f == -2:
            continue
        if f < 0:
            want = np.broadcast_to(T, (50, 4, 4))
        else:
            F = np.tile(np.eye(4), (50, 1, 1))
            F[:, :3, :3], F[:, :3, 3] = R[:, f], t[:, f]
            want = F @ T
        assert np.allclose(P[:, li], want, atol=1e-12), link

