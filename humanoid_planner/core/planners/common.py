"""What every planner shares: options, the termination condition, the result, the search tree.

Split the way OMPL splits it: the problem (robot, group, checker, grasp targets) is built by the
caller, the planner only searches, and a `Termination` (deadline, cancel flag, cycle budget) says
when to give up.
"""
from __future__ import annotations

import enum
import math
import threading
import time
from dataclasses import dataclass, field, fields
from typing import Generic, TypeVar

import numpy as np

from humanoid_planner.core.grasp.quality import DEFAULT_CONE_EDGES
from humanoid_planner.core.planners import kernels as search_kernels
from humanoid_planner.core.scene.types import GraspSpec

T = TypeVar("T")


class PlanStatus(enum.Enum):
    """Outcome classes; the ROS layer maps them to moveit-style ErrorCode values."""

    SUCCESS = "success"
    PLANNING_FAILED = "planning_failed"
    TIMED_OUT = "timed_out"
    CANCELLED = "cancelled"
    START_IN_COLLISION = "start_in_collision"
    NO_IK_SOLUTION = "no_ik_solution"
    GRASP_QUALITY_TOO_LOW = "grasp_quality_too_low"
    INVALID_REQUEST = "invalid_request"  # e.g. unknown planner name
    INVALID_GROUP = "invalid_group"
    INVALID_START = "invalid_start"
    INVALID_GOAL = "invalid_goal"
    INVALID_OBJECT = "invalid_object"
    INVALID_FRAME = "invalid_frame"  # a frame that is neither the planning frame nor a robot link
    INTERNAL_ERROR = "internal_error"  # e.g. DAGRRT's arm process died mid-plan: not the request's fault


@dataclass(frozen=True)
class OptionRange:
    """The values an option accepts: lo <= value <= hi (the node declares them as ROS parameter ranges)."""

    lo: float
    hi: float
    description: str

    def check(self, name: str, value) -> None:
        """Raise ValueError naming the option and its range when `value` is outside it (NaN included)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not self.lo <= value <= self.hi:
            raise ValueError(f"{name} must be in [{self.lo:g}, {self.hi:g}] ({self.description}), got {value!r}")


def _option(default, lo: float, hi: float, description: str):
    """A PlannerOptions field with its range and description: the one place both are written."""
    return field(default=default, metadata={"range": OptionRange(lo, hi, description)})


@dataclass
class PlannerOptions:
    """Tunables of all planners; the defaults are the papers' where they give one (the GIRRT and DAGRRT papers: "GIRRT Motion
    Planning Algorithm for Humanoid Robot"; "Parallel Algorithm for Collision Avoidance Motion
    Planning of Dual Arm Grasping of Humanoid Robot"). Fields with a range (`option_ranges`) are the
    node's parameters of the same name; `validate` checks them."""

    f_extend: float = _option(0.3, 0.0, 1.0, "probability of a goal (grasp) extension per cycle (GIRRT and DAGRRT papers)")
    max_cycles: int = _option(40000, 1, 100_000_000, "RRT iterations before a plan gives up (MaxCycles of the GIRRT and DAGRRT papers)")
    joint_step: float = _option(0.1, 0.001, 3.14, "rad, joint-space Connect step between tree nodes")
    tcp_step_pos: float = _option(0.02, 0.0001, 0.5, "m, TCP translation step when extending to a grasp")
    tcp_step_rot: float = _option(0.1, 0.001, 3.14, "rad, TCP rotation step when extending to a grasp")
    max_joint_step: float = 0.1  # rad, largest joint change of one Jacobian step
    goal_tolerance_pos: float = _option(0.002, 0.00001, 0.1, "m, position tolerance of a reached grasp")
    goal_tolerance_rot: float = _option(0.0174, 0.0001, 0.5, "rad, orientation tolerance of a reached grasp (1 deg)")
    max_approach_steps: int = 60  # Jacobian steps per approach before giving up on it
    nullspace_gain: float = 0.0  # the GIRRT paper eq. 24 joint-limit gradient projected into the null space
    restart_cycles: int = 150  # re-root the tree after this many cycles without a grasp (0 = never, as in the papers)
    dual_inverse: str = "svd"  # DAGRRT's per-arm generalized inverse: the DAGRRT paper's damped SVD, or "wln"
    goal_bias: float = 0.1  # goal-biased RRT baseline
    # RRT-Connect's dynamic domain (Yershova et al. 2005): a node whose extension was blocked only takes
    # samples within this radius (rad) of it, so the search stops drawing towards walls it stands at
    # (0 = off: the plain RRT-Connect of scenarios.reference_plan). 0.5 rather than 1.0: MotionBenchMaker's
    # Fetch cage, 40 GIRRT runs (problems 1-4, 10 seed offsets, 10 s of CPU) 30 solved instead of 27, mean
    # CPU 5.7 vs 6.4 s (TIAGo + torso cage: 10 vs 9 of 12, 4.5 vs 5.9 s); 2.0 solved 6 of 12, 0.25 31 of
    # 40. Fetch shelf and box, Panda cage and shelf: alike within the spread between seeds (docs/PLANNERS.md)
    dynamic_domain: float = 0.5
    # GIRRT/GRRT: failed approaches (blocked by an obstacle or stalled at a limit) before IK solutions of
    # the grasps are solved for: tried straight from the start, then a goal tree (0 = from the start, None = never).
    # 0 because the straight motion to a hint solves most problems at once (20 boxes6 problems, paired medians
    # against 2: armar3 15 vs 38 ms, G1 16 vs 107 ms; TALOS table_shelf 144 vs 195 ms)
    ik_hint_after: int | None = 0
    dual_ik_hint_after: int | None = 0  # the same for DAGRRT's arms: two-handed grasp poses mostly stall the approach from home
    # ... then this share of the start tree's Connect samples is an IK solution instead of a uniform draw
    # (0.2 against 0.5 with the goal tree: TALOS table_shelf mean 3.0k vs 4.5k checks per plan, presets neutral)
    ik_hint_bias: float = 0.2
    ik_hint_seeds: int = 8  # IK starts per grasp for those hints
    ik_seeds: int = 32  # seeds per grasp for the batched multi-start IK
    max_goal_configs: int = 16  # baselines: goal configurations taken from IK
    min_grasp_score: float = _option(0.001, 0.0, 100.0, "dual-arm gs_min (epsilon quality) when a request gives <= 0")
    friction: float = _option(0.5, 0.001, 10.0, "Coulomb friction of grasp contacts when a grasp gives 0")
    cone_edges: int = DEFAULT_CONE_EDGES  # friction-pyramid edges in GraspScore (grasp/quality.py says why 4)
    min_contacts_per_hand: int = 1
    smoothing_max_iterations: int = 6  # random shortcuts after the greedy pass
    max_point_motion: float = 0.015  # m: no robot point moves more between two checked samples (geometry padded by half)
    collision_padding: float = _option(0.0, 0.0, 0.5, "m, added around the robot's collision geometry")
    edge_resolution: float = _option(0.02, 0.001, 1.0, "rad, largest joint step between collision checks along an edge")
    seed: int | None = None

    def validate(self) -> "PlannerOptions":
        """Self, or ValueError naming the first option outside its range."""
        for name, spec in option_ranges().items():
            spec.check(name, getattr(self, name))
        return self


