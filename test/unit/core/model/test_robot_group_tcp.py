"""A planning group's TCP (the link a grasp is asked of) by MoveIt's end-effector rule, for every SRDF group
form: the parent_link of an end effector whose parent_group is the group (or, without parent_group, whose
parent_link is a link of the group), else the group's last link. RobotModel.group_tcp decides it once;
GroupKinematics, the hand rule and verification all read it from PlanningGroup.tip_link."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel


def _urdf() -> str:
    """base -> waist (j0) -> two arms, each l1..l4 (j1..j4), then fixed flange -> tool (8 cm past l4),
    and a fixed camera on l2 (a side branch)."""
    links = ['<link name="base"/>', '<link name="torso"/>']
    joints = ['<joint name="j0" type="revolute"><parent link="base"/><child link="torso"/><axis xyz="0 0 1"/>'
              '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>']
    for side, y in (("a", 0.2), ("b", -0.2)):
        parent = "torso"
        for i in range(1, 5):
            link = f"{side}{i}"
            origin = f"0 {y} 0.3" if i == 1 else "0 0 0.2"
            links.append(f'<link name="{link}"/>')
            joints.append(f'<joint name="{side}_j{i}" type="revolute"><parent link="{parent}"/><child link="{link}"/>'
                          f'<origin xyz="{origin}"/><axis xyz="{i % 2} {1 - i % 2} 0"/>'
                          '<limit lower="-2" upper="2" velocity="1" effort="1"/></joint>')
            parent = link
        for link, par, xyz in ((f"{side}_flange", f"{side}4", "0 0 0.05"), (f"{side}_tool", f"{side}_flange", "0 0 0.08"),
                               (f"{side}_camera", f"{side}2", "0.05 0 0")):
            links.append(f'<link name="{link}"/>')
            joints.append(f'<joint name="{link}_joint" type="fixed"><parent link="{par}"/><child link="{link}"/>'
                          f'<origin xyz="{xyz}"/></joint>')
    return f'<?xml version="1.0"?><robot name="tcp_rule">{"".join(links)}{"".join(joints)}</robot>'


URDF = _urdf()
JOINTS_A = "".join(f'<joint name="a_j{i}"/>' for i in range(1, 5))


def _robot(body: str) -> RobotModel:
    return RobotModel.from_urdf_srdf(URDF, f'<?xml version="1.0"?><robot name="tcp_rule">{body}</robot>')


@pytest.mark.parametrize("form,body,tcp", [
    ("chain", '<group name="arm"><chain base_link="torso" tip_link="a4"/></group>', "a4"),
    ("chain through fixed joints", '<group name="arm"><chain base_link="torso" tip_link="a_tool"/></group>', "a_tool"),
    ("joints", f'<group name="arm">{JOINTS_A}</group>', "a4"),
    ("joints listed backwards", '<group name="arm">' + "".join(f'<joint name="a_j{i}"/>' for i in (4, 3, 2, 1))
     + "</group>", "a4"),
    # a side branch listed last is not the last link: the deepest link below every joint is
    ("joints + links", f'<group name="arm">{JOINTS_A}<link name="a_flange"/><link name="a_camera"/></group>',
     "a_flange"),
    ("links", '<group name="arm">' + "".join(f'<link name="a{i}"/>' for i in range(1, 5)) + "</group>", "a4"),
])
def test_without_end_effector_the_tcp_is_the_groups_last_link(form, body, tcp):
    robot = _robot(body)
    g = robot.group("arm")
    assert g.tip_link == tcp, form
    assert set(g.joint_names) == {"a_j1", "a_j2", "a_j3", "a_j4"}  # a listed link brings its joint (MoveIt)
    assert g.tcp_source == "the group's last link"


@pytest.mark.parametrize("group", [
    '<chain base_link="torso" tip_link="a4"/>',
    JOINTS_A,
    JOINTS_A + "".join(f'<link name="a{i}"/>' for i in range(1, 5)),
    "".join(f'<link name="a{i}"/>' for i in range(1, 5)),
])
def test_end_effector_of_the_group_decides_the_tcp_for_every_form(group):
    """Baxter's case: the arm ends at the wrist joint, the gripper hangs 13 cm further on fixed joints;
    the end effector's parent_link is the TCP, and FK / Jacobian reach it."""
    robot = _robot(f'<group name="arm">{group}</group><group name="hand"><link name="a_tool"/></group>'
                   '<end_effector name="gripper" parent_link="a_tool" parent_group="arm" group="hand"/>')
    g = robot.group("arm")
    assert g.tip_link == "a_tool"
    assert g.tcp_source == "end effector 'gripper' (its parent_group)"
    kin = GroupKinematics(robot, "arm")
    q = np.array([0.3, -0.5, 0.7, 0.2])
    want = robot.link_poses(robot.expand("arm", q, robot.home), ["a_tool"])[0]
    assert np.allclose(kin.fk(q), want, atol=1e-12)
    # the Jacobian is the TCP's: a finite difference of its position
    J = kin.jacobian(q)
    eps = 1e-7
    for k in range(4):
        dq = np.zeros(4)
        dq[k] = eps
        assert np.allclose((kin.fk(q + dq)[:3, 3] - kin.fk(q)[:3, 3]) / eps, J[:3, k], atol=1e-6)
    assert robot.hand_usable_by("gripper", "arm")


