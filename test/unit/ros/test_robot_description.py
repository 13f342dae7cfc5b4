"""ros/robot_description.py's log of each planning group's TCP (no message field carries it)."""
from __future__ import annotations

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.ros.robot_description import tcp_lines

URDF = """<?xml version="1.0"?><robot name="two_arms"><link name="base"/>
  <link name="a1"/><link name="a2"/><link name="a_tool"/><link name="b1"/>
  <joint name="a_j1" type="revolute"><parent link="base"/><child link="a1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="a_j2" type="revolute"><parent link="a1"/><child link="a2"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="a_tool_joint" type="fixed"><parent link="a2"/><child link="a_tool"/><origin xyz="0 0 0.1"/></joint>
  <joint name="b_j1" type="revolute"><parent link="base"/><child link="b1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
</robot>"""
SRDF = """<?xml version="1.0"?><robot name="two_arms">
  <group name="arm"><joint name="a_j1"/><joint name="a_j2"/></group>
  <group name="hand"><link name="a_tool"/></group>
  <group name="both"><group name="arm"/><joint name="b_j1"/></group>
  <end_effector name="gripper" parent_link="a_tool" parent_group="arm" group="hand"/>
</robot>"""


def test_one_line_per_group_with_joints_names_its_tcp_and_the_rule():
    assert tcp_lines(RobotModel.from_urdf_srdf(URDF, SRDF)) == [
        "group 'arm' (2 joints): TCP link 'a_tool', from end effector 'gripper' (its parent_group)",
        "group 'both' (3 joints): no TCP: its joints lie on several branches",
    ]
