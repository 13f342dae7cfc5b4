"""Per-pair clearance tables: pairs whose relative pose depends on one or two group joints — two
moving units, or a moving unit and a link fixed at q_ref (TALOS l_arm: arm_left_2 vs torso_2) — and
self pairs moved by three that level 1 flags in most configurations (TIAGo's torso lift vs its upper arm).

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
by table_q_ref rounded to SELECTION_RESOLUTION: noisy joint_states reuse it instead of sampling again.
The cache (`TableCache`) keeps at most CACHE_BYTES per robot, least recently used entries out first:
keys hold q_ref values, so a robot whose path joints keep moving adds entries with every plan.

Off the plans' path: a table set costs seconds on a mesh robot (TALOS l_arm 2.7 s, r_arm_torso 3.6 s,
Fetch arm_with_torso 1.5 s), and a plan that built its own ran past its timeout (TALOS, first l_arm plan,
1 s timeout: TIMED_OUT after 2.0 s). So a checker takes the tables built so far and hands what it lacks
to BUILDER, one thread per process that builds them for later checkers, at a quarter of the time while a
plan runs here (TableBuilder.planning). `build_in_background(False)` (tests of the tables, benchmarks
that time steady-state searches) has the first check build them as before.
"""
from __future__ import annotations

import atexit
import os
import threading
import time
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Callable, Iterator, Protocol, Sequence

import fcl
import numpy as np

from humanoid_planner.core.collision.geometry import RobotCollisionModel
from humanoid_planner.core.collision.levels import TABLE_JOINTS, CompiledPairs
from humanoid_planner.core.model.robot import RobotModel


class TableSource(Protocol):
    """What the tables read of one CollisionChecker: its settings and its compiled pairs and levels."""

    robot: RobotModel
    groups: tuple[str, ...]
    joint_indices: np.ndarray
    joint_names: tuple[str, ...]
    q_ref: np.ndarray  # (robot.dof,)
    dof: int
    self_padding: float
    margin: float
    cross_groups_only: bool
    unit_levers: np.ndarray  # (U, dof)
    levels: CompiledPairs
    collision_model: RobotCollisionModel  # links, and the `pair_tables` cache shared by the robot's checkers


GRID_1D = 256
"""Grid points for a pair moved by one joint: one FCL distance each, built once per robot and pair; at
256 the grid step is small next to the levers, so the bound stays close to the exact distance."""
GRID_2D = 60
"""Grid points per joint for a pair moved by two joints: fewer than GRID_1D because the count is squared
(60² FCL distance calls per shape pair, the ~0.7 s of a TALOS table)."""
GRID_3D = 14
"""Grid points per joint for a pair moved by three joints (14³ FCL distance calls per shape pair: TIAGo's
torso_lift_link against arm_3_link 2.6 s, in the background), only for a pair level 1 flags in most
configurations (FLAG3_SHARE). Random TIAGo arm_torso configurations: the table clears that pair in 66 % of
them (at 20 points 79 %, for 9.2 s of build); the checker's rate 79k -> 124k/s, 0 false free."""
SAMPLE = 256
"""Random configurations sampled to find the pairs that reach FCL often (one batch through levels 1–2:
enough to see a 5 % share, cheap next to one table)."""
MIN_SHARE = 0.05
"""A pair gets a table when at least this share of the sample sends it to FCL: rarer pairs cost fewer FCL
calls than their table's build."""
FLAG3_SHARE = 0.5
"""A pair moved by three joints gets a table only when level 1 flags it in at least this share of the sample:
TIAGo's torso_lift_link against arm_3_link, flagged in every configuration, cost a third of the kernel's time
per configuration (8.9 -> 5.8 us with the pair left out); a 3-D grid costs more to build and proves less."""
FLAG_SHARE = 0.2
"""With the compiled levels, a pair also gets a table when level 1 flags it in at least this share of the
sample: the kernel then runs its cover and hull tests, which the table's lookup replaces (Panda's link5
against link7, flagged in every configuration: half the kernel's time per configuration without one)."""

SELECTION_RESOLUTION = 0.05
"""rad (m for prisms): q_ref outside the groups is rounded to this in the keys of pair selections: coarser
than joint_states noise (a selection is reused), fine enough that the sampled pairs still fit the posture."""
_lock = threading.Lock()
_background = True


