"""A copy of the planning scene kept in another process, fed only what changed.

A planning worker process keeps its own copy of the scene (`SceneReplica`) and is sent, with each job,
the changes since the version it holds (`SceneFeed.delta`), not the whole scene: objects added or
changed, ids removed, the order when it changed, attached objects and the point-cloud layer when they
changed. Scene objects are immutable and an update makes a new object only for what it changes, so
"changed" is an identity test (`is`), and a MOVE keeps its object's shapes and grasps (the same
tuples): a moved object travels as id + pose. Each Shape travels once per worker (named by a token
the feed keeps alive); the replica keeps the Shape object it got, so geometry built per Shape object
(collision.geometry.scene_mesh, a mesh's BVH) is built once in the worker, not once per plan.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from humanoid_planner.core.scene.types import AttachedObject, GraspSpec, SceneObject, SceneSnapshot, Shape, VoxelLayer


@dataclass(frozen=True)
class ObjectDelta:
    """An object added or changed: its pose, its shapes by token, its grasps (None: the replica's
    object of this id keeps its own)."""

    id: str
    pose: np.ndarray
    shapes: tuple[int, ...]
    grasps: tuple[GraspSpec, ...] | None


@dataclass(frozen=True)
class AttachedDelta:
    """An attached object with its shapes by token."""

    id: str
    link: str
    pose: np.ndarray
    shapes: tuple[int, ...]
    touch_links: frozenset[str]
    grasps: tuple[GraspSpec, ...]


@dataclass(frozen=True)
class SceneDelta:
    """What turns the replica's scene into scene `version` (pickled to the worker with a job).

    reset: the replica starts from an empty scene first (a new worker, or one that lost track)."""

    version: int
    frame: str
    reset: bool = False
    shapes: dict[int, Shape] = field(default_factory=dict)  # token -> Shape the replica does not have
    dropped_shapes: tuple[int, ...] = ()  # tokens no object uses any more
    objects: tuple[ObjectDelta, ...] = ()
    removed: tuple[str, ...] = ()
    order: tuple[str, ...] | None = None  # object ids in scene order; None: as the replica's
    attached: tuple[AttachedDelta, ...] | None = None  # None: unchanged
    voxels_changed: bool = False
    voxels: VoxelLayer | None = None

    @property
    def empty(self) -> bool:
        """Nothing but the version changes (e.g. an update that was refused after all, or none at all)."""
        return not (self.reset or self.shapes or self.dropped_shapes or self.objects or self.removed
                    or self.order is not None or self.attached is not None or self.voxels_changed)

    def __reduce__(self):
        """Pickled by columns: the objects' poses and the primitives' poses as one array each, ids, tokens
        and dimensions as plain tuples. Object by object (a dataclass and a 4x4 array each) a delta of
        1,000 new boxes took 27 ms to pickle, once per worker, under a stream of updates."""
        return _unpack_delta, (self.version, self.frame, self.reset, _pack_shapes(self.shapes), self.dropped_shapes,
                               _pack_objects(self.objects), self.removed, self.order, self.attached,
                               self.voxels_changed, self.voxels)


def _frozen_stack(arrays: list[np.ndarray]) -> np.ndarray:
    out = np.array(arrays, dtype=float).reshape(len(arrays), 4, 4)
    out.setflags(write=False)
    return out


def _pack_objects(objects: tuple[ObjectDelta, ...]) -> tuple:
    return (tuple(o.id for o in objects), _frozen_stack([o.pose for o in objects]), tuple(o.shapes for o in objects),
            tuple(o.grasps for o in objects))


def _pack_shapes(shapes: dict[int, Shape]) -> tuple:
    """Primitives by columns (token, kind, dimensions, poses as one array); meshes as they are."""
    prims = [(t, s) for t, s in shapes.items() if s.kind != "mesh"]
    return (tuple(t for t, _ in prims), tuple(s.kind for _, s in prims), tuple(s.dims for _, s in prims),
            _frozen_stack([s.pose for _, s in prims]), {t: s for t, s in shapes.items() if s.kind == "mesh"})


def _unpack_delta(version, frame, reset, shapes, dropped, objects, removed, order, attached, voxels_changed,
                  voxels) -> SceneDelta:
    tokens, kinds, dims, poses, meshes = shapes
    unpacked = {t: Shape(k, p, d) for t, k, d, p in zip(tokens, kinds, dims, poses)}
    unpacked.update(meshes)
    ids, object_poses, object_shapes, grasps = objects
    return SceneDelta(version, frame, reset, unpacked, dropped,
                      tuple(map(ObjectDelta, ids, object_poses, object_shapes, grasps)), removed, order, attached,
                      voxels_changed, voxels)


class SceneFeed:
    """The sending side, one per worker: what that worker's replica holds, and the deltas to bring it
    up to a snapshot. Not thread-safe (one plan at a time per worker)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget what the worker holds: the next delta rebuilds its replica from nothing."""
        self._snapshot: SceneSnapshot | None = None
        self._objects: dict[str, SceneObject] = {}
        self._order: tuple[str, ...] = ()
        self._attached: tuple[AttachedObject, ...] = ()
        self._voxels: VoxelLayer | None = None
        self._shapes: dict[int, Shape] = {}  # token (id of the Shape here) -> Shape: keeps the id unique
        self._refs: dict[int, int] = {}  # token -> objects and attached objects using it
        self._fresh = True

    def holds(self, snap: SceneSnapshot) -> bool:
        """Whether the worker is taken to hold `snap` already (PlanningScene.snapshot() gives the same
        object while the scene is unchanged)."""
        return self._snapshot is snap

    def delta(self, snap: SceneSnapshot) -> SceneDelta:
        """The changes from what the worker holds to `snap`; from now on the worker is taken to hold
        `snap` (call `reset` if the delta never arrived)."""
        if snap is self._snapshot:
            return SceneDelta(snap.version, snap.frame)
        new_shapes: dict[int, Shape] = {}
        released: list[int] = []
        objects: list[ObjectDelta] = []
        seen = self._objects
        now: dict[str, SceneObject] = {}
        for o in snap.objects:
            now[o.id] = o
            old = seen.get(o.id)
            if old is o:
                continue
            tokens = self._tokens(o.shapes, new_shapes)
            if old is not None:
                released += [id(s) for s in old.shapes]
            same_grasps = old is not None and old.grasps is o.grasps
            objects.append(ObjectDelta(o.id, o.pose, tokens, None if same_grasps else o.grasps))
        removed = tuple(k for k in seen if k not in now)
        for k in removed:
            released += [id(s) for s in seen[k].shapes]
        order = tuple(now)
        attached = None
        if len(snap.attached) != len(self._attached) or any(a is not b for a, b in zip(snap.attached, self._attached)):
            attached = tuple(AttachedDelta(a.id, a.link, a.pose, self._tokens(a.shapes, new_shapes), a.touch_links,
                                           a.grasps) for a in snap.attached)
            released += [id(s) for a in self._attached for s in a.shapes]
        dropped = self._release(released)
        delta = SceneDelta(snap.version, snap.frame, reset=self._fresh, shapes=new_shapes, dropped_shapes=dropped,
                           objects=tuple(objects), removed=removed, order=None if order == self._order else order,
                           attached=attached, voxels_changed=snap.voxels is not self._voxels, voxels=snap.voxels)
        self._snapshot, self._objects, self._order = snap, now, order
        self._attached, self._voxels, self._fresh = snap.attached, snap.voxels, False
        return delta

    def _tokens(self, shapes: tuple[Shape, ...], new: dict[int, Shape]) -> tuple[int, ...]:
        """Tokens of `shapes` (counted as used once more); those the worker lacks go into `new`."""
        out = []
        for s in shapes:
            t = id(s)
            if t not in self._shapes:
                self._shapes[t] = s
                new[t] = s
            self._refs[t] = self._refs.get(t, 0) + 1
            out.append(t)
        return tuple(out)

    def _release(self, tokens: list[int]) -> tuple[int, ...]:
        """One use fewer of each token; the tokens no longer used are forgotten and returned."""
        dropped = []
        for t in tokens:
            left = self._refs[t] - 1
            if left:
                self._refs[t] = left
            else:
                del self._refs[t], self._shapes[t]
                dropped.append(t)
        return tuple(dropped)


class SceneReplica:
    """The receiving side, in the worker: the scene as of the last delta applied."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self._shapes: dict[int, Shape] = {}
        self._objects: dict[str, SceneObject] = {}
        self._attached: tuple[AttachedObject, ...] = ()
        self._voxels: VoxelLayer | None = None
        self._snapshot: SceneSnapshot | None = None

    @property
    def shape_count(self) -> int:
        """Shapes held (each one sent once)."""
        return len(self._shapes)

    def apply(self, d: SceneDelta) -> SceneSnapshot:
        """Apply `d` and return the scene it describes. Objects and Shapes the delta does not name are
        the same Python objects as before (their per-object caches stay valid)."""
        if d.reset:
            self.clear()
        if d.empty and self._snapshot is not None:
            if self._snapshot.version != d.version:
                self._snapshot = SceneSnapshot(d.version, d.frame, self._snapshot.objects, self._voxels, self._attached)
            return self._snapshot
        self._shapes.update(d.shapes)
        objects = self._objects
        for k in d.removed:
            del objects[k]
        for o in d.objects:
            old = objects.get(o.id)
            grasps = o.grasps if o.grasps is not None else old.grasps
            objects[o.id] = SceneObject(o.id, o.pose, tuple(self._shapes[t] for t in o.shapes), grasps)
        if d.order is not None:
            self._objects = objects = {k: objects[k] for k in d.order}
        if d.attached is not None:
            self._attached = tuple(AttachedObject(a.id, a.link, a.pose, tuple(self._shapes[t] for t in a.shapes),
                                                  a.touch_links, a.grasps) for a in d.attached)
        if d.voxels_changed:
            self._voxels = d.voxels
        for t in d.dropped_shapes:
            self._shapes.pop(t, None)
        self._snapshot = SceneSnapshot(d.version, d.frame, tuple(objects.values()), self._voxels, self._attached)
        return self._snapshot
