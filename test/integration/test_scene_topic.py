"""Planning scene over ROS: CollisionObjects published by a separate node, read back via get_planning_scene.

Every operation, every primitive type and a mesh are applied; many kinds of invalid message are each
shown to be rejected whole, leaving the objects and the version unchanged. A rejected message has no
visible effect, so each one is followed by a valid "sentinel" message from the same publisher: the
subscription is reliable and applies messages in order, so once the sentinel shows up, the invalid
message before it has been processed.
"""
import math
from dataclasses import replace
import time

import numpy as np
import pytest
from geometry_msgs.msg import Point, Quaternion
from sensor_msgs.msg import JointState
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner.ros.parameters import PlannerParameters, usable_cores
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS
from humanoid_planner_interfaces.msg import CollisionObject, Grasp
from humanoid_planner_interfaces.srv import GetPlanningScene
from ros_messages import grasp, obj, pose, prim, tetra_mesh  # test/ros_messages.py
from humanoid_planner.child_env import child_environment

pytestmark = pytest.mark.integration

FRAME = "base_link"
SENTINEL = "__sentinel__"


class SceneClient:
    """A separate node that publishes CollisionObjects and calls get_planning_scene."""

    def __init__(self, ros):
        self.ros = ros
        self.planner = ros.planner()
        self.node = ros.node("scene_test_client")
        self.pub = self.node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        self.cli = self.node.create_client(GetPlanningScene, "get_planning_scene")
        self._sentinels = 0
        ros.wait_for_subscribers(self.pub)

    def get(self):
        return self.ros.call(self.cli, GetPlanningScene.Request())

    def publish(self, msg):
        self.pub.publish(msg)

    def apply(self, msg):
        """Publish a valid message and wait until the scene version moves past it."""
        before = self.get().version
        self.publish(msg)
        self.ros.wait_until(lambda: self.get().version > before, what=f"scene update {msg.id!r}")
        return self.get()

    def sentinel(self):
        """Publish a valid ADD of the sentinel object and wait until it is applied; return the scene."""
        self._sentinels += 1
        before = self.get().version
        self.publish(obj(SENTINEL, at=pose(self._sentinels, 0, 0), primitives=[(prim(SolidPrimitive.SPHERE, 0.01), pose())]))
        self.ros.wait_until(lambda: self.get().version > before, what="sentinel")
        return self.get()


def without_sentinel(resp):
    return [o for o in resp.objects if o.id != SENTINEL]


@pytest.fixture
def scene(ros):
    return SceneClient(ros)


def by_id(resp):
    return {o.id: o for o in resp.objects}