def build_in_background(on: bool) -> None:
    """Whether a checker's first check leaves missing tables to BUILDER (True, the default: no plan waits
    for a table) or builds them itself before it answers (tests of the tables, benchmarks)."""
    global _background
    _background = bool(on)


def building_in_background() -> bool:
    return _background


class _Stopped(Exception):
    """The process is exiting: a background build gives up."""


class TableBuilder:
    """One daemon thread per process that builds the tables checkers found missing (jobs deduplicated by
    key; per slot — a robot's groups and settings — only the newest waits, so requests whose q_ref keeps
    moving do not queue a build each; at most MAX_JOBS waiting, the oldest dropped). While a plan runs in
    this process (`planning`), it works at most a quarter of the time: the plan keeps the interpreter, a
    table still comes within seconds."""

    MAX_JOBS = 8
    DUTY = 0.25

    def __init__(self) -> None:
        self._start_afresh()
        atexit.register(self.stop)

    def _start_afresh(self) -> None:
        """No job, no thread (also in a forked child: the parent's thread and lock holders are not there)."""
        self._cv = threading.Condition()
        self._jobs: deque[tuple[tuple, tuple, Callable[[], None]]] = deque()  # (key, slot, job)
        self._pending: set[tuple] = set()  # keys queued or running
        self._failed: set[tuple] = set()  # keys whose job raised: not tried again in this process
        self._thread: threading.Thread | None = None
        self._active = 0  # plans running in this process
        self._since = 0.0  # when the builder last paced itself
        self._stopping = False

    def submit(self, key: tuple, slot: tuple, job: Callable[[], None]) -> None:
        """Run job() on the builder thread unless a job of this key is waiting or running (or failed once);
        it replaces a waiting job of the same slot."""
        with self._cv:
            if key in self._pending or key in self._failed or self._stopping:
                return
            for old in [j for j in self._jobs if j[1] == slot]:
                self._jobs.remove(old)
                self._pending.discard(old[0])
            if len(self._jobs) >= self.MAX_JOBS:
                self._pending.discard(self._jobs.popleft()[0])
            self._jobs.append((key, slot, job))
            self._pending.add(key)
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._run, name="pair-tables", daemon=True)
                self._thread.start()
            self._cv.notify_all()

    @property
    def failed(self) -> int:
        """Jobs whose build raised (their keys are not tried again)."""
        return len(self._failed)

    def wait_idle(self, timeout: float) -> bool:
        """Wait until no job waits or runs; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while self._pending:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(left)
        return True

    @contextmanager
    def planning(self) -> Iterator[None]:
        """Mark a plan running in this process (the builder then paces itself)."""
        with self._cv:
            self._active += 1
        try:
            yield
        finally:
            with self._cv:
                self._active -= 1

    def pace(self) -> None:
        """Called by a build between chunks of work: on the builder thread, while a plan runs, sleep three
        times what was worked since the last call (DUTY); raises _Stopped when the process exits."""
        if threading.current_thread() is not self._thread:
            return
        if self._stopping:
            raise _Stopped
        now = time.perf_counter()
        if self._active:
            time.sleep(min(0.2, (now - self._since) * (1 - self.DUTY) / self.DUTY))
        self._since = time.perf_counter()

    def stop(self) -> None:
        """At exit: drop the waiting jobs, make a running one give up."""
        with self._cv:
            self._stopping = True
            self._jobs.clear()
            self._cv.notify_all()

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._jobs and not self._stopping:
                    self._cv.wait()
                if self._stopping:
                    self._pending.clear()
                    self._cv.notify_all()
                    return
                key, _, job = self._jobs.popleft()
            self._since = time.perf_counter()
            try:
                job()
            except _Stopped:
                return
            except Exception:  # noqa: BLE001 - a table is an optimization: a checker without one asks FCL
                with self._cv:
                    self._failed.add(key)
            finally:
                with self._cv:
                    self._pending.discard(key)
                    self._cv.notify_all()


BUILDER = TableBuilder()
"""This process's table builder (CollisionChecker hands it the tables its first check found missing)."""


def _after_fork_in_child() -> None:
    """A child forked while the builder ran has neither its thread nor the locks' holders."""
    global _lock
    _lock = threading.Lock()
    BUILDER._start_afresh()