def test_end_effector_without_parent_group_counts_where_its_link_is_a_group_link():
    body = (f'<group name="arm">{JOINTS_A}<link name="a_flange"/><link name="a_tool"/></group>'
            '<group name="short">' + JOINTS_A + "</group>"
            '<end_effector name="flange_hand" parent_link="a_flange" group="hand"/>')
    robot = _robot(body)
    # a_flange is a link of `arm`: the end effector wins over the deeper last link a_tool
    assert robot.group("arm").tip_link == "a_flange"
    assert robot.group("arm").tcp_source == "end effector 'flange_hand' (its parent_link is a group link)"
    # not a link of `short` (joints only: a1..a4): its last link stays the TCP
    assert robot.group("short").tip_link == "a4"


def test_end_effectors_of_other_groups_or_off_the_chain_are_ignored():
    body = (f'<group name="arm">{JOINTS_A}</group><group name="other">{JOINTS_A}</group>'
            '<end_effector name="elsewhere" parent_link="a_tool" parent_group="other" group="x"/>'
            # the other arm's tool is not below this group's joints: it cannot be this group's TCP
            '<end_effector name="wrong_arm" parent_link="b_tool" parent_group="arm" group="x"/>'
            '<end_effector name="no_such_link" parent_link="nowhere" parent_group="arm" group="x"/>')
    robot = _robot(body)
    assert robot.group("arm").tip_link == "a4"
    assert robot.group("other").tip_link == "a_tool"


def test_subgroups_keep_the_tcp_of_their_deepest_subgroup():
    body = ('<group name="torso"><joint name="j0"/></group>'
            f'<group name="arm">{JOINTS_A}</group>'
            '<group name="arm_torso"><group name="arm"/><group name="torso"/></group>'
            '<group name="both_arms"><group name="arm"/><chain base_link="torso" tip_link="b4"/></group>'
            '<end_effector name="gripper" parent_link="a_tool" parent_group="arm" group="hand"/>')
    robot = _robot(body)
    g = robot.group("arm_torso")
    assert g.tip_link == "a_tool" and g.base_link == "base"
    assert set(g.joint_names) == {"j0", "a_j1", "a_j2", "a_j3", "a_j4"}
    kin = GroupKinematics(robot, "arm_torso")
    q = np.linspace(-0.5, 0.5, kin.n)
    assert np.allclose(kin.fk(q), robot.link_poses(robot.expand("arm_torso", q, robot.home), ["a_tool"])[0])
    # joints on two branches: no link lies below all of them, so no TCP (and no kinematics)
    assert robot.group("both_arms").tip_link == ""
    with pytest.raises(ValueError, match="no tip link"):
        GroupKinematics(robot, "both_arms")
    # a request for it is refused with the reason, before any planning
    from humanoid_planner.core.pipeline.validation import RequestRefused, check_group
    from humanoid_planner.core.planners.common import PlanStatus

    with pytest.raises(RequestRefused, match="'both_arms' has no TCP: its joints lie on several branches") as e:
        check_group(robot, "both_arms")
    assert e.value.status == PlanStatus.INVALID_GROUP
    # a joint goal needs no TCP: plan_to_state takes the group as MoveIt does
    assert check_group(robot, "both_arms", tcp=False) == "both_arms"


def test_an_end_effector_attached_to_the_combined_group_decides_its_tcp():
    body = ('<group name="torso"><joint name="j0"/></group>'
            '<group name="arm"><chain base_link="torso" tip_link="a4"/></group>'
            '<group name="arm_torso"><group name="torso"/><group name="arm"/></group>'
            '<end_effector name="tool" parent_link="a_flange" parent_group="arm_torso" group="hand"/>')
    robot = _robot(body)
    assert robot.group("arm").tip_link == "a4"
    assert robot.group("arm_torso").tip_link == "a_flange"

