"""Builders of the interface package's messages, shared by the unit and integration tests (test/ is on
sys.path: pytest puts the folder of the rootdir-less test/conftest.py there)."""
import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject, Grasp, GripperTranslation


def pose(x=0.0, y=0.0, z=0.0, q=(0.0, 0.0, 0.0, 1.0)):
    return Pose(position=Point(x=float(x), y=float(y), z=float(z)),
                orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def prim(kind, *dims):
    return SolidPrimitive(type=kind, dimensions=[float(d) for d in dims])


def tetra_mesh():
    m = Mesh()
    m.vertices = [Point(x=0.0, y=0.0, z=0.0), Point(x=0.1, y=0.0, z=0.0),
                  Point(x=0.0, y=0.1, z=0.0), Point(x=0.0, y=0.0, z=0.1)]
    m.triangles = [MeshTriangle(vertex_indices=np.array(t, dtype=np.uint32))
                   for t in ([0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3])]
    return m


def grasp(gid="top", hand="gripper"):
    return Grasp(id=gid, hand=hand, tcp_in_object=pose(0, 0, 0.12, (1.0, 0.0, 0.0, 0.0)),
                 contacts=[Point(x=0.04, y=0.0, z=0.05), Point(x=-0.04, y=0.0, z=0.05)],
                 normals=[Vector3(x=-1.0, y=0.0, z=0.0), Vector3(x=1.0, y=0.0, z=0.0)], friction=0.6)


def obj(oid, op=CollisionObject.ADD, at=pose(), primitives=(), meshes=(), grasps=(), frame="base_link"):
    m = CollisionObject()
    m.header.frame_id = frame
    m.id = oid
    m.operation = op
    m.pose = at
    m.primitives = [p for p, _ in primitives]
    m.primitive_poses = [pp for _, pp in primitives]
    m.meshes = [p for p, _ in meshes]
    m.mesh_poses = [pp for _, pp in meshes]
    m.grasps = list(grasps)
    return m


def translation(v, desired: float, least: float = 0.0, frame: str = "") -> GripperTranslation:
    """A GripperTranslation along v (in `frame`; "" = the TCP frame)."""
    gt = GripperTranslation(desired_distance=float(desired), min_distance=float(least))
    gt.direction.header.frame_id = frame
    gt.direction.vector = Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))
    return gt


def attached_msg(oid: str, link: str = "", op=CollisionObject.ADD, touch=()) -> AttachedCollisionObject:
    """An attached_collision_object message for scene object `oid` (ADD attaches it to `link`, REMOVE detaches)."""
    msg = AttachedCollisionObject(link_name=link, touch_links=list(touch))
    msg.object.id = oid
    msg.object.operation = op
    return msg
