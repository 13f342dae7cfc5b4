"""A reference model of the README's planning-scene rules, and a seeded generator of hostile
CollisionObject messages — shared by the reliability tests and `make soak` (scripts/soak.py).

The model is written from the README ("The planning scene", "Limits"), not from the code: plain
Python over message objects, an ordered dict of objects, one rule per line. The node (or the core
pipeline) and the model must agree, message by message, on accepted or rejected and on the scene.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from geometry_msgs.msg import Point, Pose, Vector3
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive

from humanoid_planner_interfaces.msg import CollisionObject, Grasp

FRAME = "base_link"
DIMS = {1: 3, 2: 1, 3: 2, 4: 2}  # box, sphere, cylinder, cone


@dataclass(frozen=True)
class Limits:
    triangles_per_message: int = 500_000
    triangles_per_scene: int = 2_000_000
    primitives_per_object: int = 10_000
    grasps_per_object: int = 20_000


@dataclass
class ModelObject:
    position: tuple[float, float, float]
    primitives: int
    meshes: int
    triangles: int
    grasp_ids: list[str] = field(default_factory=list)


def _finite(*xs) -> bool:
    return all(math.isfinite(x) for x in xs)


def _pose_ok(p: Pose) -> bool:
    o, q = p.position, p.orientation
    if not _finite(o.x, o.y, o.z, q.x, q.y, q.z, q.w):
        return False
    return abs(math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) - 1.0) <= 1e-3


def _normal_ok(n: Vector3) -> bool:
    """Finite, not zero, and its length does not overflow a float64 (e.g. (1e200, 1e200, 0))."""
    if not _finite(n.x, n.y, n.z):
        return False
    square = n.x * n.x + n.y * n.y + n.z * n.z
    return math.isfinite(square) and math.sqrt(square) >= 1e-9


def _grasp_ok(g: Grasp) -> bool:
    return (_pose_ok(g.tcp_in_object) and len(g.contacts) == len(g.normals)
            and all(_finite(c.x, c.y, c.z) for c in g.contacts) and all(_normal_ok(n) for n in g.normals)
            and math.isfinite(g.friction) and g.friction >= 0.0)


def _named(ids: list[str], first: int) -> list[str]:
    return [gid if gid else f"#{first + k}" for k, gid in enumerate(ids)]


class SceneModel:
    """The scene as the README says it behaves."""

    def __init__(self, limits: Limits = Limits(), frames: tuple[str, ...] = ("", FRAME)):
        self.limits = limits
        self.frames = frames
        self.objects: dict[str, ModelObject] = {}
        self.version = 0

    def apply(self, m: CollisionObject) -> bool:
        """Apply one message; True if accepted (the version moves by one)."""
        ok = self._apply(m)
        if ok:
            self.version += 1
        return ok

    def _apply(self, m: CollisionObject) -> bool:
        lim = self.limits
        tri = sum(len(mesh.triangles) for mesh in m.meshes)
        if tri > lim.triangles_per_message or len(m.primitives) > lim.primitives_per_object \
                or len(m.grasps) > lim.grasps_per_object:
            return False
        op = m.operation
        if op not in (0, 1, 2, 3):
            return False
        if op == 1:  # REMOVE: only the id matters
            if m.id == "":
                self.objects.clear()
                return True
            return self.objects.pop(m.id, None) is not None
        if m.id == "" or m.header.frame_id not in self.frames:
            return False
        if op == 3 and (m.primitives or m.meshes or m.primitive_poses or m.mesh_poses or m.grasps):
            return False
        if len(m.primitives) != len(m.primitive_poses) or len(m.meshes) != len(m.mesh_poses):
            return False
        if not _pose_ok(m.pose):
            return False
        for p, pp in zip(m.primitives, m.primitive_poses):
            if p.type not in DIMS or len(p.dimensions) != DIMS[p.type] or not _pose_ok(pp):
                return False
            if not all(math.isfinite(d) and d >= 0.0 for d in p.dimensions):
                return False
        for mesh, mp in zip(m.meshes, m.mesh_poses):
            if not mesh.vertices or not mesh.triangles or not _pose_ok(mp):
                return False
            if not all(_finite(v.x, v.y, v.z) for v in mesh.vertices):
                return False
            if max(max(t.vertex_indices) for t in mesh.triangles) >= len(mesh.vertices):
                return False
        if not all(_grasp_ok(g) for g in m.grasps):
            return False
        position = (m.pose.position.x, m.pose.position.y, m.pose.position.z)
        if op == 3:  # MOVE
            if m.id not in self.objects:
                return False
            self.objects[m.id].position = position
            return True
        if not m.primitives and not m.meshes:  # ADD / APPEND need shapes
            return False
        old = self.objects.get(m.id) if op == 2 else None
        if old is None:
            new = ModelObject(position, len(m.primitives), len(m.meshes), tri, _named([g.id for g in m.grasps], 0))
        else:
            new = ModelObject(old.position, old.primitives + len(m.primitives), old.meshes + len(m.meshes),
                              old.triangles + tri, old.grasp_ids + _named([g.id for g in m.grasps], len(old.grasp_ids)))
            if new.primitives > lim.primitives_per_object or len(new.grasp_ids) > lim.grasps_per_object:
                return False
        if len(set(new.grasp_ids)) != len(new.grasp_ids):
            return False
        others = sum(o.triangles for k, o in self.objects.items() if k != m.id)
        if others + new.triangles > lim.triangles_per_scene:
            return False
        if op == 0:
            self.objects.pop(m.id, None)  # ADD replaces: the object moves to the end
        self.objects[m.id] = new
        return True

    def state(self) -> list[tuple]:
        """(id, position, primitives, meshes, grasp ids) of every object, in order."""
        return [(k, o.position, o.primitives, o.meshes, tuple(o.grasp_ids)) for k, o in self.objects.items()]


def state_of(objects) -> list[tuple]:
    """The same view of get_planning_scene's CollisionObjects."""
    return [(o.id, (o.pose.position.x, o.pose.position.y, o.pose.position.z), len(o.primitives), len(o.meshes),
             tuple(g.id for g in o.grasps)) for o in objects]


