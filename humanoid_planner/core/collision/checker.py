"""Collision checking for planning: robot self-collision and scene obstacles, batched.

An RRT in Python spends nearly all its time here, so the common case must be cheap. For a batch
of N configurations (numpy over N, a Python loop only over the few configurations FCL decides):

The compiled bodies and pairs, and levels 1–2 over them, are `levels.CompiledPairs` (`checker.levels`).

0. FK of the group's joint frames only (`RobotModel.kinematic_tree`, the one FK engine), every shape a
   constant offset from one.
1. Level 1: one bounding sphere per moving *unit* (a link's shapes, grouped) against the fixed
   bodies in its reach (rounded OBBs: fixed links at q_ref, scene shapes) and the other units.
2. Level 2, for the flagged (configuration, pair) entries only:
   - proofs: spheres *inside* a unit reaching an exact box (a box, sphere or capsule) mean the
     solids overlap — the configuration collides, no FCL needed;
   - covers: the unit's sphere cover (contains it) against the other side's rounded box
     (contains it); what still touches becomes (configuration, shape pair) entries.
3. Level 3: python-fcl on those shape pairs, stopping at a configuration's first collision;
   transforms are set only for the shapes involved.

Every test of levels 1–2 that calls a pair free is conservative (containing geometry, radii
inflated by EPS), and every proof uses contained geometry (radii shrunk by EPS), so the result
equals a brute-force FCL check of the same pairs up to FCL's own tolerance (tested on 10k configs).

Which pairs: all link pairs except SRDF-disabled and adjacent ones, every link against every scene
shape, except the grasped object against the hand's links. Objects attached to the robot
(SceneSnapshot.attached) are extra bodies fixed to their link: checked against the scene and every
link but their link and touch_links (which may also name scene objects: a placed object touches its support). Pairs whose relative pose no
configuration changes — both fixed at q_ref, both rigid on the same group joint, a fixed link and
the scene — are never re-checked; ``fixed_collisions()`` reports the colliding ones (a start-state
or environment problem, not a per-configuration one).

Point-cloud cells (the snapshot's `voxels`) are scene obstacles too, without a body each
(core/collision/voxels.py): after the levels above, the configurations still free test their
units' bounding spheres, then cover spheres, against a summed-area table of the occupancy grid
(inner sphere centres in an occupied cell prove a collision), and python-fcl decides the rest
against the few cells a flagged shape's cover reaches.

Padding: a robot–scene pair collides when closer than `padding` (a margin for perceived obstacles),
a robot–robot pair when closer than `self_padding` (default 0: the SRDF's disabled pairs were
computed for the bare model). FCL: collide, then distance < padding. These decide which
configurations collide.

Edge margins: a sample of a motion (``check_configs(q, edge_margins(Δ))``, MotionValidator) must
also keep, per moving unit u, half of how far u may move over the joint displacement Δ to the next
sample (m_u = |Δ| · unit_levers[u] / 2) from the scene and the fixed links, and between two moving
units a, b half of how far they may move relative to each other (the same sum over the joints that
move one but not the other: joints above both move them together) — so that two neighbouring
samples' clearances cover the motion between them.
"""
from __future__ import annotations

import copy
import weakref
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Callable, Iterable, Sequence

import fcl
import numpy as np

from humanoid_planner.core.collision import kernels
from humanoid_planner.core.collision.kernels import STATUS_FREE1, STATUS_FREE2, STATUS_HIT, STATUS_OPEN, STATUS_UNCHECKED
from humanoid_planner.core.collision.levels import EPS, NO_MARGINS, Body, Boxes, CompiledPairs
from humanoid_planner.core.collision.pair_tables import (BUILDER, building_in_background, cluster_tables_for, env_tables_for,
                                                        table_q_ref, tables_for)
from humanoid_planner.core.collision.voxels import VoxelObstacles
from humanoid_planner.core.collision.geometry import (DEFAULT_SPHERE_TOLERANCE, BoundingBox, HULL_TOLERANCE, LinkCollision,
                                 RobotCollisionModel, SphereCover, SphereTable, attached_collision,
                                 box_is_tight, enclosing_sphere, fcl_from_shape, group_shapes,
                                 link_geometry_primitive, scene_bodies, scene_body_inner, shape_primitive,
                                 union_box)
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot

_BATCH = 1024
"""Largest batch handled at once: the numpy work is memory-bound, bigger batches fall out of cache."""


class Interrupted(Exception):
    """check_configs did not start: the checker's `stop` (a plan's deadline or cancel) said so. Raised,
    not answered as a collision, so that no caller takes a configuration for blocked that is not."""


