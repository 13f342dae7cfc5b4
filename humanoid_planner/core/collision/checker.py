"""Collision checking for planning: robot self-collision and scene obstacles, batched.

An RRT in Python spends nearly all its time here, so the common case must be cheap. For a batch
of N configurations (numpy over N, a Python loop only over the few configurations FCL decides):

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
inflated by _EPS), and every proof uses contained geometry (radii shrunk by _EPS), so the result
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

from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Iterable, Sequence

import fcl
import numpy as np

from humanoid_planner.core.collision.pair_tables import NO_MARGINS, CheckerView, env_tables_for, tables_for
from humanoid_planner.core.collision.voxels import VoxelObstacles
from humanoid_planner.core.collision.geometry import (DEFAULT_SPHERE_TOLERANCE, BoundingBox, HULL_TOLERANCE, LinkCollision,
                                 RobotCollisionModel, SphereCover, SphereTable, attached_collision,
                                 box_is_tight, enclosing_sphere, fcl_from_shape, group_shapes,
                                 link_geometry_primitive, scene_bodies, shape_primitive, union_box)
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneSnapshot

_EPS = 1e-4
"""Margin (m): prefilter radii grow by it, proof radii shrink by it (float rounding, FCL tolerance)."""
_BATCH = 1024
"""Largest batch handled at once: the numpy work is memory-bound, bigger batches fall out of cache."""




CLUSTER_RADIUS = 0.18
"""m: level 1 first tests one sphere per cluster of a frame's units (around its largest unit left, the
units within this radius or that unit's own sphere): one for a gripper's links, not one for a whole arm
riding on the torso, whose sphere would touch everything (measured on TALOS: 0.12 and 0.25 slower)."""
CLUSTER_GAIN = 0.5
"""Clusters are tested first only where their pairs are at most this share of the unit pairs (TALOS
l_arm 113 of 445 unit–box pairs; ARMAR-III 72 of 102, where the extra step cost 12 %)."""


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


@dataclass(frozen=True)
class _Body:
    """One collision shape: moving (frame ≥ 0, offset in that frame) or fixed (frame -1, world)."""

    name: str  # link name, or scene object id
    is_link: bool
    frame: int
    offset: np.ndarray
    obj: fcl.CollisionObject | None


@dataclass(frozen=True)
class _Boxes:
    """Rounded boxes stacked as arrays: rotation (K, 3, 3), centre (K, 3), half extents, rounding."""

    R: np.ndarray
    t: np.ndarray
    h: np.ndarray
    rho: np.ndarray

    @classmethod
    def build(cls, boxes: list[BoundingBox]) -> "_Boxes":
        k = len(boxes)
        return cls(np.array([b.pose[:3, :3] for b in boxes]).reshape(k, 3, 3),
                   np.array([b.pose[:3, 3] for b in boxes]).reshape(k, 3),
                   np.array([b.half for b in boxes]).reshape(k, 3),
                   np.array([b.rounding for b in boxes], dtype=float))

    def take(self, idx) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.R[idx], self.t[idx], self.h[idx], self.rho[idx]


def _touch(C, radii, box_R, box_t, half, rounding) -> np.ndarray:
    """(K, S) bool: sphere s of row k (centre C[k, s], radius radii[k, s]) reaches rounded box k.
    Radii ≤ 0 never touch (signed square), which is how table padding is ignored."""
    L = np.matmul(C - box_t[:, None, :], box_R)
    np.abs(L, out=L)
    L -= half[:, None, :]
    np.maximum(L, 0.0, out=L)
    d2 = np.einsum("ksi,ksi->ks", L, L)
    thr = radii + rounding[:, None]
    return d2 < thr * np.abs(thr)


def _box_gap2(C: np.ndarray, idx: tuple, box_R: np.ndarray, box_t: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Squared distance of points C[idx] (..., K, 3) to boxes K (rotation, centre, half extents),
    without the boxes' rounding. Components kept apart as (N, K) arrays: ~10× faster here than one
    (N·U, 3E) matmul, and gathered per component (no (N, K, 3) copy)."""
    d = [C[idx + (i,)] - box_t[:, i] for i in range(3)]
    acc = None
    for j in range(3):
        x = d[0] * box_R[:, 0, j] + d[1] * box_R[:, 1, j] + d[2] * box_R[:, 2, j]
        np.abs(x, out=x)
        x -= half[:, j]
        np.maximum(x, 0.0, out=x)
        x *= x
        acc = x if acc is None else acc + x
    return acc


