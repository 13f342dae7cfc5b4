"""Immutable value types of the planning scene, shared by the scene store, collision and planners.

These mirror the interface package's ROS messages in plain numpy form so that the core never touches
rclpy. All poses are 4x4 matrices in the planning frame (object poses) or in the object frame
(shape poses, grasps, contacts). Values are validated before these are built.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

SHAPE_KINDS = ("box", "sphere", "cylinder", "cone", "mesh")


@dataclass(frozen=True)
class Shape:
    """One primitive or mesh of an object.

    dims follow shape_msgs/SolidPrimitive: box (x, y, z), sphere (r,), cylinder and cone
    (height, radius); a mesh has vertices (V, 3) and triangles (F, 3) and empty dims.
    """

    kind: str
    pose: np.ndarray  # 4x4, in the object frame
    dims: tuple[float, ...] = ()
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None


@dataclass(frozen=True)
class GraspSpec:
    """A candidate grasp: T_world_tcp = T_world_object @ tcp_in_object."""

    id: str
    hand: str  # SRDF end effector or group name; "" = any hand
    tcp_in_object: np.ndarray  # 4x4
    contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (k, 3), object frame
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (k, 3) inward unit normals
    friction: float = 0.0  # 0 = use the planner default


def shape_radius(shape: Shape) -> float:
    """Radius of a ball about the shape's origin that contains it."""
    d = shape.dims
    if shape.kind == "box":
        return 0.5 * math.sqrt(sum(float(x) * float(x) for x in d))
    if shape.kind == "sphere":
        return float(d[0])
    if shape.kind in ("cylinder", "cone"):
        return float(np.hypot(0.5 * d[0], d[1]))
    v = shape.vertices
    return float(np.linalg.norm(v, axis=1).max()) if v is not None and len(v) else 0.0


@dataclass(frozen=True)
class SceneObject:
    """A collision object with its grasp set."""

    id: str
    pose: np.ndarray  # 4x4, object frame in the planning frame
    shapes: tuple[Shape, ...] = ()
    grasps: tuple[GraspSpec, ...] = ()

    @cached_property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """(centre in the planning frame, radius) of a ball containing every shape: computed once per
        object (a scene update makes a new object only for what it changes), so that a checker culls
        objects out of a group's reach at a few microseconds each instead of building them."""
        if not self.shapes:
            return np.asarray(self.pose, float)[:3, 3].copy(), 0.0
        if len(self.shapes) == 1:  # most objects (a box): a tenth of the general case's numpy calls
            T, s = np.asarray(self.pose, float), self.shapes[0]
            return T[:3, :3] @ np.asarray(s.pose, float)[:3, 3] + T[:3, 3], shape_radius(s)
        centres = np.array([(np.asarray(self.pose, float) @ np.asarray(s.pose, float))[:3, 3] for s in self.shapes])
        radii = np.array([shape_radius(s) for s in self.shapes])
        c = centres.mean(axis=0)
        return c, float((np.linalg.norm(centres - c, axis=1) + radii).max())


@dataclass(frozen=True, eq=False)
class VoxelLayer:
    """Occupied cells of the point-cloud layer, in the planning frame.

    Cell (i, j, k) is the cube [i, i+1) x [j, j+1) x [k, k+1) times `size`: a fixed lattice, so that
    the collision checker can index cells instead of searching them. `cells` is (K, 3) int32, unique.
    Compared by identity (eq=False), so per-layer caches (the checker's occupancy grid) key on it.
    """

    size: float
    cells: np.ndarray

    def __len__(self) -> int:
        return len(self.cells)

    @property
    def centers(self) -> np.ndarray:
        """(K, 3) cube centres (m)."""
        return (self.cells + 0.5) * self.size