os.register_at_fork(after_in_child=_after_fork_in_child)


def _cached(cache, key: tuple, make: Callable[[], object], build: bool):
    """cache[key]; when missing, make() outside the lock (a table takes up to a second: checkers of other
    threads only read the cache meanwhile) when build, else None."""
    with _lock:
        if key in cache:
            return cache[key]
    if not build:
        return None
    value = make()
    with _lock:
        cache[key] = value
    return value


def stable_bytes(x: np.ndarray | Sequence[float]) -> bytes:
    """Floats as a cache-key part that is the same on every CPU: rounded to 1e-9 and with -0.0 made 0.0.
    A value that is 0 in exact arithmetic comes out of FK / solve as ±1e-18 depending on the BLAS kernel
    (OpenBLAS Haswell vs SkylakeX), and np.round keeps the sign: without the `+ 0.0` the same geometry
    got a different key (and a 0.7 s table rebuild) on another machine."""
    return (np.round(np.asarray(x, dtype=float), 9) + 0.0).tobytes()


def _selection_q(checker: TableSource) -> bytes:
    """q_ref outside the groups, rounded to SELECTION_RESOLUTION (the groups' joints zeroed), from
    table_q_ref's values: the checker that builds the tables sits there, so the one that asked for them
    finds its selection under the same key. Rounded from q_ref itself, a value that the 1 mrad rounding
    moves across a 0.05 boundary (TALOS's half_sitting: a torso joint at -0.5254) keyed the two apart,
    and the asking checkers never found a table."""
    q = table_q_ref(checker)
    q[checker.joint_indices] = 0.0
    return np.round(q / SELECTION_RESOLUTION).astype(np.int64).tobytes()


@dataclass(frozen=True)
class PairTable:
    """Exact distance lower bound of one unit pair over a grid of its 1–3 relative joints."""

    cols: np.ndarray  # (k,) group configuration columns
    lo: np.ndarray  # (k,) grid origin
    step: np.ndarray  # (k,) grid spacing
    levers: np.ndarray  # (k,) metres per radian (Lipschitz bound per joint)
    dist: np.ndarray  # k-D array of exact distances at the grid points (≤ 0: touching)
    slack: float = 0.0  # subtracted from every bound: how far the checker's own path values may move the pair

    @property
    def nbytes(self) -> int:
        """Size of its arrays (what TableCache counts)."""
        return sum(a.nbytes for a in (self.cols, self.lo, self.step, self.levers, self.dist))

    def lower_bound(self, q: np.ndarray) -> np.ndarray:
        """(N, dof) group configurations → (N,) lower bounds of the pair's distance."""
        x = q[:, self.cols]
        n = np.array(self.dist.shape)
        idx = np.clip(np.rint((x - self.lo) / self.step), 0, n - 1).astype(np.int64)
        delta = np.abs(x - (self.lo + idx * self.step))
        lb = self.dist[tuple(idx.T)] - self.slack - delta @ self.levers
        # the levers hold within the grid (+ half a step): outside the joint limits, prove nothing
        outside = (np.abs(x - (self.lo + (n - 1) * self.step / 2)) > (n - 1) * self.step / 2 + self.step / 2).any(1)
        lb[outside] = -np.inf
        return lb


PATH_RESOLUTION = 1e-3
"""rad (m for prisms): the joints outside the groups are rounded to this where a table is built
(table_q_ref), and a table is keyed by the rounded values on its pair's path. A checker whose own values
lie up to half of it off takes the table with its bound lowered by how far that may move the pair
(path_values' slack: ≤ 0.5 mm × twice the robot's reach per joint, ~1.5 mm per torso joint on TALOS):
joint_states that jitter or drift by less than that (a live or simulated robot) reuse their tables instead
of having every one on the path rebuilt for every plan."""


def table_q_ref(checker: TableSource) -> np.ndarray:
    """The q_ref tables are built at: the checker's, with the joints outside its groups rounded to
    PATH_RESOLUTION."""
    q = checker.q_ref.copy()
    out = np.ones(len(q), dtype=bool)
    out[checker.joint_indices] = False
    q[out] = np.round(q[out] / PATH_RESOLUTION) * PATH_RESOLUTION
    return q


