"""Problem set-up shared by every planning path (after validation.py has checked the request): the arm
problem (`ArmProblem`: kinematics, collision checking with guaranteed edge sampling, limits, targets),
the validators of a hand holding the object, and the batched IK behind reachability tests and GraspRRT's
hints.

The planning thread (single.py, dual.py), DAGRRT's arm process, the benchmark's OMPL peer and the
tests all build their arm problems here, so the two sides of a dual plan are set up the same way and
neither reaches into the other.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Callable, Iterator, Sequence

import numpy as np

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.collision.geometry import RobotCollisionModel
from humanoid_planner.core.ik.solver import DEFAULT_ITERATIONS as IK_ITERATIONS, STALL_ITERATIONS as IK_STALL, solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot, attach

HINT_IK_ITERATIONS = 30  # damped least-squares iterations of the IK behind GraspRRT's hints
NEAR_START_SPREAD = 0.5
"""rad: a quarter of the IK starts are the start configuration plus this much normal noise per joint;
the others are uniform over the limits (every branch)."""
MIN_HINT_STARTS = 256
"""IK starts of the hints of a one-grasp request (fewer per grasp as grasps are added): a grasp deep in
a box has few collision-free postures — Fetch reaching into a box: 32 starts gave 2 free solutions, both
4.9 rad from the benchmark's goal configuration; 256 gave 18, one 0.6 rad from it (30 ms)."""
FALLBACK_IK_ITERATIONS = 40
"""Iterations of the fallback's IK batches from fresh starts, but for every FALLBACK_FULL_IK_EVERY-th batch,
which runs the full IK: the short ones find most of the postures a full batch finds (most starts converge
within 30 iterations) at a third of its cost. MotionBenchMaker, problems 1-10, 10 s of CPU, all solved both
ways, total CPU every batch full -> this: Fetch cage 24.8 -> 18.7 s (median 2.17 -> 1.48 s), bookshelf_tall
4.2 -> 4.2 s, box 2.3 -> 2.4 s, Panda cage 2.7 -> 2.6 s."""
FALLBACK_FULL_IK_EVERY = 4
"""Every this many fallback IK batches one runs the full iterations; only those count towards
UNREACHABLE_STARTS, so a target that converges slowly is not given up for what short batches missed."""
UNREACHABLE_STARTS = 128
"""IK starts (collisions ignored) after which a target that none of them solved is taken as out of the
group's reach: GraspRRT's fallback asks IK for it no more, and a search left with such targets only
ends (single.run_girrt) rather than spinning IK until its timeout. Placements at the edge of
ARMAR-III's reach (the place benchmark) are solved by 7-10 of 32 starts, those out of reach by none of
1024."""