def option_ranges() -> dict[str, OptionRange]:
    """PlannerOptions fields that have a range (in declaration order) -> the range."""
    return {f.name: f.metadata["range"] for f in fields(PlannerOptions) if "range" in f.metadata}


def substream(seed, stream: int):
    """Seed of an independent generator derived from `seed` (an int, a list of ints, or None: then
    None, i.e. fresh entropy); the same (seed, stream) always gives the same generator."""
    return None if seed is None else [*np.atleast_1d(seed).tolist(), stream]


class Progress:
    """Live figures of one plan, for a caller that reports progress while it runs (the node's action
    feedback). The planning thread(s) write them, any thread reads them; no lock: every update is one
    assignment (a reader may see figures a cycle apart). Arms searched in another process (DAGRRT's
    arm process) do not report here."""

    PHASES = ("queued", "searching", "shortcutting", "timing")

    def __init__(self) -> None:
        self.phase = "queued"
        self.iterations = 0  # search cycles of all arms so far
        self.solutions = 0  # grasps reached so far
        self._best: dict[str, float] = {}  # arm (group name) -> closest its tree's TCP came to any grasp target, m

    def tcp_distance(self, arm: str, distance: float) -> None:
        """An arm's tree reached a TCP `distance` m from a grasp target."""
        if distance < self._best.get(arm, math.inf):
            self._best[arm] = distance

    def state(self) -> tuple:
        """Its figures as plain values: a plan in a worker process sends them to the node's Progress (`load`)."""
        return self.phase, self.iterations, self.solutions, dict(self._best)

    def load(self, state: tuple) -> None:
        """Take the figures of `state()` (one assignment each, as the planners' own updates)."""
        self.phase, self.iterations, self.solutions, best = state
        self._best = dict(best)

    @property
    def best_tcp_distance(self) -> float:
        """m: the closest any tree's TCP came to a grasp target (dual: the larger of the arms'); inf before."""
        best = list(self._best.values())
        return max(best) if best else math.inf


