"""Message <-> core conversions, with the validation that belongs to the message level.

Message -> core functions raise `SceneUpdateError` (a ValueError) with a clear message on anything
malformed: NaN or inf, a zero or clearly non-unit quaternion (small deviations are normalized, see
`core.transforms.checked_unit_quaternion`), unknown primitive types, wrong dimension counts, pose
count mismatches, mesh indices out of range. The core `PlanningScene` validates its own invariants
again, so an update that gets through here is still checked as a whole before it is applied.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Point, Pose, Vector3
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner.core.scene.planning_scene import PRIMITIVE_DIMS, Operation, SceneUpdate, SceneUpdateError
from humanoid_planner.core.scene.types import GraspSpec, SceneObject, Shape
from humanoid_planner.core.transforms import InvalidQuaternion, checked_unit_quaternion, matrix_to_pose, pose_to_matrix
from humanoid_planner_interfaces.msg import CollisionObject, Grasp

PRIMITIVE_KINDS = {
    SolidPrimitive.BOX: "box",
    SolidPrimitive.SPHERE: "sphere",
    SolidPrimitive.CYLINDER: "cylinder",
    SolidPrimitive.CONE: "cone",
}
"""shape_msgs/SolidPrimitive type -> core Shape kind. PRISM (5) is not supported."""
PRIMITIVE_TYPES = {kind: t for t, kind in PRIMITIVE_KINDS.items()}


def _finite(values, what: str) -> list[float]:
    vals = [float(v) for v in values]
    if not all(math.isfinite(v) for v in vals):
        raise SceneUpdateError(f"{what}: contains NaN or inf ({vals})")
    return vals


def point_to_array(p, what: str) -> np.ndarray:
    return np.array(_finite((p.x, p.y, p.z), what))


def pose_to_matrix_checked(pose: Pose, what: str) -> np.ndarray:
    """geometry_msgs/Pose -> 4x4; rejects NaN/inf and zero or clearly non-unit quaternions."""
    pos = _finite((pose.position.x, pose.position.y, pose.position.z), f"{what} position")
    o = pose.orientation
    try:
        q = checked_unit_quaternion([o.x, o.y, o.z, o.w])
    except InvalidQuaternion as e:
        raise SceneUpdateError(f"{what} orientation: {e}") from None
    return pose_to_matrix(pos, q)


def matrix_to_pose_msg(T: np.ndarray) -> Pose:
    p, q = matrix_to_pose(T)
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in p)
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = (float(v) for v in q)
    return msg


# ---------------------------------------------------------------------- shapes
def primitive_to_shape(prim: SolidPrimitive, pose: Pose, what: str) -> Shape:
    kind = PRIMITIVE_KINDS.get(prim.type)
    if kind is None:
        raise SceneUpdateError(
            f"{what}: unsupported primitive type {prim.type} (BOX=1, SPHERE=2, CYLINDER=3, CONE=4)")
    dims = _finite(prim.dimensions, f"{what} dimensions")
    n = PRIMITIVE_DIMS[kind]
    if len(dims) != n:
        raise SceneUpdateError(f"{what}: a {kind} needs {n} dimension(s), got {len(dims)}: {dims}")
    if any(d < 0.0 for d in dims):
        raise SceneUpdateError(f"{what}: negative {kind} dimension in {dims}")
    return Shape(kind=kind, pose=pose_to_matrix_checked(pose, f"{what} pose"), dims=tuple(dims))


def mesh_to_shape(mesh: Mesh, pose: Pose, what: str) -> Shape:
    if not mesh.vertices or not mesh.triangles:
        raise SceneUpdateError(f"{what}: empty mesh ({len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles)")
    V = np.array([(v.x, v.y, v.z) for v in mesh.vertices], dtype=float)
    if not np.all(np.isfinite(V)):
        raise SceneUpdateError(f"{what}: mesh vertices contain NaN or inf")
    F = np.array([list(t.vertex_indices) for t in mesh.triangles], dtype=np.int64).reshape(-1, 3)
    if F.max() >= len(V):
        raise SceneUpdateError(
            f"{what}: triangle vertex index {int(F.max())} out of range ({len(V)} vertices)")
    return Shape(kind="mesh", pose=pose_to_matrix_checked(pose, f"{what} pose"), vertices=V, triangles=F)


def shape_to_msgs(shape: Shape) -> tuple[SolidPrimitive | Mesh, Pose]:
    """Core Shape -> (SolidPrimitive or Mesh, pose in the object frame)."""
    if shape.kind == "mesh":
        msg = Mesh()
        msg.vertices = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in shape.vertices]
        msg.triangles = [MeshTriangle(vertex_indices=np.asarray(t, dtype=np.uint32)) for t in shape.triangles]
    else:
        msg = SolidPrimitive(type=PRIMITIVE_TYPES[shape.kind], dimensions=[float(d) for d in shape.dims])
    return msg, matrix_to_pose_msg(shape.pose)


# ---------------------------------------------------------------------- grasps
def grasp_from_msg(g: Grasp, what: str) -> GraspSpec:
    contacts = [point_to_array(p, f"{what} contact {i}") for i, p in enumerate(g.contacts)]
    normals = [np.array(_finite((n.x, n.y, n.z), f"{what} normal {i}")) for i, n in enumerate(g.normals)]
    if len(contacts) != len(normals):
        raise SceneUpdateError(f"{what}: {len(contacts)} contacts but {len(normals)} normals (must be the same)")
    friction = float(g.friction)
    if not math.isfinite(friction) or friction < 0.0:
        raise SceneUpdateError(f"{what}: friction must be finite and >= 0, got {g.friction}")
    return GraspSpec(
        id=g.id, hand=g.hand,
        tcp_in_object=pose_to_matrix_checked(g.tcp_in_object, f"{what} tcp_in_object"),
        contacts=np.array(contacts, dtype=float).reshape(-1, 3),
        normals=np.array(normals, dtype=float).reshape(-1, 3),
        friction=friction)


def grasp_to_msg(g: GraspSpec) -> Grasp:
    return Grasp(
        id=g.id, hand=g.hand, tcp_in_object=matrix_to_pose_msg(g.tcp_in_object),
        contacts=[Point(x=float(x), y=float(y), z=float(z)) for x, y, z in np.reshape(g.contacts, (-1, 3))],
        normals=[Vector3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.reshape(g.normals, (-1, 3))],
        friction=float(g.friction))


# ---------------------------------------------------------------------- collision objects
def collision_object_to_update(msg: CollisionObject, planning_frame: str,
                               frame_aliases: tuple[str, ...] = ()) -> SceneUpdate:
    """CollisionObject -> SceneUpdate; raises SceneUpdateError if any part of it is invalid.

    header.frame_id must be empty, the planning frame, or one of frame_aliases (frames that coincide
    with it, e.g. the URDF root when the planning frame is "world"). As in MoveIt, REMOVE looks only
    at the id (pose, shapes and grasps are ignored), so a client may reuse the message it added an
    object with.
    """
    try:
        op = Operation(int(msg.operation))
    except ValueError:
        raise SceneUpdateError(
            f"object {msg.id!r}: unknown operation {msg.operation} (ADD=0, REMOVE=1, APPEND=2, MOVE=3)") from None
    oid = msg.id
    if op == Operation.REMOVE:
        return SceneUpdate(operation=op, id=oid)
    frame = msg.header.frame_id
    if frame in frame_aliases:
        frame = planning_frame
    if frame and frame != planning_frame:
        raise SceneUpdateError(
            f"{op.name} of {oid!r}: frame_id {frame!r} is not the planning frame {planning_frame!r} "
            "(give poses in the planning frame, or leave frame_id empty)")
    if op == Operation.MOVE and (msg.primitives or msg.meshes or msg.primitive_poses or msg.mesh_poses):
        raise SceneUpdateError(f"MOVE of {oid!r}: changes the pose only; primitives and meshes must be empty")
    if len(msg.primitives) != len(msg.primitive_poses):
        raise SceneUpdateError(
            f"{op.name} of {oid!r}: {len(msg.primitives)} primitives but {len(msg.primitive_poses)} primitive_poses")
    if len(msg.meshes) != len(msg.mesh_poses):
        raise SceneUpdateError(f"{op.name} of {oid!r}: {len(msg.meshes)} meshes but {len(msg.mesh_poses)} mesh_poses")
    pose = pose_to_matrix_checked(msg.pose, f"{op.name} of {oid!r}: pose")
    shapes = [primitive_to_shape(p, pp, f"{op.name} of {oid!r}: primitive {i}")
              for i, (p, pp) in enumerate(zip(msg.primitives, msg.primitive_poses))]
    shapes += [mesh_to_shape(m, mp, f"{op.name} of {oid!r}: mesh {i}")
               for i, (m, mp) in enumerate(zip(msg.meshes, msg.mesh_poses))]
    grasps = [grasp_from_msg(g, f"{op.name} of {oid!r}: grasp {i}") for i, g in enumerate(msg.grasps)]
    return SceneUpdate(operation=op, id=oid, pose=pose, shapes=tuple(shapes), grasps=tuple(grasps),
                       frame=frame)


def scene_object_to_msg(obj: SceneObject, frame: str) -> CollisionObject:
    """A scene object as the CollisionObject (operation ADD) that would recreate it."""
    msg = CollisionObject()
    msg.header.frame_id = frame
    msg.id = obj.id
    msg.pose = matrix_to_pose_msg(obj.pose)
    for shape in obj.shapes:
        geom, pose = shape_to_msgs(shape)
        if shape.kind == "mesh":
            msg.meshes.append(geom)
            msg.mesh_poses.append(pose)
        else:
            msg.primitives.append(geom)
            msg.primitive_poses.append(pose)
    msg.grasps = [grasp_to_msg(g) for g in obj.grasps]
    msg.operation = CollisionObject.ADD
    return msg