class ProblemBuilder:
    """Builds the pieces of one robot's planning problems. Stateless per request, so thread-safe."""

    def __init__(self, robot: RobotModel, options: PlannerOptions):
        self.robot = robot
        self.options = options

    def warm_up(self) -> None:
        """Build the robot's collision model now (seconds on a mesh robot: TALOS 2-3 s) with its meshes'
        bounding polytopes; every later checker of this robot shares it, so the first request does not pay
        for it."""
        r = self.robot
        RobotCollisionModel.for_robot(r).prepare_outer_hulls()
        group = next((g for g, grp in r.groups.items() if grp.joint_names), None)
        if group is not None:
            motion = self.motion(SceneSnapshot(0, r.root_link, ()), group, r.home, "", r.hand_links(group))
            # the check loads the compiled kernels; its group's clearance tables are not asked for (the first
            # SRDF group may be a whole body nobody plans with: TALOS's "all", 12 s of tables per process)
            motion.checker.without_tables()
            motion.check_configs(r.home[r.group_joint_indices(group)][None])

    def motion(self, scene: SceneSnapshot, groups: str | tuple[str, ...], q_ref: np.ndarray, object_id: str,
                hands: Sequence[str], cross_only: bool = False) -> MotionValidator:
        """Collision checker + guaranteed edge sampling: configurations collide by the user's padding;
        samples between them keep the edge margins (planners/motion.py).

        cross_only (several groups): check only links of different groups against each other — for
        pairing arm paths that were each checked already; ignored unless the groups move disjoint
        link sets (a shared torso would move the other arm's links too)."""
        step = self.options.max_point_motion
        disjoint = False
        if not isinstance(groups, str):
            moved = [set(self.robot.moving_links(g)) for g in groups]
            disjoint = all(not (moved[i] & moved[j]) for i in range(len(moved)) for j in range(i + 1, len(moved)))
        checker = CollisionChecker(self.robot, scene, groups, q_ref,
                                   CheckerSettings(padding=self.options.collision_padding, margin=step / 2,
                                                   grasp_object_id=object_id or None, hand_links=tuple(hands),
                                                   edge_resolution=self.options.edge_resolution,
                                                   cross_groups_only=cross_only and disjoint))
        return MotionValidator(checker, step)

    def targets(self, object_pose: np.ndarray, grasps: Sequence[GraspSpec], group: str) -> list[GraspTarget]:
        """The grasps `group`'s hand may use, as TCP targets in the planning frame (index: the grasp's
        place in the request)."""
        return [GraspTarget(i, g, object_pose @ g.tcp_in_object) for i, g in enumerate(grasps)
                if self.robot.hand_usable_by(g.hand, group)]

    def arm(self, scene: SceneSnapshot, group: str, start: np.ndarray, targets: Sequence[GraspTarget],
            rng: np.random.Generator, options: PlannerOptions | None = None, object_id: str = "") -> ArmProblem:
        """One group's problem at `start` (a full configuration, already checked): its kinematics, a
        motion validator of the scene (object_id: the grasped object, which only the hand may
        touch), its motion limits, the targets, options (default: the builder's) and random stream."""
        r = self.robot
        idx = r.group_joint_indices(group)
        lower, upper = r.motion_limits(idx, start[idx])
        hands = r.hand_links(group)
        kin = GroupKinematics(r, group, start)
        motion = self.motion(scene, group, start, object_id, hands)
        held = HeldMotions(self, scene, (group,), start, object_id, hands).at
        return ArmProblem(kin, motion, lower, upper, options or self.options, rng, tuple(targets), start, held)

    def reachable(self, kin: GroupKinematics, targets: Sequence[GraspTarget], q0: np.ndarray, lower, upper,
                   rng: np.random.Generator, seeds: int | None = None, iterations: int = IK_ITERATIONS,
                   stall: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Batched multi-start IK of every target (collisions ignored): (solutions, target index). stall:
        solve_ik_batch's (starts that stopped converging given up; goal sampling)."""
        if not len(targets):  # GraspRRT's fallback may ask in the cycle whose accept hook dropped the last target
            return np.empty((0, len(q0))), np.empty(0, dtype=np.int64)
        o = self.options
        s = seeds or o.ik_seeds
        near = (s - 1) // 4  # starts around q0: solutions on the start's IK branch (short paths, same wrist turns)
        Q = np.vstack([q0[None], np.clip(q0 + rng.normal(0.0, NEAR_START_SPREAD, size=(near, len(q0))), lower, upper),
                       rng.uniform(lower, upper, size=(s - 1 - near, len(q0)))])
        seeds_all = np.repeat(Q[None], len(targets), axis=0).reshape(-1, len(q0))
        T = np.repeat(np.stack([t.T_target for t in targets])[:, None], s, axis=1).reshape(-1, 4, 4)
        q, ok, _ = solve_ik_batch(kin, T, seeds_all, lower, upper, tol_pos=o.goal_tolerance_pos,
                                  tol_rot=o.goal_tolerance_rot, iterations=iterations, stall=stall)
        tidx = np.repeat(np.arange(len(targets)), s)
        return q[ok], tidx[ok]

    def ik_hints(self, kin: GroupKinematics, q0: np.ndarray, lower, upper, seed) -> "IKHints":
        """GraspRRT's `ik` (IKHints): the same batched IK as reachable, with the few starts and
        iterations hints need."""
        return IKHints(self, kin, q0, (lower, upper), seed)

@dataclass(frozen=True)
class DualProblem:
    """A dual request set up (after validation): the scene, the two groups at the start configuration,
    and per arm the grasp targets its hand may use (GraspTarget.index: the grasp's place in the
    request). Each arm's search gets its own ArmProblem (ProblemBuilder.arm); the pair checks are
    pair_completion.PairCompleter's."""

    scene: SceneSnapshot
    groups: tuple[str, str]
    start: np.ndarray
    grasps: tuple[tuple[GraspTarget, ...], tuple[GraspTarget, ...]]
    object_id: str = ""


def held_scene(scene: SceneSnapshot, object_id: str, link: str, T_link: np.ndarray, touch) -> SceneSnapshot:
    """The scene with the grasped object taken out of the world and attached to `link` (pose T_link),
    as it is once the hand has closed; unchanged when there is no scene object to hold."""
    obj = scene.get(object_id) if object_id else None
    if obj is None:
        return scene
    held = attach(obj, link, T_link, touch)
    return replace(scene, objects=tuple(o for o in scene.objects if o.id != object_id),
                   attached=scene.attached + (held,))


@dataclass(frozen=True)
class HeldMotions:
    """Motion validators of `groups` with the grasped object attached to the first group's TCP link
    (touching only `hands`): what a retreat is checked with, once the hand has closed."""

    builder: ProblemBuilder
    scene: SceneSnapshot
    groups: tuple[str, ...]
    start: np.ndarray
    object_id: str
    hands: tuple[str, ...]

    def at(self, T_tcp: np.ndarray) -> MotionValidator:
        """The validator with the object held at TCP pose T_tcp (a new checker each call)."""
        tip = self.builder.robot.group(self.groups[0]).tip_link
        scene = held_scene(self.scene, self.object_id, tip, T_tcp, self.hands)
        return self.builder.motion(scene, self.groups if len(self.groups) > 1 else self.groups[0], self.start, "",
                                   self.hands)


@dataclass(frozen=True)
class IKHints:
    """GraspRRT's `ik`: the builder's batched IK with the few starts and iterations hints need (most
    solutions converge within 30 iterations; the rest cost 3× as much). When those find nothing usable
    — no solution, or none that `keep` (GraspRRT: collision-free) keeps — the full multi-start IK once:
    where few grasps are reachable at all (Romeo's arm on boxes6: 2 of 16), 8 starts × 30 iterations
    found none in 2 of 3 problems, 32 × 120 found ~35 solutions (~40 ms), and without hints such a
    search crawls by Jacobian approaches alone; where the arm is cramped (iCub's right_arm_torso, ~10 %
    of its joint space free) 8 starts found 7 solutions that all collided, 32 found a free one. Every call
    gives up starts that stopped converging (solver.STALL_ITERATIONS): they are goal sampling."""

    builder: ProblemBuilder
    kin: GroupKinematics
    q0: np.ndarray
    limits: tuple[np.ndarray, np.ndarray]
    seed: object  # int | list | None: the hints' own starts, apart from the search's stream
    tried: dict = field(default_factory=dict, compare=False)
    """per target (index, pose): [IK starts run, solutions found] (`out_of_reach`)"""
    batches: Iterator[int] = field(default_factory=itertools.count, compare=False)
    """numbers the fallback's IK batches (FALLBACK_FULL_IK_EVERY)"""

    def __call__(self, targets: Sequence[GraspTarget], keep: Callable[[np.ndarray], np.ndarray] | None = None,
                 rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(solutions, index into targets of each). With rng: one batch of the multi-start IK from that
        generator's starts for the targets not yet out of reach (GraspRRT's fallback, which keeps asking for
        goal configurations where few solutions are free): FALLBACK_IK_ITERATIONS, every
        FALLBACK_FULL_IK_EVERY-th batch the full iterations."""
        b, (lower, upper) = self.builder, self.limits
        if rng is not None:
            ask = np.array([k for k, t in enumerate(targets) if not self.out_of_reach(t)], dtype=np.int64)
            if len(ask) == 0:
                return np.empty((0, len(self.q0))), np.empty(0, dtype=np.int64)
            asked = [targets[k] for k in ask]
            full = next(self.batches) % FALLBACK_FULL_IK_EVERY == FALLBACK_FULL_IK_EVERY - 1
            q, which = b.reachable(self.kin, asked, self.q0, lower, upper, rng,
                                   iterations=IK_ITERATIONS if full else FALLBACK_IK_ITERATIONS, stall=IK_STALL)
            self._count(asked, b.options.ik_seeds if full else 0, which)
            return q, ask[which]
        # few grasps: more starts each, for postures of several IK branches (1 grasp: MIN_HINT_STARTS, 2:
        # half of it each, 4 and more: ik_hint_seeds each; IK time grows with the starts, 8 grasps × 32
        # starts cost TALOS boxes6 +15 ms per plan)
        seeds = max(b.options.ik_hint_seeds, MIN_HINT_STARTS // max(len(targets), 1) ** 2)
        q, which = b.reachable(self.kin, targets, self.q0, lower, upper, np.random.default_rng(self.seed),
                               seeds=seeds, iterations=HINT_IK_ITERATIONS, stall=IK_STALL)
        if len(q) == 0 or (keep is not None and not keep(q).any()):  # the full IK instead
            seeds = b.options.ik_seeds
            q, which = b.reachable(self.kin, targets, self.q0, lower, upper, np.random.default_rng(self.seed),
                                   stall=IK_STALL)
        self._count(targets, seeds, which)
        return q, which

    def _count(self, targets: Sequence[GraspTarget], starts: int, which: np.ndarray) -> None:
        found = np.bincount(which, minlength=len(targets)) if len(which) else np.zeros(len(targets), int)
        for t, n in zip(targets, found):
            entry = self.tried.setdefault((t.index, t.T_target.tobytes()), [0, 0])
            entry[0] += starts
            entry[1] += int(n)

    def out_of_reach(self, t: GraspTarget) -> bool:
        """Has IK run UNREACHABLE_STARTS starts for target t and solved none (collisions ignored)?"""
        n = self.tried.get((t.index, t.T_target.tobytes()))
        return n is not None and n[1] == 0 and n[0] >= UNREACHABLE_STARTS