def path_values(checker: TableSource, link_a: str, link_b: str) -> tuple[bytes, float]:
    """(key part, slack) of the joints outside the groups on the tree path between two links: with the
    groups, all a pair table's distance function depends on. Only those, not all of q_ref, key a table,
    so a live robot whose other arm or legs moved (or whose joint_states are noisy off the path) reuses
    its tables instead of rebuilding them (TALOS l_arm: 1.7-2.6 s per table set) in every plan. The key
    holds the values rounded to PATH_RESOLUTION; slack bounds how far the checker's own values move either
    link relative to the other from there (a point moves at most its distance from a revolute joint's
    axis, ≤ 2 · collision_model.reach, per radian; a prismatic joint's offset itself)."""
    robot = checker.robot
    chains = [robot.chain_joints(robot.root_link, link) for link in (link_a, link_b)]
    names = [{j.name for j in c} for c in chains]
    joints = {j.name: j for c in chains for j in c}
    group = set(checker.joint_names)
    index = {n: i for i, n in enumerate(robot.joint_names)}
    path = sorted(n for n in names[0] ^ names[1] if n in index and n not in group)
    v = np.array([checker.q_ref[index[n]] for n in path], dtype=float)
    vq = np.round(v / PATH_RESOLUTION) * PATH_RESOLUTION
    per = np.array([1.0 if joints[n].type == "prismatic" else 2.0 * checker.collision_model.reach for n in path])
    return stable_bytes(vq) + "|".join(path).encode(), float(np.abs(v - vq) @ per) if len(path) else 0.0


def pair_key(checker: TableSource, p: int) -> tuple[tuple, float]:
    """Everything that fixes pair p's table: groups, q_ref outside the groups on the path between the
    two links (path_values), both units' link names and shape offsets in their frames, the grid; and the
    checker's slack for it (path_values)."""
    q, slack = path_values(checker, checker.levels.units[checker.levels.self_s[p]],
                           checker.levels.units[checker.levels.self_o[p]])
    sides = tuple(sorted(_unit_key(checker, u) for u in (checker.levels.self_s[p], checker.levels.self_o[p])))
    return (checker.groups, q, sides, GRID_1D, GRID_2D), slack


def _gather(cache, entries: Iterator[tuple[object, tuple, float, Callable[[], PairTable]]],
            build: bool) -> tuple[dict, bool]:
    """The tables of entries (name, cache key, the checker's slack, how to build one) as one checker reads
    them — name → table, its bound lowered by the slack (path_values) — and whether none is missing; build:
    make the missing ones (_cached)."""
    out, complete = {}, True
    for name, key, slack, make in entries:
        tab = _cached(cache, key, make, build)
        if tab is None:
            complete = False
        else:
            out[name] = tab if slack == 0.0 else replace(tab, slack=slack)
    return out, complete


def _unit_key(checker: TableSource, u: int) -> tuple:
    """A moving unit's part of a table key: its link and its shapes' offsets in their frames."""
    shapes = _unit_shapes(checker, u)
    return checker.levels.units[u], stable_bytes(checker.levels.shape_R[shapes]), stable_bytes(checker.levels.shape_t[shapes])


def _sample_q(checker: TableSource) -> np.ndarray:
    """The seeded SAMPLE random configurations the pair selections test."""
    lo, hi = checker.robot.lower[checker.joint_indices], checker.robot.upper[checker.joint_indices]
    return np.random.default_rng(0).uniform(lo, hi, size=(SAMPLE, checker.dof))


