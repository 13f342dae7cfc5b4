"""scene_intake.peek: the id and operation of serialized CollisionObjects, read without building them."""
from __future__ import annotations

from rclpy.serialization import serialize_message
from shape_msgs.msg import SolidPrimitive

from humanoid_planner.ros.scene_intake import peek
from humanoid_planner_interfaces.msg import CollisionObject


def test_peek_reads_id_and_operation_of_messages_without_shapes():
    for frame in ("", "base_link", "a_frame"):
        for oid in ("", "b", "box17", "ünïcode"):
            for op in (CollisionObject.ADD, CollisionObject.REMOVE, CollisionObject.APPEND, CollisionObject.MOVE):
                m = CollisionObject(id=oid, operation=op)
                m.header.frame_id = frame
                assert peek(serialize_message(m)) == (oid, op)


def test_peek_gives_no_operation_for_a_message_with_shapes_and_none_for_other_bytes():
    m = CollisionObject(id="box", operation=CollisionObject.MOVE)
    m.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.1, 0.1])]
    assert peek(serialize_message(m)) == ("box", None)
    data = serialize_message(CollisionObject(id="box", operation=CollisionObject.MOVE))
    assert peek(data[:-1]) is None  # truncated
    assert peek(data + b"\x01") is None  # not padding after the operation
    assert peek(b"\x01\x00" + data[2:]) is None  # not plain CDR
    assert peek(b"") is None