def assert_pose(p, x, y, z, q=(0.0, 0.0, 0.0, 1.0)):
    assert (p.position.x, p.position.y, p.position.z) == pytest.approx((x, y, z), abs=1e-12)
    got = np.array([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
    want = np.array(q, dtype=float) / np.linalg.norm(q)
    assert min(np.abs(got - want).max(), np.abs(got + want).max()) < 1e-9


# ---------------------------------------------------------------------- valid operations
def test_empty_scene(scene):
    resp = scene.get()
    assert resp.objects == [] and resp.version == 0 and resp.planning_frame == FRAME


def test_add_every_primitive_and_a_mesh_with_grasps(scene):
    msg = obj("things", at=pose(0.5, -0.2, 0.8, (0.0, 0.0, math.sin(0.25), math.cos(0.25))),
              primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.2, 0.3), pose(0.1, 0, 0)),
                          (prim(SolidPrimitive.SPHERE, 0.05), pose(0, 0.1, 0)),
                          (prim(SolidPrimitive.CYLINDER, 0.2, 0.04), pose(0, 0, 0.1)),
                          (prim(SolidPrimitive.CONE, 0.15, 0.06), pose(0, 0, -0.1, (1.0, 0.0, 0.0, 0.0)))],
              meshes=[(tetra_mesh(), pose(0.2, 0.2, 0))],
              grasps=[grasp("top"), grasp("side", hand="")])
    resp = scene.apply(msg)
    assert resp.version == 1 and len(resp.objects) == 1
    o = resp.objects[0]
    assert o.id == "things" and o.header.frame_id == FRAME and o.operation == CollisionObject.ADD
    assert_pose(o.pose, 0.5, -0.2, 0.8, (0.0, 0.0, math.sin(0.25), math.cos(0.25)))
    assert [p.type for p in o.primitives] == [SolidPrimitive.BOX, SolidPrimitive.SPHERE,
                                              SolidPrimitive.CYLINDER, SolidPrimitive.CONE]
    assert [list(p.dimensions) for p in o.primitives] == [[0.1, 0.2, 0.3], [0.05], [0.2, 0.04], [0.15, 0.06]]
    assert_pose(o.primitive_poses[0], 0.1, 0, 0)
    assert_pose(o.primitive_poses[3], 0, 0, -0.1, (1.0, 0.0, 0.0, 0.0))
    assert len(o.meshes) == 1 and len(o.mesh_poses) == 1
    assert [(v.x, v.y, v.z) for v in o.meshes[0].vertices] == [(v.x, v.y, v.z) for v in tetra_mesh().vertices]
    assert [list(t.vertex_indices) for t in o.meshes[0].triangles] == [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    assert_pose(o.mesh_poses[0], 0.2, 0.2, 0)
    assert [(g.id, g.hand, g.friction) for g in o.grasps] == [("top", "gripper", 0.6), ("side", "", 0.6)]
    g = o.grasps[0]
    assert_pose(g.tcp_in_object, 0, 0, 0.12, (1.0, 0.0, 0.0, 0.0))
    assert [(c.x, c.y, c.z) for c in g.contacts] == [(0.04, 0.0, 0.05), (-0.04, 0.0, 0.05)]
    assert [(n.x, n.y, n.z) for n in g.normals] == [(-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]


def test_components_answer_only_the_parts_asked_for(scene):
    """GetPlanningScene.components: names and poses only, + shapes, + grasps, nothing of the objects;
    0 is everything. The same object, read through every mask, changes with a MOVE in each."""
    msg = obj("things", at=pose(0.5, -0.2, 0.8), primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.2, 0.3), pose())],
              meshes=[(tetra_mesh(), pose(0.2, 0.2, 0))], grasps=[grasp("top")])
    scene.apply(msg)
    R = GetPlanningScene.Request

    def get(components: int):
        return scene.ros.call(scene.cli, R(components=components))

    for k in range(2):  # the second round reads the per-version lists built by the first
        full = get(0)
        names = get(R.OBJECT_NAMES)
        shapes = get(R.OBJECT_GEOMETRY)
        grasps = get(R.OBJECT_GRASPS)
        other = get(R.ATTACHED_OBJECTS | R.VOXELS)
        assert {r.version for r in (full, names, shapes, grasps, other)} == {full.version}
        assert all(r.planning_frame == FRAME for r in (full, names, shapes, grasps, other))
        (f,), (n,), (s,), (g,) = full.objects, names.objects, shapes.objects, grasps.objects
        assert f.id == n.id == s.id == g.id == "things"
        assert [(x.pose.position.x, x.pose.position.y) for x in (f, n, s, g)] == [(f.pose.position.x, -0.2)] * 4
        assert len(f.primitives) == 1 and len(f.meshes) == 1 and len(f.grasps) == 1
        assert n.primitives == [] and n.meshes == [] and n.grasps == []
        assert len(s.primitives) == 1 and len(s.meshes) == 1 and s.grasps == []
        assert s.primitives[0].dimensions.tolist() == [0.1, 0.2, 0.3]
        assert g.primitives == [] and g.meshes == [] and [x.id for x in g.grasps] == ["top"]
        assert other.objects == []
        moved = obj("things", at=pose(0.6 + 0.1 * k, -0.2, 0.8))
        moved.operation = CollisionObject.MOVE
        scene.apply(moved)
    assert get(R.OBJECT_NAMES).objects[0].pose.position.x == pytest.approx(0.7)


def test_add_replaces_same_id(scene):
    scene.apply(obj("a", at=pose(1, 0, 0), primitives=[(prim(SolidPrimitive.BOX, 1, 1, 1), pose())],
                    grasps=[grasp()]))
    resp = scene.apply(obj("a", at=pose(2, 0, 0), primitives=[(prim(SolidPrimitive.SPHERE, 0.3), pose())]))
    assert resp.version == 2 and len(resp.objects) == 1
    o = resp.objects[0]
    assert_pose(o.pose, 2, 0, 0)
    assert [p.type for p in o.primitives] == [SolidPrimitive.SPHERE] and o.grasps == []