class Termination:
    """Cooperative stop: a deadline, an external cancel event and a cycle budget; `progress` (optional)
    is where the plan reports its phase."""

    def __init__(self, timeout: float, cancel: threading.Event | None = None, max_cycles: int | None = None,
                 progress: Progress | None = None):
        self.start = time.perf_counter()
        self.deadline = self.start + timeout
        self.cancel = cancel if cancel is not None else threading.Event()
        self.max_cycles = max_cycles
        self.progress = progress

    def phase(self, name: str) -> None:
        """Report the plan's phase (one of Progress.PHASES) to whoever watches it."""
        if self.progress is not None:
            self.progress.phase = name

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def remaining(self) -> float:
        return self.deadline - time.perf_counter()

    def expired(self) -> bool:
        return time.perf_counter() >= self.deadline

    def should_stop(self, cycles: int = 0) -> bool:
        return (self.cancel.is_set() or time.perf_counter() >= self.deadline
                or (self.max_cycles is not None and cycles >= self.max_cycles))

    def stop_status(self) -> PlanStatus:
        if self.cancel.is_set():
            return PlanStatus.CANCELLED
        if self.expired():
            return PlanStatus.TIMED_OUT
        return PlanStatus.PLANNING_FAILED


@dataclass(frozen=True)
class GraspTarget:
    """A grasp of the set with its TCP target pose in the planning frame."""

    index: int
    grasp: GraspSpec
    T_target: np.ndarray  # 4x4


class Verdict(enum.Enum):
    """What a hook decided about one candidate (a reached grasp, a pair, a straight line)."""

    ACCEPTED = "accepted"
    RETRY = "retry"  # not as it is, but the outcome's value (e.g. a nearer pre-grasp target) is worth a try
    REJECTED = "rejected"


@dataclass(frozen=True)
class Outcome(Generic[T]):
    """A hook's answer: its verdict, why (for a failure message), and what it produced — the accepted
    result, or for RETRY the replacement to try. One type for every hook, so no caller tells success
    from failure by the type of what came back."""

    verdict: Verdict
    reason: str = ""
    value: T | None = None

    @property
    def ok(self) -> bool:
        return self.verdict is Verdict.ACCEPTED

    @classmethod
    def accepted(cls, value: T | None = None) -> "Outcome[T]":
        return cls(Verdict.ACCEPTED, "", value)

    @classmethod
    def rejected(cls, reason: str) -> "Outcome[T]":
        return cls(Verdict.REJECTED, reason)

    @classmethod
    def retry(cls, value: T, reason: str) -> "Outcome[T]":
        return cls(Verdict.RETRY, reason, value)


@dataclass
class PlanResult:
    """A planner's answer: a geometric path of group configurations (not yet timed)."""

    status: PlanStatus
    message: str = ""
    path: np.ndarray | None = None  # (M, n), path[0] = start, path[-1] reaches the grasp
    target: GraspTarget | None = None
    iterations: int = 0
    tree_size: int = 0
    planning_time: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status is PlanStatus.SUCCESS