def same_state(a: list[tuple], b: list[tuple]) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if x[0] != y[0] or x[2:] != y[2:] or any(abs(p - q) > 1e-9 for p, q in zip(x[1], y[1])):
            return False
    return True


# ------------------------------------------------------------------------------- hostile messages
WEIRD = (math.nan, math.inf, -math.inf, 1e308, -0.0, 5e-324, 1e200)


class MessageFuzzer:
    """Seeded random CollisionObject messages: mostly valid, each field sometimes hostile."""

    def __init__(self, seed: int, ids=("a", "b", "c", "d", "")):
        self.rng = random.Random(seed)
        self.ids = ids

    def _num(self, good: float, p: float = 0.02) -> float:
        return self.rng.choice(WEIRD) if self.rng.random() < p else good

    def pose(self, p_bad: float = 0.03) -> Pose:
        r = self.rng
        pose = Pose()
        pose.position = Point(x=self._num(r.uniform(-1, 1)), y=self._num(r.uniform(-1, 1)), z=self._num(r.uniform(0, 2)))
        q = [r.gauss(0, 1) for _ in range(4)]
        n = math.sqrt(sum(x * x for x in q)) or 1.0
        q = [x / n for x in q]
        if r.random() < p_bad:
            q = r.choice(([0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 2.0], [q[0] * 1.0005, q[1], q[2], q[3]],
                          [math.nan, 0.0, 0.0, 1.0]))
        elif r.random() < 0.1:  # a small deviation that is normalized
            q = [x * (1 + 5e-4) for x in q]
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = q
        return pose

    def primitive(self) -> SolidPrimitive:
        r = self.rng
        t = r.choice((1, 2, 3, 4)) if r.random() > 0.03 else r.choice((0, 5, 9))
        n = DIMS.get(t, 3) if r.random() > 0.03 else r.randint(0, 3)
        dims = [self._num(r.choice((r.uniform(0.01, 0.3), 0.0, -0.1 if r.random() < 0.2 else 0.05)), 0.03)
                for _ in range(n)]
        return SolidPrimitive(type=t, dimensions=dims)

    def mesh(self) -> Mesh:
        r = self.rng
        nv = r.randint(0, 6) if r.random() < 0.05 else r.randint(3, 8)
        nt = 0 if r.random() < 0.03 else r.randint(1, 6)
        verts = [Point(x=self._num(r.uniform(-0.1, 0.1), 0.01), y=r.uniform(-0.1, 0.1), z=r.uniform(0, 0.1))
                 for _ in range(nv)]
        hi = nv if r.random() < 0.05 else max(nv - 1, 0)
        tris = [MeshTriangle(vertex_indices=[r.randint(0, hi), r.randint(0, hi), r.randint(0, hi)]) for _ in range(nt)]
        return Mesh(vertices=verts, triangles=tris)

    def grasp(self) -> Grasp:
        r = self.rng
        k = r.randint(0, 3)
        g = Grasp(id=r.choice(("", "", "g1", "g2", "#0", "#1", "top")), hand=r.choice(("", "left_hand")),
                  tcp_in_object=self.pose(0.02), friction=r.choice((0.0, 0.5, self._num(0.4, 0.05), -0.1
                                                                     if r.random() < 0.05 else 0.3)))
        g.contacts = [Point(x=self._num(r.uniform(-0.05, 0.05), 0.01), y=0.0, z=0.0) for _ in range(k)]
        normals = []
        for _ in range(k + (1 if r.random() < 0.03 else 0)):
            roll = r.random()
            if roll < 0.02:
                normals.append(Vector3(x=1e200, y=1e200, z=0.0))
            elif roll < 0.04:
                normals.append(Vector3())
            else:
                normals.append(Vector3(x=self._num(r.uniform(-1, 1), 0.01), y=r.uniform(-1, 1), z=1.0))
        g.normals = normals
        return g

    def message(self) -> CollisionObject:
        r = self.rng
        m = CollisionObject()
        roll = r.random()
        m.operation = 0 if roll < 0.45 else 2 if roll < 0.6 else 3 if roll < 0.75 else 1 if roll < 0.98 else r.choice(
            (4, -1, 100))
        m.id = r.choice(self.ids)
        m.header.frame_id = FRAME if r.random() < 0.5 else ("" if r.random() < 0.95 else r.choice(("world", "odom")))
        m.pose = self.pose()
        shapes = r.random() > (0.7 if m.operation in (1, 3) else 0.05)
        if shapes:
            m.primitives = [self.primitive() for _ in range(r.randint(0, 3))]
            m.primitive_poses = [self.pose(0.01) for _ in range(len(m.primitives) + (r.random() < 0.03))]
            m.meshes = [self.mesh() for _ in range(r.randint(0, 2) if r.random() < 0.3 else 0)]
            m.mesh_poses = [self.pose(0.01) for _ in m.meshes]
        if r.random() < (0.5 if m.operation in (0, 2) else 0.05):
            m.grasps = [self.grasp() for _ in range(r.randint(1, 4))]
        return m
