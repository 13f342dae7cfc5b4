"""The raw collision_object reader (ros/collision_object_cdr.py) against rclpy's own deserialization.

Random messages (hypothesis, seeded by the test's name: the same run every time) are serialized with
rclpy and read back both ways: the plain numbers must be identical, bit for bit (NaN where NaN).
Cut or damaged bytes must give a SceneUpdateError, never another exception.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import Point, Point32, Polygon, Pose, Vector3
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner.core.scene.planning_scene import SceneLimits, SceneUpdateError
from humanoid_planner.ros.collision_object_cdr import parse_collision_object
from humanoid_planner.ros.conversions import raw_object_from_msg
from humanoid_planner_interfaces.msg import CollisionObject, Grasp

FLOATS = st.one_of(st.floats(-2.0, 2.0), st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, 1e200, 5e-324]))
TEXT = st.text(max_size=6)


@st.composite
def poses(draw) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = (draw(FLOATS) for _ in range(3))
    o = p.orientation
    o.x, o.y, o.z, o.w = (draw(FLOATS) for _ in range(4))
    return p


@st.composite
def primitives(draw) -> SolidPrimitive:
    n = draw(st.integers(0, 3))
    return SolidPrimitive(type=draw(st.integers(0, 6)), dimensions=[draw(FLOATS) for _ in range(n)],
                          polygon=Polygon(points=[Point32(x=1.0, y=2.0, z=3.0)] * draw(st.integers(0, 2))))


@st.composite
def meshes(draw) -> Mesh:
    nv, nt = draw(st.integers(0, 5)), draw(st.integers(0, 5))
    return Mesh(vertices=[Point(x=draw(FLOATS), y=1.0, z=2.0) for _ in range(nv)],
                triangles=[MeshTriangle(vertex_indices=[draw(st.integers(0, 2**32 - 1)), 1, 2]) for _ in range(nt)])


@st.composite
def grasps(draw) -> Grasp:
    nc, nn = draw(st.integers(0, 3)), draw(st.integers(0, 3))
    return Grasp(id=draw(TEXT), hand=draw(TEXT), tcp_in_object=draw(poses()),
                 contacts=[Point(x=draw(FLOATS), y=0.5, z=0.0) for _ in range(nc)],
                 normals=[Vector3(x=draw(FLOATS), y=0.0, z=1.0) for _ in range(nn)], friction=draw(FLOATS))


@st.composite
def collision_objects(draw) -> CollisionObject:
    msg = CollisionObject(id=draw(TEXT), operation=draw(st.integers(-128, 127)), pose=draw(poses()))
    msg.header.frame_id = draw(TEXT)
    msg.header.stamp.sec = draw(st.integers(-2**31, 2**31 - 1))
    msg.primitives = draw(st.lists(primitives(), max_size=3))
    msg.primitive_poses = draw(st.lists(poses(), max_size=3))
    msg.meshes = draw(st.lists(meshes(), max_size=2))
    msg.mesh_poses = draw(st.lists(poses(), max_size=2))
    msg.grasps = draw(st.lists(grasps(), max_size=3))
    return msg


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and np.array_equal(a.view(np.uint8) if a.dtype == b.dtype else a, b.view(np.uint8)
                                                      if a.dtype == b.dtype else b, equal_nan=a.dtype != b.dtype)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return a == b


def assert_same_raw(a, b) -> None:
    for f in ("operation", "id", "frame", "pose", "primitives", "primitive_poses", "meshes", "mesh_poses", "grasps"):
        assert _same(getattr(a, f), getattr(b, f)), f"{f}: {getattr(a, f)!r} != {getattr(b, f)!r}"


@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(collision_objects())
def test_raw_reader_matches_rclpy(msg):
    data = serialize_message(msg)
    assert_same_raw(parse_collision_object(data), raw_object_from_msg(deserialize_message(data, CollisionObject)))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(collision_objects(), st.integers(0, 10**6), st.binary(min_size=1, max_size=8))
def test_cut_or_damaged_bytes_give_a_scene_error(msg, where, junk):
    data = serialize_message(msg)
    cut = data[: where % len(data)]
    with pytest.raises(SceneUpdateError):
        parse_collision_object(cut if len(cut) < len(data) - 1 else data[:4])
    k = where % len(data)
    damaged = data[:k] + junk + data[k + len(junk):]
    try:
        parse_collision_object(damaged)
    except SceneUpdateError:
        pass


def test_limits_refuse_by_counts_before_copying():
    tri = [MeshTriangle(vertex_indices=[0, 1, 2])] * 11
    msg = CollisionObject(id="m", meshes=[Mesh(vertices=[Point()] * 3, triangles=tri)], mesh_poses=[Pose()])
    msg.primitives = [SolidPrimitive(type=1, dimensions=[0.1, 0.1, 0.1])] * 4
    msg.grasps = [Grasp()] * 3
    data = serialize_message(msg)
    for limits, words in [(SceneLimits(max_triangles_per_message=10), "max_triangles_per_message = 10"),
                          (SceneLimits(max_primitives_per_object=3), "max_primitives_per_object = 3"),
                          (SceneLimits(max_grasps_per_object=2), "max_grasps_per_object = 2")]:
        with pytest.raises(SceneUpdateError, match=words):
            parse_collision_object(data, limits)
    assert len(parse_collision_object(data, SceneLimits()).meshes[0][1]) == 11


def test_a_count_larger_than_the_message_is_refused_without_allocating():
    data = bytearray(serialize_message(CollisionObject(id="x")))
    # the primitives count sits right after the pose: make it 2^32 - 1
    raw = parse_collision_object(bytes(data))
    assert raw.primitives == []
    off = data.index(b"x\x00") + 2
    off += (-(off - 4)) % 8 + 56
    data[off:off + 4] = b"\xff\xff\xff\xff"
    with pytest.raises(SceneUpdateError, match="does not fit"):
        parse_collision_object(bytes(data))
