"""Message <-> core conversions, with the validation that belongs to the message level.

Message -> core functions raise `SceneUpdateError` (a ValueError) with a clear message on anything
malformed: NaN or inf, a zero or clearly non-unit quaternion (small deviations are normalized, see
`core.transforms.checked_unit_quaternion`), unknown primitive types, wrong dimension counts, pose
count mismatches, mesh indices out of range. The core `PlanningScene` validates its own invariants
again, so an update that gets through here is still checked as a whole before it is applied.
"""
from __future__ import annotations

import copy
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from geometry_msgs.msg import Point, Pose, Vector3
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner.core.scene.planning_scene import (PRIMITIVE_CACHE_SIZE, PRIMITIVE_DIMS, AttachUpdate, Operation,
                                                        SceneLimits, SceneUpdate, SceneUpdateError)
from humanoid_planner.core.scene.types import AttachedObject, GraspSpec, SceneObject, Shape
from humanoid_planner.core.transforms import (InvalidQuaternion, checked_unit_quaternion_tuple, matrix_to_quat_tuple,
                                             pose_to_matrix)
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject, Grasp

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
    return _pose7_to_matrix(_pose7(pose), what)


def matrix_to_pose_msg(T: np.ndarray) -> Pose:
    T = np.asarray(T, dtype=float)
    msg = Pose()
    p, o = msg.position, msg.orientation
    p.x, p.y, p.z = T[:3, 3].tolist()
    o.x, o.y, o.z, o.w = matrix_to_quat_tuple(T)
    return msg


# ---------------------------------------------------------------------- shapes
def primitive_to_shape(prim: SolidPrimitive, pose: Pose, what: str) -> Shape:
    return _primitive(prim.type, np.array(prim.dimensions, dtype=float), _pose7(pose), what)


def mesh_to_shape(mesh: Mesh, pose: Pose, what: str) -> Shape:
    V = np.array([(v.x, v.y, v.z) for v in mesh.vertices], dtype=float).reshape(-1, 3)
    F = np.array([list(t.vertex_indices) for t in mesh.triangles], dtype=np.int64).reshape(-1, 3)
    return _mesh(V, F, _pose7(pose), what)


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
    """Grasp message -> GraspSpec (the same rules as a grasp in a CollisionObject)."""
    return _grasp((g.id, g.hand, _pose7(g.tcp_in_object),
                   np.array([(c.x, c.y, c.z) for c in g.contacts], dtype=float).reshape(-1, 3),
                   np.array([(n.x, n.y, n.z) for n in g.normals], dtype=float).reshape(-1, 3), g.friction), what)


def grasp_to_msg(g: GraspSpec) -> Grasp:
    return Grasp(
        id=g.id, hand=g.hand, tcp_in_object=matrix_to_pose_msg(g.tcp_in_object),
        contacts=[Point(x=float(x), y=float(y), z=float(z)) for x, y, z in np.reshape(g.contacts, (-1, 3))],
        normals=[Vector3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.reshape(g.normals, (-1, 3))],
        friction=float(g.friction))


# ---------------------------------------------------------------------- collision objects
@dataclass
class RawObject:
    """A CollisionObject as plain numbers: what both ways in (a message object, or the serialized
    bytes of a raw subscription, `collision_object_cdr`) produce, so one function applies the rules.

    Poses are 7 floats (x, y, z, qx, qy, qz, qw); a primitive is (type, dims, pose); a mesh is
    (vertices (V, 3) float, triangles (F, 3) int, pose); a grasp is (id, hand, tcp pose, contacts
    (k, 3), normals (k, 3), friction).
    """

    operation: int
    id: str
    frame: str = ""
    pose: np.ndarray | None = None
    primitives: list = field(default_factory=list)
    primitive_poses: list = field(default_factory=list)
    meshes: list = field(default_factory=list)
    mesh_poses: list = field(default_factory=list)
    grasps: list = field(default_factory=list)


def _pose7_to_matrix(p, what: str) -> np.ndarray:
    """7 numbers (position, xyzw quaternion) -> 4x4, checked; on Python floats (numpy's per-call cost
    dominated a box's ADD)."""
    vals = p.tolist() if isinstance(p, np.ndarray) else [float(v) for v in p]
    position = vals[:3]
    if not all(map(math.isfinite, position)):
        raise SceneUpdateError(f"{what} position: contains NaN or inf ({position})")
    try:
        q = checked_unit_quaternion_tuple(vals[3:])
    except InvalidQuaternion as e:
        raise SceneUpdateError(f"{what} orientation: {e}") from None
    return pose_to_matrix(position, q)