def test_append_to_existing_keeps_pose(scene):
    scene.apply(obj("a", at=pose(1, 0, 0), primitives=[(prim(SolidPrimitive.BOX, 1, 1, 1), pose())],
                    grasps=[grasp("g1")]))
    resp = scene.apply(obj("a", op=CollisionObject.APPEND, at=pose(5, 5, 5),
                           primitives=[(prim(SolidPrimitive.SPHERE, 0.3), pose(0, 0, 1))],
                           meshes=[(tetra_mesh(), pose())], grasps=[grasp("g2")]))
    o = by_id(resp)["a"]
    assert resp.version == 2
    assert_pose(o.pose, 1, 0, 0)  # as MoveIt: appending keeps the object's pose
    assert [p.type for p in o.primitives] == [SolidPrimitive.BOX, SolidPrimitive.SPHERE]
    assert_pose(o.primitive_poses[1], 0, 0, 1)
    assert len(o.meshes) == 1
    assert [g.id for g in o.grasps] == ["g1", "g2"]


def test_append_creates_missing_object(scene):
    resp = scene.apply(obj("new", op=CollisionObject.APPEND, at=pose(0, 1, 0),
                           primitives=[(prim(SolidPrimitive.CONE, 0.2, 0.1), pose())]))
    o = by_id(resp)["new"]
    assert_pose(o.pose, 0, 1, 0)
    assert [p.type for p in o.primitives] == [SolidPrimitive.CONE]


def test_move_changes_pose_keeps_shapes_and_grasps(scene):
    first = scene.apply(obj("a", at=pose(1, 0, 0), primitives=[(prim(SolidPrimitive.CYLINDER, 0.3, 0.05), pose())],
                            grasps=[grasp()]))
    resp = scene.apply(obj("a", op=CollisionObject.MOVE, at=pose(0, 0, 2, (0.0, 0.0, 1.0, 0.0))))
    before, after = first.objects[0], resp.objects[0]
    assert resp.version == 2
    assert_pose(after.pose, 0, 0, 2, (0.0, 0.0, 1.0, 0.0))
    assert after.primitives == before.primitives and after.primitive_poses == before.primitive_poses
    assert after.grasps == before.grasps


def test_remove_one_then_all(scene):
    for oid in ("a", "b", "c"):
        scene.apply(obj(oid, primitives=[(prim(SolidPrimitive.SPHERE, 0.1), pose())]))
    resp = scene.apply(obj("b", op=CollisionObject.REMOVE))
    assert [o.id for o in resp.objects] == ["a", "c"] and resp.version == 4
    resp = scene.apply(obj("", op=CollisionObject.REMOVE))
    assert resp.objects == [] and resp.version == 5


def test_remove_reusing_the_add_message(scene):
    msg = obj("a", primitives=[(prim(SolidPrimitive.BOX, 1, 1, 1), pose())])
    scene.apply(msg)
    msg.operation = CollisionObject.REMOVE  # MoveIt clients often do this: REMOVE ignores the geometry
    resp = scene.apply(msg)
    assert resp.objects == []


def test_empty_frame_means_planning_frame_and_small_quaternion_error_is_normalized(scene):
    q = (0.0, 0.0, 0.0, 1.0004)  # |q| - 1 = 4e-4 < 1e-3: normalized, not rejected
    resp = scene.apply(obj("a", frame="", at=pose(0, 0, 1, q), primitives=[(prim(SolidPrimitive.BOX, 1, 1, 1), pose())]))
    o = resp.objects[0]
    assert o.header.frame_id == FRAME
    assert (o.pose.orientation.x, o.pose.orientation.y, o.pose.orientation.z, o.pose.orientation.w) == \
        pytest.approx((0.0, 0.0, 0.0, 1.0), abs=1e-12)


def test_joint_states_latest_is_kept(ros, scene):
    pub = scene.node.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
    ros.wait_for_subscribers(pub)
    assert scene.planner.latest_joint_state() is None
    for k in range(2):
        pub.publish(JointState(name=["shoulder", "elbow", "wrist"], position=[0.1 * k, 0.2, 0.3]))
    ros.publish_until(pub, JointState(name=["shoulder", "elbow", "wrist"], position=[0.2, 0.2, 0.3]),
                      lambda: (s := scene.planner.latest_joint_state()) is not None and s.position[0] == pytest.approx(0.2),
                      what="latest joint state")


