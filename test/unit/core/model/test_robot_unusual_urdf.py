"""URDF / SRDF features of robots nobody here modelled (the example-robot-data sweep, scripts/robot_sweep.py):
each loads as under ROS, or fails with an error that names the problem."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel, RobotModelError

URDF = """<?xml version="1.0"?>
<robot name="two_links">
  <link name="base"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="upper"/>
  <link name="hand"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <link name="wheel"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="hand"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="wheel_joint" type="revolute"><parent link="base"/><child link="wheel"/><axis xyz="0 0 1"/>
    {wheel_limit}</joint>
</robot>"""
WHEEL = '<limit effort="35" velocity="20.0"/>'  # Centauro's wheels: no lower / upper


def test_revolute_limit_without_bounds_stays_at_zero_as_in_urdfdom():
    robot = RobotModel.from_urdf_srdf(URDF.format(wheel_limit=WHEEL))
    i = robot.joint_names.index("wheel_joint")
    assert robot.lower[i] == robot.upper[i] == 0.0
    assert robot.max_velocity[i] == pytest.approx(20.0)


def test_revolute_without_limit_element_names_the_joint():
    with pytest.raises(RobotModelError, match="wheel_joint.*<limit>"):
        RobotModel.from_urdf_srdf(URDF.format(wheel_limit=""))


SRDF = """<?xml version="1.0"?>
<robot name="two_links">
  <group name="arm"><chain base_link="base" tip_link="hand"/></group>
  <group name="leg"><chain base_link="base" tip_link="foot"/></group>
  <group name="head"><joint name="head_pan"/></group>
  <group name="body"><group name="arm"/><group name="leg"/></group>
  <group name="wrong_way"><chain base_link="hand" tip_link="base"/></group>
  <group_state name="home" group="arm"><joint name="j2" value="0.5"/></group_state>
</robot>"""


def test_srdf_groups_naming_what_the_urdf_lacks_are_skipped_like_moveit():
    """An SRDF written for a fuller model (TALOS full vs reduced, iCub reduced, PR2, Baxter) still loads: the
    groups it cannot resolve are skipped, as srdfdom does, and asking for one says why."""
    robot = RobotModel.from_urdf_srdf(URDF.format(wheel_limit=WHEEL), SRDF)
    assert set(robot.groups) == {"arm"}
    assert robot.group("arm").joint_names == ("j1", "j2")
    assert robot.home[robot.joint_names.index("j2")] == pytest.approx(0.5)
    assert set(robot.skipped_groups) == {"leg", "head", "body", "wrong_way"}
    with pytest.raises(KeyError, match="'leg'.*unknown link foot"):
        robot.group("leg")
    with pytest.raises(KeyError, match="'head'.*unknown joint head_pan"):
        robot.group("head")
    with pytest.raises(KeyError, match="unknown planning group 'nothing'"):
        robot.group("nothing")
    assert np.all(robot.lower <= robot.upper)


def _single_arm_urdf(n: int = 6) -> str:
    """base -> n revolute links in a row -> hand (two fingers) + a tool0 frame; a 1-joint 'wheel' off the base."""
    links = ['<link name="base"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>',
             '<link name="wheel"/>', '<link name="tool0"/>']
    joints = ['<joint name="wheel_joint" type="continuous"><parent link="base"/><child link="wheel"/></joint>']
    parent = "base"
    for i in range(1, n + 1):
        links.append(f'<link name="l{i}"><collision><geometry><sphere radius="0.03"/></geometry></collision></link>')
        joints.append(f'<joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/>'
                      f'<origin xyz="0 0 0.1"/><axis xyz="{i % 2} {1 - i % 2} 0"/>'
                      '<limit lower="-2" upper="2" velocity="1" effort="1"/></joint>')
        parent = f"l{i}"
    for f in ("finger_a", "finger_b"):
        links.append(f'<link name="{f}"><collision><geometry><box size="0.01 0.01 0.04"/></geometry></collision></link>')
        joints.append(f'<joint name="{f}_joint" type="prismatic"><parent link="{parent}"/><child link="{f}"/>'
                      '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" velocity="0.1" effort="1"/></joint>')
    joints.append(f'<joint name="tool_joint" type="fixed"><parent link="{parent}"/><child link="tool0"/></joint>')
    # Baxter hangs a rigid "*_visual" link with geometry off its arm links: a branch, but not the hand
    links.append('<link name="l3_visual"><collision><geometry><sphere radius="0.03"/></geometry></collision></link>')
    joints.append('<joint name="l3_visual_joint" type="fixed"><parent link="l3"/><child link="l3_visual"/></joint>')
    return f'<?xml version="1.0"?><robot name="one_arm">{"".join(links)}{"".join(joints)}</robot>'


def test_planner_setup_gives_a_single_arm_robot_arm_and_hand(tmp_path):
    """UR, Kinova, xArm, Panda, TIAGo have one arm: no mirrored pair, so planner_setup used to refuse them;
    a rigid side branch with geometry (Baxter) used to end the arm there (3 joints: no arm found)."""
    from humanoid_planner.core.model.srdf_setup import generate_srdf

    urdf = tmp_path / "one_arm.urdf"
    urdf.write_text(_single_arm_urdf())
    res = generate_srdf(urdf, samples=0)
    robot = RobotModel.from_urdf_srdf(urdf, res.srdf)
    assert robot.group("arm").joint_names == tuple(f"j{i}" for i in range(1, 7))
    assert (robot.group("arm").base_link, robot.group("arm").tip_link) == ("base", "tool0")
    assert robot.end_effectors["hand"].parent_group == "arm"
    assert robot.hand_usable_by("hand", "arm")
    assert "left_arm" not in robot.groups


def test_a_request_for_a_skipped_group_is_refused_with_the_reason():
    from humanoid_planner.core.pipeline.validation import RequestRefused, check_group
    from humanoid_planner.core.planners.common import PlanStatus

    robot = RobotModel.from_urdf_srdf(URDF.format(wheel_limit=WHEEL), SRDF)
    assert check_group(robot, "arm") == "arm"
    with pytest.raises(RequestRefused, match="'leg' of the SRDF cannot be used: .*unknown link foot") as e:
        check_group(robot, "leg")
    assert e.value.status == PlanStatus.INVALID_GROUP


FOLDED = """<?xml version="1.0"?>
<robot name="folded">
  <link name="base"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="upper"><collision><origin xyz="0.25 0 0"/><geometry><sphere radius="0.03"/></geometry></collision></link>
  <link name="hand"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="hand"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