def _pose7(pose: Pose) -> np.ndarray:
    o, q = pose.position, pose.orientation
    return np.array([o.x, o.y, o.z, q.x, q.y, q.z, q.w], dtype=float)


def raw_object_from_msg(msg: CollisionObject) -> RawObject:
    """The plain-number form of a CollisionObject message object."""
    return RawObject(
        operation=int(msg.operation), id=msg.id, frame=msg.header.frame_id, pose=_pose7(msg.pose),
        primitives=[(int(p.type), np.array(p.dimensions, dtype=float)) for p in msg.primitives],
        primitive_poses=[_pose7(p) for p in msg.primitive_poses],
        meshes=[(np.array([(v.x, v.y, v.z) for v in m.vertices], dtype=float).reshape(-1, 3),
                 np.array([list(t.vertex_indices) for t in m.triangles], dtype=np.int64).reshape(-1, 3))
                for m in msg.meshes],
        mesh_poses=[_pose7(p) for p in msg.mesh_poses],
        grasps=[(g.id, g.hand, _pose7(g.tcp_in_object),
                 np.array([(c.x, c.y, c.z) for c in g.contacts], dtype=float).reshape(-1, 3),
                 np.array([(n.x, n.y, n.z) for n in g.normals], dtype=float).reshape(-1, 3), float(g.friction))
                for g in msg.grasps])


def collision_object_to_update(msg: CollisionObject, planning_frame: str, frame_aliases: tuple[str, ...] = (),
                               limits: SceneLimits | None = None) -> SceneUpdate:
    """CollisionObject -> SceneUpdate; raises SceneUpdateError if any part of it is invalid."""
    return raw_object_to_update(raw_object_from_msg(msg), planning_frame, frame_aliases, limits)


def raw_object_to_update(raw: RawObject, planning_frame: str, frame_aliases: tuple[str, ...] = (),
                         limits: SceneLimits | None = None,
                         frame_pose: Callable[[str], np.ndarray] | None = None) -> SceneUpdate:
    """RawObject -> SceneUpdate; raises SceneUpdateError if any part of it is invalid.

    header.frame_id must be empty, the planning frame, one of frame_aliases (frames that coincide
    with it, e.g. the URDF root when the planning frame is "world"), or a frame `frame_pose` resolves
    (ros/frames.Frames.pose: the robot's links): the pose is then expressed in the planning frame. As in MoveIt, REMOVE looks only
    at the id (pose, shapes and grasps are ignored), so a client may reuse the message it added an
    object with. `limits` (the scene's) are checked on the counts before anything is converted.
    """
    op = _OPERATIONS.get(int(raw.operation))
    if op is None:
        raise SceneUpdateError(
            f"object {raw.id!r}: unknown operation {raw.operation} (ADD=0, REMOVE=1, APPEND=2, MOVE=3)")
    oid = raw.id
    if op == Operation.REMOVE:
        return SceneUpdate(operation=op, id=oid)
    what = f"{op.name} of {oid!r}"
    frame = raw.frame
    if frame in frame_aliases:
        frame = planning_frame
    T_frame = None
    if frame and frame != planning_frame:
        if frame_pose is None:
            raise SceneUpdateError(
                f"{what}: frame_id {frame!r} is not the planning frame {planning_frame!r} "
                "(give poses in the planning frame, or leave frame_id empty)")
        try:
            T_frame = frame_pose(frame)
        except ValueError as e:  # FrameError
            raise SceneUpdateError(f"{what}: {e}") from None
        frame = planning_frame
    if op == Operation.MOVE and (raw.primitives or raw.meshes or raw.primitive_poses or raw.mesh_poses):
        raise SceneUpdateError(f"MOVE of {oid!r}: changes the pose only; primitives and meshes must be empty")
    if len(raw.primitives) != len(raw.primitive_poses):
        raise SceneUpdateError(f"{what}: {len(raw.primitives)} primitives but {len(raw.primitive_poses)} primitive_poses")
    if len(raw.meshes) != len(raw.mesh_poses):
        raise SceneUpdateError(f"{what}: {len(raw.meshes)} meshes but {len(raw.mesh_poses)} mesh_poses")
    if limits is not None:
        limits.check_message(len(raw.primitives), sum(len(F) for _, F in raw.meshes), len(raw.grasps), what)
    pose = _pose7_to_matrix(raw.pose, f"{what}: pose")
    if T_frame is not None:
        pose = T_frame @ pose
    shapes = [_primitive(t, dims, pp, f"{what}: primitive {i}")
              for i, ((t, dims), pp) in enumerate(zip(raw.primitives, raw.primitive_poses))]
    shapes += [_mesh(V, F, mp, f"{what}: mesh {i}") for i, ((V, F), mp) in enumerate(zip(raw.meshes, raw.mesh_poses))]
    grasps = [_grasp(g, f"{what}: grasp {i}") for i, g in enumerate(raw.grasps)]
    return SceneUpdate(operation=op, id=oid, pose=pose, shapes=tuple(shapes), grasps=tuple(grasps), frame=frame)