def test_parameters_declared_with_defaults(scene):
    p = scene.planner
    # num_workers 0 (the default) is resolved to the cores the node may use; the tests' nodes plan in threads
    assert p.params == replace(PlannerParameters(), num_workers=usable_cores(), planning_processes=False)
    assert p.get_parameter("num_workers").value == 0 and p.runner.pool is None
    assert p.get_parameter("f_extend").value == 0.3 and p.get_parameter("max_cycles").value == 40000
    assert p.get_parameter("robot").value == ""
    assert p.planning_frame == FRAME and p.robot.name == "test_arm"


# ---------------------------------------------------------------------- invalid messages
BOX = (prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1), pose())
NAN, INF = float("nan"), float("inf")


def _bad_mesh_index():
    m = tetra_mesh()
    m.triangles[1] = MeshTriangle(vertex_indices=np.array([0, 1, 4], dtype=np.uint32))
    return m


def _nan_vertex_mesh():
    m = tetra_mesh()
    m.vertices[2] = Point(x=0.0, y=NAN, z=0.0)
    return m


def _grasp_count_mismatch():
    g = grasp()
    g.normals = g.normals[:1]
    return g


def _grasp_bad_quaternion():
    g = grasp()
    g.tcp_in_object.orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=0.5)
    return g


def _count_mismatch(field):
    m = obj("x", primitives=[BOX], meshes=[(tetra_mesh(), pose())])
    getattr(m, field).append(pose())
    return m


INVALID = {
    "unknown operation": lambda: obj("x", op=5, primitives=[BOX]),
    "negative operation": lambda: obj("x", op=-1, primitives=[BOX]),
    "MOVE with shapes": lambda: obj("cup", op=CollisionObject.MOVE, at=pose(3, 3, 3), primitives=[BOX]),
    "MOVE of a missing object": lambda: obj("nothing", op=CollisionObject.MOVE, at=pose(3, 3, 3)),
    "REMOVE of a missing object": lambda: obj("nothing", op=CollisionObject.REMOVE),
    "ADD without an id": lambda: obj("", primitives=[BOX]),
    "ADD without shapes": lambda: obj("x"),
    "APPEND without shapes": lambda: obj("cup", op=CollisionObject.APPEND, grasps=[grasp("extra")]),
    "MOVE with grasps": lambda: obj("cup", op=CollisionObject.MOVE, at=pose(3, 3, 3), grasps=[grasp("extra")]),
    "NaN in pose position": lambda: obj("x", at=pose(NAN, 0, 0), primitives=[BOX]),
    "inf in pose position": lambda: obj("cup", op=CollisionObject.MOVE, at=pose(0, INF, 0)),
    "NaN in quaternion": lambda: obj("x", at=pose(q=(0, 0, 0, NAN)), primitives=[BOX]),
    "zero quaternion": lambda: obj("x", at=pose(q=(0, 0, 0, 0)), primitives=[BOX]),
    "clearly non-unit quaternion": lambda: obj("x", at=pose(q=(0, 0, 0, 2)), primitives=[BOX]),
    "non-unit quaternion on MOVE": lambda: obj("cup", op=CollisionObject.MOVE, at=pose(q=(0.1, 0, 0, 0.9))),
    "NaN in primitive pose": lambda: obj("x", primitives=[(prim(SolidPrimitive.BOX, 1, 1, 1), pose(0, NAN, 0))]),
    "negative box dimension": lambda: obj("x", primitives=[(prim(SolidPrimitive.BOX, 0.1, -0.1, 0.1), pose())]),
    "negative sphere radius": lambda: obj("x", primitives=[(prim(SolidPrimitive.SPHERE, -0.1), pose())]),
    "inf dimension": lambda: obj("x", primitives=[(prim(SolidPrimitive.CYLINDER, INF, 0.1), pose())]),
    "box with 2 dimensions": lambda: obj("x", primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.1), pose())]),
    "sphere with 3 dimensions": lambda: obj("x", primitives=[(prim(SolidPrimitive.SPHERE, 0.1, 0.1, 0.1), pose())]),
    "cone with 1 dimension": lambda: obj("x", primitives=[(prim(SolidPrimitive.CONE, 0.1), pose())]),
    "unsupported primitive type": lambda: obj("x", primitives=[(prim(SolidPrimitive.PRISM, 0.1), pose())]),
    "unknown primitive type": lambda: obj("x", primitives=[(prim(42, 0.1), pose())]),
    "primitive_poses count mismatch": lambda: _count_mismatch("primitive_poses"),
    "mesh_poses count mismatch": lambda: _count_mismatch("mesh_poses"),
    "mesh index out of range": lambda: obj("x", meshes=[(_bad_mesh_index(), pose())]),
    "mesh NaN vertex": lambda: obj("x", meshes=[(_nan_vertex_mesh(), pose())]),
    "empty mesh": lambda: obj("x", meshes=[(Mesh(), pose())]),
    "frame other than the planning frame": lambda: obj("x", frame="world", primitives=[BOX]),
    "APPEND in another frame": lambda: obj("cup", op=CollisionObject.APPEND, frame="odom", primitives=[BOX]),
    "grasp contacts/normals mismatch": lambda: obj("x", primitives=[BOX], grasps=[_grasp_count_mismatch()]),
    "grasp with non-unit quaternion": lambda: obj("x", primitives=[BOX], grasps=[_grasp_bad_quaternion()]),
    "grasp with negative friction": lambda: obj("x", primitives=[BOX], grasps=[Grasp(id="g", friction=-1.0)]),
    "duplicate grasp ids": lambda: obj("x", primitives=[BOX], grasps=[grasp("g"), grasp("g")]),
    "valid shapes then one bad shape": lambda: obj(
        "x", primitives=[BOX, BOX, (prim(SolidPrimitive.SPHERE, NAN), pose())]),
}