@dataclass(frozen=True)
class AttachedObject:
    """An object held by the robot (MoveIt's AttachedCollisionObject): its shapes ride on `link`.

    shapes are posed in the link frame, so forward kinematics moves them with the link; the object
    is checked against the world and every robot link except `link` and `touch_links`. grasps are
    kept (object frame) so that a detached object gets its grasp set back.
    """

    id: str
    link: str
    pose: np.ndarray  # 4x4, object frame in the link frame
    shapes: tuple[Shape, ...] = ()
    touch_links: frozenset[str] = frozenset()
    grasps: tuple[GraspSpec, ...] = ()

    @property
    def allowed_links(self) -> frozenset[str]:
        """Links it may touch: touch_links and the holding link."""
        return self.touch_links | {self.link}

    def in_link_frame(self) -> tuple[Shape, ...]:
        """Its shapes with poses in the link frame (object pose folded in)."""
        return tuple(Shape(s.kind, self.pose @ s.pose, s.dims, s.vertices, s.triangles) for s in self.shapes)


def attach(obj: SceneObject, link: str, T_world_link: np.ndarray, touch_links=()) -> AttachedObject:
    """A world object taken into the hand where it is now: its pose re-expressed in the link frame."""
    T = np.linalg.inv(np.asarray(T_world_link, float)) @ np.asarray(obj.pose, float)
    return AttachedObject(obj.id, link, T, obj.shapes, frozenset(touch_links), obj.grasps)


def detach(att: AttachedObject, T_world_link: np.ndarray) -> SceneObject:
    """The object put back into the world where the link now holds it."""
    return SceneObject(att.id, np.asarray(T_world_link, float) @ att.pose, att.shapes, att.grasps)


@dataclass(frozen=True)
class SceneSnapshot:
    """A frozen, versioned view of the scene: what one plan is made against.

    attached: objects held by the robot; every collision checker built on the snapshot carries them."""

    version: int
    frame: str
    objects: tuple[SceneObject, ...] = ()
    voxels: VoxelLayer | None = None  # the point-cloud layer; None: no cloud yet
    attached: tuple[AttachedObject, ...] = ()

    @cached_property
    def object_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) centres and (N,) radii of the objects' bounding balls, built once per snapshot: each
        collision checker a plan builds culls the scene against them in one array operation."""
        spheres = [o.bounding_sphere for o in self.objects]
        return (np.array([c for c, _ in spheres], dtype=float).reshape(len(spheres), 3),
                np.array([r for _, r in spheres], dtype=float))

    @cached_property
    def _near_cache(self) -> dict[bytes, np.ndarray]:
        return {}

    def objects_near(self, centres: np.ndarray, radii: np.ndarray, gap: float) -> np.ndarray:
        """(N,) bool: the objects whose bounding ball comes within `gap` of one of the balls (centres
        (B, 3), radii (B,)). Cached per snapshot and balls (the checkers of one plan ask alike); the
        objects outside one ball around all of them are dropped first, so a scene of far objects costs
        one distance per object, not one per object and ball."""
        centres = np.asarray(centres, dtype=float).reshape(-1, 3)
        radii = np.asarray(radii, dtype=float).reshape(-1)
        key = centres.tobytes() + radii.tobytes() + np.float64(gap).tobytes()
        hit = self._near_cache.get(key)
        if hit is not None:
            return hit
        oc, orad = self.object_spheres
        near = np.zeros(len(oc), dtype=bool)
        if len(oc) and len(centres):
            mid = 0.5 * (centres.min(axis=0) + centres.max(axis=0))
            reach = float((np.linalg.norm(centres - mid, axis=1) + radii).max())
            d = oc - mid
            # a ball's gap to every ball is at least its gap to the one around all (triangle
            # inequality); the 1e-9 m keeps rounding at that bound on the side of the exact test
            maybe = np.flatnonzero(np.sqrt(np.einsum("ni,ni->n", d, d)) - orad <= reach + gap + 1e-9)
            if len(maybe):
                gaps = np.linalg.norm(oc[maybe, None, :] - centres[None], axis=-1) - radii[None] - orad[maybe, None]
                near[maybe] = (gaps <= gap).any(axis=1)
        near.flags.writeable = False
        self._near_cache[key] = near
        return near

    @cached_property
    def _by_id(self) -> dict[str, SceneObject]:
        return {o.id: o for o in reversed(self.objects)}  # reversed: the first of a repeated id wins

    def get(self, object_id: str) -> SceneObject | None:
        """The object of this id (a dict built once per snapshot: a plan looks objects up several times,
        and a scan of 3,000 objects is a tenth of a millisecond each)."""
        return self._by_id.get(object_id)
