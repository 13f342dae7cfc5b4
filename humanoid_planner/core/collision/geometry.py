"""Shapes → the collision representations the checker uses.

* exact: python-fcl geometries (primitives stay primitives, meshes become OBBRSS BVH models);
* containing (to call pairs free): sphere covers (every point of the shape lies in the union of its
  spheres) and rounded oriented boxes (points within `rounding` of an OBB);
* contained (to prove collisions): inner spheres of primitives;
* prefilter units: how one link's shapes are grouped (group_shapes) and when a unit's rounded box
  is its exact geometry (box_is_tight: boxes, spheres, capsules).

Sphere covers and fcl geometries of a robot depend only on the robot, so they are built once per
RobotModel (``RobotCollisionModel.for_robot``) and shared by every checker; a checker only creates
its own, cheap, fcl CollisionObjects (they hold mutable transforms).

FCL treats meshes as triangle soups (surfaces), so a mesh's cover only has to contain its triangles;
each triangle lies in a sphere that contains its three vertices (balls are convex).
"""
from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import fcl
import numpy as np

from humanoid_planner.core.collision.fcl_objects import PRIMITIVES, CollisionObjectPool
from humanoid_planner.core.collision.table_cache import RecentCache, TableCache
from humanoid_planner.core.model.robot import LinkGeometry, RobotModel
from humanoid_planner.core.scene.types import AttachedObject, SceneObject, Shape

DEFAULT_SPHERE_TOLERANCE = 0.02
"""Target overshoot (m) of a sphere cover beyond its shape: smaller means more spheres, fewer exact checks."""
MAX_SPHERES_PER_SHAPE = 32
"""Largest sphere cover of one primitive: a thin long shape stops here and overshoots more instead (level 2 tests
every sphere of a flagged unit, so its cost grows with the count; FCL decides what the overshoot lets through)."""


@dataclass(frozen=True)
class SphereCover:
    """Spheres (centers (S, 3) in the owning frame, radii (S,)) whose union contains a shape."""

    centers: np.ndarray
    radii: np.ndarray

    def transformed(self, T: np.ndarray) -> "SphereCover":
        return SphereCover(self.centers @ T[:3, :3].T + T[:3, 3], self.radii)


@dataclass(frozen=True)
class BoundingBox:
    """Rounded OBB: points within `rounding` of the box (pose 4x4, half extents (3,)) contain the shape."""

    pose: np.ndarray
    half: np.ndarray
    rounding: float = 0.0

    def transformed(self, T: np.ndarray) -> "BoundingBox":
        return BoundingBox(T @ self.pose, self.half, self.rounding)


# ----------------------------------------------------------------------------- fcl geometry
def fcl_mesh(vertices: np.ndarray, triangles: np.ndarray) -> fcl.BVHModel:
    m = fcl.BVHModel()
    m.beginModel(len(vertices), len(triangles))
    m.addSubModel(np.ascontiguousarray(vertices, dtype=float), np.ascontiguousarray(triangles, dtype=np.int32))
    m.endModel()
    return m


def link_geometry_primitive(g: LinkGeometry) -> tuple[str, tuple[float, ...]] | None:
    """(fcl primitive kind, its arguments) of URDF dims — box sizes, sphere (r,), cylinder
    (radius, length) —; None for a mesh."""
    if g.kind == "box":
        return "box", tuple(g.dims[:3])
    if g.kind == "sphere":
        return "sphere", (g.dims[0],)
    if g.kind == "cylinder":
        return "cylinder", (g.dims[0], g.dims[1])
    if g.kind == "mesh":
        return None
    raise ValueError(f"unknown link geometry kind {g.kind!r}")


def shape_primitive(s: Shape) -> tuple[str, tuple[float, ...]] | None:
    """(fcl primitive kind, its arguments) of shape_msgs dims — box (x, y, z), sphere (r,), cylinder
    and cone (height, radius) —; None for a mesh."""
    if s.kind == "box":
        return "box", tuple(s.dims[:3])
    if s.kind == "sphere":
        return "sphere", (s.dims[0],)
    if s.kind in ("cylinder", "cone"):
        return s.kind, (s.dims[1], s.dims[0])
    if s.kind == "mesh":
        return None
    raise ValueError(f"unknown shape kind {s.kind!r}")


def fcl_from_link_geometry(g: LinkGeometry) -> fcl.CollisionGeometry:
    """URDF dims: box sizes, sphere (r,), cylinder (radius, length)."""
    prim = link_geometry_primitive(g)
    return fcl_mesh(g.vertices, g.triangles) if prim is None else PRIMITIVES[prim[0]](*prim[1])


def fcl_from_shape(s: Shape) -> fcl.CollisionGeometry:
    """shape_msgs dims: box (x, y, z), sphere (r,), cylinder and cone (height, radius). A mesh's BVH is
    built once per Shape object (scene_mesh)."""
    prim = shape_primitive(s)
    return scene_mesh(s).geometry if prim is None else PRIMITIVES[prim[0]](*prim[1])


MESH_PIECE_TRIANGLES = 8192
"""Scene meshes with more triangles are split into spatially coherent pieces of at most this many,
each with its own BVH and bounding box. python-fcl builds a BVH holding the interpreter lock (7 s for
1.3·10^6 triangles): built piece by piece, every other thread runs between pieces (a piece takes
~50 ms), and a piece's box lets the checker skip the parts of a big mesh no link comes near."""


@dataclass(frozen=True)
class SceneMesh:
    """What the checker needs of a scene mesh Shape, built once per Shape object: its BVH and OBB (object
    frame), or, above MESH_PIECE_TRIANGLES, its pieces (mesh Shapes with the same pose, each a SceneMesh)."""

    geometry: fcl.BVHModel | None
    box: BoundingBox | None
    pieces: tuple[Shape, ...] = ()


_SCENE_MESHES: dict[int, SceneMesh] = {}  # id(Shape) -> SceneMesh, dropped when the Shape is collected
_SCENE_MESH_LOCK = threading.Lock()