@pytest.mark.parametrize("kind", list(INVALID))
def test_invalid_message_is_rejected_whole(scene, kind):
    scene.apply(obj("table", at=pose(0.6, 0, 0.4), primitives=[(prim(SolidPrimitive.BOX, 0.8, 1.2, 0.05), pose())]))
    scene.apply(obj("cup", at=pose(0.5, 0.1, 0.5), primitives=[(prim(SolidPrimitive.CYLINDER, 0.12, 0.04), pose())],
                    grasps=[grasp()]))
    before = scene.sentinel()
    scene.publish(INVALID[kind]())
    after = scene.sentinel()
    # exactly one applied change (the sentinel): the invalid message changed nothing, not even the version
    assert after.version == before.version + 1
    assert without_sentinel(after) == without_sentinel(before)


# ---------------------------------------------------------------------- planning frame parameter
def test_planning_frame_outside_the_urdf_coincides_with_the_root(ros):
    planner = ros.planner(planning_frame="world")
    node = ros.node("frame_client")
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    cli = node.create_client(GetPlanningScene, "get_planning_scene")
    ros.wait_for_subscribers(pub)
    pub.publish(obj("in_world", frame="world", primitives=[BOX]))
    pub.publish(obj("in_root", frame=FRAME, primitives=[BOX]))  # the root link is the same frame
    pub.publish(obj("in_odom", frame="odom", primitives=[BOX]))  # rejected
    pub.publish(obj("last", frame="", primitives=[BOX]))
    resp = ros.wait_until(lambda: (r := ros.call(cli, GetPlanningScene.Request())).version >= 3 and r)
    assert resp.planning_frame == "world" and planner.planning_frame == "world"
    assert [o.id for o in resp.objects] == ["in_world", "in_root", "last"]
    assert {o.header.frame_id for o in resp.objects} == {"world"}


def test_planning_frame_on_a_non_root_link_is_refused(ros):
    from humanoid_planner.ros.node import RobotLoadError

    with pytest.raises(RobotLoadError, match="not its root"):
        ros.planner(planning_frame="forearm")


def _publisher_and_drop_counts(ros, name: str):
    """A collision_object publisher matched with the node, and the ~/dropped_scene_updates values received
    (the latched 0 already in)."""
    from std_msgs.msg import UInt64

    from humanoid_planner.ros.qos import DROPPED_QOS

    node = ros.node(name)
    counts: list[int] = []
    node.create_subscription(UInt64, "humanoid_planner/dropped_scene_updates", lambda m: counts.append(m.data),
                             DROPPED_QOS)
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    ros.wait_for_subscribers(pub)
    ros.wait_until(lambda: counts == [0], what="the latched count 0")
    return pub, counts


