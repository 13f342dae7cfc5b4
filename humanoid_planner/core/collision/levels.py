"""The collision checker's compiled pairs and its levels 1–2 (see checker.py for the whole check).

`CompiledPairs` holds what `CollisionChecker` compiles from a robot and a scene snapshot — units (a
link's shapes grouped), their bounding spheres, sphere covers and rounded boxes, the fixed bodies, the
unit × fixed and unit × unit pairs in reach, the clusters of level 1 — and the numpy levels that read
them: level 1 (bounding spheres, cluster spheres first), level 2 (inner-sphere proofs, cover spheres
against rounded boxes). The checker runs them and hands what is left to FCL (level 3); the pair
clearance tables (pair_tables.py) sample the same levels to choose their pairs. Both import this
module, which imports neither.

Arrays are the checker's, filled once by `CollisionChecker._build` and read-only afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np
from scipy.spatial import cKDTree

from humanoid_planner.core.collision import kernels
from humanoid_planner.core.collision.geometry import BoundingBox, SphereCover, SphereTable, enclosing_sphere
from humanoid_planner.core.model.fk import KinematicTree

EPS = 1e-4
"""Margin (m): prefilter radii grow by it, proof radii shrink by it (float rounding, FCL tolerance)."""
CLUSTER_RADIUS = 0.18
"""m: level 1 first tests one sphere per cluster of a frame's units (around its largest unit left, the
units within this radius or that unit's own sphere): one for a gripper's links, not one for a whole arm
riding on the torso, whose sphere would touch everything (measured on TALOS: 0.12 and 0.25 slower)."""
CLUSTER_GAIN = 0.5
"""Clusters are tested first only where their pairs are at most this share of the unit pairs (TALOS
l_arm 113 of 445 unit–box pairs; ARMAR-III 72 of 102, where the extra step cost 12 %)."""


INDEX_MIN_BODIES = 50
"""Level 1 against fixed bodies asks a k-d tree for candidate pairs instead of testing every pair
once this many small fixed bodies are in some unit's reach (ARMAR-III left_arm_torso, 96 configurations
near home, random boxes: at 30–40 the tree costs 0.6–0.8 ms, the dense test 0.3–1.4 ms; at 60 1.0
against 2.0 ms, at 150 1.3 against 4.6, at 400 2.6 against 14–19)."""
INDEX_BODY_REACH = 0.15
"""m: fixed bodies reaching farther than this from their box centre (a table, a fixed link) are
candidates of every configuration: one of them in the tree would widen every query."""


class PairIndex:
    """Candidate (configuration, pair) entries of a level-1 test of sphere slots s (clusters or units)
    against fixed boxes e: pair k = (slot[k], body[k]) passes `box_gap2 < thr_k²`, thr_k = r_s + extra
    + rho_e + pad_e, only if the sphere centre lies within thr_k + |h_e| of the box centre, so a ball
    query of radius r_s + extra + max_e(|h_e| + rho_e + pad_e) about each sphere centre, in a k-d tree
    of the box centres, returns every pair that can pass (and some that do not: the caller runs the
    same test on them). Bodies reaching farther than INDEX_BODY_REACH are candidates everywhere."""

    @staticmethod
    def reach(fbox: "Boxes", f_pad: np.ndarray) -> np.ndarray:
        """(E,) how far beyond its box centre a fixed body's level-1 test can pass, past the sphere's radius."""
        return np.linalg.norm(fbox.h, axis=1) + fbox.rho + f_pad

    @classmethod
    def pays(cls, body: np.ndarray, fbox: "Boxes", f_pad: np.ndarray) -> bool:
        """Enough distinct small bodies among the pairs' for the tree to beat testing every pair."""
        bodies = np.unique(body)
        return int((cls.reach(fbox, f_pad)[bodies] <= INDEX_BODY_REACH).sum()) >= INDEX_MIN_BODIES

    def __init__(self, slot: np.ndarray, body: np.ndarray, slot_radius: np.ndarray, extra: float, fbox: "Boxes",
                 f_pad: np.ndarray):
        reach = self.reach(fbox, f_pad)
        small = reach[body] <= INDEX_BODY_REACH
        self.slots = len(slot_radius)
        self.pair_of = np.full((self.slots, len(reach)), -1, dtype=np.int64)  # (slot, body) → pair
        self.pair_of[slot[small], body[small]] = np.flatnonzero(small)
        self.bodies = np.unique(body[small])
        self.tree = cKDTree(fbox.t[self.bodies])
        # 1e-9: float rounding of the test the radius is derived from
        self.radius = slot_radius + extra + reach[self.bodies].max(initial=0.0) + 1e-9
        self.big = np.flatnonzero(~small)

    def candidates(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """P (N, S, 3) sphere centres of each slot → (config, pair) candidates, in no useful order.
        Per slot, its N centres a k-d tree of their own against the bodies' (a dual-tree query at the
        slot's radius: 3000 boxes, 96 configurations × 23 units, 2× faster than a ball query per centre
        and 2× faster than one dual-tree query per class of similar radii)."""
        N = len(P)
        ns, ks = [], []
        for s in range(self.slots):
            m = cKDTree(P[:, s]).sparse_distance_matrix(self.tree, self.radius[s], output_type="ndarray")
            k = self.pair_of[s, self.bodies[m["j"]]]
            keep = k >= 0
            ns.append(m["i"][keep])
            ks.append(k[keep])
        if len(self.big):
            ns.append(np.repeat(np.arange(N), len(self.big)))
            ks.append(np.tile(self.big, N))
        return np.concatenate(ns).astype(np.int64, copy=False), np.concatenate(ks)


GRID_CELL = 0.1
"""m: the cells of a PairGrid (the small bodies' centres, 3–8 cm boxes: a few per cell in dense clutter)."""


class PairGrid:
    """The kernels' level 1 against many fixed bodies (what PairIndex is to the numpy levels): the small
    bodies (PairIndex's) binned by their box centre on a uniform grid, the big ones (a table, a fixed
    link) candidates of every configuration. A unit sphere (centre c, radius r) can pass level 1 against a
    small body only if that body's centre lies within r + `extra` + the largest small body's reach of c,
    so the kernel visits the cells of that cube; `pair_of` maps (unit, body) to the env pair, -1 when not
    in reach. Same test then as without the grid, on fewer pairs."""

    def __init__(self, levels: "CompiledPairs", extra: float):
        env_u, env_e, fbox, f_pad = levels.env_u, levels.env_e, levels.fbox, levels.f_pad
        reach = PairIndex.reach(fbox, f_pad)
        bodies = np.unique(env_e)
        small = bodies[reach[bodies] <= INDEX_BODY_REACH]
        self.big = bodies[reach[bodies] > INDEX_BODY_REACH]
        c = fbox.t[small]
        self.lo = c.min(axis=0) if len(small) else np.zeros(3)
        self.step = GRID_CELL
        self.shape = (np.floor((c.max(axis=0) - self.lo) / self.step).astype(np.int64) + 1 if len(small)
                      else np.ones(3, dtype=np.int64))
        cell = np.floor((c - self.lo) / self.step).astype(np.int64)
        cells = (cell[:, 0] * self.shape[1] + cell[:, 1]) * self.shape[2] + cell[:, 2]
        order = np.argsort(cells, kind="stable")
        self.body = small[order]
        self.start = np.searchsorted(cells[order], np.arange(int(np.prod(self.shape)) + 1)).astype(np.int64)
        # per unit: how far from its sphere centre a small body's centre can be and still pass
        self.query = levels.bound_r + extra + reach[small].max(initial=0.0) + 1e-9
        self.pair_of = np.full((len(levels.units), len(fbox.t)), -1, dtype=np.int64)  # (unit, body) → env pair
        self.pair_of[env_u, env_e] = np.arange(len(env_u))


class _NoGrid:
    """PairGrid's arrays when there is none (the kernel ignores them)."""

    lo = np.zeros(3)
    step = 1.0
    shape = np.ones(3, dtype=np.int64)
    start = np.zeros(2, dtype=np.int64)
    body = np.zeros(0, dtype=np.int64)
    big = np.zeros(0, dtype=np.int64)
    query = np.zeros(1)
    pair_of = np.zeros((1, 1), dtype=np.int64)


NO_GRID = _NoGrid()
_NONE = np.zeros((1, 1))  # what the kernel gets for margins it does not read


TABLE_JOINTS = 3  # the most joints a clearance table spans (pair_tables.GRID_3D)


class TablePack:
    """Clearance tables (pair_tables.PairTable: cols, lo, step, levers, dist) as the kernel reads them:
    per table its 1–3 joint columns, grid and levers in rows of TABLE_JOINTS, its distances at an offset in one flat
    array; per self pair p, per env pair k in reach (env_pairs: its unit and fixed body, env_u and env_e)
    and per cluster pair g (cl_self) the row of its table or -1."""

    def __init__(self, P: int, G: int, env_pairs: tuple[np.ndarray, np.ndarray], self_tables: dict | None = None,
                 env_tables: dict | None = None, cluster_tables: dict | None = None):
        env_u, env_e = env_pairs
        self.self_tab = np.full(P, -1, dtype=np.int64)
        self.env_tab = np.full(len(env_u), -1, dtype=np.int64)
        self.cluster_tab = np.full(G, -1, dtype=np.int64)
        tabs = []
        for p, tab in (self_tables or {}).items():
            self.self_tab[p] = len(tabs)
            tabs.append(tab)
        for g, tab in (cluster_tables or {}).items():
            self.cluster_tab[g] = len(tabs)
            tabs.append(tab)
        if env_tables:
            row = {(u, e): k for k, (u, e) in enumerate(zip(env_u.tolist(), env_e.tolist()))}
            for (u, e), tab in env_tables.items():
                if (u, e) in row:  # tables are kept for pairs in reach only (those level 1 tests)
                    self.env_tab[row[(u, e)]] = len(tabs)
                    tabs.append(tab)
        T = len(tabs)
        J = TABLE_JOINTS
        self.cols = np.zeros((T, J), dtype=np.int64)
        self.nd = np.zeros(T, dtype=np.int64)
        self.lo, self.step, self.lev = np.zeros((T, J)), np.ones((T, J)), np.zeros((T, J))
        self.size = np.ones((T, J), dtype=np.int64)
        sizes = np.array([t.dist.size for t in tabs], dtype=np.int64)
        self.off = np.cumsum(sizes) - sizes  # where each table's distances start in `dist`
        for i, tab in enumerate(tabs):
            k = len(tab.cols)
            self.nd[i] = k
            self.cols[i, :k], self.lo[i, :k], self.step[i, :k], self.lev[i, :k] = tab.cols, tab.lo, tab.step, tab.levers
            self.size[i, :k] = tab.dist.shape
        self.dist = np.ascontiguousarray(np.concatenate([(t.dist - t.slack).ravel() for t in tabs]) if tabs else np.zeros(0))

    @property
    def arrays(self) -> tuple:
        return (self.cols, self.nd, self.lo, self.step, self.lev, self.size, self.off, self.dist, self.self_tab,
                self.env_tab, self.cluster_tab)


def _sorted_pairs(n: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(config, pair) entries in np.nonzero's order over a (config, pair) mask."""
    order = np.lexsort((k, n))
    return n[order], k[order]


class NoMargins:
    """What levels 2–3 index for configurations checked without edge margins: 0.0 for any entry, no arrays."""

    def __getitem__(self, index) -> float:
        return 0.0


NO_MARGINS = NoMargins()


@dataclass(frozen=True)
class Body:
    """One collision shape: moving (frame ≥ 0, offset in that frame) or fixed (frame -1, world)."""

    name: str  # link name, or scene object id
    is_link: bool
    frame: int
    offset: np.ndarray
    obj: fcl.CollisionObject | None


@dataclass(frozen=True)
class Boxes:
    """Rounded boxes stacked as arrays: rotation (K, 3, 3), centre (K, 3), half extents, rounding."""

    R: np.ndarray
    t: np.ndarray
    h: np.ndarray
    rho: np.ndarray

    @classmethod
    def build(cls, boxes: list[BoundingBox]) -> "Boxes":
        k = len(boxes)
        return cls(np.array([b.pose[:3, :3] for b in boxes]).reshape(k, 3, 3),
                   np.array([b.pose[:3, 3] for b in boxes]).reshape(k, 3),
                   np.array([b.half for b in boxes]).reshape(k, 3),
                   np.array([b.rounding for b in boxes], dtype=float))

    def take(self, idx) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.R[idx], self.t[idx], self.h[idx], self.rho[idx]


def touch(C, radii, box_R, box_t, half, rounding) -> np.ndarray:
    """(K, S) bool: sphere s of row k (centre C[k, s], radius radii[k, s]) reaches rounded box k.
    Radii ≤ 0 never touch (signed square), which is how table padding is ignored."""
    L = np.matmul(C - box_t[:, None, :], box_R)
    np.abs(L, out=L)
    L -= half[:, None, :]
    np.maximum(L, 0.0, out=L)
    d2 = np.einsum("ksi,ksi->ks", L, L)
    thr = radii + rounding[:, None]
    return d2 < thr * np.abs(thr)


def box_gap2(C: np.ndarray, idx: tuple, box_R: np.ndarray, box_t: np.ndarray, half: np.ndarray) -> np.ndarray:
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
class Groups:
    """Members (indices into a pair list) grouped by key: the unit pairs under each cluster pair."""

    keys: np.ndarray  # (G,) sorted distinct keys
    members: np.ndarray  # pair indices, grouped by key
    start: np.ndarray  # (G,) first member of each group in `members`
    count: np.ndarray  # (G,)

    @classmethod
    def build(cls, key: np.ndarray, gain: float = 1.0) -> "Groups | None":
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


class CompiledPairs:
    """One checker's compiled bodies and pairs (units u, moving shapes m, fixed bodies e, self pairs p =
    (self_s[p], self_o[p])), and the levels 1–2 over them. Shapes hang from the frames of `fk` at
    (shape_R, shape_t)."""

    units: list[str]  # (U,) link of each unit
    unit_frame: np.ndarray  # (U,) frame of each unit
    bound_c: np.ndarray  # (U, 3) bounding-sphere centre of each unit in its frame
    bound_r: np.ndarray  # (U,) ... radius
    outer: SphereTable  # the units' sphere covers (contain the unit)
    inner: SphereTable  # spheres inside the units' exact solids (proofs)
    ubox: Boxes  # the units' rounded boxes in their frames
    ubox_tight: np.ndarray  # (U,) the unit's box is its exact solid
    unit_shape_tab: np.ndarray  # (U, k) moving-shape indices per unit, -1 padded
    unit_of_shape: np.ndarray  # (M,) unit of each moving shape
    frame_of: np.ndarray  # (M,) frame of each moving shape
    shape_R: np.ndarray  # (M, 3, 3) moving shapes in their frames
    shape_t: np.ndarray  # (M, 3)
    shape_kind: list[str]  # (M,)
    hull_v: np.ndarray  # (M, V, 3) hull vertices of mesh shapes in their frames (kernels' vertex tests)
    hull_n: np.ndarray  # (M,) how many (0: none)
    hull_p: np.ndarray  # (M, F, 4) their hulls' face planes (n, d: n·x ≤ d inside), frame coordinates
    hull_pn: np.ndarray  # (M,) how many
    hull_pts: np.ndarray  # (M,) bool: the hull's vertices are mesh points (may prove contact; a bounding polytope's not)
    f_hull_v: np.ndarray  # (E, V, 3) hull vertices of fixed meshes (world)
    f_hull_n: np.ndarray  # (E,)
    f_hull_p: np.ndarray  # (E, F, 4) their face planes
    f_hull_pn: np.ndarray  # (E,)
    sbox_ok: np.ndarray  # (M,) the shape is a box or sphere: exactly the rounded box sbox_h, sbox_rho
    sbox_h: np.ndarray  # (M, 3) half extents (at shape_R, shape_t in its frame)
    sbox_rho: np.ndarray  # (M,) rounding (a sphere's radius)
    moving: list[Body]  # (M,) moving bodies (`.obj`: the shape's fcl object)
    fixed: list[Body]  # (E,) fixed bodies (world pose `.offset`)
    f_pad: np.ndarray  # (E,) clearance required of the fixed body: self_padding for links, padding for the scene
    fbox: Boxes  # (E,) world boxes of the fixed bodies
    f_tight: np.ndarray  # (E,) the box is the body's exact solid
    f_cover: SphereTable  # fixed robot meshes' sphere covers
    f_has_cover: np.ndarray  # (E,)
    f_inner: SphereTable  # spheres inside fixed bodies whose box is not exact (robot meshes, scene cylinders)
    f_ibox_ok: np.ndarray  # (E,) the fixed body has an inner box (a robot mesh: geometry.mesh_inner_box)
    f_ibox: Boxes  # (E,) world boxes inside those fixed bodies (kernels: a hull vertex inside proves contact)
    env_u: np.ndarray  # (Q,) unit × fixed pairs in reach: unit
    env_e: np.ndarray  # (Q,) ... fixed body
    env_R: np.ndarray  # (Q, 3, 3) ... its box
    env_t: np.ndarray
    env_h: np.ndarray
    env_thr2: np.ndarray  # (Q,) squared level-1 threshold
    self_s: np.ndarray  # (P,) self pairs: the side whose spheres are tested
    self_o: np.ndarray  # (P,) ... the side whose box they are tested against
    self_two: np.ndarray  # (P,) neither box exact: test both ways
    self_thr2: np.ndarray  # (P,) squared level-1 threshold
    pair_levers: np.ndarray  # (P, dof) joints moving one side of the pair only

    def __init__(self, fk: KinematicTree, self_padding: float, margin: float):
        self.fk = fk
        self.self_padding = self_padding
        self.margin = margin
        self._kernel_args: tuple | None = None  # the arrays compiled_12 hands the kernel, gathered at its first call
        self.tables: TablePack | None = None  # the clearance tables the kernel applies (none until set_tables)
        self._no_tables: TablePack | None = None  # the empty pack, made once
        self._kernel_data = None  # kernels.KernelData of _kernel_args, the grid and the tables, made at first use
        self._kernel_data_tables: TablePack | None = None  # the tables it holds

    def build_clusters(self) -> None:
        """Level 1's first step: one sphere per cluster of a frame's units (containing their bounding
        spheres), tested against each fixed box and other cluster its units are paired with; unit pairs
        are tested only under the cluster pairs it cannot clear (TALOS l_arm: 445 unit–box pairs per
        configuration, 113 cluster–box pairs — the gripper's 11 links share one frame)."""
        self._kernel_args = None  # the pairs changed (a build, or `exempting`'s copy)
        self.tables = self._no_tables = self._kernel_data = None
        slot = np.zeros(len(self.units), dtype=np.int64)
        frames: list[int] = []
        for f in np.unique(self.unit_frame):  # around the largest unit left, what fits in CLUSTER_RADIUS
            rest = np.nonzero(self.unit_frame == f)[0]
            rest = rest[np.argsort(-self.bound_r[rest], kind="stable")]
            while len(rest):
                s = rest[0]
                reach = np.linalg.norm(self.bound_c[rest] - self.bound_c[s], axis=1) + self.bound_r[rest]
                take = reach <= max(CLUSTER_RADIUS, self.bound_r[s])
                slot[rest[take]] = len(frames)
                frames.append(int(f))
                rest = rest[~take]
        spheres = [enclosing_sphere(SphereCover(self.bound_c[slot == k], self.bound_r[slot == k]))
                   for k in range(len(frames))]
        self.cl_slot = slot  # unit → its cluster
        self.cl_frame = np.array(frames, dtype=np.int64)
        self.cl_c = np.array([c for c, _ in spheres]).reshape(len(frames), 3)
        self.cl_r = np.array([r for _, r in spheres])
        E = max(len(self.fixed), 1)
        self.cl_env = Groups.build(slot[self.env_u] * E + self.env_e, CLUSTER_GAIN)
        if self.cl_env is not None:
            ks, ke = self.cl_env.keys // E, self.cl_env.keys % E
            self.cl_env_slot = ks
            self.cl_env_R, self.cl_env_t, self.cl_env_h, _ = self.fbox.take(ke)
            thr = self.cl_r[ks] + self.fbox.rho[ke] + self.f_pad[ke] + self.margin + EPS
            self.cl_env_thr2 = thr * thr
        F = max(len(frames), 1)
        self.cl_self = Groups.build(slot[self.self_s] * F + slot[self.self_o], CLUSTER_GAIN)
        if self.cl_self is not None:
            sa, sb = self.cl_self.keys // F, self.cl_self.keys % F
            self.cl_self_a, self.cl_self_b = sa, sb
            thr = self.cl_r[sa] + self.cl_r[sb] + self.self_padding + 2 * self.margin + EPS
            self.cl_self_thr2 = thr * thr
        self.env_index = None
        self.env_grid = None
        if PairIndex.pays(self.env_e, self.fbox, self.f_pad):  # level 1's first step through a k-d tree
            extra = self.margin + EPS
            self.env_index = (PairIndex(self.env_u, self.env_e, self.bound_r, extra, self.fbox, self.f_pad)
                              if self.cl_env is None else
                              PairIndex(ks, ke, self.cl_r, extra, self.fbox, self.f_pad))
            self.env_grid = PairGrid(self, extra)

    use_compiled = True
    """The checker runs the compiled levels (kernels.levels_12); False (on an instance): the numpy levels,
    the reference the tests compare the kernels with."""

    def set_tables(self, self_tables: dict, env_tables: dict, cluster_tables: dict) -> None:
        """The clearance tables compiled_12 applies from now on: self pair → table, (unit, fixed body) → table,
        cluster pair (cl_self) → table."""
        self.tables = TablePack(len(self.self_s), self._n_cluster_pairs(), (self.env_u, self.env_e), self_tables,
                                env_tables, cluster_tables)

    def _n_cluster_pairs(self) -> int:
        return 0 if self.cl_self is None else len(self.cl_self.keys)

    def kernel_data(self):
        """The kernels.KernelData levels_12 reads (built at first use, again when the tables change)."""
        a = self._kernel_args
        if a is None:
            a = self._kernel_args = tuple(np.ascontiguousarray(x) for x in (  # one layout: one compilation
                self.unit_frame, self.bound_c, self.bound_r,
                self.env_u, self.env_e, self.env_R, self.env_t, self.env_h, self.env_thr2,
                self.fbox.R, self.fbox.t, self.fbox.h, self.fbox.rho, self.f_pad, self.f_tight,
                self.f_cover.centers, self.f_cover.radii, self.f_cover.counts,
                self.f_inner.centers, self.f_inner.radii, self.f_inner.counts,
                self.self_s, self.self_o, self.self_two, self.self_thr2,
                self.ubox.R, self.ubox.t, self.ubox.h, self.ubox.rho, self.ubox_tight,
                self.outer.centers, self.outer.radii, self.outer.counts, self.outer.owners,
                self.inner.centers, self.inner.radii, self.inner.counts, self.unit_shape_tab,
                self.hull_v, self.hull_n, self.hull_p, self.hull_pn, self.hull_pts, self.sbox_ok, self.sbox_h, self.sbox_rho, self.shape_R, self.shape_t,
                self.frame_of, self.f_hull_v, self.f_hull_n, self.f_hull_p, self.f_hull_pn,
                self.f_ibox_ok, self.f_ibox.R, self.f_ibox.t, self.f_ibox.h)) + self._cluster_args()
            self._kernel_data = None
        if self._kernel_data is None or self._kernel_data_tables is not self.tables:
            tabs = self.tables
            if tabs is None:  # none set yet (the tables' own selection samples without them)
                if self._no_tables is None:
                    self._no_tables = TablePack(len(self.self_s), self._n_cluster_pairs(), (self.env_u, self.env_e))
                tabs = self._no_tables
            g = self.env_grid or NO_GRID
            self._kernel_data = kernels.make_kernel_data(
                *self.fk.kernel_arrays, *a[:-18], self.env_grid is not None, g.lo, float(g.step), g.shape, g.start,
                g.body, g.big, g.query, g.pair_of, *tabs.arrays, *a[-18:])
            self._kernel_data_tables = self.tables
        return self._kernel_data

    def compiled_12(self, q: np.ndarray, me: np.ndarray | None, mp: np.ndarray | None):
        """FK and levels 1–2 compiled (kernels.py) → R, t, status (N,) (kernels.STATUS_*), env entries
        (config, moving shape, fixed body) and self entries (config, shape, shape, pair) still open,
        none of a configuration a proof marked, and how many pairs the clearance tables (set_tables) cleared.
        me / mp: edge margins (N, U) / (N, P), or None."""
        d = self.kernel_data()
        none = _NONE
        R, t, status, env, slf, n_tab = kernels.levels_12(
            np.ascontiguousarray(q, dtype=float), me is not None, none if me is None else np.ascontiguousarray(me),
            mp is not None, none if mp is None else np.ascontiguousarray(mp), self.margin, self.self_padding, EPS, d)
        return R, t, status, (env[:, 0], env[:, 1], env[:, 2]), (slf[:, 0], slf[:, 1], slf[:, 2], slf[:, 3]), n_tab

    def _cluster_args(self) -> tuple:
        """Level 1's clusters as the kernel reads them (18 arrays and flags): cluster frames and centres;
        cluster–body pairs (cluster, box, squared threshold, their unit pairs); cluster pairs (likewise).
        Not used with the grid (many bodies), whose cells already limit the pairs."""
        i64 = np.int64
        env = self.cl_env is not None and self.env_grid is None
        ce = ((self.cl_env_slot, self.cl_env_R, self.cl_env_t, self.cl_env_h, self.cl_env_thr2, self.cl_env.start,
               self.cl_env.count, self.cl_env.members) if env else
              (np.zeros(0, i64), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
               np.zeros(0, i64), np.zeros(0, i64), np.zeros(0, i64)))
        slf = self.cl_self is not None
        cs = ((self.cl_self_a, self.cl_self_b, self.cl_self_thr2, self.cl_self.start, self.cl_self.count,
               self.cl_self.members) if slf else
              (np.zeros(0, i64), np.zeros(0, i64), np.zeros(0), np.zeros(0, i64), np.zeros(0, i64), np.zeros(0, i64)))
        ce = tuple(np.ascontiguousarray(x) for x in ce)
        cs = tuple(np.ascontiguousarray(x) for x in cs)
        return (np.ascontiguousarray(self.cl_frame, dtype=i64), np.ascontiguousarray(self.cl_c).reshape(-1, 3),
                env, *ce, slf, *cs)

    def cluster_spheres(self, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(N, C, 3) world centres of the cluster spheres."""
        f = self.cl_frame
        return np.matmul(R[:, f], self.cl_c[:, :, None])[..., 0] + t[:, f]

    def level1_env(self, R: np.ndarray, t: np.ndarray, B: np.ndarray):
        """Unit bounding spheres against fixed boxes in reach → (config, unit, fixed body) entries:
        cluster spheres first (over the cluster × box pairs), then the unit pairs below the cluster
        pairs still touching. The first step tests every pair, or with many fixed bodies (env_index)
        only the pairs a k-d tree returns: the same entries in the same order either way."""
        e0 = np.empty(0, np.int64)
        if len(self.env_u) == 0:
            return e0, e0, e0
        index = self.env_index
        if self.cl_env is None:
            if index is None:
                n, p = np.nonzero(box_gap2(B, (slice(None), self.env_u), self.env_R, self.env_t, self.env_h)
                                  < self.env_thr2)
            else:
                n, p = index.candidates(B)
                near = box_gap2(B, (n, self.env_u[p]), self.env_R[p], self.env_t[p], self.env_h[p]) < self.env_thr2[p]
                n, p = _sorted_pairs(n[near], p[near])
            return n, self.env_u[p], self.env_e[p]
        BC = self.cluster_spheres(R, t)
        if index is None:
            n, k = np.nonzero(box_gap2(BC, (slice(None), self.cl_env_slot), self.cl_env_R, self.cl_env_t,
                                       self.cl_env_h) < self.cl_env_thr2)
        else:
            n, k = index.candidates(BC)
            near = (box_gap2(BC, (n, self.cl_env_slot[k]), self.cl_env_R[k], self.cl_env_t[k], self.cl_env_h[k])
                    < self.cl_env_thr2[k])
            n, k = _sorted_pairs(n[near], k[near])
        if len(n) == 0:
            return e0, e0, e0
        n, p = self.cl_env.expand(n, k)
        u = self.env_u[p]
        near = box_gap2(B, (n, u), self.env_R[p], self.env_t[p], self.env_h[p]) < self.env_thr2[p]
        return n[near], u[near], self.env_e[p[near]]

    def level1_self(self, R, t, B: np.ndarray):
        """Unit pairs: bounding spheres, then each side's bounding sphere against the other side's box
        → (config, pair, o box rotation, o box centre) entries."""
        if len(self.self_s) == 0:
            e = np.empty(0, np.int64)
            return e, e, np.empty((0, 3, 3)), np.empty((0, 3))
        if self.cl_self is None:
            a, b = self.self_s, self.self_o
            acc = None
            for i in range(3):
                x = B[:, a, i] - B[:, b, i]
                x *= x
                acc = x if acc is None else acc + x
            n, p = np.nonzero(acc < self.self_thr2)
            a, b = a[p], b[p]
        else:
            BC = self.cluster_spheres(R, t)
            d = BC[:, self.cl_self_a] - BC[:, self.cl_self_b]
            n, k = np.nonzero(np.einsum("nki,nki->nk", d, d) < self.cl_self_thr2)
            n, p = self.cl_self.expand(n, k)
            a, b = self.self_s[p], self.self_o[p]
            d = B[n, a] - B[n, b]
            near = np.einsum("ki,ki->k", d, d) < self.self_thr2[p]
            n, p, a, b = n[near], p[near], a[near], b[near]
        reach = self.self_padding + 2 * self.margin + EPS
        Rb, tb = self.unit_box_world(R, t, n, b)
        near = touch(B[n, a][:, None, :], (self.bound_r[a] + reach)[:, None], Rb, tb, self.ubox.h[b],
                     self.ubox.rho[b])[:, 0]
        n, p, a, b, Rb, tb = n[near], p[near], a[near], b[near], Rb[near], tb[near]
        # the other way round too: a small unit's sphere against a big one's box (kernels._levels_12 says why)
        Ra, ta = self.unit_box_world(R, t, n, a)
        near = touch(B[n, b][:, None, :], (self.bound_r[b] + reach)[:, None], Ra, ta, self.ubox.h[a],
                     self.ubox.rho[a])[:, 0]
        return n[near], p[near], Rb[near], tb[near]

    def unit_box_world(self, R, t, n, unit):
        """World pose (K, 3, 3), (K, 3) of the rounded boxes of units `unit` in configurations `n`."""
        f = self.unit_frame[unit]
        Rf = R[n, f]
        return Rf @ self.ubox.R[unit], np.matmul(Rf, self.ubox.t[unit][:, :, None])[:, :, 0] + t[n, f]

    def spheres_touch(self, R, t, n, u, table: SphereTable, extra, box_R, box_t, half, rounding):
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
            f = self.unit_frame[us]
            C = table.centers[us, :cap] @ R[ns, f].transpose(0, 2, 1) + t[ns, f][:, None, :]
            return touch(C, table.radii[us, :cap] + extra[sel, None], box_R[sel], box_t[sel], half[sel],
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

    def prove_env(self, R, t, n, u, e, me, hit_out) -> None:
        """Mark configurations where an inner sphere of a unit reaches an exact fixed box."""
        sure = np.nonzero(self.f_tight[e] & (self.inner.counts[u] > 0))[0]
        if len(sure):
            n, u, e = n[sure], u[sure], e[sure]
            inside = self.spheres_touch(R, t, n, u, self.inner, self.f_pad[e] + me[n, u] - EPS, *self.fbox.take(e))
            hit_out[n[inside.any(1)]] = True

    def prove_self(self, R, t, n, p, Rb, tb, mp, hit_out) -> None:
        """Mark configurations where an inner sphere of the s side reaches the o side's exact box."""
        a, b = self.self_s[p], self.self_o[p]
        sure = np.nonzero(self.ubox_tight[b] & (self.inner.counts[a] > 0))[0]
        if len(sure):
            bs = b[sure]
            ns = n[sure]
            inside = self.spheres_touch(R, t, ns, a[sure], self.inner, self.self_padding + mp[ns, p[sure]] - EPS, Rb[sure],
                                         tb[sure], self.ubox.h[bs], self.ubox.rho[bs])
            hit_out[n[sure][inside.any(1)]] = True

    def prove_inner(self, R, t, env, slf, me, mp, hit_out) -> None:
        """Mark configurations where inner spheres of both sides meet, for the entries left to FCL whose
        other side's box is not exact (meshes, scene cylinders): after the covers, so that only what
        would cost an FCL call pays for these tests."""
        n, u, e = env[0], self.unit_of_shape[env[1]], env[2]
        sel = np.nonzero(~self.f_tight[e] & (self.inner.counts[u] > 0) & (self.f_inner.counts[e] > 0))[0]
        if len(sel):
            key = np.unique(np.stack([n[sel], u[sel], e[sel]], 1), axis=0)
            ns, us, es = key[:, 0], key[:, 1], key[:, 2]
            self._inner_meet(R, t, ns, us, self.f_inner.centers[es], self.f_inner.radii[es],
                             self.f_pad[es] + me[ns, us] - EPS, hit_out)
        n, p = slf[0], slf[3]
        a, b = self.self_s[p], self.self_o[p]
        sel = np.nonzero(~self.ubox_tight[b] & (self.inner.counts[a] > 0) & (self.inner.counts[b] > 0) & ~hit_out[n])[0]
        if len(sel):
            key = np.unique(np.stack([n[sel], p[sel]], 1), axis=0)
            ns, ps = key[:, 0], key[:, 1]
            bs = self.self_o[ps]
            self._inner_meet(R, t, ns, self.self_s[ps], self._inner_world(R, t, ns, bs), self.inner.radii[bs],
                             self.self_padding + mp[ns, ps] - EPS, hit_out)

    def _inner_world(self, R, t, n, u, width: int | None = None) -> np.ndarray:
        """(K, width, 3) world centres of the inner spheres of units u[k] in configurations n[k]."""
        f = self.unit_frame[u]
        return self.inner.centers[u, :width] @ R[n, f].transpose(0, 2, 1) + t[n, f][:, None, :]

    def _inner_meet(self, R, t, n, u, Cb, rb, extra, hit_out, chunk: int = 2048) -> None:
        """Mark configurations n[k] where an inner sphere of unit u[k] comes within extra[k] of one of
        the spheres (Cb[k], rb[k]) (world; padding entries never meet: signed squares)."""
        extra = np.broadcast_to(np.asarray(extra, float), (len(n),))
        W = max(int(self.inner.counts[u].max()), 1)
        for lo in range(0, len(n), chunk):
            sl = slice(lo, lo + chunk)
            ns, us = n[sl], u[sl]
            d = self._inner_world(R, t, ns, us, W)[:, :, None, :] - Cb[sl][:, None, :, :]
            thr = self.inner.radii[us, :W, None] + rb[sl][:, None, :] + extra[sl, None, None]
            meet = np.einsum("kabi,kabi->kab", d, d) < thr * np.abs(thr)
            hit_out[ns[meet.any(axis=(1, 2))]] = True

    def shape_mask(self, table: SphereTable, unit, k, i, rows: int) -> np.ndarray:
        """(rows, kmax) bool: hits (k, sphere i of unit[k]) → the owning shapes (index in unit)."""
        mask = np.zeros((rows, self.unit_shape_tab.shape[1]), dtype=bool)
        mask[k, table.owners[unit[k], i]] = True
        return mask

    def level2_env(self, R, t, n, u, e, me=NO_MARGINS):
        """(config, unit, fixed body) → (config, moving shape, fixed body) entries whose cover
        spheres reach the fixed box (and, for fixed meshes, whose unit box the mesh's spheres reach)."""
        if len(n) == 0:
            return n, u, e
        pad = self.f_pad[e] + me[n, u] + EPS
        hit = self.spheres_touch(R, t, n, u, self.outer, pad, *self.fbox.take(e))
        ok = hit.any(1)
        rev = np.nonzero(ok & self.f_has_cover[e])[0]
        if len(rev):
            ur, er = u[rev], e[rev]
            Rb, tb = self.unit_box_world(R, t, n[rev], ur)
            back = touch(self.f_cover.centers[er], self.f_cover.radii[er] + pad[rev, None], Rb, tb, self.ubox.h[ur],
                          self.ubox.rho[ur])
            ok[rev] = back.any(1)
        k, i = np.nonzero(hit & ok[:, None])
        k, ls = np.nonzero(self.shape_mask(self.outer, u, k, i, len(n)))
        return n[k], self.unit_shape_tab[u[k], ls], e[k]

    def level2_self(self, R, t, n, p, Rb, tb, mp=NO_MARGINS):
        """(config, unit pair) → (config, moving shape, moving shape, pair) entries: the s side's cover
        against the o side's box, and the other way round when neither box is exact."""
        if len(n) == 0:
            return n, n, n, n
        a, b = self.self_s[p], self.self_o[p]
        pad = np.broadcast_to(self.self_padding + mp[n, p] + EPS, (len(n),))
        hit_a = self.spheres_touch(R, t, n, a, self.outer, pad, Rb, tb, self.ubox.h[b], self.ubox.rho[b])
        ok = hit_a.any(1)
        mask_b = self.unit_shape_tab[b] >= 0  # every shape of the o side, unless tested below
        two = np.nonzero(ok & self.self_two[p])[0]
        if len(two):
            a2, b2, n2 = a[two], b[two], n[two]
            Ra, ta = self.unit_box_world(R, t, n2, a2)
            hit_b = self.spheres_touch(R, t, n2, b2, self.outer, pad[two], Ra, ta, self.ubox.h[a2], self.ubox.rho[a2])
            ok[two] = hit_b.any(1)
            kk, ii = np.nonzero(hit_b)
            mask_b[two] = self.shape_mask(self.outer, b2, kk, ii, len(two))
        k, i = np.nonzero(hit_a & ok[:, None])
        mask_a = self.shape_mask(self.outer, a, k, i, len(n))
        k, la, lb = np.nonzero(mask_a[:, :, None] & mask_b[:, None, :])
        return n[k], self.unit_shape_tab[a[k], la], self.unit_shape_tab[b[k], lb], p[k]