def _triangle_tables(parts: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, np.ndarray]:
    """The meshes' triangles (moving shapes in their frames, then fixed bodies in the world; parts:
    _triangles_in_frame's) as the levels hold them for kernels.triangle_tests: flat (T, 3, 3) `tri` with
    offsets per shape `tri_off`, a bounding sphere per triangle and per run of 16 (leaves of _triangle_leaves;
    runs never span two shapes: `run_lo`, `run_hi`), offsets of the runs per shape `run_off`, and `tri_rank`: a
    mesh's triangle index (FCL's primitive id) at tri_off[s] + i → its row in tri. Shapes after these with no
    triangles (scene bodies) only repeat the last offsets."""
    m_tri = [x for x, _ in parts]
    tri = np.ascontiguousarray((np.concatenate(m_tri) if m_tri else np.zeros((0, 3, 3))).reshape(-1, 3, 3), dtype=float)
    tri_off = np.concatenate([[0], np.cumsum([len(x) for x in m_tri])]).astype(np.int64)
    tri_rank = np.zeros(len(tri), dtype=np.int64)
    for lo, (_, order) in zip(tri_off[:-1].tolist(), parts):
        tri_rank[lo + order] = lo + np.arange(len(order))
    runs = [(lo + i, lo + min(i + 16, len(x))) for x, lo in zip(m_tri, tri_off[:-1].tolist()) for i in range(0, len(x), 16)]
    run_lo = np.array([a for a, _ in runs], dtype=np.int64)
    run_hi = np.array([b for _, b in runs], dtype=np.int64)
    tri_c, tri_r, run_c, run_r = kernels.triangle_spheres(tri, run_lo, run_hi)
    run_off = np.concatenate([[0], np.cumsum([(len(x) + 15) // 16 for x in m_tri])]).astype(np.int64)
    return {"tri": tri, "tri_off": tri_off, "tri_rank": tri_rank, "run_lo": run_lo, "run_hi": run_hi, "tri_c": tri_c,
            "tri_r": tri_r, "run_c": run_c, "run_r": run_r, "run_off": run_off}


@dataclass
class GroupPart:
    """What a checker's build takes from the robot alone, for one group (or groups), reference posture,
    set of links and paddings: the kinematic tree, the shapes (moving ones in frame coordinates, fixed
    ones in the world), the units and their arrays, the triangle tables, the self pairs. A checker is
    built per plan against that plan's scene; this part is the same every time, so it is built once and
    shared read-only (RobotCollisionModel.group_parts; nothing may change its arrays in place). A build
    with a shelf scene, measured: TIAGo + torso 8.1 → 1.7 ms, TALOS l_arm 7.2 → 1.8 ms, G1 3.9 → 1.4 ms,
    Panda 2.6 → 0.8 ms. Each checker still makes its own fcl objects (they carry transforms) and its scene part."""

    fk: object  # the KinematicTree
    m_shapes: list  # (LinkCollision, shape index, frame, pose in frame, robot link?) per moving shape
    f_shapes: list  # ... per fixed robot shape (frame -1, pose in the world)
    unit_shapes: list  # per unit, its moving shapes
    m_cover: list
    m_geo: list  # (kind, dims, pose) per moving shape
    f_box: list  # per fixed robot shape: world box, tight?, cover, inner spheres, hull, inner-box source
    f_tight: list
    f_cover: list
    f_inner: list
    f_hull: list
    f_ibox: list
    arrays: dict  # the levels' attributes of the units and moving shapes
    triangles: dict  # _triangle_tables of the moving and fixed robot shapes
    reach: tuple  # CollisionChecker._reach
    unit_levers: np.ndarray
    self_pairs: dict | None = None  # the levels' self-pair arrays and the checker's _self_shapes (_self_pairs)
    allowed_links: np.ndarray | None = None  # (U, fixed robot shapes) _pair_allowed
    partners: dict | None = None  # CollisionChecker._partners
    fixed_pairs: tuple | None = None  # the robot's pairs of fixed_collisions, once a checker asked


@dataclass
class CollisionStats:
    """Work counters; planners and the benchmark read them (checks per second, where time goes)."""

    configs_checked: int = 0
    edges_checked: int = 0
    exact_checks: int = 0  # configurations whose verdict needed python-fcl
    exact_pairs: int = 0  # fcl collide/distance calls
    level1_free: int = 0  # configurations called free by the bounding spheres
    level2_free: int = 0  # ... by the sphere covers
    level2_colliding: int = 0  # configurations proven colliding by inner spheres
    table_free: int = 0  # (configuration, shape pair) entries proven free by pair clearance tables

    def reset(self) -> None:
        for f in fields(self):
            setattr(self, f.name, 0)


@dataclass(frozen=True)
class CheckerSettings:
    """How strictly and how finely one checker decides, apart from what it checks (robot, scene, groups).

    padding: robot–scene clearance; self_padding: robot–robot clearance (default 0: the SRDF's
    disabled pairs were computed for the bare model); margin: the largest edge margin a check may
    ask (level 1 allows for it). grasp_object_id: the object the hand may touch; hand_links: the
    links allowed to touch it (empty: the links below each group's last joint). ignore_links: links
    left out entirely (e.g. the other arm while growing one arm's tree independently).
    edge_resolution (rad) and edge_chunk: an edge's sample spacing and how many samples are checked
    at once. sphere_tolerance: how far (m) a link's sphere cover may overshoot it. cross_groups_only:
    check nothing but pairs of links moved by different groups — two arms on one timeline whose own
    motions against the scene and themselves were checked already (valid only when the groups move
    disjoint link sets).
    """

    padding: float = 0.0
    self_padding: float = 0.0
    margin: float = 0.0
    grasp_object_id: str | None = None
    hand_links: tuple[str, ...] = ()
    ignore_links: tuple[str, ...] = ()
    edge_resolution: float = 0.02
    edge_chunk: int = 16
    sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE
    cross_groups_only: bool = False

    def __post_init__(self) -> None:
        # any iterable of link names is accepted; a tuple keeps the settings immutable and hashable
        object.__setattr__(self, "hand_links", tuple(self.hand_links))
        object.__setattr__(self, "ignore_links", tuple(self.ignore_links))
        if not (self.padding >= 0 and self.self_padding >= 0 and self.margin >= 0):
            raise ValueError("padding, self_padding and margin must be >= 0")
        if not self.edge_resolution > 0 or self.edge_chunk < 1:
            raise ValueError("edge_resolution must be > 0 and edge_chunk >= 1")


def _hull_in_frame(v: np.ndarray, planes: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hull vertices and face planes (n, d: n·x ≤ d) of a shape, moved from its frame by pose."""
    R, p = pose[:3, :3], pose[:3, 3]
    n = planes[:, :3] @ R.T
    return v @ R.T + p, np.hstack([n, (planes[:, 3] + n @ p)[:, None]])


MESH_BOX_TRIANGLES = 2000
"""Meshes with at most this many triangles are tested triangle by triangle against scene boxes in the
compiled kernel (kernels.mesh_box_entries) before FCL; larger ones go to FCL's BVH directly."""


def _triangles_in_frame(g, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A link mesh's triangles (T, 3, 3) at pose (its shape's pose in the frame), in the leaf order of
    _triangle_leaves, and that order (the mesh's triangle index of each); none (0, 3, 3) for a
    primitive or a mesh of more than MESH_BOX_TRIANGLES."""
    if link_geometry_primitive(g) is not None or g.triangles is None or not 0 < len(g.triangles) <= MESH_BOX_TRIANGLES:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    v = np.asarray(g.vertices, float) @ pose[:3, :3].T + pose[:3, 3]
    order = _leaf_order(g)
    return v[np.asarray(g.triangles, np.int64)[order]], order


_LEAF_ORDERS: dict[int, tuple[weakref.ref, np.ndarray]] = {}
"""id(a mesh's triangle array) → (a weak reference to that array, its leaf order). An entry leaves with its
array (weakref.finalize): attached objects' meshes come and go with the picks of a node that runs for days."""


def _leaf_order(g) -> np.ndarray:
    """The mesh's triangles in the leaf order of _triangle_leaves, in the mesh's own frame (runs of nearby
    triangles are that in any frame), computed once per mesh: a checker is built per plan, and the
    recursion cost 4.5 ms of each on the Panda's meshes."""
    t = g.triangles
    hit = _LEAF_ORDERS.get(id(t))
    if hit is not None and hit[0]() is t:
        return hit[1]
    c = np.asarray(g.vertices, float)[np.asarray(t, np.int64)].mean(axis=1)
    order = np.concatenate(_triangle_leaves(c, np.arange(len(c))))
    try:
        ref = weakref.ref(t)
    except TypeError:  # not an array (a list): not kept
        return order
    _LEAF_ORDERS[id(t)] = (ref, order)
    weakref.finalize(t, _LEAF_ORDERS.pop, id(t), None)
    return order


_NO_FLOATS = np.zeros(0)
_NO_SLOTS = np.zeros((0, 0), dtype=np.int64)

WITNESSES = 16
"""Intersecting triangle pairs remembered per pair of meshes (the latest ones; CollisionChecker._add_witness)."""


def _triangle_leaves(c: np.ndarray, idx: np.ndarray, leaf: int = 16) -> list[np.ndarray]:
    """Triangles (centroids c[idx]) split at the median of their widest axis until at most `leaf` are left:
    runs of nearby triangles, each bounded by one sphere, so that a box far from a run skips it whole."""
    if len(idx) <= leaf:
        return [idx]
    x = c[idx]
    order = idx[np.argsort(x[:, np.argmax(np.ptp(x, axis=0))], kind="stable")]
    h = len(order) // 2
    return _triangle_leaves(c, order[:h], leaf) + _triangle_leaves(c, order[h:], leaf)


def _hull_tables(hulls: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Hulls (vertices, planes) or None per body → padded vertices (K, V, 3), counts, planes (K, F, 4), counts."""
    nv = np.array([0 if h is None else len(h[0]) for h in hulls], dtype=np.int64)
    npl = np.array([0 if h is None else len(h[1]) for h in hulls], dtype=np.int64)
    V = np.zeros((len(hulls), max(int(nv.max(initial=0)), 1), 3))
    P = np.zeros((len(hulls), max(int(npl.max(initial=0)), 1), 4))
    for k, h in enumerate(hulls):
        if h is not None:
            V[k, :len(h[0])], P[k, :len(h[1])] = h
    return V, nv, P, npl


@lru_cache(maxsize=1024)
def coarse_to_fine(n: int) -> np.ndarray:
    """Step indices 1..n of an edge: the endpoint, then breadth-first bisection midpoints."""
    order = [n]
    level = [(0, n)]
    while level:
        nxt = []
        for lo, hi in level:
            if hi - lo >= 2:
                mid = (lo + hi) // 2
                order.append(mid)
                nxt += [(lo, mid), (mid, hi)]
        level = nxt
    out = np.array(order, dtype=np.int64)
    out.setflags(write=False)
    return out


def default_hand_links(robot: RobotModel, group: str) -> tuple[str, ...]:
    """Links below the last group joint on the path from the root to the group's TCP.

    (RobotModel.hand_links uses the group's last joint, which for SRDF groups listing an arm before
    the torso — TALOS's r_arm_torso — is a torso joint.)"""
    g = robot.group(group)
    if not g.tip_link:  # joints on several branches: no single hand
        return ()
    names = set(g.joint_names)
    chain = [j for j in robot.chain_joints(robot.root_link, g.tip_link) if j.name in names]
    return robot.subtree_links(chain[-1].child) if chain else robot.hand_links(group)












class CollisionChecker:
    """Validity of configurations and motions of one planning group, or several (concatenated).

    Build one per plan against a frozen scene snapshot (1-2 ms; per-robot work — fcl geometries,
    sphere covers — is shared through RobotCollisionModel.for_robot, and per-group work — units,
    triangles, self pairs — through its group_parts, GroupPart). Not thread-safe: use one
    checker per thread (fcl objects carry transforms).

    group: a group name, or several whose joints are concatenated — e.g. ("left_arm", "right_arm")
    checks both arms against each other on one timeline. q_ref: full configuration
    (RobotModel.joint_names) for every joint outside the group(s); default: the robot's home.
    settings: paddings, the grasped object, ignored links, edge sampling (CheckerSettings).
    """

    def __init__(self, robot: RobotModel, scene: SceneSnapshot | None, group: str | Sequence[str],
                 q_ref: np.ndarray | None = None, settings: CheckerSettings = CheckerSettings()):
        groups = (group,) if isinstance(group, str) else tuple(group)
        if not groups:
            raise ValueError("give a planning group or several")
        self.robot = robot
        self.settings = settings
        self.groups = groups
        idx = np.concatenate([robot.group_joint_indices(g) for g in self.groups])
        if len(set(idx.tolist())) != len(idx):
            raise ValueError(f"groups {self.groups} share joints")
        self.joint_indices = idx
        self.joint_names = tuple(robot.joint_names[i] for i in idx)
        self.dof = len(idx)
        self.q_ref = np.array(robot.home if q_ref is None else q_ref, dtype=float)
        if self.q_ref.shape != (robot.dof,) or not np.all(np.isfinite(self.q_ref)):
            raise ValueError(f"q_ref must be {robot.dof} finite values, got shape {self.q_ref.shape}")
        self.padding = float(settings.padding)
        self.self_padding = float(settings.self_padding)
        self.margin = float(settings.margin)  # the largest edge margin m_u a check may ask (level 1 allows for it)
        self.edge_resolution = float(settings.edge_resolution)
        self.edge_chunk = int(settings.edge_chunk)
        self.scene = scene
        self.grasp_object_id = settings.grasp_object_id
        hands = set(settings.hand_links)
        if self.grasp_object_id and not hands:
            for g in self.groups:
                hands.update(default_hand_links(robot, g))
        self.hand_links = frozenset(hands)
        self.cross_groups_only = bool(settings.cross_groups_only)
        self._group_sizes = np.cumsum([0] + [len(robot.group_joint_indices(g)) for g in self.groups])
        self.stats = CollisionStats()
        sphere_tolerance = settings.sphere_tolerance
        self.collision_model = RobotCollisionModel.for_robot(robot, sphere_tolerance)
        ignore = set(settings.ignore_links)
        links = [n for n in self.collision_model.links if n not in ignore]
        # attached objects are robot bodies riding on their link (they go where the link goes)
        held = [a for a in (scene.attached if scene is not None else ()) if a.link not in ignore]
        self._excluded = (robot.disabled_collision_pairs | robot.adjacent_link_pairs
                          | {frozenset((a.id, link)) for a in held for link in a.allowed_links})
        # the robot's part of the build, shared by every checker of this group, posture and paddings
        # (not with attached objects, which come and go with a request)
        key = None if held else (tuple(idx.tolist()), self.q_ref.tobytes(), tuple(links), self.self_padding,
                                 self.margin, self.cross_groups_only)
        part = self.collision_model.group_parts.get(key) if key is not None else None
        fk = part.fk if part is not None else robot.kinematic_tree(idx, self.q_ref, needed=links + [a.link for a in held])
        self.levels = CompiledPairs(fk, self.self_padding, self.margin)
        # id(shape's fcl object) -> a convex solid containing it: its hull (meshes) or itself (primitives)
        self._hulls: dict[int, fcl.CollisionObject] = {}
        self._loan = self.collision_model.objects.loan(self)  # fcl objects borrowed, back when this checker is collected
        self._req = fcl.CollisionRequest()
        self._dreq = fcl.DistanceRequest()
        if part is None:
            bodies = [(self.collision_model.links[n], n) for n in links]
            part = self._group_part(bodies + [(attached_collision(a, sphere_tolerance), a.link) for a in held])
            if key is not None:
                self.collision_model.group_parts.offer(key, part)  # kept from the second build of the key on
        self._shared_part = part if key is not None else None  # (fixed_collisions keeps the robot's pairs in it)
        self._build(part)
        self._fixed_collisions: tuple[tuple[str, str], ...] | None = None
        self._managers: list | None = None
        # asked before every batch; True: check_configs raises Interrupted (a search past its deadline
        # stops within one batch, not at the end of its cycle)
        self.stop: Callable[[], bool] | None = None

    # ------------------------------------------------------------------ construction
    def _pair_allowed(self, a: Body, b: Body) -> bool:
        """Is this pair checked at all (SRDF, adjacency, grasped object vs hand)?"""
        if a.is_link and b.is_link:
            return a.name != b.name and frozenset((a.name, b.name)) not in self._excluded
        link, other = (a, b) if a.is_link else (b, a)
        if not link.is_link:
            return False  # scene vs scene is not the robot's problem
        if frozenset((link.name, other.name)) in self._excluded:
            return False  # an attached object whose touch_links name this scene object (a placement's support)
        return not (self.grasp_object_id is not None and other.name == self.grasp_object_id
                    and link.name in self.hand_links)

    def _allowed_links(self, probe: list[Body], links: list[Body]) -> np.ndarray:
        """(U, L) bool: `_pair_allowed` of each unit (probe) and fixed robot body."""
        if self.cross_groups_only:
            return np.zeros((len(probe), len(links)), dtype=bool)
        return np.array([[self._pair_allowed(p, f) for f in links] for p in probe], dtype=bool).reshape(len(probe), len(links))

    def _partners(self) -> dict[str, set[str]]:
        """Per name, the names it is excluded with (`_excluded`'s pairs)."""
        partners: dict[str, set[str]] = {}
        for pair in self._excluded:
            if len(pair) == 2:
                a, b = pair
                partners.setdefault(a, set()).add(b)
                partners.setdefault(b, set()).add(a)
        return partners

    def _allowed_fixed(self, probe: list[Body], fixed: list[Body], part: GroupPart | None = None) -> np.ndarray:
        """(U, E) bool: `_pair_allowed` of each unit (probe) and fixed body; scene bodies by the names a
        unit may not meet (few), not a Python call per pair (thousands of objects). part: the group's,
        whose robot bodies (the first of `fixed`) and exclusions hold for this checker."""
        if self.cross_groups_only:
            return np.zeros((len(probe), len(fixed)), dtype=bool)
        out = np.ones((len(probe), len(fixed)), dtype=bool)
        links = [j for j, f in enumerate(fixed) if f.is_link]
        if links:
            if part is not None:
                assert links == list(range(part.allowed_links.shape[1]))  # the robot's fixed bodies come first
                out[:, links] = part.allowed_links
            else:
                out[:, links] = self._allowed_links(probe, [fixed[j] for j in links])
        at: dict[str, list[int]] = {}  # scene object -> its bodies
        for j, f in enumerate(fixed):
            if not f.is_link:
                at.setdefault(f.name, []).append(j)
        partners = self._partners() if part is None else part.partners
        rows, cols = [], []
        for u, p in enumerate(probe):
            barred = partners.get(p.name, set())
            if self.grasp_object_id is not None and p.name in self.hand_links:
                barred = barred | {self.grasp_object_id}
            for name in barred:
                js = at.get(name, ())
                rows += [u] * len(js)
                cols += js
        out[rows, cols] = False
        return out

    def _shape_object(self, robot_link: bool, geom, shape, place: np.ndarray | None) -> fcl.CollisionObject:
        """A borrowed fcl object of one link shape, posed at `place` (fixed at q_ref: its world pose;
        moving: None, placed per check): the robot's own geometry, or an attached object's primitive
        (pooled by kind) or mesh (a new object)."""
        if robot_link:
            return self._loan.object(geom, place)
        prim = link_geometry_primitive(shape)
        return self._loan.unpooled(geom, place) if prim is None else self._loan.primitive(*prim, place)

    def _scene_body(self, sb) -> Body:
        """A scene shape (geometry.SceneBody) as a fixed body: a pooled primitive or a mesh's own object."""
        prim = shape_primitive(sb.shape)
        obj = (self._loan.unpooled(fcl_from_shape(sb.shape), sb.pose) if prim is None
               else self._loan.primitive(*prim, sb.pose))
        if prim is not None:
            self._hulls[id(obj)] = obj  # a convex primitive bounds itself
        return Body(sb.object_id, False, -1, sb.pose, obj)

    def _group_part(self, links: list[tuple[LinkCollision, str]]) -> "GroupPart":
        """The robot's part of a build (links: collision data and the link it is fixed to — a robot link, or
        an attached object on one): moving shapes → prefilter units (frame coordinates), fixed robot shapes
        → world boxes, the self pairs and their tables. Sets this checker's levels' unit arrays on the way."""
        lv = self.levels
        m_shapes: list[tuple[LinkCollision, int, int, np.ndarray, bool]] = []  # (link data, shape, frame, pose, robot link)
        f_shapes: list[tuple[LinkCollision, int, int, np.ndarray, bool]] = []
        unit_list: list[tuple[str, list[int]]] = []
        m_cover: list[SphereCover] = []
        m_box: list[BoundingBox] = []
        m_inner: list[SphereCover | None] = []
        m_geo: list[tuple[str, tuple[float, ...], np.ndarray]] = []  # kind, dims, pose in frame
        m_hull: list[tuple[np.ndarray, np.ndarray] | None] = []  # mesh shapes' hull vertices, planes (frame)
        m_pts: list[bool] = []  # ... whether those vertices are mesh points (not a bounding polytope)
        m_tri: list[tuple[np.ndarray, np.ndarray]] = []  # mesh shapes' triangles in their frames, order (_triangles_in_frame)
        f_tri: list[tuple[np.ndarray, np.ndarray]] = []  # ... of fixed robot meshes (world)
        f_hull: list[tuple[np.ndarray, np.ndarray] | None] = []  # ... of fixed meshes (world)
        f_box: list[BoundingBox] = []
        f_tight: list[bool] = []
        f_cover: list[SphereCover | None] = []
        f_inner: list[SphereCover | None] = []
        f_ibox: list[tuple[str, int, np.ndarray] | None] = []  # fixed robot meshes: (link, shape, pose) for inner boxes
        for lc, anchor in links:
            name = lc.name
            frame, T = lv.fk.anchors[anchor]
            ids = []
            points = lc.hull_points or (None,) * len(lc.shapes)
            robot_link = self.collision_model.links.get(name) is lc  # its geometries live as long as the model
            for k, (shape, cover, box, inner, pts) in enumerate(zip(lc.shapes, lc.covers, lc.boxes, lc.inners, points)):
                pose = T @ shape.origin
                # a convex solid holding the shape: its hull, or where that has too many vertices for the kernels
                # its bounding polytope (whose vertices are no mesh points: it only proves a pair apart)
                outer = self.collision_model.outer_hull(name, k) if robot_link and shape.kind == "mesh" else pts
                hull_in_frame = None if outer is None else _hull_in_frame(*outer, pose)
                if frame >= 0:
                    ids.append(len(m_shapes))
                    m_shapes.append((lc, k, frame, pose, robot_link))
                    m_cover.append(cover.transformed(T))
                    m_box.append(box.transformed(T))
                    m_inner.append(inner.transformed(T) if inner is not None else None)
                    m_geo.append((shape.kind, shape.dims, pose))
                    m_hull.append(hull_in_frame)
                    m_pts.append(pts is not None)
                    m_tri.append(_triangles_in_frame(shape, pose))
                else:
                    f_shapes.append((lc, k, -1, pose, robot_link))
                    f_box.append(box.transformed(T))
                    f_tight.append(shape.kind in ("box", "sphere"))
                    f_cover.append(cover.transformed(T) if shape.kind == "mesh" else None)
                    f_inner.append(inner.transformed(T) if inner is not None else None)
                    f_hull.append(hull_in_frame)  # (world coordinates; only proves apart: a bound is all it needs)
                    f_tri.append(_triangles_in_frame(shape, pose))  # world coordinates
                    f_ibox.append((name, k, T) if robot_link and shape.kind == "mesh" else None)
            if ids:
                parts = {m: (*m_geo[m], m_cover[m]) for m in ids}
                unit_list += [(name, g) for g in group_shapes(parts)]
        unit_shapes = [ms for _, ms in unit_list]
        U, M = len(unit_list), len(m_shapes)
        a: dict[str, object] = {"units": [name for name, _ in unit_list]}  # the levels' arrays of the robot alone

        # Moving shapes (for FCL): frame and constant offset in it.
        a["frame_of"] = np.array([frame for _, _, frame, _, _ in m_shapes], dtype=np.int64)
        a["shape_R"] = np.array([pose[:3, :3] for _, _, _, pose, _ in m_shapes]).reshape(M, 3, 3)
        a["shape_t"] = np.array([pose[:3, 3] for _, _, _, pose, _ in m_shapes]).reshape(M, 3)
        a["hull_v"], a["hull_n"], a["hull_p"], a["hull_pn"] = _hull_tables(m_hull)
        a["hull_pts"] = np.array(m_pts, dtype=bool).reshape(M)
        a["sbox_ok"] = np.array([k in ("box", "sphere") for k, _, _ in m_geo], dtype=bool)
        a["sbox_h"] = np.array([np.asarray(d[:3], float) / 2 if k == "box" else np.zeros(3)
                                for k, d, _ in m_geo]).reshape(M, 3)
        a["sbox_rho"] = np.array([float(d[0]) if k == "sphere" else 0.0 for k, d, _ in m_geo])

        # Units: bounding sphere, sphere cover (outer), inner spheres, rounded box; frame coordinates.
        a["unit_frame"] = np.array([m_shapes[ms[0]][2] for ms in unit_shapes], dtype=np.int64)
        outer = a["outer"] = SphereTable.build([[(m_cover[m], k) for k, m in enumerate(ms)] for ms in unit_shapes])
        a["inner"] = SphereTable.build([[(m_inner[m], k) for k, m in enumerate(ms) if m_inner[m] is not None]
                                        for ms in unit_shapes])
        bounds = [enclosing_sphere(SphereCover(outer.centers[u, :c], outer.radii[u, :c]))
                  for u, c in enumerate(outer.counts)]
        a["bound_c"] = np.array([c for c, _ in bounds]).reshape(U, 3)
        a["bound_r"] = np.array([r for _, r in bounds])
        a["ubox"] = Boxes.build([union_box([m_box[m] for m in ms]) for ms in unit_shapes])
        a["ubox_tight"] = np.array([box_is_tight([m_geo[m] for m in ms]) for ms in unit_shapes], dtype=bool)
        kmax = max((len(ms) for ms in unit_shapes), default=1)
        a["unit_shape_tab"] = np.full((U, kmax), -1, dtype=np.int64)  # unit → its shapes (moving ids)
        a["unit_of_shape"] = np.zeros(M, dtype=np.int64)
        for u, ms in enumerate(unit_shapes):
            a["unit_shape_tab"][u, :len(ms)] = ms
            a["unit_of_shape"][ms] = u
        a["shape_kind"] = [kind for kind, _, _ in m_geo]
        for name, value in a.items():
            setattr(lv, name, value)
        part = GroupPart(lv.fk, m_shapes, f_shapes, unit_shapes, m_cover, m_geo, f_box, f_tight, f_cover, f_inner,
                         f_hull, f_ibox, a, _triangle_tables(m_tri + f_tri), self._reach(), self._unit_levers())
        self._unit_shapes = unit_shapes
        part.self_pairs = self._self_pairs()
        part.partners = self._partners()
        part.allowed_links = self._allowed_links([Body(n, True, 0, np.eye(4), None) for n in lv.units],
                                                 [Body(lc.name, True, -1, pose, None) for lc, _, _, pose, _ in f_shapes])
        return part

    def _build(self, part: "GroupPart") -> None:
        """Moving shapes → prefilter units (frame coordinates); fixed shapes → world boxes: the robot's from
        part (its fcl objects this checker's own), the scene's in reach added."""
        lv = self.levels
        for name, value in part.arrays.items():
            setattr(lv, name, value)
        moving: list[Body] = []
        fixed: list[Body] = []
        for shapes, out in ((part.m_shapes, moving), (part.f_shapes, fixed)):
            for lc, k, frame, pose, robot_link in shapes:
                shape = lc.shapes[k]
                obj = self._shape_object(robot_link, lc.fcl_geoms[k], shape, None if frame >= 0 else pose)
                out.append(Body(lc.name, True, frame, pose, obj))
                self._add_hull(obj, lc.hulls[k] if lc.hulls else None, shape.kind)
        unit_shapes = part.unit_shapes
        U, M = len(unit_shapes), len(moving)
        f_box, f_tight, f_cover, f_inner, f_hull = (list(part.f_box), list(part.f_tight), list(part.f_cover),
                                                    list(part.f_inner), list(part.f_hull))
        f_ibox = list(part.f_ibox)
        n_robot_fixed = len(fixed)

        # Scene objects that some unit can reach (a ball test per object, on bounds cached per object);
        # only those become bodies: a plan's cost does not grow with objects no link can touch.
        objects = self.scene.objects if self.scene is not None else ()
        # out of reach (indices into the scene's objects): only fixed_collisions looks at them
        self._culled = np.arange(len(objects) if not U else 0)
        if objects and U:
            near = self.scene.objects_near(*part.reach, self.padding + self.margin + EPS)
            self._culled = np.flatnonzero(~near)
            objects = tuple(objects[i] for i in np.flatnonzero(near).tolist())
        elif not U:
            objects = ()
        self.scene_objects_culled = len(self._culled)
        for sb in scene_bodies(objects):
            fixed.append(self._scene_body(sb))
            f_box.append(sb.box)
            f_tight.append(sb.tight)
            f_cover.append(None)
            f_inner.append(scene_body_inner(sb))
            f_hull.append(None)  # (no triangles either: scene meshes stay with FCL's BVH)
            f_ibox.append(None)  # a scene box's own box is exact (f_tight); other shapes have inner spheres
        self.levels.moving, self.levels.fixed = moving, fixed
        # Required clearance per pair kind: `padding` against the scene, `self_padding` robot–robot.
        self.levels.f_pad = np.array([self.self_padding if b.is_link else self.padding for b in fixed])

        # Fixed bodies: world boxes; robot meshes also keep their cover (tested against unit boxes).
        self.levels.fbox = Boxes.build(f_box)
        self.levels.f_tight = np.array(f_tight, dtype=bool)
        self.levels.f_cover = SphereTable.build([[(c, 0)] if c is not None else [] for c in f_cover])
        self.levels.f_has_cover = self.levels.f_cover.counts > 0
        self.levels.f_inner = SphereTable.build([[(c, 0)] if c is not None else [] for c in f_inner])
        self.levels.f_hull_v, self.levels.f_hull_n, self.levels.f_hull_p, self.levels.f_hull_pn = _hull_tables(f_hull)

        # triangles: moving shape m, then fixed body e as M + e (the scene's bodies have none)
        for name, value in part.triangles.items():
            setattr(lv, name, value)
        n_scene = len(fixed) - n_robot_fixed
        lv.tri_off = np.concatenate([lv.tri_off, np.full(n_scene, lv.tri_off[-1])])
        lv.run_off = np.concatenate([lv.run_off, np.full(n_scene, lv.run_off[-1])])
        self._reset_witnesses()
        fb = self.levels.fbox  # the fixed boxes as triangle_tests reads them (contiguous, made once)
        self.levels.fbox_R, self.levels.fbox_t, self.levels.fbox_h, self.levels.fbox_rho = (
            np.ascontiguousarray(x, dtype=float) for x in (fb.R, fb.t, fb.h, fb.rho))
        self._unit_shapes = unit_shapes
        self._pairs(part)
        self._inner_boxes(f_ibox)
        # Point-cloud cells: against every unit (no SRDF or grasp exemption applies to them).
        self._shape_cover = part.m_cover
        self._shape_is_sphere = [kind == "sphere" for kind, _, _ in part.m_geo]
        self._fcl_bodies = [x.obj for x in fixed] + [x.obj for x in moving]  # level 3's body index: fixed, then moving
        self._pair_hits = np.zeros((M, len(fixed) + M))  # level 3: (moving shape, body) collisions found
        self._pair_calls = np.zeros((M, len(fixed) + M))  # ... and FCL calls made (orders the next ones)
        self._tables: dict | None = None  # pair clearance tables (pair_tables.py), built at the first check
        self._env_tables: dict | None = None  # ... of units against fixed links
        self._cluster_tables: dict | None = None  # ... of level 1's cluster pairs (compiled levels)
        layer = self.scene.voxels if self.scene is not None else None
        self._vox = None
        if layer is not None and len(layer) and U and not self.cross_groups_only:
            # cells keep the whole edge margin for configurations too (conservative; per-row margins
            # are not threaded through the cell tests)
            s = float(layer.size)
            vox = VoxelObstacles(layer, *part.reach, self.padding + self.margin,
                                 cube=self._loan.primitive("box", (s, s, s)))
            self._vox = vox if vox.active else None
        self.unit_levers = part.unit_levers
        self._pair_levers_table()

    def _reset_witnesses(self) -> None:
        """No witnesses yet (a new checker, or an exempting copy: its own, not its parent's)."""
        n = len(self.levels.tri_off) - 1
        self._wit_slot = np.full((n, n), -1, dtype=np.int64)  # (shape, shape or M + e) → witness slot
        self._wit = np.zeros((0, WITNESSES, 2), dtype=np.int64)  # per slot: triangle pairs (rows of tri)
        self._wit_n = np.zeros(0, dtype=np.int64)  # per slot: how many are set
        self._wit_held: list[list[tuple[int, int]]] = []  # per slot: the pairs held, oldest first (plain Python:
        # _add_witness runs once per FCL contact, and numpy calls there cost more than the kernel's tests)
        self._tri_counts = np.diff(self.levels.tri_off).tolist()

    def _add_witness(self, a: int, b: int, ta: int, tb: int) -> None:
        """Remember that triangles ta of a and tb of b (FCL's primitive ids; a, b as in _wit_slot) were
        found intersecting, or nearest and closer than the pair's clearance: nearby configurations often
        collide there again (the samples around a contact, a motion's samples along a link they keep their
        margins from), and kernels.triangle_tests tests such pairs first."""
        counts = self._tri_counts
        if not (0 <= ta < counts[a] and 0 <= tb < counts[b]):
            return  # a shape without triangles (a primitive, a large mesh), or ids that are not its
        rank, off = self.levels.tri_rank, self.levels.tri_off
        pair = (int(rank[off[a] + ta]), int(rank[off[b] + tb]))
        s = int(self._wit_slot[a, b])
        if s < 0:
            s = self._wit_slot[a, b] = len(self._wit_held)
            self._wit = np.concatenate([self._wit, np.zeros((1, WITNESSES, 2), np.int64)])
            self._wit_n = np.append(self._wit_n, 0)
            self._wit_held.append([])
        held = self._wit_held[s]
        if pair in held:
            return
        if len(held) == WITNESSES:
            held.pop(0)
        held.append(pair)
        self._wit[s, :len(held)] = held[::-1]  # the latest first: the likeliest to hold again
        self._wit_n[s] = len(held)

    def _inner_boxes(self, meshes: list[tuple[str, int, np.ndarray] | None]) -> None:
        """Boxes inside the fixed robot meshes (link, shape, link pose) some unit can reach, from the robot's
        collision model (geometry.mesh_inner_box, built at first use): only those in reach, so that a group
        pays for the few meshes it can touch (TALOS l_arm: 28 of its 35 fixed meshes in reach, 6 big enough)."""
        reach = set(self.levels.env_e.tolist())
        boxes = []
        for e, m in enumerate(meshes):
            b = self.collision_model.inner_box(m[0], m[1]) if m is not None and e in reach else None
            boxes.append(None if b is None else b.transformed(m[2]))
        self.levels.f_ibox_ok = np.array([b is not None for b in boxes], dtype=bool)
        self.levels.f_ibox = Boxes.build([b if b is not None else BoundingBox(np.eye(4), np.zeros(3)) for b in boxes])

    def _pairs(self, part: GroupPart | None = None) -> None:
        """The pairs checked (those `_pair_allowed` keeps) and their level-1 tables: units against fixed
        bodies, unit against unit, and the clusters over them. part: the group's, whose self pairs and
        robot-link exemptions hold for this checker (None: computed again, `exempting`)."""
        # Unit × fixed pairs: checked ones (exact_check visits them), and those in reach (level 1).
        fixed = self.levels.fixed
        probe = [Body(n, True, 0, np.eye(4), None) for n in self.levels.units]
        self._allowed_env = self._allowed_fixed(probe, fixed, part)
        reach_c, reach_r = self._reach() if part is None else part.reach
        gap = self._box_distance(reach_c) - self.levels.fbox.rho[None, :]
        reach = gap <= reach_r[:, None] + self.levels.f_pad[None, :] + self.margin + EPS
        self.levels.env_u, self.levels.env_e = np.nonzero(self._allowed_env & reach)
        self.levels.env_R, self.levels.env_t, self.levels.env_h, _ = self.levels.fbox.take(self.levels.env_e)
        thr = self.levels.bound_r[self.levels.env_u] + self.levels.fbox.rho[self.levels.env_e] + self.levels.f_pad[self.levels.env_e] + self.margin + EPS
        self.levels.env_thr2 = thr * thr
        sp = self._self_pairs() if part is None else part.self_pairs
        for name in ("self_s", "self_o", "self_two", "self_thr2"):
            setattr(self.levels, name, sp[name])
        self._self_shapes = sp["shapes"]
        self.levels.build_clusters()

    def _self_pairs(self) -> dict:
        """Unit × unit pairs in different frames (same frame: the relative pose is constant) that
        `_pair_allowed` keeps: the levels' self_s, self_o, self_two, self_thr2, and per shape pair its pair
        ("shapes")."""
        U, unit_shapes, lv = len(self.levels.units), self._unit_shapes, self.levels
        probe = [Body(n, True, 0, np.eye(4), None) for n in lv.units]
        group_of = np.searchsorted(self._group_sizes, [lv.fk.frames[f].column for f in lv.unit_frame],
                                   side="right") - 1
        pairs = [(a, b) for a in range(U) for b in range(a + 1, U)
                 if lv.unit_frame[a] != lv.unit_frame[b] and self._pair_allowed(probe[a], probe[b])
                 and (not self.cross_groups_only or group_of[a] != group_of[b])]
        # Level 2 tests the spheres of one side (s) against the rounded box of the other (o): take o
        # with an exact box (if both, s has fewer spheres); neither exact: test both ways.
        s_side, o_side, two = [], [], []
        for a, b in pairs:
            ta, tb = lv.ubox_tight[a], lv.ubox_tight[b]
            if (ta and tb and lv.outer.counts[a] > lv.outer.counts[b]) or (ta and not tb):
                a, b = b, a
            s_side.append(a)
            o_side.append(b)
            two.append(not (ta or tb))
        out = {"self_s": np.array(s_side, dtype=np.int64), "self_o": np.array(o_side, dtype=np.int64),
               "self_two": np.array(two, dtype=bool)}
        thr = lv.bound_r[out["self_s"]] + lv.bound_r[out["self_o"]] + self.self_padding + 2 * self.margin + EPS
        out["self_thr2"] = thr * thr
        out["shapes"] = [(x, y, p) for p, (a, b) in enumerate(pairs) for x in unit_shapes[a] for y in unit_shapes[b]]
        return out

    def _pair_levers_table(self) -> None:
        """Per checked self pair, the joints that move one side only (what edge_margins sums)."""
        L, a, b = self.unit_levers, self.levels.self_s, self.levels.self_o
        self.levels.pair_levers = L[a] * (L[b] == 0) + L[b] * (L[a] == 0)  # joints moving one side only
        self._levers = np.vstack([L, self.levels.pair_levers])  # (U + P, dof): what edge_margins sums
        self._half_levers = np.ascontiguousarray(0.5 * self._levers.T)

    def exempting(self, pairs: Iterable[tuple[str, str]]) -> "CollisionChecker":
        """This checker with the named body pairs (a robot link or attached object, and a link or
        scene object) no longer checked: a hand allowed to touch the object it let go of, an attached
        object its support. It shares this checker's geometry and fcl objects (only the pair tables
        are built again, a fraction of a build), so neither may be used while the other checks (from
        another thread)."""
        out = copy.copy(self)
        out.levels = copy.copy(self.levels)  # the pair arrays are rebuilt; the bodies are shared
        out._excluded = self._excluded | {frozenset(p) for p in pairs}
        out._parent = self  # keeps the borrowed fcl objects on loan while the copy lives
        out._shared_part = None  # its exclusions are not the group's: its own fixed_collisions
        out.stats = CollisionStats()
        M = len(self.levels.moving)
        out._pair_hits = np.zeros((M, len(self.levels.fixed) + M))
        out._pair_calls = np.zeros((M, len(self.levels.fixed) + M))
        out._tables, out._env_tables, out._cluster_tables, out._fixed_collisions, out._managers = (None,) * 5
        out._reset_witnesses()
        out._pairs()
        out._pair_levers_table()
        return out



    def _unit_levers(self) -> np.ndarray:
        """(U, dof): metres a point of unit u may move per radian of each group joint (per metre of a
        prismatic one): a bound on the distance of the unit's points from the joint's *axis* (a turn
        by θ moves a point by at most θ times that), 0 for joints that do not move the unit. Along the
        chain by the triangle inequality: from a joint's axis, at most the distance of the child
        joint's origin from that axis plus how far the unit reaches from that origin. The axis, not
        the origin: a forearm turning about its own length moves by its radius, not its length
        (iCub's arm: 20-35 % fewer samples per motion, and smaller margins)."""
        lim = np.maximum(np.abs(self.robot.lower), np.abs(self.robot.upper))[self.joint_indices]
        lv = self.levels
        frames = lv.fk.frames
        out = np.zeros((len(lv.units), self.dof))
        for u, f in enumerate(lv.unit_frame):
            c, r = lv.outer.centers[u, :lv.outer.counts[u]], lv.outer.radii[u, :lv.outer.counts[u]]
            whole = float(np.linalg.norm(lv.bound_c[u])) + lv.bound_r[u]
            dist = min(whole, float((np.linalg.norm(c, axis=1) + r).max(initial=0.0)))  # from frame f's origin
            axial = min(dist, float((np.linalg.norm(c[:, :2], axis=1) + r).max(initial=0.0)))  # from its z axis
            k = int(f)
            while k >= 0:
                fr = frames[k]
                slide = float(lim[fr.column]) if fr.prismatic else 0.0
                out[u, fr.column] = 1.0 if fr.prismatic else axial
                # fr.t: this joint's origin in the parent frame, whose z axis is the parent joint's axis
                axial = float(np.linalg.norm(fr.t[:2])) + slide + dist
                dist += float(np.linalg.norm(fr.t)) + slide
                k = fr.parent
        return out

    def _reach(self) -> tuple[np.ndarray, np.ndarray]:
        """Per unit, a world ball that contains it in every configuration: centred on the origin of
        its chain's first group joint (fixed in the world), radius by the triangle inequality."""
        lim = np.maximum(np.abs(self.robot.lower), np.abs(self.robot.upper))[self.joint_indices]
        root, dist = [], []
        for fr in self.levels.fk.frames:
            slide = float(lim[fr.column]) if fr.prismatic else 0.0
            if fr.parent < 0:
                root.append(fr.t)
                dist.append(slide)
            else:
                root.append(root[fr.parent])
                dist.append(dist[fr.parent] + float(np.linalg.norm(fr.t)) + slide)
        f = self.levels.unit_frame
        centres = np.array([root[k] for k in f]).reshape(len(f), 3)
        radii = np.array([dist[k] for k in f]) + np.linalg.norm(self.levels.bound_c, axis=1) + self.levels.bound_r
        return centres, radii

    def _box_distance(self, points: np.ndarray, rows=slice(None)) -> np.ndarray:
        """(P, 3) points → (P, E) distances to the fixed boxes `rows` (default all; without their rounding)."""
        R, t, h, _ = self.levels.fbox.take(rows)
        local = np.einsum("pei,eij->pej", points[:, None, :] - t[None], R)
        return np.linalg.norm(np.maximum(np.abs(local) - h[None], 0.0), axis=-1)

    # ------------------------------------------------------------------ public API
    @property
    def moving_links(self) -> tuple[str, ...]:
        """Links with geometry that move with the group(s)."""
        return tuple(dict.fromkeys(self.levels.units))

    def edge_margins(self, motion: np.ndarray) -> np.ndarray:
        """Edge margins (m) of joint displacements `motion` (N, n) to a neighbouring sample: (N, U + P),
        per moving unit, then per self pair. The elementwise maximum of two is the margins of both."""
        d = np.abs(np.atleast_2d(np.asarray(motion, dtype=float)))
        out = np.zeros((len(d), len(self._levers)))
        for j in range(self.dof):  # multiply-adds: a BLAS matmul of these small shapes costs ~1 ms on a busy machine
            out += d[:, j, None] * self._half_levers[j]
        return out

    def check_configs(self, q: np.ndarray, margins: np.ndarray | None = None) -> np.ndarray:
        """(N, n) group configurations → (N,) bool, True = collision-free.

        margins: for the samples of a motion (not for deciding whether a configuration collides),
        (N, U + P) edge margins (edge_margins) each row must keep too, at most the checker's `margin`
        per unit (2 × margin per pair). Raises Interrupted when `stop` is set and says so."""
        if self.stop is not None and self.stop():
            raise Interrupted("collision checking stopped (deadline or cancel)")
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f"expected (N, {self.dof}) configurations, got {q.shape}")
        U = len(self.levels.units)
        if margins is None:
            w = None  # configurations: no margins
        else:
            w = np.asarray(margins, dtype=float).reshape(len(q), len(self._levers))
            if len(q) and (w[:, :U].max(initial=0) > self.margin + 1e-12 or w[:, U:].max(initial=0) > 2 * self.margin + 1e-12):
                raise ValueError(f"edge margins exceed the checker's margin {self.margin:.4g} m")
        if len(q) <= _BATCH:
            return self._valid_all(q, w)
        return np.concatenate([self._valid_all(q[i:i + _BATCH], None if w is None else w[i:i + _BATCH])
                               for i in range(0, len(q), _BATCH)])

    def first_collision(self, q: np.ndarray, bounds: np.ndarray) -> int:
        """The first colliding configuration of q (N, n) (N: none), each decided as check_configs decides
        it (no margins; the same verdict), in order, stopping there: a search's motion with an early stop.
        bounds (B, 2): the batches [lo, hi) of q in order; the compiled path checks their configurations one
        by one in one kernel call (kernels.screen_batches) and comes back here at the end of a batch whose
        configurations before the first collision have entries left for FCL (FCL then stops at the first
        colliding one too). The statistics count the configurations decided: those up to the first
        collision, and any decided past it."""
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f"expected (N, {self.dof}) configurations, got {q.shape}")
        bounds = np.asarray(bounds, dtype=np.int64).reshape(-1, 2)
        lv = self.levels
        if not lv.use_compiled or self._vox is not None or not lv.units:
            for lo, hi in bounds.tolist():
                bad = np.flatnonzero(~self.check_configs(q[lo:hi]))
                if len(bad):
                    return lo + int(bad[0])
            return len(q)
        if lv.tables is None:
            self._kernel_tables()
        q = np.ascontiguousarray(q)
        st = self.stats
        b = 0
        while b < len(bounds):
            if self.stop is not None and self.stop():
                raise Interrupted("collision checking stopped (deadline or cancel)")
            wit = self._wit_slot if len(self._wit_n) else _NO_SLOTS
            b, first, ok, R, t, env, slf, counts, n_tab, hits, dropped = kernels.screen_batches(
                q, bounds, b, lv.margin, lv.self_padding, EPS, lv.kernel_data(), lv.frame_of, lv.tri, lv.tri_c,
                lv.tri_r, lv.run_lo, lv.run_hi, lv.run_c, lv.run_r, lv.run_off, lv.fbox_R, lv.fbox_t, lv.fbox_h,
                lv.fbox_rho, lv.f_tight, lv.f_pad, wit, self._wit, self._wit_n)
            checked = int(counts.sum()) - int(counts[STATUS_UNCHECKED]) - dropped
            st.configs_checked += checked
            st.level1_free += int(counts[STATUS_FREE1])
            st.level2_colliding += int(counts[STATUS_HIT]) + hits
            st.level2_free += int(counts[STATUS_FREE2]) + int(counts[STATUS_OPEN]) - hits - dropped
            st.table_free += n_tab
            if len(env) or len(slf):  # FCL decides the configurations before `first` the kernel left open
                env, slf = (env[:, 0], env[:, 1], env[:, 2]), (slf[:, 0], slf[:, 1], slf[:, 2], slf[:, 3])
                exact = st.exact_checks
                left = self._exact_open(R, t, env, slf, NO_MARGINS, NO_MARGINS, ok, first_only=True)
                st.configs_checked -= left - (st.exact_checks - exact)  # those FCL did not reach
                bad = np.flatnonzero(~ok)
                if len(bad):
                    return int(bounds[b, 0]) + int(bad[0])
            if first >= 0:
                return int(first)
            b += 1
        return len(q)

    def _valid_all(self, q: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Bodies (_valid), then the point-cloud cells for the configurations still free."""
        ok = self._valid(q, w)
        if self._vox is not None:
            live = np.nonzero(ok)[0]
            if len(live):
                ok[live] = self._voxels_free(q[live])
        return ok

    def check_config(self, q: np.ndarray) -> bool:
        """One configuration (n,) → True when collision-free."""
        return bool(self.check_configs(np.asarray(q, dtype=float).reshape(1, -1))[0])

    def edge_steps(self, q0: np.ndarray, q1: np.ndarray) -> int:
        """Interpolation steps of q0 → q1: no joint moves more than edge_resolution per step."""
        d = np.max(np.abs(np.asarray(q1, float) - np.asarray(q0, float)))
        return max(1, int(np.ceil(d / self.edge_resolution - 1e-9)))

    def check_edge(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        """Is the straight motion q0 → q1 free? q0 is taken as checked; q1 and the points between
        are checked coarse-to-fine in chunks (edge_chunk, then doubling), stopping at the first
        chunk with a collision."""
        return bool(self.check_edges(np.asarray(q0, float)[None], np.asarray(q1, float)[None])[0])

    def _chunks(self, n: int) -> list[tuple[int, int]]:
        """Step ranges [lo, hi) checked per round: edge_chunk, then doubling — early exit where
        collisions are likely (the first, coarse points), few calls along long free edges."""
        out, lo, c = [], 0, self.edge_chunk
        while lo < n:
            out.append((lo, min(lo + c, n)))
            lo, c = lo + c, 2 * c
        return out

    def check_edges(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """(M, n), (M, n) → (M,) bool for M edges at once: round r checks chunk r (coarse-to-fine)
        of every edge still alive in one batch; an edge dies at its first collision."""
        q0, q1 = np.atleast_2d(np.asarray(q0, float)), np.atleast_2d(np.asarray(q1, float))
        if q0.shape != q1.shape or q0.shape[1] != self.dof:
            raise ValueError(f"expected two (M, {self.dof}) arrays, got {q0.shape} and {q1.shape}")
        m = len(q0)
        self.stats.edges_checked += m
        steps = [self.edge_steps(a, b) for a, b in zip(q0, q1)]
        chunks = [self._chunks(n) for n in steps]
        ok = np.ones(m, dtype=bool)
        for r in range(max((len(c) for c in chunks), default=0)):
            live = [e for e in range(m) if ok[e] and r < len(chunks[e])]
            if not live:
                break
            ks = [coarse_to_fine(steps[e])[slice(*chunks[e][r])] for e in live]
            owner = np.repeat(live, [len(k) for k in ks])
            frac = (np.concatenate(ks) / np.asarray(steps)[owner])[:, None]
            bad = ~self.check_configs(q0[owner] + frac * (q1[owner] - q0[owner]))
            ok[owner[bad]] = False
        return ok

    def check_path(self, waypoints: np.ndarray) -> bool:
        """The first waypoint and every edge of a path."""
        w = np.atleast_2d(np.asarray(waypoints, float))
        return self.check_config(w[0]) and bool(len(w) < 2 or self.check_edges(w[:-1], w[1:]).all())

    def first_collision_along(self, q0: np.ndarray, q1: np.ndarray) -> float:
        """Walking from q0 (taken as free) towards q1 in edge_resolution steps: the fraction of the
        last free step (1.0: the whole motion is free; 0.0: the first step collides). The point
        q0 + t (q1 - q0) is one of the interpolated configurations, so it is known to be free."""
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        self.stats.edges_checked += 1
        n = self.edge_steps(q0, q1)
        for lo, hi in self._chunks(n):
            k = np.arange(lo + 1, hi + 1)
            bad = ~self.check_configs(q0 + (k / n)[:, None] * (q1 - q0))
            if bad.any():
                return float((k[np.argmax(bad)] - 1) / n)
        return 1.0

    def exact_check(self, q: np.ndarray, margins: np.ndarray | None = None) -> bool:
        """One configuration through python-fcl only (no prefilter): every pair the checker is
        responsible for, broad phase per moving shape (fcl's DynamicAABBTree) against fixed bodies,
        pairwise between moving shapes. True = collision-free. The per-configuration baseline.
        margins: (U,) edge margins to keep too, as in check_configs."""
        q = np.asarray(q, dtype=float).reshape(1, self.dof)
        self.stats.configs_checked += 1
        if not self.levels.moving:
            return True
        if self._managers is None:
            self._managers = self._make_managers()
        self._place_moving(*self.levels.fk(q))
        w = np.zeros(len(self._levers)) if margins is None else np.ravel(margins)
        m, mp = w[:len(self.levels.units)][self.levels.unit_of_shape], w[len(self.levels.units):]  # per shape, per pair
        if self.levels.f_pad.any() or self.self_padding > 0 or w.any():  # distances needed: every pair, one by one
            for i, b in enumerate(self.levels.moving):
                for j in np.nonzero(self._allowed_env[self.levels.unit_of_shape[i]])[0]:
                    if self._collide(b.obj, self.levels.fixed[j].obj, self.levels.f_pad[j] + m[i]):
                        return False
        else:
            for b, mgr in zip(self.levels.moving, self._managers):
                if mgr is not None:
                    data = fcl.CollisionData(request=self._req)
                    mgr.collide(b.obj, data, fcl.defaultCollisionCallback)
                    if data.result.is_collision:
                        return False
        for a, b, p in self._self_shapes:
            if self._collide(self.levels.moving[a].obj, self.levels.moving[b].obj, self.self_padding + mp[p]):
                return False
        if self._vox is not None:
            R, t = self.levels.fk(q)
            return not self._voxel_exact(R, t, [(0, m) for m in range(len(self.levels.moving))])
        return True

    def colliding_pairs(self, q: np.ndarray) -> tuple[tuple[str, str], ...]:
        """The pairs that make one configuration collide, by name (robot link or attached object
        first; then a link, an attached object, a scene object or "point cloud"): every pair
        check_configs decides, through python-fcl, none skipped after the first hit. For telling a
        user why a configuration was refused, not for planning (every pair costs an FCL call)."""
        q = np.asarray(q, dtype=float).reshape(1, self.dof)
        if not self.levels.moving:
            return ()
        R, t = self.levels.fk(q)
        self._place_moving(R, t)
        out: dict[tuple[str, str], None] = {}
        for i, b in enumerate(self.levels.moving):
            for j in np.nonzero(self._allowed_env[self.levels.unit_of_shape[i]])[0]:
                if self._collide(b.obj, self.levels.fixed[j].obj, self.levels.f_pad[j]):
                    out[(b.name, self.levels.fixed[j].name)] = None
        for a, b, _ in self._self_shapes:
            if self._collide(self.levels.moving[a].obj, self.levels.moving[b].obj, self.self_padding):
                out[(self.levels.moving[a].name, self.levels.moving[b].name)] = None
        if self._vox is not None:
            for m, body in enumerate(self.levels.moving):
                if self._voxel_exact(R, t, [(0, m)]):
                    out[(body.name, "point cloud")] = None
        return tuple(out)

    def fixed_collisions(self) -> tuple[tuple[str, str], ...]:
        """Colliding pairs that no configuration of the group can change, at q_ref: fixed links
        against each other and the scene, links rigid on the same group joint. Never counted
        against a configuration; a planner may report them (start state / environment)."""
        if self._fixed_collisions is None:
            fixed, part = self.levels.fixed, self._shared_part
            links = [a for a in fixed if a.is_link]  # the robot's (and attached objects'), first of `fixed`
            # the robot's own pairs: the same for every checker of a shared part (~1 ms of a humanoid's build)
            robot = part.fixed_pairs if part is not None else None
            if robot is None:
                robot = self._robot_fixed_collisions(links)
                if part is not None:
                    part.fixed_pairs = robot
            out: dict[tuple[str, str], None] = dict.fromkeys(robot)
            # the scene's bodies (all fixed, frame -1) against the fixed links: those in reach, and the culled
            # objects that may still touch a fixed link
            culled = [self._scene_body(sb) for sb in scene_bodies(self._culled_near_fixed_links())] if links else []
            for b in fixed[len(links):] + culled:
                for a in links:
                    if self._pair_allowed(a, b) and self._collide(a.obj, b.obj, self.padding):
                        out[(a.name, b.name)] = None
            self._fixed_collisions = tuple(out)
        return self._fixed_collisions

    def _robot_fixed_collisions(self, links: list[Body]) -> tuple[tuple[str, str], ...]:
        """fixed_collisions among the robot's bodies (fixed links, then the moving ones placed at q_ref): pairs in
        one frame, closer than self_padding."""
        self._place_moving(*self.levels.fk(self.q_ref[self.joint_indices][None, :]))
        bodies = links + self.levels.moving
        pairs = ((a.name, b.name) for i, a in enumerate(bodies) for b in bodies[i + 1:]
                 if a.frame == b.frame and self._pair_allowed(a, b) and self._collide(a.obj, b.obj, self.self_padding))
        return tuple(dict.fromkeys(pairs))  # a link of several shapes: its pair once

    def _culled_near_fixed_links(self) -> tuple[SceneObject, ...]:
        """The culled objects whose bounding ball comes within `padding` of a fixed link's rounded box
        (which contains the link): only these can touch one, and thousands of far objects then cost
        one array operation, not an fcl object and a test each."""
        if not len(self._culled):
            return ()
        rows = [j for j, b in enumerate(self.levels.fixed) if b.is_link]
        oc, orad = self.scene.object_spheres
        dist = self._box_distance(oc[self._culled], rows)
        near = (dist <= orad[self._culled, None] + self.levels.fbox.rho[rows][None] + self.padding + EPS).any(axis=1)
        objects = self.scene.objects
        return tuple(objects[i] for i in self._culled[near].tolist())

    def summary(self) -> dict:
        """Sizes of the compiled problem and the counters, for logs and benchmarks."""
        return {
            "groups": self.groups, "dof": self.dof, "frames": len(self.levels.fk),
            "moving_links": len(self.moving_links), "units": len(self.levels.units),
            "moving_shapes": len(self.levels.moving), "fixed_bodies": len(self.levels.fixed),
            "spheres": int(self.levels.outer.counts.sum()), "env_pairs": int(self._allowed_env.sum()),
            "env_pairs_in_reach": len(self.levels.env_u), "self_pairs": len(self.levels.self_s),
            "voxel_cells": self._vox.grid.count if self._vox is not None else 0,
            **{f.name: getattr(self.stats, f.name) for f in fields(self.stats)},
        }

    # ------------------------------------------------------------------ batch path
    def _valid(self, q: np.ndarray, wide: np.ndarray) -> np.ndarray:
        """wide (N, U + P): the edge margins of each row, per unit and per self pair. Level 1 always
        tests with the checker's largest margin (conservative for every row); levels 2–3 add them
        per entry."""
        N = len(q)
        self.stats.configs_checked += N
        ok = np.ones(N, dtype=bool)
        if N == 0 or not self.levels.units:
            return ok
        U = len(self.levels.units)
        me, mp = (NO_MARGINS, NO_MARGINS) if wide is None else (wide[:, :U], wide[:, U:])
        if self.levels.use_compiled:
            return self._valid_compiled(q, wide, me, mp)
        R, t = self.levels.fk(q)
        # Level 1: unit bounding spheres, world (N, U, 3).
        f = self.levels.unit_frame
        B = np.matmul(R[:, f], self.levels.bound_c[:, :, None])[..., 0] + t[:, f]
        env = self.levels.level1_env(R, t, B)
        slf = self.levels.level1_self(R, t, B)
        flagged = np.zeros(N, dtype=bool)
        flagged[env[0]] = True
        flagged[slf[0]] = True
        n1 = int(flagged.sum())
        self.stats.level1_free += N - n1
        if n1 == 0:
            return ok
        # Level 2: proofs first, then covers for the configurations still open.
        hit = np.zeros(N, dtype=bool)
        self.levels.prove_env(R, t, *env, me, hit)
        self.levels.prove_self(R, t, *slf, mp, hit)
        env = self.levels.level2_env(R, t, *(x[~hit[env[0]]] for x in env), me)
        slf = self.levels.level2_self(R, t, *(x[~hit[slf[0]]] for x in slf), mp)
        slf = self._table_filter(q, slf, mp)
        env = self._env_table_filter(q, env, me)
        self.levels.prove_inner(R, t, env, slf, me, mp, hit)
        env = tuple(x[~hit[env[0]]] for x in env)
        slf = tuple(x[~hit[slf[0]]] for x in slf)
        flagged[:] = False
        flagged[env[0]] = True
        flagged[slf[0]] = True
        n_hit, n3 = int(hit.sum()), int(flagged.sum())
        self.stats.level2_colliding += n_hit
        self.stats.level2_free += n1 - n_hit - n3
        ok &= ~hit
        if n3:
            ok &= ~self._exact(R, t, env, slf, me, mp)
        return ok

    def _valid_compiled(self, q: np.ndarray, wide: np.ndarray | None, me, mp) -> np.ndarray:
        """_valid with FK and levels 1–2 in one compiled pass (kernels.py), the pair clearance tables
        applied inside it: no entry of a proven configuration is left, so what remains goes to FCL."""
        if self.levels.tables is None:
            self._kernel_tables()
        R, t, status, env, slf, n_tab = self.levels.compiled_12(q, None if wide is None else me,
                                                                None if wide is None else mp)
        counts = np.bincount(status, minlength=4)
        self.stats.level1_free += int(counts[STATUS_FREE1])
        self.stats.level2_colliding += int(counts[STATUS_HIT])
        self.stats.level2_free += int(counts[STATUS_FREE2]) + int(counts[STATUS_OPEN])
        self.stats.table_free += n_tab
        ok = status != STATUS_HIT
        if (len(env[0]) or len(slf[0])) and len(self.levels.tri):
            env, slf = self._triangle_tests(R, t, env, slf, me, mp, ok)
        if len(env[0]) or len(slf[0]):
            self._exact_open(R, t, env, slf, me, mp, ok)
        return ok

    def _exact_open(self, R, t, env, slf, me, mp, ok: np.ndarray, first_only: bool = False) -> int:
        """FCL (_exact) decides the configurations whose entries the kernels left open, marking the colliding
        ones in ok (in place); they leave level 2's free count. Returns how many configurations those were."""
        left = np.zeros(len(ok), dtype=bool)
        left[env[0]] = True
        left[slf[0]] = True
        n = int(left.sum())
        self.stats.level2_free -= n
        ok &= ~self._exact(R, t, env, slf, me, mp, first_only=first_only)
        return n

    def _triangle_tests(self, R, t, env, slf, me, mp, ok) -> tuple[tuple, tuple]:
        """The open entries decided by triangles in the kernel before FCL (kernels.triangle_tests): link
        meshes against scene boxes (FCL's own test, compiled), and pairs of meshes by the intersecting
        triangle pairs FCL found for them before. A configuration with a contact is marked colliding in ok
        and loses all its entries; entries proven apart are dropped; the rest go on to FCL."""
        lv = self.levels
        c = np.ascontiguousarray  # one array layout: one compilation (kernels.warm)
        n, m, e = c(env[0]), c(env[1]), c(env[2])
        ns = c(slf[0])
        margins = me is not NO_MARGINS
        keep_e, keep_s, hits = kernels.triangle_tests(
            R, t, ok, n, m, e, margins, c(me[n, lv.unit_of_shape[m]], dtype=float) if margins else _NO_FLOATS,
            ns, c(slf[1]), c(slf[2]), float(self.self_padding), margins,
            c(mp[ns, slf[3]], dtype=float) if margins else _NO_FLOATS, lv.frame_of, lv.tri, lv.tri_c, lv.tri_r,
            lv.run_lo, lv.run_hi, lv.run_c, lv.run_r, lv.run_off, lv.fbox_R, lv.fbox_t, lv.fbox_h, lv.fbox_rho,
            lv.f_tight, lv.f_pad, self._wit_slot if len(self._wit_n) else _NO_SLOTS, self._wit, self._wit_n, EPS)
        if hits:
            self.stats.level2_colliding += hits
            self.stats.level2_free -= hits
        return tuple(x[keep_e] for x in env), tuple(x[keep_s] for x in slf)

    def _kernel_tables(self) -> None:
        """At the first check: the pair clearance tables, handed to the compiled levels."""
        self._load_tables()
        self.levels.set_tables(self._tables, self._env_tables, self._cluster_tables)

    def without_tables(self) -> None:
        """Check without pair clearance tables and ask none to be built (a warm-up's one check: the same
        verdicts, more FCL calls)."""
        self._tables, self._env_tables, self._cluster_tables = {}, {}, {}

    def _load_tables(self, build: bool | None = None) -> None:
        """This checker's pair clearance tables (pair_tables.py), once: those built so far; the missing ones
        are built here when `build` (default: unless pair_tables builds in the background), else handed to
        pair_tables.BUILDER for later checkers (a table set takes seconds on a mesh robot; no plan waits for
        one: a pair without a table goes to FCL, the same verdict). Tables are built by a checker at
        pair_tables.table_q_ref (this one's q_ref rounded off the groups), so that nearby q_refs share them."""
        build = not building_in_background() if build is None else build
        wanted = [name for name in ("_tables", "_env_tables", "_cluster_tables") if getattr(self, name) is None]
        if not wanted:
            return
        found, done = self._cached_tables(wanted, build=False)
        if not done:
            q_tab = table_q_ref(self)
            if build and np.array_equal(q_tab, self.q_ref):
                found, done = self._cached_tables(wanted, build=True)
            else:
                robot, scene, groups, settings = self.robot, self.scene, self.groups, self.settings

                def build_them() -> None:
                    CollisionChecker(robot, scene, groups, q_tab, settings)._load_tables(build=True)

                if build:
                    build_them()
                    found, done = self._cached_tables(wanted, build=False)
                else:
                    slot = (id(self.collision_model), groups, settings)
                    BUILDER.submit((*slot, q_tab.tobytes()), slot, build_them)
        for name in wanted:
            setattr(self, name, found[name])

    def _cached_tables(self, wanted: list[str], build: bool) -> tuple[dict[str, dict], bool]:
        """The tables of the kinds wanted (attribute names) and whether none is missing; build: make the
        missing ones (only at table_q_ref: their keys say so)."""
        find = {"_tables": tables_for, "_env_tables": env_tables_for, "_cluster_tables": cluster_tables_for}
        found, done = {}, True
        for name in wanted:
            found[name], complete = find[name](self, build)
            done = done and complete
        return found, done

    def _table_filter(self, q: np.ndarray, slf, mp):
        """Drop the (config, shape, shape, pair) entries of pairs their clearance table proves free
        (lower bound of the exact distance > self_padding + edge margin): fewer FCL calls, same verdicts."""
        self._load_tables()
        if not self._tables or len(slf[0]) == 0:
            return slf
        p = slf[3]
        return self._drop_table_free(q, slf, ((p == pair, self.self_padding, mp, pair, tab)
                                              for pair, tab in self._tables.items()))

    def _env_table_filter(self, q: np.ndarray, env, me):
        """Drop the (config, moving shape, fixed body) entries of unit–fixed-link pairs their clearance
        table proves free (lower bound > the pair's padding + edge margin): fewer FCL calls, same verdicts."""
        self._load_tables()
        if not self._env_tables or len(env[0]) == 0:
            return env
        u, e = self.levels.unit_of_shape[env[1]], env[2]
        return self._drop_table_free(q, env, (((u == u0) & (e == e0), self.levels.f_pad[e0], me, u0, tab)
                                              for (u0, e0), tab in self._env_tables.items()))

    def _drop_table_free(self, q: np.ndarray, entries: tuple, tables) -> tuple:
        """entries: arrays whose first is the configuration of each entry. tables: (entry mask,
        padding, margins, margin column, table) per table; an entry is dropped when the table's lower
        bound exceeds the padding plus its row's edge margin in that column."""
        n = entries[0]
        keep = np.ones(len(n), dtype=bool)
        for mask, pad, margins, col, tab in tables:
            sel = np.nonzero(mask)[0]
            if len(sel):
                need = pad + np.broadcast_to(margins[n[sel], col], (len(sel),)) + EPS
                keep[sel] = tab.lower_bound(q[n[sel]]) <= need
        self.stats.table_free += int(len(n) - keep.sum())
        return tuple(x[keep] for x in entries)










    def _exact(self, R, t, env, slf, me, mp, first_only: bool = False) -> np.ndarray:
        """FCL on the flagged shape pairs; True = colliding. A configuration stops at its first
        colliding pair; a moving shape's transform is set once per configuration, if used. first_only:
        stop at the first colliding configuration (the others after it stay False, undecided)."""
        Ef = len(self.levels.fixed)
        n = np.concatenate([env[0], slf[0], slf[0]])
        m = np.concatenate([env[1], slf[1], slf[2]])  # the moving shapes whose poses may be needed
        f = self.levels.frame_of[m]
        Rf = R[n, f]
        Rw = np.matmul(Rf, self.levels.shape_R[m])
        tw = np.matmul(Rf, self.levels.shape_t[m][:, :, None])[:, :, 0] + t[n, f]
        ne, ns = len(env[0]), len(slf[0])
        # entries: (config, moving shape a, pose row of a, other body, pose row of b or -1)
        rows = np.arange(ne + ns)
        entries = np.stack([n[:ne + ns], m[:ne + ns], rows,
                            np.concatenate([env[2], slf[2] + Ef]),
                            np.concatenate([np.full(ne, -1), ne + ns + np.arange(ns)])], 1)
        # per configuration, the pairs that collided most often so far first (a colliding configuration
        # stops at its first hit; the order never changes a verdict)
        hits, calls = self._pair_hits, self._pair_calls
        a_, b_ = entries[:, 1], entries[:, 3]
        order = np.lexsort((-(hits[a_, b_] + 1.0) / (calls[a_, b_] + 2.0), entries[:, 0]))
        us = self.levels.unit_of_shape
        pads = np.concatenate([np.broadcast_to(self.levels.f_pad[env[2]] + me[env[0], us[env[1]]], (ne,)),
                               np.broadcast_to(self.self_padding + mp[slf[0], slf[3]], (ns,))])[order].tolist()
        entries = zip(*entries[order].T.tolist())  # flat columns: no list object per entry
        out = np.zeros(len(R), dtype=bool)
        moving = self.levels.moving
        bodies = self._fcl_bodies
        cfg, placed, done = -1, set(), False
        M, witnesses = len(moving), len(self.levels.tri) > 0
        for (c, a, ra, b, rb), pad in zip(entries, pads):
            if c != cfg:
                cfg, placed, done = c, set(), False
                self.stats.exact_checks += 1
            if done:
                continue
            for shape, row in ((a, ra), (b - Ef, rb)):
                if row >= 0 and shape not in placed:
                    moving[shape].obj.setRotation(Rw[row])
                    moving[shape].obj.setTranslation(tw[row])
                    placed.add(shape)
            calls[a, b] += 1
            res = fcl.CollisionResult()
            dres = fcl.DistanceResult() if witnesses and pad > 0 else None
            if self._collide(moving[a].obj, bodies[b], pad, res, dres):
                out[c] = done = True
                hits[a, b] += 1
                if witnesses:  # FCL's primitive ids: the triangles that met, or the nearest ones (closer than pad)
                    ta, tb = ((res.contacts[0].b1, res.contacts[0].b2) if res.contacts else
                              (dres.b1, dres.b2) if dres is not None else (-1, -1))
                    self._add_witness(a, b - Ef if b >= Ef else M + b, ta, tb)
                if first_only:
                    break
        return out

    def _voxels_free(self, q: np.ndarray) -> np.ndarray:
        """(N, n) configurations → (N,) bool against the point-cloud cells only: unit bounding
        spheres, then inner-sphere proofs and cover spheres of the units not cleared, then FCL."""
        vox = self._vox
        grid, pad = vox.grid, self.padding + EPS
        N = len(q)
        ok = np.ones(N, dtype=bool)
        R, t = self.levels.fk(q)
        u = vox.units
        f = self.levels.unit_frame[u]
        B = np.matmul(R[:, f], self.levels.bound_c[u][:, :, None])[..., 0] + t[:, f]
        n, k = np.nonzero(~grid.spheres_clear(B, self.levels.bound_r[u] + pad))
        if len(n) == 0:
            return ok
        u = u[k]
        Rn, tn = R[n, self.levels.unit_frame[u]], t[n, self.levels.unit_frame[u]]
        inner = self.levels.inner
        if inner.counts[u].any():
            C = inner.centers[u] @ Rn.transpose(0, 2, 1) + tn[:, None, :]
            sure = grid.spheres_hit(C, inner.radii[u]).any(1)
            ok[n[sure]] = False
            n, u, Rn, tn = n[~sure], u[~sure], Rn[~sure], tn[~sure]
        C = self.levels.outer.centers[u] @ Rn.transpose(0, 2, 1) + tn[:, None, :]
        hit = ~grid.spheres_clear(C, self.levels.outer.radii[u] + pad, refine=True)
        kk, ii = np.nonzero(hit & ok[n][:, None])
        if len(kk) == 0:
            return ok
        kk, ls = np.nonzero(self.levels.shape_mask(self.levels.outer, u, kk, ii, len(n)))
        entries = sorted({(int(n[a]), int(self.levels.unit_shape_tab[u[a], b])) for a, b in zip(kk, ls)})
        self.stats.exact_checks += len({c for c, _ in entries})
        ok[list(self._voxel_exact(R, t, entries))] = False
        return ok

    def _voxel_exact(self, R, t, entries: list[tuple[int, int]]) -> set[int]:
        """(configuration, moving shape) entries → the configurations whose shape meets a cell."""
        def placer(c: int, m: int):
            def place():
                Rw, tw = R[c, self.levels.frame_of[m]], t[c, self.levels.frame_of[m]]
                obj = self.levels.moving[m].obj
                obj.setRotation(Rw @ self.levels.shape_R[m])
                obj.setTranslation(Rw @ self.levels.shape_t[m] + tw)
                return obj
            return place

        covers = []
        for c, m in entries:
            Rw, tw, cover = R[c, self.levels.frame_of[m]], t[c, self.levels.frame_of[m]], self._shape_cover[m]
            covers.append((cover.centers @ Rw.T + tw, cover.radii + EPS))
        return self._vox.collisions(entries, [placer(c, m) for c, m in entries], covers, self._collide,
                                    [self._shape_is_sphere[m] for _, m in entries])

    # ------------------------------------------------------------------ fcl helpers
    def _collide(self, o1: fcl.CollisionObject, o2: fcl.CollisionObject, pad: float = 0.0,
                 result: fcl.CollisionResult | None = None, distance: fcl.DistanceResult | None = None) -> bool:
        """Do the two bodies collide, or come closer than pad? result / distance: FCL's collision result
        (its contacts) and distance result (the nearest primitives, when it measured one), when the caller
        wants them."""
        self.stats.exact_pairs += 1
        if fcl.collide(o1, o2, self._req, fcl.CollisionResult() if result is None else result):
            return True
        if pad <= 0:
            return False
        if self._hulls and self._hulls_apart(o1, o2, pad):
            return False
        return fcl.distance(o1, o2, self._dreq, fcl.DistanceResult() if distance is None else distance) < pad

    def _add_hull(self, obj: fcl.CollisionObject, hull: fcl.Convex | None, kind: str) -> None:
        if hull is not None:
            self._hulls[id(obj)] = self._loan.object(hull)
        elif kind in ("box", "sphere", "cylinder"):
            self._hulls[id(obj)] = obj

    def _hulls_apart(self, o1: fcl.CollisionObject, o2: fcl.CollisionObject, pad: float) -> bool:
        """True when convex solids containing the two shapes are at least `pad` apart, so the shapes
        are too: a GJK distance of two convex solids (~10 µs) instead of a mesh-to-mesh BVH distance
        (~0.3 ms on TALOS's links, where most padded FCL time went)."""
        h1, h2 = self._hulls.get(id(o1)), self._hulls.get(id(o2))
        if h1 is None or h2 is None:
            return False
        for h, o in ((h1, o1), (h2, o2)):
            if h is not o:
                h.setRotation(o.getRotation())
                h.setTranslation(o.getTranslation())
        return fcl.distance(h1, h2, self._dreq, fcl.DistanceResult()) - HULL_TOLERANCE >= pad

    def _place_moving(self, R: np.ndarray, t: np.ndarray) -> None:
        """Set every moving shape's fcl transform from one configuration's frames."""
        Rf, tf = R[0, self.levels.frame_of], t[0, self.levels.frame_of]
        Rw = Rf @ self.levels.shape_R
        tw = np.einsum("mij,mj->mi", Rf, self.levels.shape_t) + tf
        for i, b in enumerate(self.levels.moving):
            b.obj.setRotation(Rw[i])
            b.obj.setTranslation(tw[i])

    def _make_managers(self) -> list:
        """Per moving shape, a broad-phase manager over the fixed bodies it may hit (shared by
        shapes with the same set; fixed objects never move)."""
        cache: dict[bytes, fcl.DynamicAABBTreeCollisionManager | None] = {}
        out = []
        for i in range(len(self.levels.moving)):
            row = self._allowed_env[self.levels.unit_of_shape[i]]
            key = row.tobytes()
            if key not in cache:
                objs = [self.levels.fixed[j].obj for j in np.nonzero(row)[0]]
                mgr = None
                if objs:
                    mgr = fcl.DynamicAABBTreeCollisionManager()
                    mgr.registerObjects(objs)
                    mgr.setup()
                cache[key] = mgr
            out.append(cache[key])
        return out