def test_a_backlog_over_max_queued_scene_updates_is_dropped_and_counted(ros):
    """While the scene thread is held (the test takes the scene's lock, as a long update would), K
    messages arrive: at most max_queued_scene_updates wait, the rest are dropped; once released, every
    message is either applied or counted on ~/dropped_scene_updates (applied + dropped = K)."""
    planner = ros.planner(max_queued_scene_updates=5)
    pub, counts = _publisher_and_drop_counts(ros, "flood_counter")
    K = 60
    msgs = [obj(f"box{k}", at=pose(2.0, 0.1 * k, 0), primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1), pose())])
            for k in range(K)]
    with planner.scene._lock:  # the scene thread blocks on the first update; the rest wait in DDS meanwhile
        pub.publish(msgs[0])
        time.sleep(0.3)  # taken and blocked on (however few a loaded machine's first take gets)
        for m in msgs[1:]:
            pub.publish(m)
        time.sleep(0.3)  # they reach the node's reader
    # released: the next take gets all the others at once; 5 may wait, the rest are dropped
    ros.wait_until(lambda: planner.scene_server.dropped > 0, what="drops once the scene thread goes on")
    ros.wait_until(lambda: counts and counts[-1] == planner.scene_server.dropped, timeout=5.0,
                   what="the count published")
    ros.wait_until(lambda: len(planner.scene) + counts[-1] == K, timeout=5.0,
                   what=f"applied + dropped = {K}")
    assert 0 < counts[-1] <= K - 5



def test_moves_that_waited_together_and_were_refused_count_as_dropped_only_when_they_were_valid(ros):
    """MOVEs of one object that wait together collapse into the last one. Refused because the object is
    not there, every one of them would have been refused: refused (logged), none dropped. Refused for its
    own content (a NaN pose), the valid MOVEs it replaced are lost: counted as dropped."""
    planner = ros.planner()
    pub, counts = _publisher_and_drop_counts(ros, "move_counter")
    box = obj("box", at=pose(2.0, 0, 0), primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1), pose())])
    v0 = planner.scene.version
    with planner.scene._lock:  # the scene thread blocks on the ADD; the MOVEs wait together behind it
        pub.publish(box)
        for k in range(5):
            pub.publish(obj("ghost", CollisionObject.MOVE, at=pose(2.0, 0.1 * k, 0)))
        for k in range(5):
            pub.publish(obj("box", CollisionObject.MOVE, at=pose(2.0, 0.1 * k, math.nan if k == 4 else 0.0)))
        time.sleep(0.5)  # they reach the node's reader
    ros.wait_until(lambda: not planner.scene_server.intake.backlog() and planner.scene.version > v0,
                   what="the backlog applied")
    time.sleep(0.2)
    assert planner.scene.version == v0 + 1  # the ADD; every MOVE refused
    assert planner.scene.get("box").pose[1, 3] == 0.0
    assert planner.scene_server.dropped == 4  # the valid MOVEs of the box the NaN one replaced
    ros.wait_until(lambda: counts[-1] == 4, timeout=5.0, what="the count published")

BURST_PUBLISHER = """
import sys, time
import rclpy
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from humanoid_planner_interfaces.msg import CollisionObject
domain, K, n = (int(a) for a in sys.argv[1:4])
rclpy.init(domain_id=domain)
node = rclpy.create_node("burst_publisher")
# what a client that never waits for the node publishes with: reliable, keep last 10
pub = node.create_publisher(CollisionObject, "collision_object", QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE))
moves = []
for k in range(K):
    m = CollisionObject(id=f"box{k % n}", operation=CollisionObject.MOVE)
    m.pose.position.x, m.pose.position.y, m.pose.orientation.w = 2.0 + 1e-4 * k, 0.2 * (k % n), 1.0
    moves.append(m)
deadline = time.monotonic() + 60.0
while pub.get_subscription_count() < 1:
    if time.monotonic() > deadline:
        sys.exit("the node's subscription was not discovered within 60 s")
    time.sleep(0.02)
print("ready", flush=True)
sys.stdin.readline()
for m in moves:
    pub.publish(m)
print("sent", flush=True)
sys.stdin.readline()  # stay until told: samples still in this publisher would be lost with it
"""


