"""Per-pair clearance tables: pairs whose relative pose depends on one or two group joints — two
moving units, or a moving unit and a link fixed at q_ref (TALOS l_arm: arm_left_2 vs torso_2).

Sphere covers at 2 cm cannot separate mesh links that pass within 1–3 cm of each other in most
configurations (TALOS: torso_2 vs arm_2 and arm_3 vs arm_5, median 14 and 28 mm), so those pairs
reach exact FCL almost always. When only one or two joints move one side of a pair relative to the
other (those above both move them together), the pair's exact distance is a function of those
joints alone: tabulate it once over a grid (FCL distance, min over the units' shape pairs) and at
check time the pair is proven free when

    table(nearest grid point g) − Σ_j lever_j · |q_j − g_j|  >  required clearance,

lever_j being how far any point of the moving side may move per radian of joint j (the checker's
unit levers: distance from the joint origin to the unit's bounding sphere, by the triangle
inequality along the chain), so that the left side is a lower bound of the true distance. Pairs not
proven free go to FCL as before: the table only removes FCL calls, never changes a verdict.

Tables are built lazily (first check) for pairs that reach FCL often in a seeded sample of random
configurations and that involve a mesh (primitive pairs are decided by the covers already), and are
cached on the robot's RobotCollisionModel, keyed by everything that fixes the pair's geometry — of
q_ref only the joints outside the groups on the path between the pair's links (path_values), so a
live robot whose other arm or legs moved reuses them. A change of a joint on that path (TALOS l_arm:
the torso, for arm links against the base) still builds that pair's table anew (~0.7 s on TALOS).

Across machines: table keys are exact (stable_bytes), and the selection's sample is rounded before the
cover tests, so the same robot gets the same tables on every CPU except where a sampled distance lies
within 1e-9 of a cover threshold. Verdicts never depend on it: a pair without a table goes to FCL.

Which pairs get a table (the selection) is a heuristic that never changes a verdict, so it is keyed
by q_ref rounded to SELECTION_RESOLUTION: noisy joint_states reuse it instead of sampling again.
The cache (`TableCache`) keeps at most CACHE_BYTES per robot, least recently used entries out first:
keys hold q_ref values, so a robot whose path joints keep moving adds entries with every plan.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import fcl
import numpy as np


class NoMargins:
    """What the checker's levels 2–3 index for configurations (no edge margins): 0.0 for any entry, no
    arrays. Here, not in checker.py, because the checker imports this module (no import circle)."""

    def __getitem__(self, index) -> float:
        return 0.0


NO_MARGINS = NoMargins()


@dataclass(frozen=True)
class CheckerView:
    """What the tables read of one CollisionChecker (`CollisionChecker.pair_table_view()`): its public
    attributes through `checker`, and the arrays of its levels 1–3 (the checker's own, not copies: read,
    never written). Units are a link's shapes grouped; self pairs are (self_s[p], self_o[p]); shapes
    hang from frames of the FK engine (`fk`, model.fk.KinematicTree) at (shape_R, shape_t)."""

    checker: Any  # the CollisionChecker: robot, joint_indices, q_ref, dof, groups, paddings, unit_levers
    fk: Any  # KinematicTree of the checker's groups
    model: Any  # RobotCollisionModel: links, and the pair_tables cache shared by the robot's checkers
    units: Sequence[str]
    unit_frame: np.ndarray  # (U,) frame of each unit
    bound_c: np.ndarray  # (U, 3) bounding-sphere centre of each unit in its frame
    outer: Any  # the units' sphere covers (centers, radii, counts)
    unit_shape_tab: np.ndarray  # (U, k) moving-shape indices per unit, -1 padded
    shape_kind: Sequence[str]
    shape_R: np.ndarray  # (M, 3, 3) moving shapes in their frames
    shape_t: np.ndarray  # (M, 3)
    frame_of: np.ndarray  # (M,) frame of each moving shape
    moving: Sequence[Any]  # moving bodies (`.obj`: the shape's python-fcl object)
    self_s: np.ndarray  # (P,) self pairs: first unit
    self_o: np.ndarray  # (P,) self pairs: second unit
    pair_levers: np.ndarray  # (P, dof) joints moving one side of the pair only
    level1_self: Callable  # the checker's level 1 (self pairs) and level 2, as the checks call them
    level2_self: Callable
    fixed: Sequence[Any]  # fixed bodies (`.name`, `.is_link`, `.offset`: world pose, `.obj`)
    f_has_cover: np.ndarray  # (E,) the fixed body is a mesh
    env_u: np.ndarray  # (Q,) unit × fixed pairs in reach: unit
    env_e: np.ndarray  # (Q,) ... fixed body
    unit_of_shape: np.ndarray  # (M,) unit of each moving shape
    level1_env: Callable  # the checker's levels 1 and 2 against fixed bodies
    level2_env: Callable


GRID_1D = 256
"""Grid points for a pair moved by one joint."""
GRID_2D = 60
"""Grid points per joint for a pair moved by two joints (60² FCL distance calls per shape pair)."""
SAMPLE = 256
"""Random configurations sampled to find the pairs that reach FCL often."""
MIN_SHARE = 0.05
"""A pair gets a table when at least this share of the sample sends it to FCL."""

SELECTION_RESOLUTION = 0.05
"""rad (m for prisms): q_ref outside the groups is rounded to this in the keys of pair selections."""
CACHE_BYTES = 64 * 2**20
"""Largest size of one robot's cache of tables and selections (TALOS: a table is 2-29 kB)."""
ENTRY_BYTES = 512
"""Counted per cache entry beside its arrays (key, Python objects)."""