_OPERATIONS = {int(o): o for o in Operation}
_PRIMITIVES: dict[tuple, Shape] = {}  # converted primitives by type and exact bytes of dimensions and pose


def _primitive_key(ptype: int, dims, pose7) -> tuple | None:
    try:
        return ptype, struct.pack(f"<{len(dims)}d", *dims), struct.pack("<7d", *pose7)
    except (struct.error, TypeError):
        return None  # not numbers: _convert_primitive says what is wrong


def _primitive(ptype: int, dims, pose7, what: str) -> Shape:
    """The Shape of a primitive, converted once per exact bits (type, dimensions, pose): a perception
    pipeline sends boxes of a few sizes; the scene then finds the checked Shape of the same bits
    (PlanningScene keeps them by value too, PRIMITIVE_CACHE_SIZE of them)."""
    key = _primitive_key(ptype, dims, pose7)
    shape = None if key is None else _PRIMITIVES.get(key)
    if shape is None:
        shape = _convert_primitive(ptype, dims, pose7, what)
        if key is not None:
            shape.pose.setflags(write=False)  # shared by later updates of the same bits
            if len(_PRIMITIVES) >= PRIMITIVE_CACHE_SIZE:
                _PRIMITIVES.clear()
            _PRIMITIVES[key] = shape
    return shape


def _convert_primitive(ptype: int, dims, pose7, what: str) -> Shape:
    kind = PRIMITIVE_KINDS.get(ptype)
    if kind is None:
        raise SceneUpdateError(f"{what}: unsupported primitive type {ptype} (BOX=1, SPHERE=2, CYLINDER=3, CONE=4)")
    dims = _finite(dims, f"{what} dimensions")
    n = PRIMITIVE_DIMS[kind]
    if len(dims) != n:
        raise SceneUpdateError(f"{what}: a {kind} needs {n} dimension(s), got {len(dims)}: {dims}")
    if any(d < 0.0 for d in dims):
        raise SceneUpdateError(f"{what}: negative {kind} dimension in {dims}")
    return Shape(kind=kind, pose=_pose7_to_matrix(pose7, f"{what} pose"), dims=tuple(dims))


def _mesh(V: np.ndarray, F: np.ndarray, pose7, what: str) -> Shape:
    if len(V) == 0 or len(F) == 0:
        raise SceneUpdateError(f"{what}: empty mesh ({len(V)} vertices, {len(F)} triangles)")
    if not np.all(np.isfinite(V)):
        raise SceneUpdateError(f"{what}: mesh vertices contain NaN or inf")
    F = np.asarray(F, dtype=np.int64)
    if F.max() >= len(V):
        raise SceneUpdateError(f"{what}: triangle vertex index {int(F.max())} out of range ({len(V)} vertices)")
    return Shape(kind="mesh", pose=_pose7_to_matrix(pose7, f"{what} pose"), vertices=V, triangles=F)