def scene_mesh(s: Shape) -> SceneMesh:
    """The SceneMesh of a mesh Shape; scene shapes are immutable, so it is built on first use (by the
    scene thread when the object arrives, see prepare_scene_meshes) and shared by every checker."""
    hit = _SCENE_MESHES.get(id(s))
    if hit is not None:
        return hit
    tri = np.asarray(s.triangles)
    if len(tri) > MESH_PIECE_TRIANGLES:
        mesh = SceneMesh(None, None, tuple(Shape("mesh", s.pose, (), v, t) for v, t in _mesh_pieces(
            np.asarray(s.vertices, float), tri)))
    else:
        pose, half = mesh_obb(s.vertices)
        mesh = SceneMesh(fcl_mesh(s.vertices, tri), BoundingBox(s.pose @ pose, half))
    with _SCENE_MESH_LOCK:
        hit = _SCENE_MESHES.get(id(s))
        if hit is not None:  # built meanwhile by another thread
            return hit
        _SCENE_MESHES[id(s)] = mesh
        weakref.finalize(s, _SCENE_MESHES.pop, id(s), None)
    for piece in mesh.pieces:
        scene_mesh(piece)
    return mesh


def _mesh_pieces(vertices: np.ndarray, triangles: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Triangles split at the median centroid along the longest extent until each part has at most
    MESH_PIECE_TRIANGLES; each part with only the vertices it uses, re-indexed."""
    centroids = vertices[triangles].mean(axis=1)
    todo, parts = [np.arange(len(triangles))], []
    while todo:
        idx = todo.pop()
        if len(idx) <= MESH_PIECE_TRIANGLES:
            parts.append(idx)
            continue
        c = centroids[idx]
        axis = int(np.argmax(c.max(0) - c.min(0)))
        half = len(idx) // 2
        order = np.argpartition(c[:, axis], half)
        todo += [idx[order[:half]], idx[order[half:]]]
    out = []
    for idx in parts:
        used, local = np.unique(triangles[idx], return_inverse=True)
        out.append((vertices[used], local.reshape(-1, 3)))
    return out


def prepare_scene_meshes(shapes: tuple[Shape, ...]) -> None:
    """Build the SceneMesh of every mesh among `shapes` now: the node's PlanningScene calls this before an
    object it adds becomes visible (PlanningScene's prepare_shapes), so that no plan pays for it."""
    for s in shapes:
        if s.kind == "mesh":
            scene_mesh(s)


def fcl_transform(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


# ----------------------------------------------------------------------------- bounding boxes
def _primitive_half(kind: str, radius: float = 0.0, length: float = 0.0, sizes=None) -> tuple[np.ndarray, float]:
    if kind == "box":
        return 0.5 * np.asarray(sizes, float), 0.0
    if kind == "sphere":
        return np.zeros(3), radius
    if kind in ("cylinder", "cone"):  # both centred on their axis (z), from -length/2 to +length/2
        return np.array([radius, radius, 0.5 * length]), 0.0
    raise ValueError(kind)


def cylinder_bound(radius: float, length: float) -> tuple[np.ndarray, float]:
    """Half extents and rounding of the smaller of a cylinder's OBB and its capsule (exact at the sides)."""
    box_volume = 4 * radius * radius * length
    capsule_volume = np.pi * radius * radius * length + 4.0 / 3.0 * np.pi * radius ** 3
    if capsule_volume < box_volume:
        return np.array([0.0, 0.0, 0.5 * length]), radius
    return np.array([radius, radius, 0.5 * length]), 0.0


def union_box(boxes: list[BoundingBox]) -> BoundingBox:
    """A rounded box containing rounded boxes (same frame): axes of the largest, rounding of the least
    rounded; a capsule made of a cylinder and two end spheres comes out exact."""
    if len(boxes) == 1:
        return boxes[0]
    ref = max(boxes, key=lambda b: float(np.prod(2 * b.half + 2 * b.rounding)))
    rho = min(b.rounding for b in boxes)
    R, o = ref.pose[:3, :3], ref.pose[:3, 3]
    pts = []
    for b in boxes:
        corners = np.array(np.meshgrid(*[[-h, h] for h in b.half], indexing="ij")).reshape(3, -1).T
        local = (corners @ b.pose[:3, :3].T + b.pose[:3, 3] - o) @ R  # in the reference box frame
        grow = b.rounding - rho  # the extra rounding, bounded by an axis-aligned margin
        pts += [local - grow, local + grow]
    pts = np.concatenate(pts)
    lo, hi = pts.min(0), pts.max(0)
    pose = ref.pose.copy()
    pose[:3, 3] = o + R @ (0.5 * (lo + hi))
    return BoundingBox(pose, 0.5 * (hi - lo), rho)


def mesh_obb(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose (4x4, in the mesh frame) and half extents of an OBB containing every vertex.

    Axes from PCA of the convex-hull vertices: ~100× cheaper than trimesh's minimum-volume OBB and
    at most 1.6× its volume on TALOS's link meshes.
    """
    v = np.unique(np.asarray(vertices, float), axis=0)
    pts = v
    if len(v) > 4:
        try:
            from scipy.spatial import ConvexHull

            pts = v[ConvexHull(v).vertices]
        except Exception:  # flat or degenerate: PCA of all vertices
            pts = v
    mean = pts.mean(0)
    d = pts - mean
    R = np.linalg.eigh(d.T @ d)[1][:, ::-1].copy()  # principal axes, largest first
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    local = (v - mean) @ R
    lo, hi = local.min(0), local.max(0)
    pose = np.eye(4)
    pose[:3, :3] = R
    pose[:3, 3] = mean + R @ (0.5 * (lo + hi))
    return pose, 0.5 * (hi - lo)


def link_geometry_box(g: LinkGeometry) -> BoundingBox:
    """OBB of one link shape, in the link frame."""
    if g.kind == "mesh":
        pose, half = mesh_obb(g.vertices)
        return BoundingBox(g.origin @ pose, half)
    if g.kind == "cylinder":
        return BoundingBox(np.array(g.origin, float), *cylinder_bound(g.dims[0], g.dims[1]))
    elif g.kind == "sphere":
        half, rho = _primitive_half("sphere", g.dims[0])
    else:
        half, rho = _primitive_half("box", sizes=g.dims)
    return BoundingBox(np.array(g.origin, float), half, rho)


def shape_box(s: Shape) -> BoundingBox:
    """OBB of one scene shape, in its object frame (a big mesh: of all its pieces' boxes)."""
    if s.kind == "mesh":
        mesh = scene_mesh(s)
        return mesh.box if mesh.box is not None else union_box([scene_mesh(p).box for p in mesh.pieces])
    if s.kind == "box":
        half, rho = _primitive_half("box", sizes=s.dims[:3])
    elif s.kind == "sphere":
        half, rho = _primitive_half("sphere", s.dims[0])
    else:  # cylinder, cone: (height, radius)
        half, rho = _primitive_half(s.kind, s.dims[1], s.dims[0])
    return BoundingBox(np.array(s.pose, float), half, rho)


# ----------------------------------------------------------------------------- sphere covers
def _grid_counts(dims: np.ndarray, tol: float) -> np.ndarray:
    """Cells per axis so that a cell's circumscribed sphere overshoots its half-thinnest side by ≤ tol."""
    dims = np.maximum(np.asarray(dims, float), 1e-9)
    best = np.ones(3, dtype=int)
    for k in range(1, 64):
        s = dims.max() / k
        n = np.maximum(np.ceil(dims / s - 1e-9).astype(int), 1)
        if n.prod() > MAX_SPHERES_PER_SHAPE:
            break
        best = n
        c = dims / n
        if 0.5 * np.linalg.norm(c) - 0.5 * c.min() <= tol:
            break
    return best


def box_cover(sizes, tol: float) -> SphereCover:
    sizes = np.asarray(sizes, float)
    n = _grid_counts(sizes, tol)
    cell = sizes / n
    axes = [(-0.5 * sizes[i] + cell[i] * (np.arange(n[i]) + 0.5)) for i in range(3)]
    centers = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    return SphereCover(centers, np.full(len(centers), 0.5 * np.linalg.norm(cell)))


def cylinder_cover(radius: float, length: float, tol: float) -> SphereCover:
    """Slabs along z; a slab of height h is inside the sphere of radius √(r² + (h/2)²) at its centre."""
    half_h = np.sqrt(max((radius + tol) ** 2 - radius ** 2, 1e-12))
    k = int(min(max(np.ceil(length / (2 * half_h) - 1e-9), 1), MAX_SPHERES_PER_SHAPE))
    h = length / k
    z = -0.5 * length + h * (np.arange(k) + 0.5)
    centers = np.column_stack([np.zeros(k), np.zeros(k), z])
    return SphereCover(centers, np.full(k, np.hypot(radius, 0.5 * h)))


def mesh_cover(vertices: np.ndarray, triangles: np.ndarray, tol: float) -> SphereCover:
    """Triangles binned on a grid in the mesh's OBB frame; one enclosing sphere per non-empty cell.

    Long triangles are subdivided first (same surface), so a cell's sphere stays close to the cell.
    """
    import trimesh

    v = np.asarray(vertices, float)
    f = np.asarray(triangles, dtype=np.int64)
    pose, half = mesh_obb(v)
    n = _grid_counts(2 * half, tol)
    cell = np.maximum(2 * half / n, 1e-9)
    max_edge = max(0.5 * cell.min(), 1e-4)
    try:
        v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge=max_edge, max_iter=8)
    except Exception:  # pragma: no cover - subdivision failed to converge: keep the coarse triangles
        pass
    local = (v - pose[:3, 3]) @ pose[:3, :3]  # vertices in the OBB frame
    tri = local[f]  # (F, 3, 3)
    cent = tri.mean(1)
    idx = np.clip(np.floor((cent + half) / cell).astype(int), 0, n - 1)
    key = (idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2]
    centers, radii = [], []
    for k in np.unique(key):
        pts = tri[key == k].reshape(-1, 3)
        c = 0.5 * (pts.min(0) + pts.max(0))
        r = np.sqrt(((pts - c) ** 2).sum(1).max())
        centers.append(c)
        radii.append(r)
    centers = np.array(centers) @ pose[:3, :3].T + pose[:3, 3]
    return SphereCover(centers, np.array(radii))


def link_geometry_cover(g: LinkGeometry, tol: float) -> SphereCover:
    """Sphere cover of one link shape, in the link frame."""
    if g.kind == "sphere":
        c = SphereCover(np.zeros((1, 3)), np.array([g.dims[0]]))
    elif g.kind == "box":
        c = box_cover(g.dims, tol)
    elif g.kind == "cylinder":
        c = cylinder_cover(g.dims[0], g.dims[1], tol)
    elif g.kind == "mesh":
        return mesh_cover(g.vertices @ g.origin[:3, :3].T + g.origin[:3, 3], g.triangles, tol)
    else:
        raise ValueError(g.kind)
    return c.transformed(g.origin)


INNER_GRID = 8
"""Candidate centres per principal axis (the longest; others in proportion) for a mesh's inner spheres."""
INNER_MAX_FACES = 100_000
"""Meshes with more faces get no inner spheres (FCL decides their collisions): the candidates' distances
cost time per face when the robot model loads (0.4 s at 80k faces)."""
INNER_FACE_CHUNK = 4096
"""Faces per block of the candidates' plane distances (memory bound for meshes of 10^4-10^5 faces)."""
INNER_SPHERES = 10
"""Inner spheres kept per mesh: the largest first, each outside the ones before it."""
INNER_MIN_SHARE = 0.2
"""A mesh's inner sphere is kept only if its radius is at least this share of the largest one's:
small ones prove little and cost a test each."""


def _closed_mesh_axes(vertices: np.ndarray, triangles: np.ndarray):
    """(trimesh mesh, vertex mean, principal axes as columns) of a watertight mesh of 4 to INNER_MAX_FACES
    faces, else None: the frame mesh_inner_spheres and mesh_inner_box search in (mesh_obb's hull costs
    ~1 s on a 30k-face mesh; their boxes need not be tight, only contain the mesh)."""
    import trimesh

    f = np.asarray(triangles, dtype=np.int64)
    if len(f) < 4 or len(f) > INNER_MAX_FACES:
        return None
    mesh = trimesh.Trimesh(np.asarray(vertices, float), f, process=True)
    if not mesh.is_watertight:
        return None
    mean = mesh.vertices.mean(0)
    return mesh, mean, np.linalg.eigh(np.cov((mesh.vertices - mean).T))[1]


def mesh_inner_spheres(vertices: np.ndarray, triangles: np.ndarray) -> SphereCover | None:
    """Spheres inside a closed mesh (its frame), or None when it is not watertight.

    A grid of candidate centres in a box along the vertices' principal axes; a centre inside the solid
    (the planes of a convex mesh, else ray parity) gets the radius min over faces of its distance to the face's plane — a
    lower bound of its distance to the surface, since a point is at least that far from each
    triangle. FCL treats a mesh as its surface: two solids whose inner spheres meet intersect, and
    their surfaces do unless one contains the other (a link inside another, which FCL would call
    free); such a proof can only err towards "colliding", never towards "free". Measured on Fetch's
    tucked start and Panda's random cage configurations: 84 % and 32 % collide, and without mesh
    proofs each of them went to FCL (0.1 ms)."""
    closed = _closed_mesh_axes(vertices, triangles)
    if closed is None:
        return None
    mesh, mean, axes_R = closed
    if mesh.volume < 0:  # faces wound inwards: the solid is the same, its normals point the other way
        mesh.invert()
    local_v = (mesh.vertices - mean) @ axes_R
    lo, hi = local_v.min(0), local_v.max(0)
    half = 0.5 * (hi - lo)
    n = np.maximum(np.ceil(INNER_GRID * half / max(half.max(), 1e-9) - 1e-9).astype(int), 1)
    axes = [(np.arange(k) + 0.5) / k * 2 * h - h + m for k, h, m in zip(n, half, 0.5 * (lo + hi))]
    local = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    pts = local @ axes_R.T + mean
    normals = np.asarray(mesh.face_normals)
    offsets = np.einsum("fi,fi->f", normals, np.asarray(mesh.triangles_center))
    convex = mesh.is_convex
    if not convex:
        pts = pts[mesh.contains(pts)]
    depth = np.full(len(pts), np.inf)
    for f0 in range(0, len(normals), INNER_FACE_CHUNK):  # (P, chunk) at a time: big meshes have 10^4 faces
        signed = offsets[None, f0:f0 + INNER_FACE_CHUNK] - pts @ normals[f0:f0 + INNER_FACE_CHUNK].T
        if convex:  # inside every face's plane, or outside the solid
            depth[(signed <= 0).any(1)] = -np.inf
        depth = np.minimum(depth, np.abs(signed).min(1))
    pts, depth = pts[depth > 0], depth[depth > 0]
    centers: list[np.ndarray] = []
    radii: list[float] = []
    for i in np.argsort(-depth, kind="stable"):
        if len(radii) == INNER_SPHERES or depth[i] < INNER_MIN_SHARE * (radii[0] if radii else depth[i]):
            break
        if any(np.linalg.norm(pts[i] - c) < r for c, r in zip(centers, radii)):
            continue
        centers.append(pts[i])
        radii.append(float(depth[i]))
    if not radii or radii[0] <= 0:
        return None
    return SphereCover(np.array(centers), np.array(radii))


INNER_BOX_STEPS = 8
"""Bisection steps per growth of a mesh's inner box (a scale known to 1/256 of the full extent)."""
INNER_BOX_MAX_FACES = 2_000
"""Meshes with more faces get no inner box: its separating-axis tests cost time per face."""
INNER_BOX_MIN_VOLUME = 0.01
"""m³ of a mesh's axis-aligned bounding box below which it gets no inner box: a small link's inner spheres
reach near its surface; a base or a torso has broad faces arms touch shallowly (Fetch's base, 0.11 m³).
It also bounds the cost (TALOS: 6 meshes, 0.1 s, instead of 0.6 s for all)."""


def _triangles_meet_box(tri: np.ndarray, half: np.ndarray) -> bool:
    """Does any triangle (T, 3, 3; box frame, centred) meet the closed axis-aligned box of half extents
    `half`? The separating-axis test (Akenine-Möller): the box's 3 face normals, each triangle's
    normal and the 9 cross products of its edges with the box axes; touching counts as meeting."""
    e = tri[:, [1, 2, 0]] - tri  # (T, 3 edges, 3)
    axes = [np.broadcast_to(np.eye(3)[i], (len(tri), 3)) for i in range(3)]
    axes.append(np.cross(e[:, 0], e[:, 1]))
    axes += [np.cross(e[:, j], np.eye(3)[i]) for j in range(3) for i in range(3)]
    apart = np.zeros(len(tri), dtype=bool)
    for a in axes:
        p = np.einsum("tvi,ti->tv", tri, a)
        r = np.abs(a) @ half
        live = np.abs(a).sum(1) > 1e-12  # a degenerate axis separates nothing
        apart |= live & ((p.min(1) > r) | (p.max(1) < -r))
    return not apart.all()


def mesh_inner_box(vertices: np.ndarray, triangles: np.ndarray) -> BoundingBox | None:
    """A box inside a closed mesh (its frame), or None when it is not watertight or no box fits.

    Along the vertices' principal axes, centred on the middle of their extent (or, when that is outside,
    on the deepest inner sphere's centre), the box is scaled up from nothing as long as no triangle meets
    it (_triangles_meet_box, exact), first all axes together, then each axis alone: a box inside the solid
    whose faces no surface crosses. A point of another solid's surface inside it proves the two surfaces
    meet, as inner spheres do (checker level 2), and reaches into the flat layers a few spheres leave out:
    Fetch's base is a 0.57 × 0.53 × 0.36 m drum whose inner spheres (radius ≤ 0.18 m) proved none of the
    575 arm contacts sampled near its tucked start; its box proves 387 of them."""
    closed = _closed_mesh_axes(vertices, triangles)
    if closed is None:
        return None
    mesh, mean, axes_R = closed
    if np.linalg.det(axes_R) < 0:
        axes_R[:, 0] *= -1
    local_v = (mesh.vertices - mean) @ axes_R
    lo, hi = local_v.min(0), local_v.max(0)
    centre, full = 0.5 * (lo + hi), 0.5 * (hi - lo)
    if not mesh.contains((centre @ axes_R.T + mean)[None])[0]:
        # the middle is outside (a ring, a U): grow the box around the deepest inner sphere instead
        spheres = mesh_inner_spheres(vertices, triangles)
        if spheres is None:
            return None
        centre = (spheres.centers[0] - mean) @ axes_R
        full = np.maximum(hi - centre, centre - lo)
    tri = local_v[np.asarray(mesh.faces)] - centre
    tri_lo, tri_hi = tri.min(1), tri.max(1)

    def fits(half: np.ndarray) -> bool:
        near = np.all(tri_hi >= -half, axis=1) & np.all(tri_lo <= half, axis=1)  # the others are apart on a box axis
        return not _triangles_meet_box(tri[near], half)

    def grow(half: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """half + s·axis for the largest s in [0, 1] that fits (bisection)."""
        a, b = 0.0, 1.0
        for _ in range(INNER_BOX_STEPS):
            m = 0.5 * (a + b)
            a, b = (m, b) if fits(half + m * axis) else (a, m)
        return half + a * axis

    half = grow(np.zeros(3), full)
    for i in range(3):
        half = grow(half, np.eye(3)[i] * (full[i] - half[i]))
    if half.min() <= 0:
        return None
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = axes_R, centre @ axes_R.T + mean
    return BoundingBox(pose, half)


def inner_box(g: LinkGeometry) -> BoundingBox | None:
    """A box inside a mesh shape (link frame): mesh_inner_box; None for other shapes (their boxes or
    spheres are exact already) and open meshes."""
    if g.kind != "mesh" or g.vertices is None or g.triangles is None:
        return None
    b = mesh_inner_box(g.vertices, g.triangles)
    return None if b is None else b.transformed(g.origin)


def inner_spheres(g: LinkGeometry) -> SphereCover | None:
    """Spheres inside a shape (link frame): if one reaches another solid, they collide for sure.
    Meshes: mesh_inner_spheres (closed meshes only)."""
    if g.kind == "mesh":
        if g.vertices is None or g.triangles is None:
            return None
        c = mesh_inner_spheres(g.vertices, g.triangles)
        return None if c is None else c.transformed(g.origin)
    if g.kind == "sphere":
        c = SphereCover(np.zeros((1, 3)), np.array([g.dims[0]]))
    elif g.kind == "box":
        half = 0.5 * np.asarray(g.dims, float)
        r = half.min()
        axes = [np.linspace(-(h - r), h - r, int(min(1 + np.ceil(2 * (h - r) / r - 1e-9), 4))) for h in half]
        centers = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        c = SphereCover(centers, np.full(len(centers), r))
    elif g.kind == "cylinder":
        radius, length = g.dims
        r = min(radius, 0.5 * length)
        k = int(min(1 + np.ceil((length - 2 * r) / r - 1e-9), 6))
        z = np.linspace(-(0.5 * length - r), 0.5 * length - r, k)
        c = SphereCover(np.column_stack([np.zeros(k), np.zeros(k), z]), np.full(k, r))
    else:
        return None
    return c.transformed(g.origin)


def enclosing_sphere(cover: SphereCover) -> tuple[np.ndarray, float]:
    """A (not minimal) sphere containing every sphere of a cover."""
    c = 0.5 * (cover.centers.min(0) + cover.centers.max(0))
    r = float((np.linalg.norm(cover.centers - c, axis=1) + cover.radii).max())
    return c, r


# ----------------------------------------------------------------------------- prefilter units
def box_is_tight(shapes: list[tuple[str, tuple[float, ...], np.ndarray]]) -> bool:
    """Is the union_box of these shapes (kind, URDF dims, pose in one frame) exactly their union?
    True for one box or sphere, and for a capsule written the only way URDF can: a cylinder plus a
    sphere of the same radius centred on each end cap (union_box makes that a rounded segment)."""
    kinds = sorted(k for k, _, _ in shapes)
    if kinds in (["box"], ["sphere"]):
        return True
    if kinds != ["cylinder", "sphere", "sphere"]:
        return False
    ((_, (r, length), T),) = [x for x in shapes if x[0] == "cylinder"]
    ends = [T[:3, 3] + s * 0.5 * length * T[:3, 2] for s in (-1.0, 1.0)]
    spheres = [(d[0], P[:3, 3]) for k, d, P in shapes if k == "sphere"]
    if any(abs(rs - r) > 1e-9 for rs, _ in spheres):
        return False
    c0, c1 = spheres[0][1], spheres[1][1]
    return bool(min(np.linalg.norm(c0 - ends[0]) + np.linalg.norm(c1 - ends[1]),
                    np.linalg.norm(c0 - ends[1]) + np.linalg.norm(c1 - ends[0])) < 1e-9)


MERGE_GROWTH = 1.3
"""Loose shapes of a link share a prefilter unit while its bounding sphere grows by at most this factor: a
shared unit saves a level-1 sphere, a much bigger one is flagged more often (a balance, not a limit)."""


def group_shapes(shapes: dict[int, tuple[str, tuple[float, ...], np.ndarray, SphereCover]]) -> list[list[int]]:
    """One link's shapes (id → kind, dims, pose, cover) → prefilter units (lists of ids).

    A capsule (cylinder + end spheres) is one unit and every box or sphere keeps a unit of its own:
    their rounded boxes are then exact, which lets inner spheres prove collisions. Other shapes
    (meshes, bare cylinders) merge greedily, largest first, while the bounding sphere stays tight.
    """
    groups: list[list[int]] = []
    free = set(shapes)
    kind = {m: v[0] for m, v in shapes.items()}
    for c in [m for m in shapes if kind[m] == "cylinder"]:
        sph = [m for m in shapes if kind[m] == "sphere"]
        for i, s1 in enumerate(sph):
            for s2 in sph[i + 1:]:
                if {c, s1, s2} <= free and box_is_tight([shapes[x][:3] for x in (c, s1, s2)]):
                    groups.append([c, s1, s2])
                    free -= {c, s1, s2}
    radius = {m: enclosing_sphere(shapes[m][3])[1] for m in free}
    loose: list[list[int]] = []
    for m in sorted(free, key=lambda m: (-radius[m], m)):
        if kind[m] in ("box", "sphere"):
            groups.append([m])
            continue
        for g in loose:
            covers = [shapes[x][3] for x in g] + [shapes[m][3]]
            merged = SphereCover(np.concatenate([c.centers for c in covers]), np.concatenate([c.radii for c in covers]))
            if enclosing_sphere(merged)[1] <= MERGE_GROWTH * max(radius[x] for x in g + [m]):
                g.append(m)
                break
        else:
            loose.append([m])
    return groups + loose


@dataclass(frozen=True)
class SphereTable:
    """Sphere sets of several units padded into arrays: centres (U, S, 3), radii (U, S) with
    padding radius NO_SPHERE, counts (U,), and the owner id of each sphere (U, S)."""

    centers: np.ndarray
    radii: np.ndarray
    counts: np.ndarray
    owners: np.ndarray

    @classmethod
    def build(cls, sets: list[list[tuple[SphereCover, int]]]) -> "SphereTable":
        counts = np.array([sum(len(c.radii) for c, _ in s) for s in sets], dtype=np.int64)
        width = max(int(counts.max()) if len(counts) else 0, 1)
        centers = np.zeros((len(sets), width, 3))
        radii = np.full((len(sets), width), NO_SPHERE)
        owners = np.zeros((len(sets), width), dtype=np.int64)
        for i, s in enumerate(sets):
            if s:
                k = counts[i]
                centers[i, :k] = np.concatenate([c.centers for c, _ in s])
                radii[i, :k] = np.concatenate([c.radii for c, _ in s])
                owners[i, :k] = np.concatenate([np.full(len(c.radii), o) for c, o in s])
        return cls(centers, radii, counts, owners)


NO_SPHERE = -1e9
"""Radius of the padding entries of sphere tables; tests use signed squares, so they never touch."""


# ----------------------------------------------------------------------------- convex hull bounds
HULL_TOLERANCE = 1e-4  # m: GJK's distance error on hull pairs (measured ≤ 2e-5 on TALOS links) with room


def mesh_hull(g: LinkGeometry):
    """The convex hull (a trimesh.Trimesh, shape frame) of a mesh shape; None for primitives (convex
    already) and degenerate (flat) meshes, which keep the exact path."""
    if g.kind != "mesh" or g.triangles is None or len(g.triangles) == 0:
        return None
    import trimesh

    try:
        return trimesh.Trimesh(np.asarray(g.vertices, float), np.asarray(g.triangles), process=False).convex_hull
    except Exception:  # no hull volume
        return None


def hull_bound(hull) -> fcl.Convex | None:
    """A mesh's convex hull (mesh_hull) as an fcl.Convex: a solid whose distance to another convex
    solid (GJK, ~10 µs) is a lower bound of the mesh's (BVH, 0.3 ms on TALOS's links), because the
    mesh lies inside it."""
    if hull is None:
        return None
    faces = np.hstack([np.full((len(hull.faces), 1), 3), hull.faces]).ravel()
    return fcl.Convex(np.asarray(hull.vertices, float), len(hull.faces), faces)


HULL_POINTS_MAX = 512
"""Hull vertices a mesh keeps for the checker's vertex tests (kernels.py); a hull with more has none
(the test would cost as much as the FCL call it saves)."""


def hull_points(hull) -> tuple[np.ndarray, np.ndarray] | None:
    """The vertices (V, 3) of a mesh's convex hull (mesh_hull), at most HULL_POINTS_MAX, and its face
    planes (F, 4): unit normal n and offset d, n·x ≤ d inside. The vertices bound the mesh along every
    axis and are points of the mesh (one inside a solid proves contact); a solid wholly beyond a face
    plane is clear of the hull."""
    if hull is None or not 0 < len(hull.vertices) <= HULL_POINTS_MAX:
        return None
    n = np.asarray(hull.face_normals, float)
    v = np.asarray(hull.vertices, float)
    d = np.einsum("fi,fi->f", n, v[np.asarray(hull.faces)[:, 0]])
    # the plane of a face through its farthest vertex: rounding in the normals never cuts the hull
    d = np.maximum(d, (v @ n.T).max(axis=0))
    return v, np.hstack([n, d[:, None]])


BOUND_DIRECTIONS = 64
"""Directions of the bounding polytope of a hull too big for hull_points (bounding_polytope): as many on a
Fibonacci sphere, and the normals of as many of the hull's largest faces."""


def bounding_polytope(hull) -> tuple[np.ndarray, np.ndarray] | None:
    """A convex polytope containing a mesh's convex hull, for a hull with more than HULL_POINTS_MAX vertices:
    vertices (V, 3) and face planes (F, 4) as hull_points', but the vertices are not points of the mesh, so
    it only bounds it: the kernels use it to prove pairs apart, never in contact (TALOS's pelvis, 758 hull
    vertices, bounded by ~200 within a few mm). The planes are the hull's supporting planes along BOUND_DIRECTIONS
    spread directions and its largest faces' normals; None when that polytope still has too many vertices
    or rounding would leave a mesh vertex outside it."""
    from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

    if hull is None or len(hull.vertices) <= HULL_POINTS_MAX:
        return None
    v = np.asarray(hull.vertices, float)
    k = np.arange(BOUND_DIRECTIONS) + 0.5
    polar, azimuth = np.arccos(1.0 - 2.0 * k / BOUND_DIRECTIONS), np.pi * (1.0 + 5.0 ** 0.5) * k
    U = np.vstack([np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], axis=1),
                   np.asarray(hull.face_normals, float)[np.argsort(hull.area_faces)[::-1][:BOUND_DIRECTIONS]]])
    h = (v @ U.T).max(axis=0)
    centre = v.mean(axis=0)
    try:
        corners = HalfspaceIntersection(np.hstack([U, -h[:, None]]), centre).intersections
        corners = centre + (corners - centre) * (1.0 + 1e-9)  # out by rounding's worth: it stays a bound
        ch = ConvexHull(corners)
    except (QhullError, ValueError):
        return None
    V = corners[ch.vertices]
    n = ch.equations[:, :3] / np.linalg.norm(ch.equations[:, :3], axis=1, keepdims=True)
    d = np.maximum((V @ n.T).max(axis=0), -ch.equations[:, 3])
    if len(V) > HULL_POINTS_MAX or not np.all(v @ n.T <= d):
        return None
    return V, np.hstack([n, d[:, None]])


# ----------------------------------------------------------------------------- per-robot cache
@dataclass(frozen=True)
class LinkCollision:
    """Everything the checker needs about one link with geometry (all in the link frame)."""

    name: str
    shapes: tuple[LinkGeometry, ...]
    fcl_geoms: tuple[fcl.CollisionGeometry, ...]
    covers: tuple[SphereCover, ...]  # one per shape: contains it
    boxes: tuple[BoundingBox, ...]  # one per shape: contains it
    inners: tuple[SphereCover | None, ...]  # one per shape: inside it (None: an open mesh)
    hulls: tuple[fcl.Convex | None, ...] = ()  # one per shape: convex hull of a mesh (hull_bound), or ()
    hull_points: tuple[tuple[np.ndarray, np.ndarray] | None, ...] = ()  # one per shape: hull vertices, planes (hull_points)


def robot_reach(robot: RobotModel, links: dict[str, LinkCollision]) -> float:
    """A bound on the distance of any point of the links' shapes from the root link's origin in any
    configuration: along each link's chain the joints' offsets (plus a prismatic joint's travel), then the
    link's farthest shape (its bounding box's centre and corner)."""
    reach = 0.0
    for name, lc in links.items():
        chain = robot.chain_joints(robot.root_link, name)
        along = sum(float(np.linalg.norm(j.origin[:3, 3])) + (max(abs(robot.lower[j.index]), abs(robot.upper[j.index]))
                                                              if j.type == "prismatic" and j.index >= 0 else 0.0)
                    for j in chain)
        shape = max((float(np.linalg.norm(b.pose[:3, 3]) + np.linalg.norm(b.half)) + b.rounding for b in lc.boxes),
                    default=0.0)
        reach = max(reach, along + shape)
    return reach


GROUP_PARTS = 6
"""Checker builds' robot parts a robot keeps (RobotCollisionModel.group_parts): the groups a node plans for (one
arm, the other, both), at a few postures of their other joints, each kept from its second build on. Measured:
TALOS l_arm 3.3 MB each (most of it the triangles of its 35 fixed meshes), TIAGo + torso 2.7 MB, G1 1.4 MB."""


class RobotCollisionModel:
    """Per-robot collision data (fcl geometries, sphere covers, OBBs), built once and shared."""

    _cache: "weakref.WeakKeyDictionary[RobotModel, dict[float, RobotCollisionModel]]" = weakref.WeakKeyDictionary()
    _lock = threading.Lock()

    def __init__(self, robot: RobotModel, sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE):
        self.robot = robot
        self.sphere_tolerance = sphere_tolerance
        self.links: dict[str, LinkCollision] = {}
        self.pair_tables = TableCache()  # clearance tables of pairs (pair_tables.py), built on demand, bounded
        self.objects = CollisionObjectPool()  # the checkers' fcl objects, reused (fcl_objects.py)
        self.group_parts = RecentCache(GROUP_PARTS)  # checker.GroupPart per group, posture and paddings
        self._inner_boxes: dict[tuple[str, int], BoundingBox | None] = {}
        self._outer_hulls: dict[tuple[str, int], tuple[np.ndarray, np.ndarray] | None] = {}
        self._lazy_lock = threading.Lock()  # inner boxes and outer hulls, computed when first asked for
        for name in robot.link_names:
            shapes = robot.collision_geometry.get(name)
            if not shapes:
                continue
            self.links[name] = LinkCollision(
                name, tuple(shapes), tuple(fcl_from_link_geometry(g) for g in shapes),
                tuple(link_geometry_cover(g, sphere_tolerance) for g in shapes),
                tuple(link_geometry_box(g) for g in shapes),
                tuple(inner_spheres(g) for g in shapes),
                *_hull_parts(shapes))
        self.reach = robot_reach(robot, self.links)  # pair_tables' bound on how far a path joint moves a pair

    def outer_hull(self, link: str, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Vertices and face planes (link frame) of a convex solid containing shape k of a link: its hull
        (hull_points), or where that has too many vertices for the kernels its bounding_polytope (computed when
        first asked for, once per robot; None where even that has too many); None for primitives."""
        lc = self.links[link]
        if lc.hull_points and lc.hull_points[k] is not None:
            return lc.hull_points[k]
        key = (link, k)
        with self._lazy_lock:
            if key not in self._outer_hulls:
                self._outer_hulls[key] = bounding_polytope(mesh_hull(lc.shapes[k]))
            return self._outer_hulls[key]

    def prepare_outer_hulls(self) -> None:
        """Every mesh's outer_hull now (20-40 ms for each one that needs a bounding polytope: G1 0.8 s, TALOS
        0.1 s), so that a warm-up, not the first plan of a group, pays for them."""
        for name, lc in self.links.items():
            for k, shape in enumerate(lc.shapes):
                if shape.kind == "mesh":
                    self.outer_hull(name, k)

    def inner_box(self, link: str, k: int) -> BoundingBox | None:
        """inner_box of shape k of a link (link frame) if it is big enough (INNER_BOX_MIN_VOLUME, _MAX_FACES),
        computed when first asked for: only links fixed in some checker need one (~50 ms for a few hundred
        faces), and a robot's load stays as it was."""
        key = (link, k)
        with self._lazy_lock:
            if key not in self._inner_boxes:
                g = self.links[link].shapes[k]
                big = g.vertices is not None and len(g.vertices) and np.prod(np.ptp(g.vertices, axis=0)) >= INNER_BOX_MIN_VOLUME
                self._inner_boxes[key] = inner_box(g) if big and len(g.triangles) <= INNER_BOX_MAX_FACES else None
            return self._inner_boxes[key]

    @classmethod
    def is_built(cls, robot: RobotModel, sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE) -> bool:
        """Would for_robot answer at once? (No lock: a build in progress holds it.)"""
        per = cls._cache.get(robot)
        return per is not None and sphere_tolerance in per

    @classmethod
    def for_robot(cls, robot: RobotModel, sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE) -> "RobotCollisionModel":
        """The shared model of a robot (built on first use; thread-safe)."""
        with cls._lock:
            per = cls._cache.setdefault(robot, {})
            model = per.get(sphere_tolerance)
            if model is None:
                model = per[sphere_tolerance] = cls(robot, sphere_tolerance)
            return model


def box_hull_points(g: LinkGeometry) -> tuple[np.ndarray, np.ndarray]:
    """A box shape's 8 corners and 6 face planes (shape frame) as hull_points gives a mesh's: the kernels'
    hull tests then decide a box link against a scene box or another link's box or hull (a vertex inside
    proves contact, a face plane with the other solid beyond it proves the pair apart) instead of leaving
    every pair their spheres cannot clear to FCL. TIAGo's hand_safety_box against MotionBenchMaker-style
    cage boards reached FCL in most configurations near the cage (half of the checks of its cage plans)."""
    h = np.asarray(g.dims[:3], float) / 2
    V = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1]) for z in (-h[2], h[2])])
    n = np.vstack([np.eye(3), -np.eye(3)])
    return V, np.hstack([n, np.concatenate([h, h])[:, None]])