@dataclass(frozen=True)
class _Groups:
    """Members (indices into a pair list) grouped by key: the unit pairs under each cluster pair."""

    keys: np.ndarray  # (G,) sorted distinct keys
    members: np.ndarray  # pair indices, grouped by key
    start: np.ndarray  # (G,) first member of each group in `members`
    count: np.ndarray  # (G,)

    @classmethod
    def build(cls, key: np.ndarray, gain: float = 1.0) -> "_Groups | None":
        """None when the groups are more than `gain` × the members (too few members share a group
        for the extra step to pay)."""
        keys, inv = np.unique(np.asarray(key, dtype=np.int64), return_inverse=True)
        if len(keys) > gain * len(inv):
            return None
        count = np.bincount(inv, minlength=len(keys))
        return cls(keys, np.argsort(inv, kind="stable"), np.cumsum(count) - count, count)

    def expand(self, n: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(config, group) entries → (config, member) entries, configurations in the same order."""
        c = self.count[k]
        first = np.repeat(self.start[k] - (np.cumsum(c) - c), c)
        return np.repeat(n, c), self.members[first + np.arange(int(c.sum()))]


class CollisionChecker:
    """Validity of configurations and motions of one planning group, or several (concatenated).

    Build one per plan against a frozen scene snapshot (a few ms; per-robot work — fcl geometries,
    sphere covers — is shared through RobotCollisionModel.for_robot). Not thread-safe: use one
    checker per thread (fcl objects carry transforms).

    group: a group name, or several (groups=(...) also works) whose joints are concatenated —
    e.g. ("left_arm", "right_arm") checks both arms against each other on one timeline.
    q_ref: full configuration (RobotModel.joint_names) for every joint outside the group(s);
    default: the robot's home. hand_links: links allowed to touch grasp_object_id (default: the
    links below each group's last joint). ignore_links: links left out entirely (e.g. the other
    arm while growing one arm's tree independently). cross_groups_only: check nothing but pairs of
    links moved by different groups — two arms on one timeline whose own motions against the scene
    and themselves were checked already (valid only when the groups move disjoint link sets).
    """

    def __init__(self, robot: RobotModel, scene: SceneSnapshot | None = None,
                 group: str | Sequence[str] | None = None, q_ref: np.ndarray | None = None, *,
                 groups: Sequence[str] | None = None, padding: float = 0.0, self_padding: float = 0.0,
                 margin: float = 0.0,
                 grasp_object_id: str | None = None, hand_links: Iterable[str] = (),
                 ignore_links: Iterable[str] = (), edge_resolution: float = 0.02, edge_chunk: int = 16,
                 sphere_tolerance: float = DEFAULT_SPHERE_TOLERANCE, cross_groups_only: bool = False):
        if groups is None:
            if group is None:
                raise ValueError("give a planning group (group=...) or several (groups=...)")
            groups = (group,) if isinstance(group, str) else tuple(group)
        self.robot = robot
        self.groups = tuple(groups)
        idx = np.concatenate([robot.group_joint_indices(g) for g in self.groups])
        if len(set(idx.tolist())) != len(idx):
            raise ValueError(f"groups {self.groups} share joints")
        self.joint_indices = idx
        self.joint_names = tuple(robot.joint_names[i] for i in idx)
        self.dof = len(idx)
        self.q_ref = np.array(robot.home if q_ref is None else q_ref, dtype=float)
        if self.q_ref.shape != (robot.dof,) or not np.all(np.isfinite(self.q_ref)):
            raise ValueError(f"q_ref must be {robot.dof} finite values, got shape {self.q_ref.shape}")
        if not (padding >= 0 and self_padding >= 0 and margin >= 0):
            raise ValueError("padding, self_padding and margin must be >= 0")
        if not edge_resolution > 0 or edge_chunk < 1:
            raise ValueError("edge_resolution must be > 0 and edge_chunk >= 1")
        self.padding = float(padding)
        self.self_padding = float(self_padding)
        self.margin = float(margin)  # the largest edge margin m_u a check may ask (level 1 allows for it)
        self.edge_resolution = float(edge_resolution)
        self.edge_chunk = int(edge_chunk)
        self.scene = scene
        self.grasp_object_id = grasp_object_id
        hands = set(hand_links)
        if grasp_object_id and not hands:
            for g in self.groups:
                hands.update(default_hand_links(robot, g))
        self.hand_links = frozenset(hands)
        self.cross_groups_only = bool(cross_groups_only)
        self._group_sizes = np.cumsum([0] + [len(robot.group_joint_indices(g)) for g in self.groups])
        self.stats = CollisionStats()
        self._model = RobotCollisionModel.for_robot(robot, sphere_tolerance)
        ignore = set(ignore_links)
        links = [n for n in self._model.links if n not in ignore]
        # attached objects are robot bodies riding on their link (they go where the link goes)
        held = [a for a in (scene.attached if scene is not None else ()) if a.link not in ignore]
        self._excluded = (robot.disabled_collision_pairs | robot.adjacent_link_pairs
                          | {frozenset((a.id, link)) for a in held for link in a.allowed_links})
        self._fk = robot.kinematic_tree(idx, self.q_ref, needed=links + [a.link for a in held])
        # id(shape's fcl object) -> a convex solid containing it: its hull (meshes) or itself (primitives)
        self._hulls: dict[int, fcl.CollisionObject] = {}
        self._loan = self._model.objects.loan(self)  # fcl objects borrowed, back when this checker is collected
        self._req = fcl.CollisionRequest()
        self._dreq = fcl.DistanceRequest()
        bodies = [(self._model.links[n], n) for n in links]
        self._build(bodies + [(attached_collision(a, sphere_tolerance), a.link) for a in held])
        self._fixed_collisions: tuple[tuple[str, str], ...] | None = None
        self._managers: list | None = None

    # ------------------------------------------------------------------ construction
    def _pair_allowed(self, a: _Body, b: _Body) -> bool:
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

    def _shape_object(self, robot_link: bool, geom, shape, place: np.ndarray | None) -> fcl.CollisionObject:
        """A borrowed fcl object of one link shape, posed at `place` (fixed at q_ref: its world pose;
        moving: None, placed per check): the robot's own geometry, or an attached object's primitive
        (pooled by kind) or mesh (a new object)."""
        if robot_link:
            return self._loan.object(geom, place)
        prim = link_geometry_primitive(shape)
        return self._loan.unpooled(geom, place) if prim is None else self._loan.primitive(*prim, place)

    def _scene_body(self, sb) -> _Body:
        """A scene shape (geometry.SceneBody) as a fixed body: a pooled primitive or a mesh's own object."""
        prim = shape_primitive(sb.shape)
        obj = (self._loan.unpooled(fcl_from_shape(sb.shape), sb.pose) if prim is None
               else self._loan.primitive(*prim, sb.pose))
        if prim is not None:
            self._hulls[id(obj)] = obj  # a convex primitive bounds itself
        return _Body(sb.object_id, False, -1, sb.pose, obj)

    def _build(self, links: list[tuple[LinkCollision, str]]) -> None:
        """Moving shapes → prefilter units (frame coordinates); fixed shapes → world boxes.
        links: (collision data, link it is fixed to) — a robot link, or an attached object on one."""
        moving: list[_Body] = []
        fixed: list[_Body] = []
        unit_list: list[tuple[str, list[int]]] = []
        m_cover: list[SphereCover] = []
        m_box: list[BoundingBox] = []
        m_inner: list[SphereCover | None] = []
        m_geo: list[tuple[str, tuple[float, ...], np.ndarray]] = []  # kind, dims, pose in frame
        f_box: list[BoundingBox] = []
        f_tight: list[bool] = []
        f_cover: list[SphereCover | None] = []
        for lc, anchor in links:
            name = lc.name
            frame, T = self._fk.anchors[anchor]
            ids = []
            hulls = lc.hulls or (None,) * len(lc.shapes)
            robot_link = self._model.links.get(name) is lc  # its geometries live as long as the model
            for geom, shape, cover, box, inner, hull in zip(lc.fcl_geoms, lc.shapes, lc.covers, lc.boxes, lc.inners, hulls):
                pose = T @ shape.origin
                obj = self._shape_object(robot_link, geom, shape, None if frame >= 0 else pose)
                if frame >= 0:
                    ids.append(len(moving))
                    moving.append(_Body(name, True, frame, pose, obj))
                    self._add_hull(moving[-1].obj, hull, shape.kind)
                    m_cover.append(cover.transformed(T))
                    m_box.append(box.transformed(T))
                    m_inner.append(inner.transformed(T) if inner is not None else None)
                    m_geo.append((shape.kind, shape.dims, pose))
                else:
                    fixed.append(_Body(name, True, -1, pose, obj))
                    self._add_hull(fixed[-1].obj, hull, shape.kind)
                    f_box.append(box.transformed(T))
                    f_tight.append(shape.kind in ("box", "sphere"))
                    f_cover.append(cover.transformed(T) if shape.kind == "mesh" else None)
            if ids:
                parts = {m: (*m_geo[m], m_cover[m]) for m in ids}
                unit_list += [(name, g) for g in group_shapes(parts)]
        self._units = [name for name, _ in unit_list]
        unit_shapes = [ms for _, ms in unit_list]
        U, M = len(unit_list), len(moving)

        # Moving shapes (for FCL): frame and constant offset in it.
        self._frame_of = np.array([b.frame for b in moving], dtype=np.int64)
        self._shape_R = np.array([b.offset[:3, :3] for b in moving]).reshape(M, 3, 3)
        self._shape_t = np.array([b.offset[:3, 3] for b in moving]).reshape(M, 3)

        # Units: bounding sphere, sphere cover (outer), inner spheres, rounded box; frame coordinates.
        self._unit_frame = np.array([moving[ms[0]].frame for ms in unit_shapes], dtype=np.int64)
        self._outer = SphereTable.build([[(m_cover[m], k) for k, m in enumerate(ms)] for ms in unit_shapes])
        self._inner = SphereTable.build([[(m_inner[m], k) for k, m in enumerate(ms) if m_inner[m] is not None]
                                         for ms in unit_shapes])
        bounds = [enclosing_sphere(SphereCover(self._outer.centers[u, :c], self._outer.radii[u, :c]))
                  for u, c in enumerate(self._outer.counts)]
        self._bound_c = np.array([c for c, _ in bounds]).reshape(U, 3)
        self._bound_r = np.array([r for _, r in bounds])
        self._ubox = _Boxes.build([union_box([m_box[m] for m in ms]) for ms in unit_shapes])
        self._ubox_tight = np.array([box_is_tight([m_geo[m] for m in ms]) for ms in unit_shapes], dtype=bool)
        kmax = max((len(ms) for ms in unit_shapes), default=1)
        self._unit_shape_tab = np.full((U, kmax), -1, dtype=np.int64)  # unit → its shapes (moving ids)
        for u, ms in enumerate(unit_shapes):
            self._unit_shape_tab[u, :len(ms)] = ms

        # Scene objects that some unit can reach (a ball test per object, on bounds cached per object);
        # only those become bodies: a plan's cost does not grow with objects no link can touch.
        objects = self.scene.objects if self.scene is not None else ()
        self._culled: tuple = objects if not U else ()  # out of reach: only fixed_collisions looks at them
        if objects and U:
            reach_c, reach_r = self._reach()
            oc, orad = self.scene.object_spheres
            gap = np.linalg.norm(oc[:, None, :] - reach_c[None], axis=-1) - reach_r[None] - orad[:, None]
            near = (gap <= self.padding + self.margin + _EPS).any(axis=1)
            self._culled = tuple(objects[i] for i in np.flatnonzero(~near).tolist())
            objects = tuple(objects[i] for i in np.flatnonzero(near).tolist())
        elif not U:
            objects = ()
        self.scene_objects_culled = len(self._culled)
        for sb in scene_bodies(objects):
            fixed.append(self._scene_body(sb))
            f_box.append(sb.box)
            f_tight.append(sb.tight)
            f_cover.append(None)
        self._moving, self._fixed = moving, fixed
        # Required clearance per pair kind: `padding` against the scene, `self_padding` robot–robot.
        self._f_pad = np.array([self.self_padding if b.is_link else self.padding for b in fixed])

        # Fixed bodies: world boxes; robot meshes also keep their cover (tested against unit boxes).
        self._fbox = _Boxes.build(f_box)
        self._f_tight = np.array(f_tight, dtype=bool)
        self._f_cover = SphereTable.build([[(c, 0)] if c is not None else [] for c in f_cover])
        self._f_has_cover = self._f_cover.counts > 0

        self._unit_shapes = unit_shapes
        self._pairs()
        self._unit_of_shape = np.zeros(M, dtype=np.int64)
        for u, ms in enumerate(unit_shapes):
            self._unit_of_shape[ms] = u
        # Point-cloud cells: against every unit (no SRDF or grasp exemption applies to them).
        self._shape_cover = m_cover
        self._shape_is_sphere = [kind == "sphere" for kind, _, _ in m_geo]
        self._shape_kind = [kind for kind, _, _ in m_geo]
        self._pair_hits = np.zeros((M, len(fixed) + M))  # level 3: (moving shape, body) collisions found
        self._pair_calls = np.zeros((M, len(fixed) + M))  # ... and FCL calls made (orders the next ones)
        self._tables: dict | None = None  # pair clearance tables (pair_tables.py), built at the first check
        self._env_tables: dict | None = None  # ... of units against fixed links
        layer = self.scene.voxels if self.scene is not None else None
        self._vox = None
        if layer is not None and len(layer) and U and not self.cross_groups_only:
            # cells keep the whole edge margin for configurations too (conservative; per-row margins
            # are not threaded through the cell tests)
            s = float(layer.size)
            vox = VoxelObstacles(layer, *self._reach(), self.padding + self.margin,
                                 cube=self._loan.primitive("box", (s, s, s)))
            self._vox = vox if vox.active else None
        self.unit_levers = self._unit_levers()
        self._pair_levers_table()

    def _pairs(self) -> None:
        """The pairs checked (those `_pair_allowed` keeps) and their level-1 tables: units against fixed
        bodies, unit against unit, and the clusters over them."""
        # Unit × fixed pairs: checked ones (exact_check visits them), and those in reach (level 1).
        fixed, U, unit_shapes = self._fixed, len(self._units), self._unit_shapes
        probe = [_Body(n, True, 0, np.eye(4), None) for n in self._units]
        self._allowed_env = np.array([[self._pair_allowed(p, f) and not self.cross_groups_only for f in fixed]
                                      for p in probe], dtype=bool).reshape(U, len(fixed))
        reach_c, reach_r = self._reach()
        gap = self._box_distance(reach_c) - self._fbox.rho[None, :]
        reach = gap <= reach_r[:, None] + self._f_pad[None, :] + self.margin + _EPS
        self._env_u, self._env_e = np.nonzero(self._allowed_env & reach)
        self._env_R, self._env_t, self._env_h, _ = self._fbox.take(self._env_e)
        thr = self._bound_r[self._env_u] + self._fbox.rho[self._env_e] + self._f_pad[self._env_e] + self.margin + _EPS
        self._env_thr2 = thr * thr

        # Unit × unit pairs in different frames (same frame: the relative pose is constant).
        group_of = np.searchsorted(self._group_sizes, [self._fk.frames[f].column for f in self._unit_frame],
                                   side="right") - 1
        pairs = [(a, b) for a in range(U) for b in range(a + 1, U)
                 if self._unit_frame[a] != self._unit_frame[b] and self._pair_allowed(probe[a], probe[b])
                 and (not self.cross_groups_only or group_of[a] != group_of[b])]
        # Level 2 tests the spheres of one side (s) against the rounded box of the other (o): take o
        # with an exact box (if both, s has fewer spheres); neither exact: test both ways.
        s_side, o_side, two = [], [], []
        for a, b in pairs:
            ta, tb = self._ubox_tight[a], self._ubox_tight[b]
            if (ta and tb and self._outer.counts[a] > self._outer.counts[b]) or (ta and not tb):
                a, b = b, a
            s_side.append(a)
            o_side.append(b)
            two.append(not (ta or tb))
        self._self_s = np.array(s_side, dtype=np.int64)
        self._self_o = np.array(o_side, dtype=np.int64)
        self._self_two = np.array(two, dtype=bool)
        thr = self._bound_r[self._self_s] + self._bound_r[self._self_o] + self.self_padding + 2 * self.margin + _EPS
        self._self_thr2 = thr * thr
        self._self_shapes = [(x, y, p) for p, (a, b) in enumerate(pairs) for x in unit_shapes[a] for y in unit_shapes[b]]
        self._build_clusters()

    def _pair_levers_table(self) -> None:
        """Per checked self pair, the joints that move one side only (what edge_margins sums)."""
        L, a, b = self.unit_levers, self._self_s, self._self_o
        self._pair_levers = L[a] * (L[b] == 0) + L[b] * (L[a] == 0)  # joints moving one side only
        self._levers = np.vstack([L, self._pair_levers])  # (U + P, dof): what edge_margins sums
        self._half_levers = np.ascontiguousarray(0.5 * self._levers.T)

    def exempting(self, pairs: Iterable[tuple[str, str]]) -> "CollisionChecker":
        """This checker with the named body pairs (a robot link or attached object, and a link or
        scene object) no longer checked: a hand allowed to touch the object it let go of, an attached
        object its support. It shares this checker's geometry and fcl objects (only the pair tables
        are built again, a fraction of a build), so neither may be used while the other checks (from
        another thread)."""
        out = copy.copy(self)
        out._excluded = self._excluded | {frozenset(p) for p in pairs}
        out._parent = self  # keeps the borrowed fcl objects on loan while the copy lives
        out.stats = CollisionStats()
        M = len(self._moving)
        out._pair_hits = np.zeros((M, len(self._fixed) + M))
        out._pair_calls = np.zeros((M, len(self._fixed) + M))
        out._tables, out._env_tables, out._fixed_collisions, out._managers = None, None, None, None
        out._pairs()
        out._pair_levers_table()
        return out

    def _build_clusters(self) -> None:
        """Level 1's first step: one sphere per cluster of a frame's units (containing their bounding
        spheres), tested against each fixed box and other cluster its units are paired with; unit pairs
        are tested only under the cluster pairs it cannot clear (TALOS l_arm: 445 unit–box pairs per
        configuration, 113 cluster–box pairs — the gripper's 11 links share one frame)."""
        slot = np.zeros(len(self._units), dtype=np.int64)
        frames: list[int] = []
        for f in np.unique(self._unit_frame):  # around the largest unit left, what fits in CLUSTER_RADIUS
            rest = np.nonzero(self._unit_frame == f)[0]
            rest = rest[np.argsort(-self._bound_r[rest], kind="stable")]
            while len(rest):
                s = rest[0]
                reach = np.linalg.norm(self._bound_c[rest] - self._bound_c[s], axis=1) + self._bound_r[rest]
                take = reach <= max(CLUSTER_RADIUS, self._bound_r[s])
                slot[rest[take]] = len(frames)
                frames.append(int(f))
                rest = rest[~take]
        spheres = [enclosing_sphere(SphereCover(self._bound_c[slot == k], self._bound_r[slot == k]))
                   for k in range(len(frames))]
        self._cl_slot = slot  # unit → its cluster
        self._cl_frame = np.array(frames, dtype=np.int64)
        self._cl_c = np.array([c for c, _ in spheres]).reshape(len(frames), 3)
        self._cl_r = np.array([r for _, r in spheres])
        E = max(len(self._fixed), 1)
        self._cl_env = _Groups.build(slot[self._env_u] * E + self._env_e, CLUSTER_GAIN)
        if self._cl_env is not None:
            ks, ke = self._cl_env.keys // E, self._cl_env.keys % E
            self._cl_env_slot = ks
            self._cl_env_R, self._cl_env_t, self._cl_env_h, _ = self._fbox.take(ke)
            thr = self._cl_r[ks] + self._fbox.rho[ke] + self._f_pad[ke] + self.margin + _EPS
            self._cl_env_thr2 = thr * thr
        F = max(len(frames), 1)
        self._cl_self = _Groups.build(slot[self._self_s] * F + slot[self._self_o], CLUSTER_GAIN)
        if self._cl_self is not None:
            sa, sb = self._cl_self.keys // F, self._cl_self.keys % F
            self._cl_self_a, self._cl_self_b = sa, sb
            thr = self._cl_r[sa] + self._cl_r[sb] + self.self_padding + 2 * self.margin + _EPS
            self._cl_self_thr2 = thr * thr

    def _cluster_spheres(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(N, C, 3) world centres of the cluster spheres."""
        f = self._cl_frame
        return np.matmul(R[:, f], self._cl_c[:, :, None])[..., 0] + t[:, f]

    def _unit_levers(self) -> np.ndarray:
        """(U, dof): metres a point of unit u may move per radian of each group joint (per metre of a
        prismatic one): the distance from the joint's origin to the unit's bounding sphere, by the
        triangle inequality along the chain; 0 for joints that do not move the unit."""
        lim = np.maximum(np.abs(self.robot.lower), np.abs(self.robot.upper))[self.joint_indices]
        frames = self._fk.frames
        out = np.zeros((len(self._units), self.dof))
        for u, f in enumerate(self._unit_frame):
            dist = float(np.linalg.norm(self._bound_c[u])) + self._bound_r[u]  # from frame f's origin
            k = int(f)
            while k >= 0:
                fr = frames[k]
                out[u, fr.column] = 1.0 if fr.prismatic else dist
                dist += float(np.linalg.norm(fr.t)) + (float(lim[fr.column]) if fr.prismatic else 0.0)
                k = fr.parent
        return out

    def _reach(self) -> tuple[np.ndarray, np.ndarray]:
        """Per unit, a world ball that contains it in every configuration: centred on the origin of
        its chain's first group joint (fixed in the world), radius by the triangle inequality."""
        lim = np.maximum(np.abs(self.robot.lower), np.abs(self.robot.upper))[self.joint_indices]
        root, dist = [], []
        for fr in self._fk.frames:
            slide = float(lim[fr.column]) if fr.prismatic else 0.0
            if fr.parent < 0:
                root.append(fr.t)
                dist.append(slide)
            else:
                root.append(root[fr.parent])
                dist.append(dist[fr.parent] + float(np.linalg.norm(fr.t)) + slide)
        f = self._unit_frame
        centres = np.array([root[k] for k in f]).reshape(len(f), 3)
        radii = np.array([dist[k] for k in f]) + np.linalg.norm(self._bound_c, axis=1) + self._bound_r
        return centres, radii

    def _box_distance(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) points → (P, E) distances to the fixed boxes (without their rounding)."""
        b = self._fbox
        local = np.einsum("pei,eij->pej", points[:, None, :] - b.t[None], b.R)
        return np.linalg.norm(np.maximum(np.abs(local) - b.h[None], 0.0), axis=-1)

    # ------------------------------------------------------------------ public API
    @property
    def moving_links(self) -> tuple[str, ...]:
        """Links with geometry that move with the group(s)."""
        return tuple(dict.fromkeys(self._units))

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
        per unit (2 × margin per pair)."""
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(f"expected (N, {self.dof}) configurations, got {q.shape}")
        U = len(self._units)
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
        if not self._moving:
            return True
        if self._managers is None:
            self._managers = self._make_managers()
        self._place_moving(*self._fk(q))
        w = np.zeros(len(self._levers)) if margins is None else np.ravel(margins)
        m, mp = w[:len(self._units)][self._unit_of_shape], w[len(self._units):]  # per shape, per pair
        if self._f_pad.any() or self.self_padding > 0 or w.any():  # distances needed: every pair, one by one
            for i, b in enumerate(self._moving):
                for j in np.nonzero(self._allowed_env[self._unit_of_shape[i]])[0]:
                    if self._collide(b.obj, self._fixed[j].obj, self._f_pad[j] + m[i]):
                        return False
        else:
            for b, mgr in zip(self._moving, self._managers):
                if mgr is not None:
                    data = fcl.CollisionData(request=self._req)
                    mgr.collide(b.obj, data, fcl.defaultCollisionCallback)
                    if data.result.is_collision:
                        return False
        for a, b, p in self._self_shapes:
            if self._collide(self._moving[a].obj, self._moving[b].obj, self.self_padding + mp[p]):
                return False
        if self._vox is not None:
            R, t = self._fk(q)
            return not self._voxel_exact(R, t, [(0, m) for m in range(len(self._moving))])
        return True

    def colliding_pairs(self, q: np.ndarray) -> tuple[tuple[str, str], ...]:
        """The pairs that make one configuration collide, by name (robot link or attached object
        first; then a link, an attached object, a scene object or "point cloud"): every pair
        check_configs decides, through python-fcl, none skipped after the first hit. For telling a
        user why a configuration was refused, not for planning (every pair costs an FCL call)."""
        q = np.asarray(q, dtype=float).reshape(1, self.dof)
        if not self._moving:
            return ()
        R, t = self._fk(q)
        self._place_moving(R, t)
        out: dict[tuple[str, str], None] = {}
        for i, b in enumerate(self._moving):
            for j in np.nonzero(self._allowed_env[self._unit_of_shape[i]])[0]:
                if self._collide(b.obj, self._fixed[j].obj, self._f_pad[j]):
                    out[(b.name, self._fixed[j].name)] = None
        for a, b, _ in self._self_shapes:
            if self._collide(self._moving[a].obj, self._moving[b].obj, self.self_padding):
                out[(self._moving[a].name, self._moving[b].name)] = None
        if self._vox is not None:
            for m, body in enumerate(self._moving):
                if self._voxel_exact(R, t, [(0, m)]):
                    out[(body.name, "point cloud")] = None
        return tuple(out)

    def fixed_collisions(self) -> tuple[tuple[str, str], ...]:
        """Colliding pairs that no configuration of the group can change, at q_ref: fixed links
        against each other and the scene, links rigid on the same group joint. Never counted
        against a configuration; a planner may report them (start state / environment)."""
        if self._fixed_collisions is None:
            self._place_moving(*self._fk(self.q_ref[self.joint_indices][None, :]))
            bodies = self._fixed + self._moving
            out: dict[tuple[str, str], None] = {}
            for i, a in enumerate(bodies):
                for b in bodies[i + 1:]:
                    pad = self.self_padding if a.is_link and b.is_link else self.padding
                    if a.frame == b.frame and self._pair_allowed(a, b) and self._collide(a.obj, b.obj, pad):
                        out[(a.name, b.name)] = None
            # objects culled as out of every moving unit's reach may still touch a fixed link
            links = [a for a in self._fixed if a.is_link]
            for sb in scene_bodies(self._culled) if links else ():
                b = self._scene_body(sb)
                for a in links:
                    if self._pair_allowed(a, b) and self._collide(a.obj, b.obj, self.padding):
                        out[(a.name, b.name)] = None
            self._fixed_collisions = tuple(out)
        return self._fixed_collisions

    def summary(self) -> dict:
        """Sizes of the compiled problem and the counters, for logs and benchmarks."""
        return {
            "groups": self.groups, "dof": self.dof, "frames": len(self._fk),
            "moving_links": len(self.moving_links), "units": len(self._units),
            "moving_shapes": len(self._moving), "fixed_bodies": len(self._fixed),
            "spheres": int(self._outer.counts.sum()), "env_pairs": int(self._allowed_env.sum()),
            "env_pairs_in_reach": len(self._env_u), "self_pairs": len(self._self_s),
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
        if N == 0 or not self._units:
            return ok
        R, t = self._fk(q)
        me, mp = (NO_MARGINS, NO_MARGINS) if wide is None else (wide[:, :len(self._units)], wide[:, len(self._units):])
        # Level 1: unit bounding spheres, world (N, U, 3).
        f = self._unit_frame
        B = np.matmul(R[:, f], self._bound_c[:, :, None])[..., 0] + t[:, f]
        env = self._level1_env(R, t, B)
        slf = self._level1_self(R, t, B)
        flagged = np.zeros(N, dtype=bool)
        flagged[env[0]] = True
        flagged[slf[0]] = True
        n1 = int(flagged.sum())
        self.stats.level1_free += N - n1
        if n1 == 0:
            return ok
        # Level 2: proofs first, then covers for the configurations still open.
        hit = np.zeros(N, dtype=bool)
        self._prove_env(R, t, *env, me, hit)
        self._prove_self(R, t, *slf, mp, hit)
        env = self._level2_env(R, t, *(x[~hit[env[0]]] for x in env), me)
        slf = self._level2_self(R, t, *(x[~hit[slf[0]]] for x in slf), mp)
        slf = self._table_filter(q, slf, mp)
        env = self._env_table_filter(q, env, me)
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

    def pair_table_view(self) -> CheckerView:
        """The arrays the pair clearance tables are built from (pair_tables.py), as one read-only view."""
        return CheckerView(self, self._fk, self._model, self._units, self._unit_frame, self._bound_c, self._outer,
                           self._unit_shape_tab, self._shape_kind, self._shape_R, self._shape_t, self._frame_of,
                           self._moving, self._self_s, self._self_o, self._pair_levers, self._level1_self,
                           self._level2_self, self._fixed, self._f_has_cover, self._env_u, self._env_e,
                           self._unit_of_shape, self._level1_env, self._level2_env)

    def _table_filter(self, q: np.ndarray, slf, mp):
        """Drop the (config, shape, shape, pair) entries of pairs their clearance table proves free
        (lower bound of the exact distance > self_padding + edge margin): fewer FCL calls, same verdicts."""
        if self._tables is None:
            self._tables = tables_for(self.pair_table_view())
        if not self._tables or len(slf[0]) == 0:
            return slf
        p = slf[3]
        return self._drop_table_free(q, slf, ((p == pair, self.self_padding, mp, pair, tab)
                                              for pair, tab in self._tables.items()))

    def _env_table_filter(self, q: np.ndarray, env, me):
        """Drop the (config, moving shape, fixed body) entries of unit–fixed-link pairs their clearance
        table proves free (lower bound > the pair's padding + edge margin): fewer FCL calls, same verdicts."""
        if self._env_tables is None:
            self._env_tables = env_tables_for(self.pair_table_view())
        if not self._env_tables or len(env[0]) == 0:
            return env
        u, e = self._unit_of_shape[env[1]], env[2]
        return self._drop_table_free(q, env, (((u == u0) & (e == e0), self._f_pad[e0], me, u0, tab)
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
                need = pad + np.broadcast_to(margins[n[sel], col], (len(sel),)) + _EPS
                keep[sel] = tab.lower_bound(q[n[sel]]) <= need
        self.stats.table_free += int(len(n) - keep.sum())
        return tuple(x[keep] for x in entries)

    def _level1_env(self, R: np.ndarray, t: np.ndarray, B: np.ndarray):
        """Unit bounding spheres against fixed boxes in reach → (config, unit, fixed body) entries:
        cluster spheres first (dense over the cluster × box pairs), then the unit pairs below the
        cluster pairs still touching."""
        e0 = np.empty(0, np.int64)
        if len(self._env_u) == 0:
            return e0, e0, e0
        if self._cl_env is None:
            n, p = np.nonzero(_box_gap2(B, (slice(None), self._env_u), self._env_R, self._env_t, self._env_h) < self._env_thr2)
            return n, self._env_u[p], self._env_e[p]
        BC = self._cluster_spheres(R, t)
        n, k = np.nonzero(_box_gap2(BC, (slice(None), self._cl_env_slot), self._cl_env_R, self._cl_env_t, self._cl_env_h)
                          < self._cl_env_thr2)
        if len(n) == 0:
            return e0, e0, e0
        n, p = self._cl_env.expand(n, k)
        u = self._env_u[p]
        near = _box_gap2(B, (n, u), self._env_R[p], self._env_t[p], self._env_h[p]) < self._env_thr2[p]
        return n[near], u[near], self._env_e[p[near]]

    def _level1_self(self, R, t, B: np.ndarray):
        """Unit pairs: bounding spheres, then the s side's bounding sphere against the o side's box
        → (config, pair, o box rotation, o box centre) entries."""
        if len(self._self_s) == 0:
            e = np.empty(0, np.int64)
            return e, e, np.empty((0, 3, 3)), np.empty((0, 3))
        if self._cl_self is None:
            a, b = self._self_s, self._self_o
            acc = None
            for i in range(3):
                x = B[:, a, i] - B[:, b, i]
                x *= x
                acc = x if acc is None else acc + x
            n, p = np.nonzero(acc < self._self_thr2)
            a, b = a[p], b[p]
        else:
            BC = self._cluster_spheres(R, t)
            d = BC[:, self._cl_self_a] - BC[:, self._cl_self_b]
            n, k = np.nonzero(np.einsum("nki,nki->nk", d, d) < self._cl_self_thr2)
            n, p = self._cl_self.expand(n, k)
            a, b = self._self_s[p], self._self_o[p]
            d = B[n, a] - B[n, b]
            near = np.einsum("ki,ki->k", d, d) < self._self_thr2[p]
            n, p, a, b = n[near], p[near], a[near], b[near]
        Rb, tb = self._unit_box_world(R, t, n, b)
        near = _touch(B[n, a][:, None, :], (self._bound_r[a] + self.self_padding + 2 * self.margin + _EPS)[:, None], Rb, tb,
                      self._ubox.h[b], self._ubox.rho[b])[:, 0]
        return n[near], p[near], Rb[near], tb[near]

    def _unit_box_world(self, R, t, n, unit):
        """World pose (K, 3, 3), (K, 3) of the rounded boxes of units `unit` in configurations `n`."""
        f = self._unit_frame[unit]
        Rf = R[n, f]
        return Rf @ self._ubox.R[unit], np.matmul(Rf, self._ubox.t[unit][:, :, None])[:, :, 0] + t[n, f]

    def _spheres_touch(self, R, t, n, u, table: SphereTable, extra, box_R, box_t, half, rounding):
        """(K, W) bool: spheres of unit u[k] in configuration n[k] (radii + extra, a scalar or (K,))
        reaching box k.
        Rows are bucketed by sphere count, so a few big covers do not widen every row."""
        cnt = table.counts[u]
        W = max(int(cnt.max()) if len(u) else 0, 1)
        extra = np.asarray(extra, dtype=float)
        if extra.ndim == 0:
            extra = np.full(len(u), float(extra))

        def rows(sel, cap):
            us, ns = u[sel], n[sel]
            f = self._unit_frame[us]
            C = table.centers[us, :cap] @ R[ns, f].transpose(0, 2, 1) + t[ns, f][:, None, :]
            return _touch(C, table.radii[us, :cap] + extra[sel, None], box_R[sel], box_t[sel], half[sel],
                          rounding[sel])

        if len(u) * W <= 4096:  # small: one pass, padding and all
            return rows(slice(None), W)
        out = np.zeros((len(u), W), dtype=bool)
        lo = 0
        for cap in sorted({min(c, W) for c in (1, 4, 8, W)}):
            sel = np.nonzero((cnt > lo) & (cnt <= cap))[0]
            lo = cap
            if len(sel):
                out[sel, :cap] = rows(sel, cap)
        return out

    def _prove_env(self, R, t, n, u, e, me, hit_out) -> None:
        """Mark configurations where an inner sphere of a unit reaches an exact fixed box."""
        sure = np.nonzero(self._f_tight[e] & (self._inner.counts[u] > 0))[0]
        if len(sure):
            n, u, e = n[sure], u[sure], e[sure]
            inside = self._spheres_touch(R, t, n, u, self._inner, self._f_pad[e] + me[n, u] - _EPS, *self._fbox.take(e))
            hit_out[n[inside.any(1)]] = True

    def _prove_self(self, R, t, n, p, Rb, tb, mp, hit_out) -> None:
        """Mark configurations where an inner sphere of the s side reaches the o side's exact box."""
        a, b = self._self_s[p], self._self_o[p]
        sure = np.nonzero(self._ubox_tight[b] & (self._inner.counts[a] > 0))[0]
        if len(sure):
            bs = b[sure]
            ns = n[sure]
            inside = self._spheres_touch(R, t, ns, a[sure], self._inner, self.self_padding + mp[ns, p[sure]] - _EPS, Rb[sure],
                                         tb[sure], self._ubox.h[bs], self._ubox.rho[bs])
            hit_out[n[sure][inside.any(1)]] = True

    def _shape_mask(self, table: SphereTable, unit, k, i, rows: int) -> np.ndarray:
        """(rows, kmax) bool: hits (k, sphere i of unit[k]) → the owning shapes (index in unit)."""
        mask = np.zeros((rows, self._unit_shape_tab.shape[1]), dtype=bool)
        mask[k, table.owners[unit[k], i]] = True
        return mask

    def _level2_env(self, R, t, n, u, e, me):
        """(config, unit, fixed body) → (config, moving shape, fixed body) entries whose cover
        spheres reach the fixed box (and, for fixed meshes, whose unit box the mesh's spheres reach)."""
        if len(n) == 0:
            return n, u, e
        pad = self._f_pad[e] + me[n, u] + _EPS
        hit = self._spheres_touch(R, t, n, u, self._outer, pad, *self._fbox.take(e))
        ok = hit.any(1)
        rev = np.nonzero(ok & self._f_has_cover[e])[0]
        if len(rev):
            ur, er = u[rev], e[rev]
            Rb, tb = self._unit_box_world(R, t, n[rev], ur)
            back = _touch(self._f_cover.centers[er], self._f_cover.radii[er] + pad[rev, None], Rb, tb, self._ubox.h[ur],
                          self._ubox.rho[ur])
            ok[rev] = back.any(1)
        k, i = np.nonzero(hit & ok[:, None])
        k, ls = np.nonzero(self._shape_mask(self._outer, u, k, i, len(n)))
        return n[k], self._unit_shape_tab[u[k], ls], e[k]

    def _level2_self(self, R, t, n, p, Rb, tb, mp):
        """(config, unit pair) → (config, moving shape, moving shape, pair) entries: the s side's cover
        against the o side's box, and the other way round when neither box is exact."""
        if len(n) == 0:
            return n, n, n, n
        a, b = self._self_s[p], self._self_o[p]
        pad = np.broadcast_to(self.self_padding + mp[n, p] + _EPS, (len(n),))
        hit_a = self._spheres_touch(R, t, n, a, self._outer, pad, Rb, tb, self._ubox.h[b], self._ubox.rho[b])
        ok = hit_a.any(1)
        mask_b = self._unit_shape_tab[b] >= 0  # every shape of the o side, unless tested below
        two = np.nonzero(ok & self._self_two[p])[0]
        if len(two):
            a2, b2, n2 = a[two], b[two], n[two]
            Ra, ta = self._unit_box_world(R, t, n2, a2)
            hit_b = self._spheres_touch(R, t, n2, b2, self._outer, pad[two], Ra, ta, self._ubox.h[a2], self._ubox.rho[a2])
            ok[two] = hit_b.any(1)
            kk, ii = np.nonzero(hit_b)
            mask_b[two] = self._shape_mask(self._outer, b2, kk, ii, len(two))
        k, i = np.nonzero(hit_a & ok[:, None])
        mask_a = self._shape_mask(self._outer, a, k, i, len(n))
        k, la, lb = np.nonzero(mask_a[:, :, None] & mask_b[:, None, :])
        return n[k], self._unit_shape_tab[a[k], la], self._unit_shape_tab[b[k], lb], p[k]

    def _exact(self, R, t, env, slf, me, mp) -> np.ndarray:
        """FCL on the flagged shape pairs; True = colliding. A configuration stops at its first
        colliding pair; a moving shape's transform is set once per configuration, if used."""
        Ef = len(self._fixed)
        n = np.concatenate([env[0], slf[0], slf[0]])
        m = np.concatenate([env[1], slf[1], slf[2]])  # the moving shapes whose poses may be needed
        f = self._frame_of[m]
        Rf = R[n, f]
        Rw = np.matmul(Rf, self._shape_R[m])
        tw = np.matmul(Rf, self._shape_t[m][:, :, None])[:, :, 0] + t[n, f]
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
        us = self._unit_of_shape
        pads = np.concatenate([np.broadcast_to(self._f_pad[env[2]] + me[env[0], us[env[1]]], (ne,)),
                               np.broadcast_to(self.self_padding + mp[slf[0], slf[3]], (ns,))])[order].tolist()
        entries = zip(*entries[order].T.tolist())  # flat columns: no list object per entry
        out = np.zeros(len(R), dtype=bool)
        moving = self._moving
        bodies = [x.obj for x in self._fixed] + [x.obj for x in moving]
        cfg, placed, done = -1, set(), False
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
            if self._collide(moving[a].obj, bodies[b], pad):
                out[c] = done = True
                hits[a, b] += 1
        return out

    def _voxels_free(self, q: np.ndarray) -> np.ndarray:
        """(N, n) configurations → (N,) bool against the point-cloud cells only: unit bounding
        spheres, then inner-sphere proofs and cover spheres of the units not cleared, then FCL."""
        vox = self._vox
        grid, pad = vox.grid, self.padding + _EPS
        N = len(q)
        ok = np.ones(N, dtype=bool)
        R, t = self._fk(q)
        u = vox.units
        f = self._unit_frame[u]
        B = np.matmul(R[:, f], self._bound_c[u][:, :, None])[..., 0] + t[:, f]
        n, k = np.nonzero(~grid.spheres_clear(B, self._bound_r[u] + pad))
        if len(n) == 0:
            return ok
        u = u[k]
        Rn, tn = R[n, self._unit_frame[u]], t[n, self._unit_frame[u]]
        inner = self._inner
        if inner.counts[u].any():
            C = inner.centers[u] @ Rn.transpose(0, 2, 1) + tn[:, None, :]
            sure = grid.spheres_hit(C, inner.radii[u]).any(1)
            ok[n[sure]] = False
            n, u, Rn, tn = n[~sure], u[~sure], Rn[~sure], tn[~sure]
        C = self._outer.centers[u] @ Rn.transpose(0, 2, 1) + tn[:, None, :]
        hit = ~grid.spheres_clear(C, self._outer.radii[u] + pad, refine=True)
        kk, ii = np.nonzero(hit & ok[n][:, None])
        if len(kk) == 0:
            return ok
        kk, ls = np.nonzero(self._shape_mask(self._outer, u, kk, ii, len(n)))
        entries = sorted({(int(n[a]), int(self._unit_shape_tab[u[a], b])) for a, b in zip(kk, ls)})
        self.stats.exact_checks += len({c for c, _ in entries})
        ok[list(self._voxel_exact(R, t, entries))] = False
        return ok

    def _voxel_exact(self, R, t, entries: list[tuple[int, int]]) -> set[int]:
        """(configuration, moving shape) entries → the configurations whose shape meets a cell."""
        def placer(c: int, m: int):
            def place():
                Rw, tw = R[c, self._frame_of[m]], t[c, self._frame_of[m]]
                obj = self._moving[m].obj
                obj.setRotation(Rw @ self._shape_R[m])
                obj.setTranslation(Rw @ self._shape_t[m] + tw)
                return obj
            return place

        covers = []
        for c, m in entries:
            Rw, tw, cover = R[c, self._frame_of[m]], t[c, self._frame_of[m]], self._shape_cover[m]
            covers.append((cover.centers @ Rw.T + tw, cover.radii + _EPS))
        return self._vox.collisions(entries, [placer(c, m) for c, m in entries], covers, self._collide,
                                    [self._shape_is_sphere[m] for _, m in entries])

    # ------------------------------------------------------------------ fcl helpers
    def _collide(self, o1: fcl.CollisionObject, o2: fcl.CollisionObject, pad: float = 0.0) -> bool:
        """Do the two bodies collide, or come closer than pad?"""
        self.stats.exact_pairs += 1
        if fcl.collide(o1, o2, self._req, fcl.CollisionResult()):
            return True
        if pad <= 0:
            return False
        if self._hulls and self._hulls_apart(o1, o2, pad):
            return False
        return fcl.distance(o1, o2, self._dreq, fcl.DistanceResult()) < pad

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
        Rf, tf = R[0, self._frame_of], t[0, self._frame_of]
        Rw = Rf @ self._shape_R
        tw = np.einsum("mij,mj->mi", Rf, self._shape_t) + tf
        for i, b in enumerate(self._moving):
            b.obj.setRotation(Rw[i])
            b.obj.setTranslation(tw[i])

    def _make_managers(self) -> list:
        """Per moving shape, a broad-phase manager over the fixed bodies it may hit (shared by
        shapes with the same set; fixed objects never move)."""
        cache: dict[bytes, fcl.DynamicAABBTreeCollisionManager | None] = {}
        out = []
        for i in range(len(self._moving)):
            row = self._allowed_env[self._unit_of_shape[i]]
            key = row.tobytes()
            if key not in cache:
                objs = [self._fixed[j].obj for j in np.nonzero(row)[0]]
                mgr = None
                if objs:
                    mgr = fcl.DynamicAABBTreeCollisionManager()
                    mgr.registerObjects(objs)
                    mgr.setup()
                cache[key] = mgr
            out.append(cache[key])
        return out