def _grasp(g, what: str) -> GraspSpec:
    gid, hand, tcp7, C, N, friction = g
    if not np.all(np.isfinite(C)):
        raise SceneUpdateError(f"{what} contacts: contain NaN or inf")
    if not np.all(np.isfinite(N)):
        raise SceneUpdateError(f"{what} normals: contain NaN or inf")
    if len(C) != len(N):
        raise SceneUpdateError(f"{what}: {len(C)} contacts but {len(N)} normals (must be the same)")
    friction = float(friction)
    if not math.isfinite(friction) or friction < 0.0:
        raise SceneUpdateError(f"{what}: friction must be finite and >= 0, got {friction}")
    return GraspSpec(id=gid, hand=hand, tcp_in_object=_pose7_to_matrix(tcp7, f"{what} tcp_in_object"),
                     contacts=C, normals=N, friction=friction)


def scene_object_to_msg(obj: SceneObject, frame: str, geometry: bool = True, grasps: bool = True) -> CollisionObject:
    """A scene object as the CollisionObject (operation ADD) that would recreate it; without its shapes
    and / or grasps when the caller asked only for the rest (get_planning_scene's components)."""
    if not geometry and not grasps:
        return _named_message(obj, frame)
    msg = CollisionObject()
    msg.header.frame_id = frame
    msg.id = obj.id
    msg.pose = matrix_to_pose_msg(obj.pose)
    msg.operation = CollisionObject.ADD
    if grasps:
        msg.grasps = [grasp_to_msg(g) for g in obj.grasps]
    if not geometry:
        return msg
    for shape in obj.shapes:
        geom, pose = shape_to_msgs(shape)
        if shape.kind == "mesh":
            msg.meshes.append(geom)
            msg.mesh_poses.append(pose)
        else:
            msg.primitives.append(geom)
            msg.primitive_poses.append(pose)
    return msg


_NAMED: dict[str, CollisionObject] = {}  # planning frame -> a message with that header, operation ADD, no parts


def _named_message(obj: SceneObject, frame: str) -> CollisionObject:
    """The message of an object without its shapes and grasps (get_planning_scene's names and poses): a
    shallow copy of one template per frame, a tenth of a new message's cost (its __init__ builds every
    default sub-message). The copies share the template's header and empty lists: messages built here
    are only serialized, never changed in place."""
    template = _NAMED.get(frame)
    if template is None:
        template = CollisionObject(operation=CollisionObject.ADD)
        template.header.frame_id = frame
        template = _NAMED.setdefault(frame, template)
    msg = moved_message(template, obj)
    msg.id = obj.id
    return msg


def moved_message(before: CollisionObject, obj: SceneObject) -> CollisionObject:
    """`before` (the message of the object before a MOVE) with obj's pose: a new message (answers being
    sent may still hold `before`) sharing its header, shape and grasp lists, which a MOVE does not change."""
    msg = copy.copy(before)
    msg.pose = matrix_to_pose_msg(obj.pose)
    return msg


# ---------------------------------------------------------------------- attached objects
def attached_object_to_update(msg: AttachedCollisionObject, planning_frame: str, frame_aliases: tuple[str, ...] = (),
                              limits: SceneLimits | None = None) -> AttachUpdate:
    """AttachedCollisionObject -> AttachUpdate; raises SceneUpdateError if any part of it is invalid.

    ADD without shapes attaches the scene object `object.id` (its pose and grasps are kept, the
    message's pose is ignored, as MoveIt does); with shapes, `object.pose` is in
    `object.header.frame_id`: "" or link_name (the link frame), the planning frame, or a robot link
    (PlanningScene.apply_attach checks which). REMOVE looks only at the id."""
    raw = raw_object_from_msg(msg.object)
    frame = planning_frame if raw.frame in frame_aliases else raw.frame
    touch = tuple(msg.touch_links)
    if raw.operation == Operation.ADD and not raw.primitives and not raw.meshes:
        return AttachUpdate(msg.link_name, SceneUpdate(Operation.ADD, raw.id), touch)
    update = raw_object_to_update(replace(raw, frame=""), planning_frame, frame_aliases, limits)
    return AttachUpdate(msg.link_name, replace(update, frame=frame), touch)


def attached_object_to_msg(att: AttachedObject) -> AttachedCollisionObject:
    """An attached object as the AttachedCollisionObject (ADD, pose in the link frame) that would recreate it."""
    obj = scene_object_to_msg(SceneObject(att.id, att.pose, att.shapes, att.grasps), att.link)
    return AttachedCollisionObject(link_name=att.link, object=obj, touch_links=sorted(att.touch_links))