def _sample(checker: TableSource) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeded SAMPLE random configurations the pair selections test: frames (R, t) and the
    units' bounding-sphere centres B, as level 1 takes them.

    Rounded to 1e-9 so that the FK's last-bit differences between CPUs / BLAS kernels do not reach the
    level tests: the selection then differs between machines only where a sampled sphere distance lies
    within rounding of its threshold (a different choice of tables, i.e. speed, never a verdict)."""
    R, t = checker.levels.fk(_sample_q(checker))
    R, t = np.round(R, 9) + 0.0, np.round(t, 9) + 0.0
    f = checker.levels.unit_frame
    return R, t, np.round(np.matmul(R[:, f], checker.levels.bound_c[:, :, None])[..., 0] + t[:, f], 9) + 0.0


def select_pairs(checker: TableSource) -> list[tuple[int, np.ndarray]]:
    """(pair, relative joint columns) of the self pairs worth a table: 1–3 relative joints, a mesh
    on either side, both sides robot links, and sent to FCL in ≥ MIN_SHARE of a seeded sample or flagged
    by level 1 in ≥ FLAG_SHARE of it (three joints: ≥ FLAG3_SHARE)."""
    cand = []
    links = checker.collision_model.links
    for p, (a, b) in enumerate(zip(checker.levels.self_s, checker.levels.self_o)):
        cols = np.nonzero(checker.levels.pair_levers[p])[0]
        if not 1 <= len(cols) <= TABLE_JOINTS:
            continue
        if checker.levels.units[a] not in links or checker.levels.units[b] not in links:
            continue  # attached objects change per request
        shapes = [m for u in (a, b) for m in checker.levels.unit_shape_tab[u] if m >= 0]
        if any(checker.levels.shape_kind[m] == "mesh" for m in shapes):
            cand.append((p, cols))
    if not cand:
        return []
    R, t, B = _sample(checker)
    flagged = checker.levels.level1_self(R, t, B)
    P = len(checker.levels.self_s)
    if checker.levels.use_compiled:
        n, _, _, pp = checker.levels.compiled_12(_sample_q(checker), None, None)[4]
        flags = np.bincount(flagged[1], minlength=P)  # one entry per (configuration, pair)
    else:
        n, _, _, pp = checker.levels.level2_self(R, t, *flagged)
        flags = np.zeros(P)
    hits = np.zeros(P)
    if len(n):
        uniq = np.unique(np.stack([n, pp], 1), axis=0)
        np.add.at(hits, uniq[:, 1], 1)
    return [(p, cols) for p, cols in cand
            if (flags[p] >= FLAG3_SHARE * SAMPLE if len(cols) == 3
                else hits[p] >= MIN_SHARE * SAMPLE or flags[p] >= FLAG_SHARE * SAMPLE)]


def _unit_shapes(checker: TableSource, u: int) -> list[int]:
    return [int(m) for m in checker.levels.unit_shape_tab[u] if m >= 0]


def build_table(checker: TableSource, p: int, cols: np.ndarray) -> PairTable:
    """Exact FCL distance of self pair p over the grid of its relative joints `cols`."""
    a, b = checker.levels.self_s[p], checker.levels.self_o[p]
    return _grid_table(checker, cols, _unit_shapes(checker, a), [checker.levels.moving[y].obj for y in _unit_shapes(checker, b)],
                       _unit_shapes(checker, b), (a, b), checker.levels.pair_levers[p][cols].copy())


def build_env_table(checker: TableSource, u: int, e: int, cols: np.ndarray) -> PairTable:
    """Exact FCL distance of moving unit u to fixed link body e over the grid of u's joints `cols`."""
    return _grid_table(checker, cols, _unit_shapes(checker, u), [checker.levels.fixed[e].obj], [], (u,),
                       checker.unit_levers[u][cols].copy())


def _grid_table(checker: TableSource, cols: np.ndarray, side_a: list[int], side_b: list, moving_b: list[int],
                units: tuple[int, ...], loose: np.ndarray) -> PairTable:
    """Min FCL distance between moving shapes side_a and the bodies side_b (moving_b: those of them
    that are moving shapes, placed per grid point) over the grid of joints `cols`, q_ref elsewhere."""
    lo_lim = checker.robot.lower[checker.joint_indices][cols]
    hi_lim = checker.robot.upper[checker.joint_indices][cols]
    size = GRID_1D if len(cols) == 1 else GRID_2D if len(cols) == 2 else GRID_3D
    axes = [np.linspace(lo, hi, size) for lo, hi in zip(lo_lim, hi_lim)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(cols))
    q = np.tile(checker.q_ref[checker.joint_indices], (len(grid), 1))
    q[:, cols] = grid
    R, t = checker.levels.fk(q)
    lv = checker.levels
    spheres = [m for m in side_a if lv.shape_kind[m] == "sphere"]
    if len(spheres) == len(side_a) and moving_b and len(moving_b) == len(side_b) and all(
            lv.shape_kind[m] == "sphere" for m in moving_b):  # spheres only (a spherized arm): no FCL call
        return PairTable(cols, lo_lim.copy(), _step(lo_lim, hi_lim, size),
                         axis_levers(checker, units, loose, cols, R, t, _step(lo_lim, hi_lim, size)),
                         _sphere_distances(checker, R, t, side_a, moving_b).reshape((size,) * len(cols)))
    req = fcl.DistanceRequest()
    dist = np.empty(len(grid))
    for g in range(len(grid)):
        if g % 32 == 0:
            BUILDER.pace()
        for m in (*side_a, *moving_b):
            fr = checker.levels.frame_of[m]
            obj = checker.levels.moving[m].obj
            obj.setRotation(R[g, fr] @ checker.levels.shape_R[m])
            obj.setTranslation(R[g, fr] @ checker.levels.shape_t[m] + t[g, fr])
        d = np.inf
        for x in side_a:
            for y in side_b:
                d = min(d, fcl.distance(checker.levels.moving[x].obj, y, req, fcl.DistanceResult()))
        dist[g] = max(d, 0.0)
    step = _step(lo_lim, hi_lim, size)
    return PairTable(cols, lo_lim.copy(), step, axis_levers(checker, units, loose, cols, R, t, step),
                     dist.reshape((size,) * len(cols)))