_lock = threading.Lock()


def stable_bytes(x: np.ndarray | Sequence[float]) -> bytes:
    """Floats as a cache-key part that is the same on every CPU: rounded to 1e-9 and with -0.0 made 0.0.
    A value that is 0 in exact arithmetic comes out of FK / solve as ±1e-18 depending on the BLAS kernel
    (OpenBLAS Haswell vs SkylakeX), and np.round keeps the sign: without the `+ 0.0` the same geometry
    got a different key (and a 0.7 s table rebuild) on another machine."""
    return (np.round(np.asarray(x, dtype=float), 9) + 0.0).tobytes()


class TableCache:
    """One robot's pair tables and pair selections (RobotCollisionModel.pair_tables): a dict whose
    least recently used entries go once the entries' sizes pass `max_bytes`. Not locked: callers
    hold pair_tables' module lock."""

    def __init__(self, max_bytes: int = CACHE_BYTES):
        self.max_bytes = max_bytes
        self.bytes = 0
        self._entries: OrderedDict[tuple, tuple[Any, int]] = OrderedDict()  # key -> (value, its size)

    def __contains__(self, key: tuple) -> bool:
        return key in self._entries

    def __iter__(self):
        return iter(list(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def __getitem__(self, key: tuple) -> Any:
        self._entries.move_to_end(key)
        return self._entries[key][0]

    def __setitem__(self, key: tuple, value: Any) -> None:
        if key in self._entries:
            self.bytes -= self._entries.pop(key)[1]
        size = _entry_bytes(value)
        self._entries[key] = (value, size)
        self.bytes += size
        while self.bytes > self.max_bytes and len(self._entries) > 1:
            self.bytes -= self._entries.popitem(last=False)[1][1]


def _entry_bytes(value: Any) -> int:
    if isinstance(value, PairTable):
        return ENTRY_BYTES + sum(a.nbytes for a in (value.cols, value.lo, value.step, value.levers, value.dist))
    return ENTRY_BYTES + sum(ENTRY_BYTES // 4 + getattr(item[-1], "nbytes", 0) for item in value)  # a selection


def _selection_q(view: "CheckerView") -> bytes:
    """q_ref outside the groups, rounded to SELECTION_RESOLUTION (the groups' joints zeroed)."""
    q = view.checker.q_ref.copy()
    q[view.checker.joint_indices] = 0.0
    return np.round(q / SELECTION_RESOLUTION).astype(np.int64).tobytes()


@dataclass(frozen=True)
class PairTable:
    """Exact distance lower bound of one unit pair over a grid of its 1–2 relative joints."""

    cols: np.ndarray  # (k,) group configuration columns
    lo: np.ndarray  # (k,) grid origin
    step: np.ndarray  # (k,) grid spacing
    levers: np.ndarray  # (k,) metres per radian (Lipschitz bound per joint)
    dist: np.ndarray  # k-D array of exact distances at the grid points (≤ 0: touching)

    def lower_bound(self, q: np.ndarray) -> np.ndarray:
        """(N, dof) group configurations → (N,) lower bounds of the pair's distance."""
        x = q[:, self.cols]
        n = np.array(self.dist.shape)
        idx = np.clip(np.rint((x - self.lo) / self.step), 0, n - 1).astype(np.int64)
        delta = np.abs(x - (self.lo + idx * self.step))
        lb = self.dist[tuple(idx.T)] - delta @ self.levers
        # the levers hold within the grid (+ half a step): outside the joint limits, prove nothing
        outside = (np.abs(x - (self.lo + (n - 1) * self.step / 2)) > (n - 1) * self.step / 2 + self.step / 2).any(1)
        lb[outside] = -np.inf
        return lb


def path_values(view: CheckerView, link_a: str, link_b: str) -> bytes:
    """The q_ref values of the joints outside the groups on the tree path between two links: with the
    groups, all a pair table's distance function depends on. Only those, not all of q_ref, key a table,
    so a live robot whose other arm or legs moved (or whose joint_states are noisy off the path) reuses
    its tables instead of rebuilding them (TALOS l_arm: 1.7-2.6 s per table set) in every plan."""
    robot = view.checker.robot
    chains = [{j.name for j in robot.chain_joints(robot.root_link, link)} for link in (link_a, link_b)]
    group = set(view.checker.joint_names)
    index = {n: i for i, n in enumerate(robot.joint_names)}
    path = sorted(n for n in chains[0] ^ chains[1] if n in index and n not in group)
    return stable_bytes([view.checker.q_ref[index[n]] for n in path]) + "|".join(path).encode()


def pair_key(view: CheckerView, p: int) -> tuple:
    """Everything that fixes pair p's table: groups, q_ref outside the groups on the path between the
    two links (path_values), both units' link names and shape offsets in their frames, the grid."""
    q = path_values(view, view.units[view.self_s[p]], view.units[view.self_o[p]])
    sides = tuple(sorted(_unit_key(view, u) for u in (view.self_s[p], view.self_o[p])))
    return (view.checker.groups, q, sides, GRID_1D, GRID_2D)


def _unit_key(view: CheckerView, u: int) -> tuple:
    """A moving unit's part of a table key: its link and its shapes' offsets in their frames."""
    shapes = _unit_shapes(view, u)
    return view.units[u], stable_bytes(view.shape_R[shapes]), stable_bytes(view.shape_t[shapes])


def _sample(view: CheckerView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeded SAMPLE random configurations the pair selections test: frames (R, t) and the
    units' bounding-sphere centres B, as level 1 takes them.

    Rounded to 1e-9 so that the FK's last-bit differences between CPUs / BLAS kernels do not reach the
    level tests: the selection then differs between machines only where a sampled sphere distance lies
    within rounding of its threshold (a different choice of tables, i.e. speed, never a verdict)."""
    rng = np.random.default_rng(0)
    lo, hi = view.checker.robot.lower[view.checker.joint_indices], view.checker.robot.upper[view.checker.joint_indices]
    R, t = view.fk(rng.uniform(lo, hi, size=(SAMPLE, view.checker.dof)))
    R, t = np.round(R, 9) + 0.0, np.round(t, 9) + 0.0
    f = view.unit_frame
    return R, t, np.round(np.matmul(R[:, f], view.bound_c[:, :, None])[..., 0] + t[:, f], 9) + 0.0


def select_pairs(view: CheckerView) -> list[tuple[int, np.ndarray]]:
    """(pair, relative joint columns) of the self pairs worth a table: 1–2 relative joints, a mesh
    on either side, both sides robot links, and sent to FCL in ≥ MIN_SHARE of a seeded sample."""
    cand = []
    links = view.model.links
    for p, (a, b) in enumerate(zip(view.self_s, view.self_o)):
        cols = np.nonzero(view.pair_levers[p])[0]
        if not 1 <= len(cols) <= 2:
            continue
        if view.units[a] not in links or view.units[b] not in links:
            continue  # attached objects change per request
        shapes = [m for u in (a, b) for m in view.unit_shape_tab[u] if m >= 0]
        if any(view.shape_kind[m] == "mesh" for m in shapes):
            cand.append((p, cols))
    if not cand:
        return []
    R, t, B = _sample(view)
    slf = view.level1_self(R, t, B)
    n, _, _, pp = view.level2_self(R, t, *slf, NO_MARGINS)
    hits = np.zeros(len(view.self_s))
    if len(n):
        uniq = np.unique(np.stack([n, pp], 1), axis=0)
        np.add.at(hits, uniq[:, 1], 1)
    return [(p, cols) for p, cols in cand if hits[p] >= MIN_SHARE * SAMPLE]


def _unit_shapes(view: CheckerView, u: int) -> list[int]:
    return [int(m) for m in view.unit_shape_tab[u] if m >= 0]


def build_table(view: CheckerView, p: int, cols: np.ndarray) -> PairTable:
    """Exact FCL distance of self pair p over the grid of its relative joints `cols`."""
    a, b = view.self_s[p], view.self_o[p]
    return _grid_table(view, cols, _unit_shapes(view, a), [view.moving[y].obj for y in _unit_shapes(view, b)],
                       _unit_shapes(view, b), (a, b), view.pair_levers[p][cols].copy())


def build_env_table(view: CheckerView, u: int, e: int, cols: np.ndarray) -> PairTable:
    """Exact FCL distance of moving unit u to fixed link body e over the grid of u's joints `cols`."""
    return _grid_table(view, cols, _unit_shapes(view, u), [view.fixed[e].obj], [], (u,),
                       view.checker.unit_levers[u][cols].copy())


def _grid_table(view: CheckerView, cols: np.ndarray, side_a: list[int], side_b: list, moving_b: list[int],
                units: tuple[int, ...], loose: np.ndarray) -> PairTable:
    """Min FCL distance between moving shapes side_a and the bodies side_b (moving_b: those of them
    that are moving shapes, placed per grid point) over the grid of joints `cols`, q_ref elsewhere."""
    lo_lim = view.checker.robot.lower[view.checker.joint_indices][cols]
    hi_lim = view.checker.robot.upper[view.checker.joint_indices][cols]
    size = GRID_1D if len(cols) == 1 else GRID_2D
    axes = [np.linspace(lo, hi, size) for lo, hi in zip(lo_lim, hi_lim)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(cols))
    q = np.tile(view.checker.q_ref[view.checker.joint_indices], (len(grid), 1))
    q[:, cols] = grid
    R, t = view.fk(q)
    req = fcl.DistanceRequest()
    dist = np.empty(len(grid))
    for g in range(len(grid)):
        for m in (*side_a, *moving_b):
            fr = view.frame_of[m]
            obj = view.moving[m].obj
            obj.setRotation(R[g, fr] @ view.shape_R[m])
            obj.setTranslation(R[g, fr] @ view.shape_t[m] + t[g, fr])
        d = np.inf
        for x in side_a:
            for y in side_b:
                d = min(d, fcl.distance(view.moving[x].obj, y, req, fcl.DistanceResult()))
        dist[g] = max(d, 0.0)
    step = np.array([(hi - lo) / (size - 1) if size > 1 else 1.0 for lo, hi in zip(lo_lim, hi_lim)])
    return PairTable(cols, lo_lim.copy(), step, axis_levers(view, units, loose, cols, R, t, step),
                     dist.reshape((size,) * len(cols)))


def axis_levers(view: CheckerView, units: tuple[int, ...], loose: np.ndarray, cols: np.ndarray, R: np.ndarray,
                t: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Lipschitz bound per relative joint, tighter than the checker's unit levers (`loose`: distance
    from the joint *origin*, through the chain): the largest distance of the moved unit's cover
    spheres from the joint *axis* over the grid (R, t: its frames), plus how far that distance may
    grow between grid points as the other relative joint moves (its loose lever × half a step).
    Never above the loose lever; prismatic joints keep it (1 m per m). units: the pair's moving
    units (one for a unit against a fixed link); joint j moves the first of them it levers."""
    out = loose.copy()
    frames = view.fk.frames
    for i, j in enumerate(cols):
        k = next(k for k, fr in enumerate(frames) if fr.column == j)
        if frames[k].prismatic:
            continue
        u = next(u for u in units if view.checker.unit_levers[u, j] > 0)
        cnt = view.outer.counts[u]
        f = view.unit_frame[u]
        C = view.outer.centers[u, :cnt] @ R[:, f].transpose(0, 2, 1) + t[:, f][:, None, :]  # (G, S, 3)
        axis = R[:, k] @ frames[k].axis  # (G, 3) world
        v = C - t[:, k][:, None, :]
        radial = v - np.einsum("gs,gi->gsi", np.einsum("gsi,gi->gs", v, axis), axis)
        reach = float((np.linalg.norm(radial, axis=-1) + view.outer.radii[u, :cnt]).max())
        slack = sum(loose[o] * step[o] / 2 for o in range(len(cols)) if o != i)
        out[i] = min(loose[i], reach + slack)
    return out


def tables_for(view: CheckerView) -> dict[int, PairTable]:
    """Pair index → table, for the checker's pairs worth one (built once per robot and geometry)."""
    cache = view.model.pair_tables
    out = {}
    chosen = ("selection", view.checker.groups, _selection_q(view), tuple(view.units), tuple(view.self_s),
              tuple(view.self_o), view.checker.self_padding, view.checker.margin, view.checker.cross_groups_only)
    with _lock:
        if chosen not in cache:  # the sample costs ~20-50 ms: once per group setup, not per plan
            cache[chosen] = select_pairs(view)
        for p, cols in cache[chosen]:
            key = pair_key(view, p)
            if key not in cache:
                cache[key] = build_table(view, p, cols)
            tab = cache[key]
            out[p] = tab
    return out


def env_candidates(view: CheckerView) -> list[tuple[int, int, np.ndarray]]:
    """(unit, fixed body, joint columns) of unit–fixed-link pairs in reach that a table could decide:
    1–2 group joints move the unit, both sides robot links (attached objects and the scene change
    per request), a mesh on either side."""
    links = view.model.links
    out = []
    for u, e in zip(view.env_u.tolist(), view.env_e.tolist()):
        body = view.fixed[e]
        if not body.is_link or body.name not in links or view.units[u] not in links:
            continue
        cols = np.nonzero(view.checker.unit_levers[u])[0]
        if not 1 <= len(cols) <= 2:
            continue
        if view.f_has_cover[e] or any(view.shape_kind[m] == "mesh" for m in _unit_shapes(view, u)):
            out.append((u, e, cols))
    return out


def select_env_pairs(view: CheckerView, cand: list[tuple[int, int, np.ndarray]]) -> list[tuple[int, int, np.ndarray]]:
    """The candidates the covers send to FCL in ≥ MIN_SHARE of a seeded sample."""
    R, t, B = _sample(view)
    n, m, e = view.level2_env(R, t, *view.level1_env(R, t, B), NO_MARGINS)
    if len(n) == 0:
        return []
    hits: dict[tuple[int, int], int] = {}
    for _, a, b in np.unique(np.stack([n, view.unit_of_shape[m], e], 1), axis=0).tolist():
        hits[(a, b)] = hits.get((a, b), 0) + 1
    return [(u, e, cols) for u, e, cols in cand if hits.get((u, e), 0) >= MIN_SHARE * SAMPLE]


def env_tables_for(view: CheckerView) -> dict[tuple[int, int], PairTable]:
    """(unit, fixed body) → table, for the checker's unit–fixed-link pairs worth one: the fixed link
    sits at q_ref, so the pair's distance is a function of the 1–2 joints moving the unit (TALOS l_arm:
    arm_left_2 against torso_2 reached FCL in 99 % of random configurations)."""
    cand = env_candidates(view)
    if not cand:
        return {}
    cache = view.model.pair_tables
    chosen = ("env-selection", view.checker.groups, _selection_q(view), tuple(view.units),
              tuple((u, e) for u, e, _ in cand), view.checker.self_padding, view.checker.margin)
    out = {}
    with _lock:
        if chosen not in cache:  # scene bodies play no part: once per group setup, not per scene
            cache[chosen] = select_env_pairs(view, cand)
        for u, e, cols in cache[chosen]:
            body = view.fixed[e]
            T_link = view.checker.robot.link_poses(view.checker.q_ref, [body.name])[0]
            key = ("env", view.checker.groups, path_values(view, view.units[u], body.name), *_unit_key(view, u),
                   body.name, stable_bytes(np.linalg.solve(T_link, body.offset)), GRID_1D, GRID_2D)
            if key not in cache:
                cache[key] = build_env_table(view, u, e, cols)
            out[(u, e)] = cache[key]
    return out
