"""Immutable value types of the planning scene, shared by the scene store, collision and planners.

These mirror the interface package's ROS messages in plain numpy form so that the core never touches
rclpy. All poses are 4x4 matrices in the planning frame (object poses) or in the object frame
(shape poses, grasps, contacts). Values are validated before these are built.
"""
from __future__ import annotations

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
        return 0.5 * float(np.linalg.norm(d))
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

    def get(self, object_id: str) -> SceneObject | None:
        for o in self.objects:
            if o.id == object_id:
                return o
        return None
