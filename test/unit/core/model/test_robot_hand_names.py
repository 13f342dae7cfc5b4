"""Grasps name their hand by SRDF end effector: the end effector wins over a link group of the same name.

MoveIt setups usually call a hand's link group and its end effector alike (Panda's `hand`; here
`left_hand` / `right_hand`). A grasp with `hand: left_hand` must be usable by `left_arm` (and
`left_arm_torso`, same TCP) and by no right-arm group, in single- and dual-arm plans.
"""
from __future__ import annotations

import dataclasses

import pytest

from humanoid_planner.core.model.presets import preset_paths
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import OBJECT_ID, make_scenario


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    """armar3 with MoveIt's naming: link groups `left_hand`/`right_hand` = end effector names."""
    urdf, srdf = preset_paths("armar3")
    text = srdf.read_text().replace("_hand_links", "_hand")
    assert '<group name="left_hand">' in text and '<end_effector name="left_hand"' in text
    return RobotModel.from_urdf_srdf(urdf, text)


def _named(grasps, hand: str):
    return tuple(dataclasses.replace(g, hand=hand) for g in grasps)


def test_end_effector_wins_over_its_link_group(robot):
    assert robot.groups["left_hand"].joint_names == ()  # the link group: no chain, no TCP
    for group in ("left_arm", "left_arm_torso"):
        assert robot.hand_usable_by("left_hand", group)
        assert not robot.hand_usable_by("right_hand", group)
    assert robot.hand_usable_by("right_hand", "right_arm")
    assert not robot.hand_usable_by("left_hand", "right_arm_torso")
    assert not robot.hand_usable_by("torso", "left_arm") and not robot.hand_usable_by("no_such_hand", "left_arm")


def test_single_arm_plan_with_end_effector_named_grasps(robot):
    sc = make_scenario(robot, "boxes6", 1, hand="left")
    req = GraspPlanRequest("left_arm", robot.home.copy(), sc.object_pose, _named(sc.left_grasps, "left_hand"),
                           OBJECT_ID, "girrt", 10.0, seed=2)
    plan = GraspPlanner(robot).plan_grasp(sc.scene, req)
    assert plan.ok, plan.message
    assert plan.grasps[0].hand == "left_hand"
    target = sc.object_pose @ plan.grasps[0].tcp_in_object
    assert verify_plan(robot, sc.scene, ("left_arm",), robot.home, plan, (target,), object_id=OBJECT_ID) == []


def test_dual_arm_plan_with_end_effector_named_grasps(robot):
    sc = make_scenario(robot, "empty", 1)
    # one grasp set holding both hands' grasps, as a scene object carries it: each arm takes its own
    both = _named(sc.left_grasps, "left_hand") + _named(sc.right_grasps, "right_hand")
    req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, both, both,
                               OBJECT_ID, timeout=10.0, seed=1)
    planner = GraspPlanner(robot, workers=1)
    plan = planner.plan_dual_grasp(sc.scene, req)
    assert plan.ok, plan.message
    assert [g.hand for g in plan.grasps] == ["left_hand", "right_hand"]
    targets = tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps)
    assert verify_plan(robot, sc.scene, ("left_arm", "right_arm"), robot.home, plan, targets,
                       object_id=OBJECT_ID) == []
