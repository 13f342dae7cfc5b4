"""Message <-> core conversions (ros.conversions): generated messages, no ROS graph."""
import math

import numpy as np
import pytest
from shape_msgs.msg import SolidPrimitive

from humanoid_planner.core.scene.planning_scene import Operation, PlanningScene, SceneUpdateError
from humanoid_planner.ros.conversions import (collision_object_to_update, moved_message, pose_to_matrix_checked,
                                              scene_object_to_msg)
from humanoid_planner_interfaces.msg import CollisionObject
from ros_messages import grasp, obj, pose, prim, tetra_mesh  # test/ros_messages.py



def test_roundtrip_message_scene_message():
    msg = obj("o", at=pose(0.1, 0.2, 0.3, (0.0, math.sin(0.4), 0.0, math.cos(0.4))),
              primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.2, 0.3), pose(0, 0, 0.1)),
                          (prim(SolidPrimitive.CONE, 0.2, 0.05), pose())],
              meshes=[(tetra_mesh(), pose(0.3, 0, 0))], grasps=[grasp("g1"), grasp("g2", hand="")])
    scene = PlanningScene("base_link")
    scene.apply(collision_object_to_update(msg, "base_link"))
    back = scene_object_to_msg(scene.snapshot().get("o"), "base_link")
    assert back.id == "o" and back.operation == CollisionObject.ADD and back.header.frame_id == "base_link"
    assert back.primitives == msg.primitives and back.meshes == msg.meshes and back.grasps == msg.grasps
    for a, b in zip([back.pose, *back.primitive_poses, *back.mesh_poses], [msg.pose, *msg.primitive_poses, *msg.mesh_poses]):
        np.testing.assert_allclose(pose_to_matrix_checked(a, "a"), pose_to_matrix_checked(b, "b"), atol=1e-12)


def test_a_moved_object_message_is_the_full_conversion_with_shared_shapes():
    from rclpy.serialization import serialize_message

    msg = obj("o", at=pose(0.1, 0.2, 0.3), primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.2, 0.3), pose(0, 0, 0.1))],
              meshes=[(tetra_mesh(), pose(0.3, 0, 0))], grasps=[grasp("g1")])
    scene = PlanningScene("base_link")
    scene.apply(collision_object_to_update(msg, "base_link"))
    before = scene_object_to_msg(scene.get("o"), "base_link")
    move = obj("o", at=pose(1.0, -2.0, 0.5, (0.0, math.sin(0.3), 0.0, math.cos(0.3))))
    move.operation = CollisionObject.MOVE
    scene.apply(collision_object_to_update(move, "base_link"))
    moved = moved_message(before, scene.get("o"))
    assert serialize_message(moved) == serialize_message(scene_object_to_msg(scene.get("o"), "base_link"))
    assert moved.primitives is before.primitives and before.pose.position.x == pytest.approx(0.1)


def test_a_names_only_message_is_the_full_one_without_shapes_and_grasps():
    """get_planning_scene's names-and-poses message (a copy of a template per frame) serializes as the
    full message with its shapes and grasps emptied, per object and frame; building more leaves the
    earlier ones as they were."""
    from rclpy.serialization import serialize_message

    scene = PlanningScene("base_link")
    for k, q in enumerate(((0.0, 0.0, 0.0, 1.0), (0.0, math.sin(0.3), 0.0, math.cos(0.3)), (1.0, 0.0, 0.0, 0.0))):
        scene.apply(collision_object_to_update(obj(f"o{k}", at=pose(0.1 * k, 0.2, 0.3, q), grasps=[grasp("g")],
                                                   primitives=[(prim(SolidPrimitive.SPHERE, 0.1), pose())]), "base_link"))
    named = [(o, frame, scene_object_to_msg(o, frame, geometry=False, grasps=False))
             for frame in ("base_link", "world") for o in scene.snapshot().objects]
    for o, frame, msg in named:
        full = scene_object_to_msg(o, frame)
        full.primitives, full.primitive_poses, full.grasps = [], [], []
        assert serialize_message(msg) == serialize_message(full)
        assert msg.header.frame_id == frame and msg.id == o.id


def test_remove_ignores_everything_but_the_id():
    msg = obj("o", op=CollisionObject.REMOVE, at=pose(q=(0, 0, 0, 0)), frame="elsewhere",
              primitives=[(prim(SolidPrimitive.BOX, -1, 1, 1), pose())])
    upd = collision_object_to_update(msg, "base_link")
    assert upd.operation == Operation.REMOVE and upd.id == "o" and upd.shapes == ()


@pytest.mark.parametrize("q", [(0, 0, 0, 0), (0, 0, 0, 1.01), (0, 0, 0, float("nan"))])
def test_bad_quaternions(q):
    with pytest.raises(SceneUpdateError, match="orientation"):
        pose_to_matrix_checked(pose(q=q), "p")


def test_small_quaternion_deviation_is_normalized():
    T = pose_to_matrix_checked(pose(q=(0, 0, 0, 0.9995)), "p")
    np.testing.assert_allclose(T, np.eye(4), atol=1e-12)


def test_a_primitive_of_the_same_bits_is_converted_once_and_others_are_not_taken_for_it():
    """Box messages of one size and pose give one Shape (read-only pose); a -0.0, another pose or an
    invalid dimension is converted (and refused) on its own."""
    from humanoid_planner.ros.collision_object_cdr import parse_collision_object
    from humanoid_planner.ros.conversions import raw_object_to_update
    from rclpy.serialization import serialize_message

    def shape(name, dims, at=None):
        raw = parse_collision_object(serialize_message(
            obj(name, primitives=[(prim(SolidPrimitive.BOX, *dims), at or pose(0.0, 0.0, 0.1))])))
        return raw_object_to_update(raw, "base_link").shapes[0]

    a, b = shape("a", (0.1, 0.2, 0.3)), shape("b", (0.1, 0.2, 0.3))
    assert a is b and not a.pose.flags.writeable
    negative_zero = shape("c", (0.1, 0.2, -0.0))
    assert negative_zero is not shape("d", (0.1, 0.2, 0.0)) and str(negative_zero.dims[2]) == "-0.0"
    assert shape("e", (0.1, 0.2, 0.3), pose(0.0, 0.0, 0.2)) is not a
    with pytest.raises(SceneUpdateError):
        shape("f", (0.1, 0.2, float("nan")))
