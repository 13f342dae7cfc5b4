"""Seeded benchmark/test scenes (humanoid_planner.scenarios) on ARMAR-III: reproducible for a seed, the
object and its grasp sets present, the clutter clear of the home pose, bad arguments refused."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_distance
from humanoid_planner.scenarios import FAMILIES, MIN_FREE_GRASPS, OBJECT_ID, make_scenario, robot_frame


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


def placement(sc) -> list:
    """Every object's id, pose and shapes' poses and sizes, and every grasp's id and pose."""
    out = []
    for o in sc.scene.objects:
        out += [o.id, o.pose.tolist()] + [(s.kind, s.pose.tolist(), list(s.dims)) for s in o.shapes]
    return out + [(g.id, g.tcp_in_object.tolist()) for g in sc.grasps]


def same_scene(a, b) -> bool:
    return a.scene.version == b.scene.version and placement(a) == placement(b)


@pytest.mark.parametrize("family,hand", [(f, "left") for f in FAMILIES] + [("boxes6", "both"), ("table_shelf", "right")])
def test_scenes_hold_the_object_its_grasps_and_leave_home_free(armar3, family, hand):
    sc = make_scenario(armar3, family, 3, hand=hand)
    assert same_scene(sc, make_scenario(armar3, family, 3, hand=hand))  # a seed fixes the scene
    obj = sc.scene.get(OBJECT_ID)
    assert obj is not None and obj.shapes and np.array_equal(obj.pose, sc.object_pose)
    assert obj.grasps == sc.grasps and sc.scene.frame == armar3.root_link
    hands = {"left": ("left_arm",), "right": ("right_arm",), "both": ("left_arm", "right_arm")}[hand]
    for group, grasps in (("left_arm", sc.left_grasps), ("right_arm", sc.right_grasps)):
        if group in hands:
            assert len(grasps) >= MIN_FREE_GRASPS
            assert all(armar3.hand_usable_by(g.hand, group) for g in grasps)
            assert all(len(g.contacts) == len(g.normals) > 0 for g in grasps)
    if family != "empty":
        assert len(sc.scene.objects) > 1
    for group in ("left_arm_torso", "right_arm_torso"):  # clutter never touches the robot at home
        checker = CollisionChecker(armar3, sc.scene, group, armar3.home, grasp_object_id=OBJECT_ID,
                                   hand_links=armar3.hand_links(group))
        assert checker.exact_check(armar3.home[checker.joint_indices])


def test_seeds_differ_and_the_object_sits_where_the_hand_says(armar3):
    a, b = make_scenario(armar3, "boxes6", 1, hand="left"), make_scenario(armar3, "boxes6", 2, hand="left")
    assert not same_scene(a, b)
    fr = robot_frame(armar3)
    left, right = (make_scenario(armar3, "empty", 0, hand=h).object_pose[:3, 3] for h in ("left", "right"))
    both = make_scenario(armar3, "empty", 0, hand="both").object_pose[:3, 3]
    assert (left - fr.center) @ fr.left > 0 > (right - fr.center) @ fr.left
    assert abs((both - fr.center) @ fr.left) < 0.05  # centred between the shoulders
    for g in a.left_grasps:  # grasp targets lie within the arm's reach of the object
        dp, _ = pose_distance(a.object_pose @ g.tcp_in_object, a.object_pose)
        assert dp < 0.3


def test_bad_arguments_are_refused(armar3):
    with pytest.raises(ValueError, match="hand"):
        make_scenario(armar3, "empty", 0, hand="middle")
    with pytest.raises(ValueError, match="narrow"):
        make_scenario(armar3, "narrow", 0, hand="both")