</robot>"""
"""The hand folded back onto the base (not adjacent: the upper link lies between them) at every configuration."""


@pytest.mark.parametrize("rules, touching", [
    ("", True),
    ('<disable_default_collisions link="hand"/>', False),
    ('<disable_default_collisions link="hand"/><enable_collisions link1="base" link2="hand"/>', True),
    ('<disable_default_collisions link="hand"/><enable_collisions link1="hand" link2="base"/>'
     '<disable_collisions link1="base" link2="hand"/>', False),
])
def test_srdf_default_collision_rules_as_moveit_reads_them(rules, touching):
    """MoveIt 2's `disable_default_collisions` (a link allowed to touch every other) and `enable_collisions`
    (an explicit pair over a link's default; `disable_collisions` over both), as the checker applies them."""
    from humanoid_planner.core.collision.checker import CollisionChecker

    srdf = f'<robot name="folded"><group name="arm"><chain base_link="base" tip_link="hand"/></group>{rules}</robot>'
    robot = RobotModel.from_urdf_srdf(FOLDED, srdf)
    assert (frozenset(("base", "hand")) not in robot.disabled_collision_pairs) is touching
    checker = CollisionChecker(robot, None, "arm")
    assert {frozenset(p) for p in checker.colliding_pairs(robot.home)} == ({frozenset(("base", "hand"))} if touching else set())
    assert checker.check_config(robot.home) is not touching


def test_srdf_group_state_values_that_are_not_finite_numbers_are_left_out_like_srdfdom():
    """A group_state value that does not parse or is not finite is left out (named in ignored_state_values, which
    the node logs); the rest of the SRDF loads and the home pose stays finite. A group without a name is ignored."""
    srdf = ('<robot name="folded"><group name="arm"><chain base_link="base" tip_link="hand"/></group><group/>'
            '<group_state name="home" group="arm"><joint name="j1" value="abc"/><joint name="j2" value="0.5"/></group_state>'
            '<group_state name="up" group="arm"><joint name="j1" value="nan"/><joint name="j2" value="inf"/></group_state>'
            '</robot>')
    robot = RobotModel.from_urdf_srdf(FOLDED, srdf)
    assert set(robot.groups) == {"arm"} and not robot.skipped_groups
    assert robot.group_states == {"home": {"j2": 0.5}, "up": {}}
    assert robot.ignored_state_values == ("home: j1='abc'", "up: j1='nan'", "up: j2='inf'")
    assert np.all(np.isfinite(robot.home)) and robot.home.tolist() == [0.0, 0.5]


@pytest.mark.parametrize("edit, message", [
    (('lower="-1"', 'lower="nan"'), "joint j2: limit lower=nan upper=1.0 must be finite"),
    (('upper="2"', 'upper="inf"'), "joint j1: limit lower=-2.0 upper=inf must be finite"),
    (('<origin xyz="0.3 0 0"/>', '<origin xyz="0.3 nan 0"/>'), "joint j2: its origin or axis is not finite"),
    (('<axis xyz="0 1 0"/>', '<axis xyz="0 1 inf"/>'), "joint j2: its origin or axis is not finite"),
    (('<box size="0.2 0.2 0.1"/>', '<box size="nan 0.2 0.1"/>'), r"link base: box size \(nan, 0.2, 0.1\) must be finite"),
    (('<sphere radius="0.05"/>', '<sphere radius="-0.05"/>'), r"link hand: sphere radius \(-0.05,\) must be finite and at least 0"),
    (('<collision><geometry><sphere radius="0.05"/>', '<collision><origin xyz="0 0 inf"/><geometry><sphere radius="0.05"/>'),
     "link hand: a collision origin is not finite"),
    (('<robot name="two_links">', '<robot>'), "invalid URDF: a required attribute is missing: 'name'"),
])
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # yourdfpy composing the inf origin
def test_urdf_numbers_that_cannot_be_planned_with_name_their_joint_or_link(edit, message):
    """NaN or infinite limits, origins, axes and shape sizes (and a negative radius) would load as garbage and
    plan with it: the robot is refused instead, naming the joint or link (the node logs it and exits 1)."""
    with pytest.raises(RobotModelError, match=message):
        RobotModel.from_urdf_srdf(URDF.format(wheel_limit=WHEEL).replace(*edit))
