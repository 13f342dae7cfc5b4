"""The planning scene: a thread-safe, versioned store of collision objects and their grasp sets.

Updates follow MoveIt's CollisionObject semantics (moveit_core PlanningScene::processCollisionObjectMsg
and collision_detection::World):

- ADD: add the object, or replace an object with the same id (the old one is dropped whole).
- REMOVE: remove the object with this id; an empty id removes every object.
- APPEND: add shapes (and grasps) to an existing object, keeping its pose; the shapes' poses are in
  the object frame. A missing object is created with the update's pose.
- MOVE: change the pose of an existing object only (its shapes and grasps move with it).

Every update is validated as a whole before anything changes: an invalid one raises
`SceneUpdateError` and leaves the objects and the version exactly as they were. Every applied update
bumps `version` by one, and so does every point-cloud layer (`set_voxels`: each cloud replaces the
previous layer whole). `snapshot()` is cheap (objects are immutable) and is what a plan runs on.

Rules beyond MoveIt's (the README's "Scene limits" lists them): primitive dimensions must be finite
and >= 0 (zero is accepted, as geometric_shapes does: a flat box or a point is still an obstacle);
a contact normal must have a finite, non-zero length (a normal like (1e200, 1e200, 0), whose length
overflows, is refused rather than stored as (0, 0, 0)); a grasp without an id is named "#<k>", its
position in the object's grasp set, so ids never repeat; and `SceneLimits` bounds the work one
message can make (primitives and grasps per object, mesh triangles per message and per scene).

This module never imports ROS; the ROS layer converts messages into `SceneUpdate`s.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Callable, Collection

import numpy as np

from humanoid_planner.core.scene.checks import (SceneStateError, SceneUpdateError, check_grasp, check_grasp_ids,
                                               check_rigid, frozen, name_grasps)
from humanoid_planner.core.scene.types import (AttachedObject, GraspSpec, SceneObject, SceneSnapshot, Shape, VoxelLayer,
                                              attach, detach)

PRIMITIVE_DIMS = {"box": 3, "sphere": 1, "cylinder": 2, "cone": 2}
"""Number of dimensions per primitive kind, as shape_msgs/SolidPrimitive: box (x, y, z),
sphere (radius,), cylinder and cone (height, radius)."""

@dataclass(frozen=True)
class SceneLimits:
    """How much one message and the whole scene may hold (node parameters of the same names).

    The defaults take what real users send (a scanned shelf of a few hundred thousand triangles,
    thousands of sampled grasps) and refuse what would hold the node for seconds: a 10^6-triangle
    mesh took 29 s to apply and 20-33 s per get_planning_scene before these existed.
    """

    max_triangles_per_message: int = 500_000
    max_triangles_per_scene: int = 2_000_000
    max_primitives_per_object: int = 10_000
    max_grasps_per_object: int = 20_000

    def check_message(self, n_primitives: int, n_triangles: int, n_grasps: int, what: str) -> None:
        """Refuse a message by its counts alone (the ROS layer calls this before building arrays)."""
        if n_triangles > self.max_triangles_per_message:
            raise SceneUpdateError(f"{what}: {n_triangles} mesh triangles in one message, more than "
                                   f"max_triangles_per_message = {self.max_triangles_per_message}")
        if n_primitives > self.max_primitives_per_object:
            raise SceneUpdateError(f"{what}: {n_primitives} primitives, more than "
                                   f"max_primitives_per_object = {self.max_primitives_per_object}")
        if n_grasps > self.max_grasps_per_object:
            raise SceneUpdateError(f"{what}: {n_grasps} grasps, more than "
                                   f"max_grasps_per_object = {self.max_grasps_per_object}")


class Operation(IntEnum):
    """Values of CollisionObject.operation."""

    ADD = 0
    REMOVE = 1
    APPEND = 2
    MOVE = 3


@dataclass(frozen=True)
class SceneUpdate:
    """One CollisionObject message in core form.

    pose: the object frame in the planning frame (4x4); may be None for REMOVE.
    frame: the frame the pose is given in; "" means the planning frame.
    """

    operation: int
    id: str
    pose: np.ndarray | None = None
    shapes: tuple[Shape, ...] = ()
    grasps: tuple[GraspSpec, ...] = ()
    frame: str = ""


@dataclass(frozen=True)
class AttachUpdate:
    """One AttachedCollisionObject message in core form (MoveIt semantics).

    ADD: attach the world object `object.id` where it is now (no shapes given), or new shapes whose
    `object.pose` is in `object.frame` ("" or `link` = the link frame; the planning frame or another
    robot link also work). REMOVE: detach `object.id` back into the world where the link now holds
    it; an empty id detaches every object."""

    link: str
    object: SceneUpdate
    touch_links: tuple[str, ...] = ()


def check_shape(s: Shape, what: str) -> Shape:
    """Validate one shape; return a copy whose arrays are read-only."""
    if not isinstance(s, Shape):
        raise SceneUpdateError(f"{what}: expected a Shape, got {type(s).__name__}")
    pose = check_rigid(s.pose, f"{what} pose")
    if s.kind in PRIMITIVE_DIMS:
        n = PRIMITIVE_DIMS[s.kind]
        dims = tuple(float(d) for d in s.dims)
        if len(dims) != n:
            raise SceneUpdateError(f"{what}: a {s.kind} needs {n} dimension(s), got {len(dims)}")
        if not all(np.isfinite(dims)):
            raise SceneUpdateError(f"{what}: {s.kind} dimensions contain NaN or inf: {dims}")
        if any(d < 0.0 for d in dims):
            raise SceneUpdateError(f"{what}: negative {s.kind} dimension in {dims}")
        return Shape(kind=s.kind, pose=pose, dims=dims)
    if s.kind == "mesh":
        if s.dims:
            raise SceneUpdateError(f"{what}: a mesh has no dimensions, got {s.dims}")
        if s.vertices is None or s.triangles is None:
            raise SceneUpdateError(f"{what}: a mesh needs vertices and triangles")
        V = np.asarray(s.vertices, dtype=float)
        F = np.asarray(s.triangles)
        if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
            raise SceneUpdateError(f"{what}: mesh vertices must be a non-empty (V, 3) array, got {V.shape}")
        if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise SceneUpdateError(f"{what}: mesh triangles must be a non-empty (F, 3) array, got {F.shape}")
        if not np.issubdtype(F.dtype, np.integer):
            raise SceneUpdateError(f"{what}: mesh triangle indices must be integers")
        if not np.all(np.isfinite(V)):
            raise SceneUpdateError(f"{what}: mesh vertices contain NaN or inf")
        if F.min() < 0 or F.max() >= len(V):
            raise SceneUpdateError(
                f"{what}: mesh triangle index out of range (indices {F.min()}..{F.max()}, {len(V)} vertices)")
        return Shape(kind="mesh", pose=pose, vertices=frozen(V), triangles=frozen(F, np.int64))
    raise SceneUpdateError(f"{what}: unknown shape kind {s.kind!r} (known: {sorted(PRIMITIVE_DIMS)} and 'mesh')")


PRIMITIVE_CACHE_SIZE = 4096
"""Checked primitives a scene keeps by value (PlanningScene._checked_shape); more and it starts afresh."""


def _triangle_count(s) -> int:
    t = getattr(s, "triangles", None)
    return 0 if t is None else int(np.shape(t)[0]) if np.ndim(t) else 0


class PlanningScene:
    """Collision objects with their grasp sets, in one planning frame; thread-safe and versioned."""

    def __init__(self, frame: str, limits: SceneLimits | None = None,
                 prepare_shapes: Callable[[tuple[Shape, ...]], None] | None = None):
        """prepare_shapes: called with the checked shapes of an ADD / APPEND before the object becomes
        visible (the collision checker's per-shape work, geometry.prepare_scene_meshes), so that no plan
        of a later version pays for it; its exceptions refuse the update."""
        if not frame:
            raise ValueError("the planning scene needs a planning frame name")
        self._frame = frame
        self.limits = limits or SceneLimits()
        self._prepare_shapes = prepare_shapes
        self._lock = threading.Lock()
        self._objects: dict[str, SceneObject] = {}
        self._triangles: dict[str, int] = {}  # object id -> its mesh triangles
        self._triangle_total = 0  # their sum
        self._snapshot: SceneSnapshot | None = None  # the last one made, reused while the version holds
        self._voxels: VoxelLayer | None = None
        self._attached: dict[str, AttachedObject] = {}
        self._version = 0
        self._primitives: dict[tuple, Shape] = {}  # checked primitives by kind and exact bytes of dims and pose

    @property
    def frame(self) -> str:
        return self._frame

    @property
    def version(self) -> int:
        with self._lock:
            return self._version

    def __len__(self) -> int:
        with self._lock:
            return len(self._objects)

    def __contains__(self, object_id: str) -> bool:
        with self._lock:
            return object_id in self._objects

    def get(self, object_id: str) -> SceneObject | None:
        with self._lock:
            return self._objects.get(object_id)

    def snapshot(self) -> SceneSnapshot:
        """A frozen view of the scene at this instant (objects in insertion order)."""
        with self._lock:
            if self._snapshot is None or self._snapshot.version != self._version:
                self._snapshot = SceneSnapshot(version=self._version, frame=self._frame,
                                               objects=tuple(self._objects.values()), voxels=self._voxels,
                                               attached=tuple(self._attached.values()))
            return self._snapshot

    @property
    def voxels(self) -> VoxelLayer | None:
        """The current point-cloud layer (None before the first cloud)."""
        with self._lock:
            return self._voxels

    def set_voxels(self, layer: VoxelLayer | None) -> int:
        """Replace the point-cloud layer whole (None clears it); returns the new version.

        Raises SceneUpdateError (scene unchanged) unless the cell size is a positive finite number and
        the cells a (K, 3) integer array.
        """
        if layer is not None:
            if not isinstance(layer, VoxelLayer):
                raise SceneUpdateError(f"expected a VoxelLayer, got {type(layer).__name__}")
            if not (np.isfinite(layer.size) and layer.size > 0):
                raise SceneUpdateError(f"voxel size must be a positive finite number, got {layer.size}")
            cells = np.asarray(layer.cells)
            if cells.ndim != 2 or cells.shape[1] != 3 or not np.issubdtype(cells.dtype, np.integer):
                raise SceneUpdateError(f"voxel cells must be a (K, 3) integer array, got {cells.dtype} {cells.shape}")
            layer = VoxelLayer(float(layer.size), frozen(cells, np.int32))
        with self._lock:
            self._voxels = layer
            self._version += 1
            return self._version

    def attached(self, object_id: str) -> AttachedObject | None:
        with self._lock:
            return self._attached.get(object_id)

    # ------------------------------------------------------------------ updates
    def apply(self, update: SceneUpdate, messages: int = 1) -> int:
        """Validate and apply one update atomically; return the new version.

        `messages`: how many messages the update stands for (a MOVE that stands for earlier MOVEs of
        the same object, superseded before they were applied); the version advances by that many.
        Raises SceneUpdateError (scene unchanged) when the update is invalid as a whole.
        """
        op, oid = self._check_header(update)
        lim = self.limits
        lim.check_message(sum(s.kind != "mesh" for s in update.shapes if isinstance(s, Shape)),
                          sum(_triangle_count(s) for s in update.shapes), len(update.grasps),
                          f"{op.name} of {oid!r}")
        shapes = tuple(self._checked_shape(s, oid, i) for i, s in enumerate(update.shapes))
        grasps = tuple(check_grasp(g, f"object {oid!r} grasp {i}") for i, g in enumerate(update.grasps))
        pose = None if update.pose is None else check_rigid(update.pose, f"object {oid!r} pose")

        if op == Operation.REMOVE:
            if shapes or grasps:
                raise SceneUpdateError(f"REMOVE of {oid!r}: shapes and grasps must be empty")
        elif op == Operation.MOVE:
            if shapes:
                raise SceneUpdateError(f"MOVE of {oid!r}: changes the pose only; shapes must be empty")
            if grasps:
                raise SceneUpdateError(f"MOVE of {oid!r}: changes the pose only; grasps must be empty")
        elif not shapes:  # ADD, APPEND: as MoveIt, an object needs geometry
            raise SceneUpdateError(f"{op.name} of {oid!r}: no shapes given (primitives or meshes)")
        if op != Operation.REMOVE and pose is None:
            raise SceneUpdateError(f"{op.name} of {oid!r}: a pose is required")
        if shapes and self._prepare_shapes is not None:
            try:
                self._prepare_shapes(shapes)
            except Exception as e:  # noqa: BLE001 - e.g. a mesh FCL cannot build: the update is refused
                raise SceneUpdateError(f"{op.name} of {oid!r}: its shapes could not be prepared: {e!r}") from e

        where = f"object {oid!r}"
        with self._lock:
            # Everything is checked first, then the store changes in place: an update costs the same
            # whatever the number of objects already there (snapshots copy what they hold).
            objects, triangles = self._objects, self._triangles
            if oid in self._attached and op != Operation.REMOVE:
                raise SceneStateError(f"{op.name} of {oid!r}: the object is attached to link "
                                      f"{self._attached[oid].link!r}; detach it first (attached_collision_object REMOVE)")
            old = objects.get(oid)
            if op == Operation.ADD:
                grasps = name_grasps(grasps)
                check_grasp_ids(grasps, where)
                obj = SceneObject(id=oid, pose=pose, shapes=shapes, grasps=grasps)
            elif op == Operation.APPEND:
                if old is None:
                    grasps = name_grasps(grasps)
                    check_grasp_ids(grasps, where)
                    obj = SceneObject(id=oid, pose=pose, shapes=shapes, grasps=grasps)
                else:  # the existing pose is kept; the new shapes are in the object frame
                    merged = old.grasps + name_grasps(grasps, len(old.grasps))
                    check_grasp_ids(merged, where)
                    obj = replace(old, shapes=old.shapes + shapes, grasps=merged)
                    lim.check_message(sum(s.kind != "mesh" for s in obj.shapes), 0, len(merged),
                                      f"APPEND to {oid!r} (object after it)")
            elif op == Operation.MOVE:
                if old is None:
                    raise SceneStateError(f"MOVE of {oid!r}: no such object")
                obj = SceneObject(old.id, pose, old.shapes, old.grasps)  # dataclasses.replace: 3x the time
            elif oid and old is None:  # REMOVE
                raise SceneStateError(f"REMOVE of {oid!r}: no such object")
            if op in (Operation.ADD, Operation.APPEND):
                count = sum(_triangle_count(s) for s in obj.shapes)
                total = self._triangle_total - triangles.get(oid, 0) + count
                if total > lim.max_triangles_per_scene:
                    raise SceneUpdateError(f"{op.name} of {oid!r}: the scene would hold {total} mesh triangles, more "
                                           f"than max_triangles_per_scene = {lim.max_triangles_per_scene}")
            # -- no refusal past this line
            if op == Operation.REMOVE:
                gone = list(objects) if not oid else [oid]
                for k in gone:
                    del objects[k]
                    self._triangle_total -= triangles.pop(k, 0)  # (attached objects keep theirs)
            else:
                if op == Operation.ADD:
                    objects.pop(oid, None)  # replacing moves it to the end, as MoveIt's remove + add
                objects[oid] = obj
                if op != Operation.MOVE:
                    self._triangle_total += count - triangles.get(oid, 0)
                    triangles[oid] = count
            self._version += max(1, int(messages))
            return self._version

    def _checked_shape(self, s: Shape, oid: str, i: int) -> Shape:
        """check_shape; a primitive equal in every bit to one checked before is that same Shape object:
        objects of one size (a perception pipeline's boxes) share one Shape, checked once and sent to
        each planning worker once (scene/sync.py sends Shapes by identity)."""
        what = f"object {oid!r} shape {i}"
        if not isinstance(s, Shape) or s.kind not in PRIMITIVE_DIMS:
            return check_shape(s, what)
        try:
            dims, pose = np.asarray(s.dims, dtype=float), np.asarray(s.pose, dtype=float)
            key = (s.kind, dims.shape, dims.tobytes(), pose.shape, pose.tobytes())
        except (TypeError, ValueError):
            return check_shape(s, what)  # which says why
        hit = self._primitives.get(key)
        if hit is None:
            hit = check_shape(s, what)
            if len(self._primitives) >= PRIMITIVE_CACHE_SIZE:
                self._primitives.clear()
            self._primitives[key] = hit
        return hit

    @property
    def triangles(self) -> int:
        """Mesh triangles in the scene (bounded by limits.max_triangles_per_scene)."""
        with self._lock:
            return self._triangle_total

    def _check_header(self, update: SceneUpdate) -> tuple[Operation, str]:
        if not isinstance(update, SceneUpdate):
            raise SceneUpdateError(f"expected a SceneUpdate, got {type(update).__name__}")
        try:
            op = Operation(int(update.operation))
        except (ValueError, TypeError):
            raise SceneUpdateError(
                f"unknown operation {update.operation!r} (ADD=0, REMOVE=1, APPEND=2, MOVE=3)") from None
        oid = str(update.id)
        if not oid and op != Operation.REMOVE:
            raise SceneUpdateError(f"{op.name}: the object id must not be empty")
        if update.frame and update.frame != self._frame:
            raise SceneUpdateError(
                f"{op.name} of {oid!r}: frame {update.frame!r} is not the planning frame {self._frame!r} "
                "(give poses in the planning frame, or leave frame_id empty)")
        return op, oid

    def apply_attach(self, update: AttachUpdate, link_pose: Callable[[str], np.ndarray],
                     robot_links: Collection[str]) -> int:
        """Attach or detach (MoveIt's AttachedCollisionObject) atomically; return the new version.

        link_pose(link): the link's current 4x4 pose in the planning frame (forward kinematics at the
        latest joint state). Raises SceneUpdateError (scene unchanged) when the update is invalid."""
        if not isinstance(update, AttachUpdate):
            raise SceneUpdateError(f"expected an AttachUpdate, got {type(update).__name__}")
        obj = update.object
        try:
            op = Operation(int(obj.operation))
        except (ValueError, TypeError):
            raise SceneUpdateError(f"attached object: unknown operation {obj.operation!r} (ADD=0, REMOVE=1)") from None
        oid, link = str(obj.id), str(update.link)
        if op == Operation.REMOVE:
            with self._lock:
                if oid and oid not in self._attached:
                    raise SceneUpdateError(f"detach of {oid!r}: no such attached object")
                gone = [oid] if oid else list(self._attached)
                back = {k: detach(self._attached[k], link_pose(self._attached[k].link)) for k in gone}
                self._attached = {k: v for k, v in self._attached.items() if k not in back}
                self._objects = {**{k: v for k, v in self._objects.items() if k not in back}, **back}
                self._version += 1
                return self._version
        if op != Operation.ADD:
            raise SceneUpdateError(f"attached object {oid!r}: operation {op.name} is not supported (ADD or REMOVE)")
        if not oid:
            raise SceneUpdateError("attach: the object id must not be empty")
        if link not in robot_links:
            raise SceneUpdateError(f"attach of {oid!r}: {link!r} is not a link of the robot")
        if oid in robot_links:
            raise SceneUpdateError(f"attach of {oid!r}: the id is the name of a robot link; choose another")
        unknown = sorted(set(update.touch_links) - set(robot_links))
        if unknown:
            raise SceneUpdateError(f"attach of {oid!r}: touch_links {unknown} are not links of the robot")
        self.limits.check_message(sum(s.kind != "mesh" for s in obj.shapes if isinstance(s, Shape)),
                                  sum(_triangle_count(s) for s in obj.shapes), len(obj.grasps), f"attach of {oid!r}")
        shapes = tuple(check_shape(s, f"attached object {oid!r} shape {i}") for i, s in enumerate(obj.shapes))
        grasps = name_grasps(tuple(check_grasp(g, f"attached object {oid!r} grasp {i}")
                                   for i, g in enumerate(obj.grasps)))
        check_grasp_ids(grasps, f"attached object {oid!r}")
        touch = frozenset(update.touch_links)
        if shapes:
            pose = check_rigid(np.eye(4) if obj.pose is None else obj.pose, f"attached object {oid!r} pose")
            if obj.frame in ("", link):
                T_link = pose
            elif obj.frame == self._frame:
                T_link = np.linalg.inv(link_pose(link)) @ pose
            elif obj.frame in robot_links:
                T_link = np.linalg.inv(link_pose(link)) @ link_pose(obj.frame) @ pose
            else:
                raise SceneUpdateError(f"attach of {oid!r}: unknown frame {obj.frame!r} (the planning frame, "
                                       "a robot link, or empty for link_name's frame)")
            new = AttachedObject(oid, link, frozen(T_link), shapes, touch, grasps)
        with self._lock:
            if not shapes:
                if oid in self._attached:  # re-attach: to the new link, where it is now
                    held = self._attached[oid]
                    new = attach(detach(held, link_pose(held.link)), link, link_pose(link), touch)
                elif oid in self._objects:
                    new = attach(self._objects[oid], link, link_pose(link), touch)
                else:
                    raise SceneUpdateError(f"attach of {oid!r}: no such object in the scene and no shapes given")
                if grasps:
                    new = replace(new, grasps=grasps)
            triangles = self._triangles
            if shapes:  # new geometry replaces whatever the id held
                triangles = {**triangles, oid: sum(_triangle_count(s) for s in shapes)}
                if sum(triangles.values()) > self.limits.max_triangles_per_scene:
                    raise SceneUpdateError(f"attach of {oid!r}: the scene would hold more than max_triangles_per_scene "
                                           f"= {self.limits.max_triangles_per_scene} mesh triangles")
            self._objects = {k: v for k, v in self._objects.items() if k != oid}
            self._attached = {**{k: v for k, v in self._attached.items() if k != oid}, oid: new}
            self._triangles = triangles
            self._triangle_total = sum(triangles.values())
            self._version += 1
            return self._version

    # ------------------------------------------------------------------ conveniences
    def add(self, object_id: str, pose, shapes, grasps=()) -> int:
        """ADD (or replace) an object; returns the new version."""
        return self.apply(SceneUpdate(Operation.ADD, object_id, pose, tuple(shapes), tuple(grasps)))

    def append(self, object_id: str, shapes, grasps=(), pose=None) -> int:
        """APPEND shapes/grasps to an object (pose used only when it is created; default identity)."""
        return self.apply(SceneUpdate(Operation.APPEND, object_id, np.eye(4) if pose is None else pose,
                                      tuple(shapes), tuple(grasps)))

    def move(self, object_id: str, pose) -> int:
        """MOVE an existing object to a new pose; returns the new version."""
        return self.apply(SceneUpdate(Operation.MOVE, object_id, pose))

    def remove(self, object_id: str = "") -> int:
        """REMOVE one object, or every object when object_id is empty; returns the new version."""
        return self.apply(SceneUpdate(Operation.REMOVE, object_id))


__all__ = ["AttachUpdate", "Operation", "PlanningScene", "SceneLimits", "SceneUpdate", "SceneUpdateError", "PRIMITIVE_DIMS",
           "check_shape"]