def _line_of(child, timeout: float) -> str:
    """The child's next line (it prints one at a time), or a failure after `timeout` s: a child stuck in
    discovery fails the test instead of hanging it."""
    import select

    ready, _, _ = select.select([child.stdout], [], [], timeout)
    assert ready, f"the publisher process printed nothing within {timeout:g} s (exit code {child.poll()})"
    return child.stdout.readline().strip()


def test_every_message_of_a_burst_is_applied_or_counted_as_dropped(ros):
    """Another process publishes K MOVEs of 10 objects (reliable, keep last 10: it never waits for the
    node) while the scene thread is held (the test takes the scene's lock, as a long update would): the
    node's reader fills, the publisher overwrites what it could not deliver, and DDS reports those. Once
    released: applied (the scene version's advance) + dropped (~/dropped_scene_updates) = K exactly, every
    object where its last MOVE put it (MOVEs of one object that waited together collapse into the last,
    each counted as applied)."""
    import subprocess
    import sys

    planner = ros.planner()
    adder, counts = _publisher_and_drop_counts(ros, "burst_watcher")
    n_objects, K = 10, 8000
    for k in range(n_objects):
        adder.publish(obj(f"box{k}", at=pose(2.0, 0.2 * k, 0), primitives=[(prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1),
                                                                             pose())]))
    ros.wait_until(lambda: len(planner.scene) == n_objects, what="the objects added")
    v0 = planner.scene.version
    # another process: within one process DDS hands samples to a full reader directly, and loses them
    # without a trace
    env = child_environment()
    child = subprocess.Popen([sys.executable, "-c", BURST_PUBLISHER, str(ros.domain_id), str(K), str(n_objects)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert _line_of(child, 90.0) == "ready"
        with planner.scene._lock:  # the scene thread blocks on its next update; DDS holds or loses the rest
            child.stdin.write("go\n")
            child.stdin.flush()
            assert _line_of(child, 30.0) == "sent"
            time.sleep(0.5)  # the last samples reach the node's reader
        applied = lambda: planner.scene.version - v0  # noqa: E731
        ros.wait_until(lambda: applied() + planner.scene_server.dropped == K, timeout=20.0,
                       what=f"applied + dropped = {K} (now {applied()} + {planner.scene_server.dropped})")
    finally:
        try:
            child.communicate("exit\n", timeout=10)
        except subprocess.TimeoutExpired:
            child.kill()
            child.communicate()
    ros.wait_until(lambda: counts[-1] == planner.scene_server.dropped, timeout=5.0, what="the count published")
    assert 0 < counts[-1] < K
    for k in range(K - n_objects, K):
        assert planner.scene.get(f"box{k % n_objects}").pose[0, 3] == pytest.approx(2.0 + 1e-4 * k)


def test_the_scene_thread_waits_while_a_request_is_answered(ros):
    """An update that arrives while a request is being answered (SceneIntake.answering) is applied by
    the scene thread only once the answer is out, or after QUIET_MAX if it takes longer; one that
    arrives after the answer is applied without that wait."""
    from humanoid_planner.ros.scene_intake import QUIET_MAX

    planner = ros.planner()
    pub, _ = _publisher_and_drop_counts(ros, "quiet_watcher")
    box = [(prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1), pose())]
    v0 = planner.scene.version
    with planner.scene_server.answering():
        t0 = time.monotonic()
        pub.publish(obj("held", at=pose(2.0, 0, 0), primitives=box))
        ros.wait_until(lambda: planner.scene.version > v0, timeout=10.0, what="the update applied after QUIET_MAX")
        assert time.monotonic() - t0 >= QUIET_MAX
    v1 = planner.scene.version
    pub.publish(obj("free", at=pose(2.5, 0, 0), primitives=box))
    ros.wait_until(lambda: planner.scene.version > v1, timeout=10.0, what="the next update")
    assert planner.scene.get("held") is not None and planner.scene.get("free") is not None


def test_a_destroyed_node_leaves_no_scene_subscription(ros):
    """Its readers go with it: a keep-all reader left behind (nobody takes from it) would hold every
    keep-all publisher on collision_object back once it fills, and a later node's clients with it."""
    planner = ros.planner()
    node = ros.node("subscription_watcher")
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    ros.wait_for_subscribers(pub)
    ros.nodes.remove(planner)
    planner.destroy_node()
    ros.wait_until(lambda: pub.get_subscription_count() == 0, timeout=5.0,
                   what="no collision_object subscriber left")
