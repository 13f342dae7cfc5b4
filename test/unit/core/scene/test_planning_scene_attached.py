"""Attached objects: MoveIt's attach/detach semantics in the scene, and held objects as robot bodies
in the collision checker (they move with their link; touch_links may touch them)."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.planning_scene import AttachUpdate, Operation, PlanningScene, SceneUpdate, SceneUpdateError
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach


def _T(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


BOX = (Shape("box", np.eye(4), (0.1, 0.1, 0.1)),)
LINKS = ("base", "hand", "finger")


def _attach(oid: str, link: str = "hand", shapes=(), pose=None, frame: str = "", touch=()) -> AttachUpdate:
    return AttachUpdate(link, SceneUpdate(Operation.ADD, oid, pose, tuple(shapes), frame=frame), tuple(touch))


def _detach(oid: str = "") -> AttachUpdate:
    return AttachUpdate("", SceneUpdate(Operation.REMOVE, oid))


def test_attach_existing_object_keeps_its_world_pose_and_detach_puts_it_where_the_link_is():
    scene = PlanningScene("base")
    scene.add("cup", _T(1.0, 0.0, 0.5), BOX)
    hand = {"hand": _T(0.9, 0.0, 0.5), "base": np.eye(4)}
    v = scene.apply_attach(_attach("cup", touch=["finger"]), hand.__getitem__, LINKS)
    snap = scene.snapshot()
    assert v == 2 and snap.version == 2 and snap.get("cup") is None
    (att,) = snap.attached
    assert att.link == "hand" and att.allowed_links == {"hand", "finger"}
    assert np.allclose(att.pose, _T(0.1, 0.0, 0.0))  # in the hand frame
    # the hand moves up 20 cm; detaching leaves the cup there, with its grasps and shapes
    hand["hand"] = _T(0.9, 0.0, 0.7)
    assert scene.apply_attach(_detach("cup"), hand.__getitem__, LINKS) == 3
    snap = scene.snapshot()
    assert not snap.attached and np.allclose(snap.get("cup").pose, _T(1.0, 0.0, 0.7))


def test_attach_new_shapes_in_link_frame_or_planning_frame_and_detach_all():
    scene = PlanningScene("base")
    link_pose = {"hand": _T(0.5, 0.0, 0.0), "base": np.eye(4)}.__getitem__
    scene.apply_attach(_attach("a", shapes=BOX, pose=_T(0, 0, 0.1)), link_pose, LINKS)
    scene.apply_attach(_attach("b", shapes=BOX, pose=_T(0.6, 0, 0), frame="base"), link_pose, LINKS)
    snap = scene.snapshot()
    assert np.allclose(snap.attached[0].pose, _T(0, 0, 0.1)) and np.allclose(snap.attached[1].pose, _T(0.1, 0, 0))
    scene.apply_attach(_detach(""), link_pose, LINKS)
    snap = scene.snapshot()
    assert not snap.attached and {o.id for o in snap.objects} == {"a", "b"}
    assert np.allclose(snap.get("a").pose, _T(0.5, 0, 0.1))


@pytest.mark.parametrize("update, words", [
    (_attach("ghost"), "no such object"),
    (_attach("cup", link="nose"), "not a link"),
    (_attach("hand", shapes=BOX), "name of a robot link"),
    (_attach("cup", touch=["tail"]), "touch_links"),
    (_attach("x", shapes=BOX, frame="moon"), "unknown frame"),
    (_detach("ghost"), "no such attached object"),
    (AttachUpdate("hand", SceneUpdate(Operation.MOVE, "cup", _T())), "not supported"),
])
def test_invalid_attach_updates_leave_the_scene_unchanged(update, words):
    scene = PlanningScene("base")
    scene.add("cup", _T(1.0, 0.0, 0.5), BOX)
    with pytest.raises(SceneUpdateError, match=words):
        scene.apply_attach(update, lambda link: np.eye(4), LINKS)
    assert scene.version == 1 and scene.get("cup") is not None and not scene.snapshot().attached


def test_collision_object_updates_refuse_an_attached_id():
    scene = PlanningScene("base")
    scene.add("cup", _T(1.0, 0.0, 0.5), BOX)
    scene.apply_attach(_attach("cup"), lambda link: np.eye(4), LINKS)
    with pytest.raises(SceneUpdateError, match="attached"):
        scene.add("cup", _T(), BOX)


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


def test_checker_carries_attached_objects_with_their_link(armar3):
    """A held box collides with an obstacle the bare arm clears, moves with its link, and may touch
    the hand's links (touch_links) but not other links."""
    r, group = armar3, "left_arm"
    tip = r.group(group).tip_link
    q = r.home[r.group_joint_indices(group)]
    T_tip = r.link_poses(r.home, [tip])[0]
    hand = r.hand_links(group)
    # a 4 cm box held 25 cm beyond the TCP along its approach axis, and a ball right there
    ahead = np.eye(4)
    ahead[:3, 3] = 0.25 * approach_axis(r, group)
    held = attach(SceneObject("cup", T_tip @ ahead, (Shape("box", np.eye(4), (0.04, 0.04, 0.04)),)), tip, T_tip, hand)
    ball = SceneObject("ball", np.eye(4), (Shape("sphere", T_tip @ ahead, (0.01,)),))
    bare = CollisionChecker(r, SceneSnapshot(1, r.root_link, (ball,)), group, r.home)
    holding = CollisionChecker(r, SceneSnapshot(1, r.root_link, (ball,), attached=(held,)), group, r.home)
    assert bare.check_config(q) and bare.exact_check(q)
    assert not holding.check_config(q) and not holding.exact_check(q)
    # the box rides on the link: turning the shoulder carries it off the ball
    q2 = q.copy()
    q2[0] += 0.5
    assert holding.check_config(q2) and holding.exact_check(q2)
    # a box around the TCP overlaps the hand: allowed for touch_links, a collision without them
    at_tcp = SceneObject("cup", T_tip, (Shape("box", np.eye(4), (0.12, 0.12, 0.12)),))
    others = [l for l in hand if l != tip and r.collision_geometry.get(l)]
    assert others, "the preset's hand has links besides the TCP link"
    touching = CollisionChecker(r, SceneSnapshot(1, r.root_link, (), attached=(attach(at_tcp, tip, T_tip, hand),)), group, r.home)
    strict = CollisionChecker(r, SceneSnapshot(1, r.root_link, (), attached=(attach(at_tcp, tip, T_tip),)), group, r.home)
    assert touching.check_config(q) and touching.exact_check(q) and not touching.fixed_collisions()
    # the hand's links ride on the same joint as the box: a constant overlap, reported as such
    assert any("cup" in pair for pair in strict.fixed_collisions())
    # a box reaching back to the forearm (another joint) collides there, touch_links or not
    big = SceneObject("cup", T_tip, (Shape("box", np.eye(4), (0.6, 0.6, 0.6)),))
    reaching = CollisionChecker(r, SceneSnapshot(1, r.root_link, (), attached=(attach(big, tip, T_tip, hand),)), group, r.home)
    assert not reaching.check_config(q) and not reaching.exact_check(q)