def _hull_parts(shapes, meshes: bool = True) -> tuple[tuple, tuple]:
    """LinkCollision's hulls and hull_points of these shapes: one convex hull per mesh (meshes False: none,
    for shapes that come and go with a request, whose hulls would cost more than they save), a box's corners
    and faces (box_hull_points); None for other primitives."""
    hulls = [mesh_hull(g) if meshes else None for g in shapes]
    return (tuple(hull_bound(h) for h in hulls),
            tuple(box_hull_points(g) if g.kind == "box" else hull_points(h) for g, h in zip(shapes, hulls)))


def shape_as_link_geometry(s: Shape, T: np.ndarray) -> LinkGeometry:
    """A scene shape posed at T in a link frame, as link geometry (URDF dims): how attached objects
    become part of the robot. A cone becomes its triangle mesh (URDF has no cone)."""
    T = np.asarray(T, float) @ np.asarray(s.pose, float)
    if s.kind == "box":
        return LinkGeometry("box", tuple(s.dims[:3]), T)
    if s.kind == "sphere":
        return LinkGeometry("sphere", (s.dims[0],), T)
    if s.kind == "cylinder":  # shape_msgs (height, radius) -> URDF (radius, length)
        return LinkGeometry("cylinder", (s.dims[1], s.dims[0]), T)
    if s.kind == "cone":  # trimesh's cone stands on z = 0; shape_msgs' is centred on its axis
        import trimesh

        m = trimesh.creation.cone(radius=s.dims[1], height=s.dims[0], sections=24)
        return LinkGeometry("mesh", (), T, np.asarray(m.vertices) - [0.0, 0.0, 0.5 * s.dims[0]],
                            np.asarray(m.faces))
    if s.kind == "mesh":
        return LinkGeometry("mesh", (), T, np.asarray(s.vertices, float), np.asarray(s.triangles))
    raise ValueError(f"unknown shape kind {s.kind!r}")