def _step(lo_lim: np.ndarray, hi_lim: np.ndarray, size: int) -> np.ndarray:
    return np.array([(hi - lo) / (size - 1) if size > 1 else 1.0 for lo, hi in zip(lo_lim, hi_lim)])


def _sphere_distances(checker: TableSource, R: np.ndarray, t: np.ndarray, side_a: list[int], side_b: list[int]
                      ) -> np.ndarray:
    """(G,) least distance between the sphere shapes side_a and side_b at each grid frame (R, t), ≥ 0:
    |c_a − c_b| − r_a − r_b, what FCL returns for two spheres, without an FCL call per pair."""
    lv = checker.levels

    def centres(ms: list[int]) -> np.ndarray:  # (G, k, 3)
        f = lv.frame_of[ms]
        return np.matmul(R[:, f], lv.shape_t[ms][:, :, None])[..., 0] + t[:, f]

    ca, cb = centres(side_a), centres(side_b)
    d = np.linalg.norm(ca[:, :, None, :] - cb[:, None, :, :], axis=-1)
    d -= lv.sbox_rho[side_a][None, :, None] + lv.sbox_rho[side_b][None, None, :]
    return np.maximum(d.reshape(len(d), -1).min(axis=1), 0.0)


def axis_levers(checker: TableSource, units: tuple[int, ...], loose: np.ndarray, cols: np.ndarray, R: np.ndarray,
                t: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Lipschitz bound per relative joint, tighter than the checker's unit levers (`loose`: distance
    from the joint *origin*, through the chain): the largest distance of the moved unit's cover
    spheres from the joint *axis* over the grid (R, t: its frames), plus how far that distance may
    grow between grid points as the other relative joint moves (its loose lever × half a step).
    Never above the loose lever; prismatic joints keep it (1 m per m). units: the pair's moving
    units (one for a unit against a fixed link, those of two clusters for a cluster pair); the reach
    is the largest of the units joint j levers."""
    out = loose.copy()
    frames = checker.levels.fk.frames
    for i, j in enumerate(cols):
        k = next(k for k, fr in enumerate(frames) if fr.column == j)
        if frames[k].prismatic:
            continue
        axis = R[:, k] @ frames[k].axis  # (G, 3) world
        reach = 0.0
        for u in (u for u in units if checker.unit_levers[u, j] > 0):
            cnt = checker.levels.outer.counts[u]
            f = checker.levels.unit_frame[u]
            C = checker.levels.outer.centers[u, :cnt] @ R[:, f].transpose(0, 2, 1) + t[:, f][:, None, :]  # (G, S, 3)
            v = C - t[:, k][:, None, :]
            radial = v - np.einsum("gs,gi->gsi", np.einsum("gsi,gi->gs", v, axis), axis)
            reach = max(reach, float((np.linalg.norm(radial, axis=-1) + checker.levels.outer.radii[u, :cnt]).max()))
        slack = sum(loose[o] * step[o] / 2 for o in range(len(cols)) if o != i)
        out[i] = min(loose[i], reach + slack)
    return out


def tables_for(checker: TableSource, build: bool = True) -> tuple[dict[int, PairTable], bool]:
    """Pair index → table, for the checker's pairs worth one (built once per robot and geometry), and
    whether none is missing; build False: only those built already."""
    cache = checker.collision_model.pair_tables
    chosen = ("selection", checker.groups, _selection_q(checker), tuple(checker.levels.units), tuple(checker.levels.self_s),
              tuple(checker.levels.self_o), checker.self_padding, checker.margin, checker.cross_groups_only,
              checker.levels.use_compiled)  # what reaches FCL depends on the levels
    # the sample costs ~20-50 ms: once per group setup, not per plan
    selection = _cached(cache, chosen, lambda: select_pairs(checker), build)
    if selection is None:
        return {}, False
    return _gather(cache, ((p, *pair_key(checker, p), lambda p=p, cols=cols: build_table(checker, p, cols))
                           for p, cols in selection), build)


def cluster_candidates(checker: TableSource) -> list[tuple[int, np.ndarray, list[int], list[int]]]:
    """(cluster pair, relative joint columns, units of each side) of level 1's cluster pairs
    (CompiledPairs.build_clusters) over two or more unit pairs, moved relative to each other by 1–2
    joints, robot links on both sides: one table then clears all their unit pairs at once."""
    lv = checker.levels
    if lv.cl_self is None:
        return []
    links = checker.collision_model.links
    out = []
    for g, (first, count) in enumerate(zip(lv.cl_self.start.tolist(), lv.cl_self.count.tolist())):
        members = lv.cl_self.members[first:first + count]
        cols = np.nonzero(lv.pair_levers[members].max(axis=0))[0]
        side_a, side_b = sorted(set(lv.self_s[members].tolist())), sorted(set(lv.self_o[members].tolist()))
        if count >= 2 and 1 <= len(cols) <= 2 and all(lv.units[u] in links for u in side_a + side_b):
            out.append((g, cols, side_a, side_b))
    return out


def cluster_tables_for(checker: TableSource, build: bool = True) -> tuple[dict[int, PairTable], bool]:
    """Cluster pair → table, for the cluster pairs that touch in ≥ FLAG_SHARE of the seeded sample (the
    compiled levels then visit their unit pairs one by one: a spherized Panda's link5 spheres against those
    of link7 and the hand, 270 unit pairs, in every configuration), and whether none is missing. The
    distance is the least over all shape pairs of the two sides, the allowed ones among them included: a
    lower bound for each. build False: only those built already."""
    lv = checker.levels
    if not lv.use_compiled:
        return {}, True
    cand = cluster_candidates(checker)
    if not cand:
        return {}, True
    cache = checker.collision_model.pair_tables
    chosen = ("cluster-selection", checker.groups, _selection_q(checker), tuple(lv.units), tuple(lv.self_s),
              tuple(lv.self_o), tuple(lv.cl_self.keys), checker.self_padding, checker.margin)

    def select() -> list:
        R, t, _ = _sample(checker)
        BC = lv.cluster_spheres(R, t)
        d = BC[:, lv.cl_self_a] - BC[:, lv.cl_self_b]
        share = (np.einsum("nki,nki->nk", d, d) < lv.cl_self_thr2).mean(axis=0)
        return [c for c in cand if share[c[0]] >= FLAG_SHARE]

    def make(g: int, cols: np.ndarray, side_a: list[int], side_b: list[int]) -> PairTable:
        members = lv.cl_self.members[lv.cl_self.start[g]:lv.cl_self.start[g] + lv.cl_self.count[g]]
        shapes_b = [m for u in side_b for m in _unit_shapes(checker, u)]
        return _grid_table(checker, cols, [m for u in side_a for m in _unit_shapes(checker, u)],
                           [lv.moving[m].obj for m in shapes_b], shapes_b, tuple(side_a + side_b),
                           lv.pair_levers[members][:, cols].max(axis=0))

    selection = _cached(cache, chosen, select, build)
    if selection is None:
        return {}, False
    def entries():
        for g, cols, side_a, side_b in selection:
            path, slack = path_values(checker, lv.units[side_a[0]], lv.units[side_b[0]])
            key = ("cluster", checker.groups, path, tuple(_unit_key(checker, u) for u in side_a),
                   tuple(_unit_key(checker, u) for u in side_b), GRID_1D, GRID_2D)
            yield g, key, slack, lambda g=g, cols=cols, a=side_a, b=side_b: make(g, cols, a, b)

    return _gather(cache, entries(), build)


def env_candidates(checker: TableSource) -> list[tuple[int, int, np.ndarray]]:
    """(unit, fixed body, joint columns) of unit–fixed-link pairs in reach that a table could decide:
    1–2 group joints move the unit, both sides robot links (attached objects and the scene change
    per request), a mesh on either side."""
    links = checker.collision_model.links
    out = []
    for u, e in zip(checker.levels.env_u.tolist(), checker.levels.env_e.tolist()):
        body = checker.levels.fixed[e]
        if not body.is_link or body.name not in links or checker.levels.units[u] not in links:
            continue
        cols = np.nonzero(checker.unit_levers[u])[0]
        if not 1 <= len(cols) <= 2:
            continue
        if checker.levels.f_has_cover[e] or any(checker.levels.shape_kind[m] == "mesh" for m in _unit_shapes(checker, u)):
            out.append((u, e, cols))
    return out


def select_env_pairs(checker: TableSource, cand: list[tuple[int, int, np.ndarray]]) -> list[tuple[int, int, np.ndarray]]:
    """The candidates the covers send to FCL in ≥ MIN_SHARE of a seeded sample or, with the compiled levels,
    that level 1 flags in ≥ FLAG_SHARE of it (as select_pairs: the kernel's cover and hull tests of a pair
    flagged in every configuration cost more than the table's lookup; TALOS l_arm's arm_left_2 against
    torso_2, decided by the hulls and flagged in every configuration, had no table)."""
    R, t, B = _sample(checker)
    flagged = checker.levels.level1_env(R, t, B)
    if checker.levels.use_compiled:
        n, m, e = checker.levels.compiled_12(_sample_q(checker), None, None)[3]
    else:
        n, m, e = checker.levels.level2_env(R, t, *flagged)
    hits = _configurations_per_pair(n, checker.levels.unit_of_shape[m], e)
    flags = _configurations_per_pair(*flagged) if checker.levels.use_compiled else {}
    return [(u, e, cols) for u, e, cols in cand
            if hits.get((u, e), 0) >= MIN_SHARE * SAMPLE or flags.get((u, e), 0) >= FLAG_SHARE * SAMPLE]


def _configurations_per_pair(n: np.ndarray, u: np.ndarray, e: np.ndarray) -> dict[tuple[int, int], int]:
    """(configuration, unit, fixed body) entries → (unit, body): how many configurations hold one."""
    if len(n) == 0:
        return {}
    pairs, count = np.unique(np.unique(np.stack([n, u, e], 1), axis=0)[:, 1:], axis=0, return_counts=True)
    return {(int(a), int(b)): int(c) for (a, b), c in zip(pairs, count)}


def env_tables_for(checker: TableSource, build: bool = True) -> tuple[dict[tuple[int, int], PairTable], bool]:
    """(unit, fixed body) → table, for the checker's unit–fixed-link pairs worth one: the fixed link
    sits at q_ref, so the pair's distance is a function of the 1–2 joints moving the unit (TALOS l_arm:
    arm_left_2 against torso_2 reached FCL in 99 % of random configurations), and whether none is
    missing. build False: only those built already."""
    cand = env_candidates(checker)
    if not cand:
        return {}, True
    cache = checker.collision_model.pair_tables
    chosen = ("env-selection", checker.groups, _selection_q(checker), tuple(checker.levels.units),
              tuple((u, e) for u, e, _ in cand), checker.self_padding, checker.margin, checker.levels.use_compiled)
    # scene bodies play no part: once per group setup, not per scene
    selection = _cached(cache, chosen, lambda: select_env_pairs(checker, cand), build)
    if selection is None:
        return {}, False
    def entries():
        for u, e, cols in selection:
            body = checker.levels.fixed[e]
            T_link = checker.robot.link_poses(checker.q_ref, [body.name])[0]
            path, slack = path_values(checker, checker.levels.units[u], body.name)
            key = ("env", checker.groups, path, *_unit_key(checker, u), body.name,
                   stable_bytes(np.linalg.solve(T_link, body.offset)), GRID_1D, GRID_2D)
            yield (u, e), key, slack, lambda u=u, e=e, cols=cols: build_env_table(checker, u, e, cols)

    return _gather(cache, entries(), build)