class Tree:
    """An RRT in a group's joint space, with TCP poses kept for goal-directed nearest queries.

    Nearest neighbour is brute force argmin(|x|² - 2X·q), compiled (planners/kernels.py): faster than a k-d
    tree below ~40k nodes (measured for this project: benchmarks/bench_kinematics.py) and it appends
    without rebuilding.
    """

    def __init__(self, q_root: np.ndarray, T_root: np.ndarray | None = None, capacity: int = 1024):
        n = len(q_root)
        self.q = np.empty((capacity, n))
        self.qT = np.empty((n, capacity))  # q by joint: the nearest-neighbour loops run along the nodes (SIMD)
        self.sq = np.empty(capacity)  # |q|² cache for the nearest-neighbour trick
        self.parent = np.empty(capacity, dtype=np.int64)
        self.root = np.empty(capacity, dtype=np.int64)  # index of each node's root (a tree may have several)
        self.tcp_pos = np.empty((capacity, 3))
        self.tcp_rot = np.empty((capacity, 3, 3))
        self.fails = np.zeros(capacity, dtype=np.int64)  # RC-RRT: failed expansions per node
        self.domain = np.full(capacity, np.inf)  # dynamic-domain radius per node (inf: not yet blocked)
        # may the node be a tight motion end (MotionValidator.free_prefix)? Roots (the start, IK
        # solutions) and nodes reached from one through samples that keep no margin
        self.tight = np.zeros(capacity, dtype=bool)
        self.size = 0
        self.add(q_root[None, :], -1, None if T_root is None else T_root[None])

    def _grow(self, need: int) -> None:
        cap = len(self.q)
        if self.size + need <= cap:
            return
        new = max(2 * cap, self.size + need)
        for name in ("q", "sq", "parent", "root", "tcp_pos", "tcp_rot", "fails", "tight", "domain"):
            old = getattr(self, name)
            arr = np.full((new,) + old.shape[1:], np.inf if name == "domain" else 0, dtype=old.dtype)
            arr[: self.size] = old[: self.size]
            setattr(self, name, arr)
        qT = np.empty((self.qT.shape[0], new))
        qT[:, :self.size] = self.qT[:, :self.size]
        self.qT = qT

    def add(self, qs: np.ndarray, parent: int, T: np.ndarray | None = None, tight: np.ndarray | None = None) -> int:
        """Append a chain of configurations (each the parent of the next); returns the last index.
        parent = -1 starts a new root (a forest: e.g. one root per goal configuration), which may be
        tight; tight (k,) marks the other nodes that may be."""
        k = len(qs)
        if k == 0:
            return parent
        self._grow(k)
        s = self.size
        self.q[s:s + k] = qs
        self.qT[:, s:s + k] = qs.T
        self.sq[s:s + k] = np.einsum("ij,ij->i", qs, qs)
        self.parent[s] = parent
        self.parent[s + 1:s + k] = np.arange(s, s + k - 1)
        self.root[s:s + k] = s if parent < 0 else self.root[parent]
        self.tight[s:s + k] = False if tight is None else tight
        self.tight[s] |= parent < 0
        if T is not None:
            self.tcp_pos[s:s + k] = T[:, :3, 3]
            self.tcp_rot[s:s + k] = T[:, :3, :3]
        self.size = s + k
        return s + k - 1

    def nearest(self, q: np.ndarray) -> int:
        return int(search_kernels.nearest_rows(self.qT, self.sq, self.size, _rows(q))[0])

    def nearest_in_domain(self, Q: np.ndarray) -> tuple[int, int]:
        """(k, i): the first row k of Q (M, n) that lies within the dynamic-domain radius of its nearest
        node i, else the last row and its nearest node; rows after k are not queried."""
        k, i = search_kernels.first_in_domain(self.qT, self.sq, self.domain, self.size, _rows(Q))
        return int(k), int(i)

    def nearest_tcp(self, T_target: np.ndarray, rot_weight: float = 0.1, fail_penalty: float = 0.05) -> int:
        """Node whose TCP is closest to a target pose: metres + rot_weight · rotation angle.

        Each failed approach from a node adds fail_penalty metres to it, so a node that is close
        but blocked (an obstacle or a joint limit in the way) stops being picked again and again —
        the papers always take the nearest node, which can stall a search on one bad node.
        """
        n = self.size
        dp = np.linalg.norm(self.tcp_pos[:n] - T_target[:3, 3], axis=1)
        tr = np.einsum("kij,ij->k", self.tcp_rot[:n], T_target[:3, :3])
        ang = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
        return int(np.argmin(dp + rot_weight * ang + fail_penalty * self.fails[:n]))

    def cut(self, i: int) -> None:
        """Take node i and every node below it out of the nearest-neighbour queries (a lazy search's
        edge into i failed validation: they are reached through it only). Indices stay as they are."""
        dead = np.zeros(self.size, dtype=bool)
        dead[i] = True
        for j in range(i + 1, self.size):  # a child comes after its parent
            dead[j] = self.parent[j] >= 0 and dead[self.parent[j]]
        self.sq[:self.size][dead] = np.inf

    def path_indices(self, i: int) -> np.ndarray:
        """Node indices from node i's root to node i."""
        idx = []
        while i >= 0:
            idx.append(i)
            i = int(self.parent[i])
        return np.array(idx[::-1], dtype=np.int64)

    def path_to(self, i: int) -> np.ndarray:
        return self.q[self.path_indices(i)].copy()


def _rows(q: np.ndarray) -> np.ndarray:
    """q as the (M, n) C-contiguous float rows the tree kernels are compiled for."""
    return np.ascontiguousarray(np.atleast_2d(q), dtype=float)


def interpolate_steps(q0: np.ndarray, q1: np.ndarray, step: float) -> np.ndarray:
    """Points from q0 (excluded) to q1 (included) no farther apart than `step` (max-norm); compiled (a
    search interpolates every extension), the points of q0 + (i / k)·(q1 - q0), i = 1..k."""
    return search_kernels.interpolate_steps(np.ascontiguousarray(q0, dtype=float),
                                            np.ascontiguousarray(q1, dtype=float), float(step))