def attached_collision(att: AttachedObject, sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE) -> LinkCollision:
    """An attached object's shapes as one more 'link' of the robot (link frame of att.link)."""
    shapes = tuple(shape_as_link_geometry(s, att.pose) for s in att.shapes)
    return LinkCollision(att.id, shapes, tuple(fcl_from_link_geometry(g) for g in shapes),
                         tuple(link_geometry_cover(g, sphere_tolerance) for g in shapes),
                         tuple(link_geometry_box(g) for g in shapes), tuple(inner_spheres(g) for g in shapes),
                         *_hull_parts(shapes, meshes=False))


@dataclass(frozen=True)
class SceneBody:
    """One scene shape as an obstacle: world pose, the shape and its bounding box (world frame)."""

    object_id: str
    pose: np.ndarray
    shape: Shape
    box: BoundingBox
    tight: bool  # the box is the shape itself (boxes and spheres)


def scene_body_inner(sb: SceneBody) -> SphereCover | None:
    """Inner spheres of a scene cylinder (world frame), whose box is not its solid; None otherwise (a
    box or sphere is proven against its exact box; a mesh's inner spheres would cost a solid test
    per plan)."""
    if sb.shape.kind != "cylinder":
        return None
    height, radius = sb.shape.dims[:2]
    return inner_spheres(LinkGeometry("cylinder", (radius, height), sb.pose))


def scene_bodies(objects: tuple[SceneObject, ...]) -> list[SceneBody]:
    """One body per shape; a big mesh gives one per piece (scene_mesh)."""
    out = []
    for o in objects:
        T_o = np.asarray(o.pose, float)
        for s in o.shapes:
            T = T_o @ np.asarray(s.pose, float)
            parts = scene_mesh(s).pieces if s.kind == "mesh" else ()
            for part in parts or (s,):
                out.append(SceneBody(o.id, T, part, shape_box(part).transformed(T_o), s.kind in ("box", "sphere")))
    return out
