"""The hand's approach axis (grasp.approach): from the last joint toward the TCP, in the TCP frame."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.model.robot import RobotModel


def test_small_arm_approaches_along_its_tcp_offset(test_robot_description):
    robot = RobotModel.from_urdf_srdf(*test_robot_description)  # TCP 6 cm beyond the hand along z
    np.testing.assert_allclose(approach_axis(robot, "arm"), [0.0, 0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("group", ["left_arm", "right_arm", "left_arm_torso"])
def test_armar3_axis_points_from_the_wrist_through_the_tcp(group):
    robot = RobotModel.preset("armar3")
    a = approach_axis(robot, group)
    assert np.linalg.norm(a) == pytest.approx(1.0)
    g = robot.group(group)
    wrist = robot.joints[g.joint_names[-1]].child
    W, T = robot.link_poses(robot.home, [wrist, g.tip_link])
    forward = T[:3, 3] - W[:3, 3]
    np.testing.assert_allclose(T[:3, :3] @ a, forward / np.linalg.norm(forward), atol=1e-9)


def test_tcp_at_the_wrist_defaults_to_z():
    urdf = """<?xml version="1.0"?><robot name="r">
      <link name="base"/><link name="hand"/><link name="tcp"/>
      <joint name="j" type="revolute"><parent link="base"/><child link="hand"/><origin xyz="0 0 0.1"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
      <joint name="f" type="fixed"><parent link="hand"/><child link="tcp"/><origin rpy="0 1 0"/></joint>
    </robot>"""
    srdf = """<?xml version="1.0"?><robot name="r"><group name="g"><chain base_link="base" tip_link="tcp"/></group></robot>"""
    robot = RobotModel.from_urdf_srdf(urdf, srdf)
    np.testing.assert_array_equal(approach_axis(robot, "g"), [0.0, 0.0, 1.0])
