"""GIRRT (GIRRT paper, Alg. 1–2) and its per-arm twin GRRT (DAGRRT paper, Alg. 3–4).

Both grow one tree from the start configuration. With probability f_extend a cycle approaches a
randomly chosen grasp of the set: from the tree node whose TCP is nearest to the grasp's target
pose it takes step-limited generalized-inverse steps (weighted least-norm for GIRRT, damped SVD
for GRRT), adding every collision-free step to the tree, until the TCP is within tolerance
(success) or a step collides or leaves the joint limits (that branch stops; the search goes on —
the papers' "return RRT_ERROR … StopSearch" would end the whole search at the first blocked
approach, which Simox's Grasp-RRT, the reference implementation, does not do). Otherwise a
cycle samples the joint space and Connects the nearest node toward the sample in steps of λ
until an obstacle is met.

No goal configuration is needed: the grasp set is the goal. Our addition (IK hints): from the first
cycle (`ik_hint_after` = 0, the default for GIRRT and DAGRRT's arms: the straight motion to a hint
solves most problems at once), or once n approaches have failed — blocked by an obstacle or stalled
at a joint limit — the arm solves inverse kinematics of its grasps once (batched, collisions
ignored, then the free solutions kept). Those solutions are
used three ways, the grasps staying the goal throughout:
- a straight joint motion from the start to the nearest few is tried first (a free one is a plan
  at once — most problems with open space between the hand and the object);
- they root a second tree, grown as RRT-Connect grows its goal tree (Kuffner & LaValle): each
  Connect alternately extends one tree toward a uniform sample and pulls the other greedily toward
  the new node; when the trees meet, the path runs on through the goal tree to its root, an IK
  solution that holds the grasp. This is what gets a hand into a pocket (a shelf over a table)
  that the Jacobian approach, coming straight at the grasp from the start tree, runs into;
- a share `ik_hint_bias` of the start tree's Connect samples is a solution instead of uniform.
Counting blocked approaches matters: where the table is in the way every approach is blocked, and
a trigger that waited for unobstructed stalls (the first version) never fired.

The fallback: GIRRT from its first cycle on (once the straight motions to the hints failed;
`fallback_from`), DAGRRT's arms only when the fast path stops making progress — neither tree grew in
STALL_CYCLES cycles, no IK solution of a searched grasp is collision-free (no hint to connect to), or a
whole restart period went by without a grasp — nine tenths of the configuration checks go to a balanced RRT-Connect
(baselines' LazyConnectSearch) from the start to collision-free IK solutions of the searched grasps (the
hints, then more from fresh IK starts), within the same budget. It is lazy: its trees grow on
motion.LazyMotion, the reference's check (the validator's samples, no margins, every free
configuration a node), so it is as complete as a plain RRT-Connect with the same checker; a path it
finds counts once the validator has proven each edge (both ends may be tight), and an edge it refuses
is cut from its tree with the nodes below it. The fast path's own rule (a search's nodes are no tight
motion ends) is what had kept it from iCub's torso problems, where the chest slides 0-2 mm over the
root link along every path: half the extensions the reference took were refused there. Its path
ends at an IK solution, so it reaches the grasp like any other; `found_by_fallback` and
`fallback_report` say what was used.
"""
from __future__ import annotations

import time
import weakref
from dataclasses import replace
from typing import Callable

import numpy as np

from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.baselines import GoalRRT, LazyConnectSearch
from humanoid_planner.core.planners.cartesian import LINE_STEP, straight_line
from humanoid_planner.core.planners.common import (GraspTarget, Outcome, PlanResult, PlanStatus, Progress, Termination, Tree,
                                                  Verdict, interpolate_steps)
from humanoid_planner.core.planners.motion import LazyMotion


HINTS_PER_GRASP = 2  # IK postures per grasp kept as hints: the nearest, and one more in case its region is walled off
MIN_HINTS = 8
"""Hints kept in all (at most, as many as IK found free): a request with one or two grasps keeps more
postures per grasp. A pose goal given as one grasp (a benchmark's goal configuration's TCP pose) had
2 hints, both in postures walled off from the start (Fetch in a box: roll joints turned by π)."""
DIRECT_TRIES = 3  # straight start -> IK-solution motions tried when the hints arrive (nearest first)
STALL_CYCLES = 50
"""Cycles in which neither tree gained a node: the fast path is stuck (Baxter at its zero pose, where
no motion out of the start could be proven: tree_size 1 after 900 cycles); the fallback joins in."""
FALLBACK_SHARE = 0.9
"""Once the fallback has joined, it gets this share of the search's configuration checks: the fast path takes
a cycle only while its checks since then are below 1 - FALLBACK_SHARE of both's. Shared by checks, not
cycles: a fast-path cycle (Jacobian approaches, Connects on the validator, which keeps margins and refines
next to tight samples) costs several lazy fallback cycles — at three cycles in four, the fast path still
took 47 % of the time on iCub `left_arm_torso` (sweep seed 1). By checks, not seconds, so a seed still
fixes the plan. 0.9 rather than 0.75: on Fetch's small shelves (MotionBenchMaker problems 1-6) every plan
came from the fallback, and its CPU time fell by a fifth (median 1.3 vs 1.6 s); Panda's cage the same."""
EXIT_DISTANCE = 0.15
"""m: each goal-tree root (an IK solution holding a grasp) starts with the straight TCP line backwards
along the hand's axis, as far as it is free: the way a hand leaves a shelf, a box or a cage, which
uniform samples almost never find (Fetch, bookshelf: 30 % of the configurations within 0.05 rad of a
grasp are free; Panda cage)."""
EXIT_FAR = 0.45
"""m: an exit line free for its whole EXIT_DISTANCE goes on to this, drawn only once the search is slow (the
fast path's goal tree after EXIT_AFTER_CYCLES, the fallback's after as many of its cycles): a Fetch hand in a
small shelf is still inside it 15 cm back. MotionBenchMaker Fetch bookshelf_small, 16 runs (problems 1-10 and
more seeds of 3 and 5), 10 s of CPU each, same seeds: total CPU 29.6 s at 0.15 m, 12.5 s at 0.3, 6.3 s at 0.45,
7.2 s at 0.6 (medians 1.17 / 0.44 / 0.33 / 0.43 s). Panda's quick plans pay nothing: most are found before."""
EXIT_FAR_STEP = 0.05
"""m between the far part's waypoints (the near part's: cartesian.LINE_STEP, 2.5 cm): half the inverse
kinematics of a far line, whose straightness matters less than its cost (each edge is checked all the same).
Fetch bookshelf_small/tall (21 runs): total CPU 9.6 -> 9.4 s, median 0.42 -> 0.31 s; bookshelf_thin and the
tables (13 runs): 5.7 -> 3.8 s."""
EXIT_FAR_TOL = 0.01  # m: the far part's TCP may stray this far from the line (the near part's: 2 mm)
EXIT_ROOTS = 8
"""Goal-tree roots given an exit line (the first ones: nearest the start per grasp); each costs a few
inverse-kinematics steps."""
EXIT_AFTER_CYCLES = 30
"""The exit lines join the goal tree once the search has run this many cycles without a grasp: most
problems are solved sooner, and the lines cost ~9 ms per root (Panda table_shelf: 70 of 245 ms)."""
FALLBACK_FROM = 1
"""GIRRT's cycle from which the fallback runs beside the fast path (once the straight motions to the hints
failed), not only after a stall: on the MotionBenchMaker scenes (goals inside shelves, boxes, a cage) the
balanced lazy RRT-Connect found nearly every plan, and waiting for the stall (a restart: 150 cycles) cost
0.2-0.5 s first. Problems 1-10, both versions side by side, median CPU: Panda cage 0.81 -> 0.57 s, Fetch
bookshelf_small 0.86 -> 0.58 s, Fetch box 0.61 -> 0.42 s; armar3 narrow 113 -> 58 ms (benchmarks/README.md)."""
FALLBACK_EXTEND_STEPS = 10
"""Connect steps (joint_step each, 1 rad in all) the fallback's RRT-Connect extends a tree toward its
sample per cycle, as OMPL's RRT-Connect extends by its range: each cycle pays a whole Connect of the
other tree anyway, and one 0.1 rad step per cycle left the trees tiny (Fetch reaching into a box,
MotionBenchMaker problems 1-5, 10 s: 1 -> 10 steps solved 1/5 -> 5/5, median 1.9 s; 20 steps the same)."""
FALLBACK_IK_EVERY = 20
"""Fallback cycles between two batches of IK from fresh random starts, while it has fewer goal
configurations than PlannerOptions.max_goal_configs (iCub's cramped right_arm_torso: 1 free
solution in 30-100 for some grasps)."""
FALLBACK_POSTURE_TRIES = 3
"""Goal configurations of one grasp the fallback may reach and find its approach or retreat blocked in
before the grasp is dropped (GraspRRT._accepted)."""
TCP_NOTE_PERIOD = 0.05  # s between two TCP distances a Connect reports (the action feedback comes every 0.1 s)


class GraspRRT:
    """One arm (or arm + torso) searching toward a grasp set; `inverse` = 'wln' (GIRRT) or 'svd' (GRRT)."""

    def __init__(self, problem: ArmProblem, inverse: str = "wln",
                 ik: Callable[..., tuple[np.ndarray, np.ndarray]] | None = None,
                 accept: Callable[[np.ndarray, GraspTarget], Outcome] | None = None,
                 fallback_from: int | None = None):
        """ik: (targets, keep, rng=None) → (IK solutions, index into targets of each), collisions
        ignored (keep: the solutions' collision check, for an IK that tries harder when it keeps
        none; rng: fresh starts, for the fallback's further goal configurations); enables IK hints
        and the fallback (ProblemBuilder.ik_hints).
        accept(q, target): called when a target is reached — an accepted outcome keeps the solution;
        otherwise the target is dropped from the searched list, or replaced by the outcome's target
        (a straight approach onto the grasp that failed: pipeline.completion), and the search goes on.
        fallback_from: the cycle from which the fallback runs beside the fast path whether or not it
        stalled (GIRRT: FALLBACK_FROM); None: only once it stalls (DAGRRT's arms)."""
        if not problem.targets:
            raise ValueError("GraspRRT needs at least one grasp target")
        self.problem = problem
        self.kin, self.motion = problem.kin, problem.motion
        self.lower, self.upper = np.asarray(problem.lower, float), np.asarray(problem.upper, float)
        self.targets = list(problem.targets)
        self.opt, self.rng, self.inverse = problem.options, problem.rng, inverse
        self.tree: Tree | None = None
        self.cycles = 0
        self.ik = ik
        self.hints: np.ndarray | None = None  # collision-free IK solutions, once computed
        self.hint_targets = np.empty(0, dtype=np.int64)  # GraspTarget.index of each hint
        self.ik_reachable = False  # the hint IK found a solution (collisions ignored): no reachability probe needed
        self.failed_approaches = 0
        self.accept = accept
        self.progress: Progress | None = None  # where the search reports its cycles, TCP distance and solutions
        self.goal_tree: Tree | None = None  # rooted at the hints of the grasps still wanted
        self._goal_for: tuple[int, ...] = ()  # ids of the hinted targets the goal tree was rooted for
        self._goal_root_target: list[GraspTarget] = []  # per goal-tree root: the target its IK solution holds
        self._exit_roots: list[int] = []  # goal-tree roots whose exit line is still due
        self._exits: dict[tuple[bytes, bool, bool], tuple[np.ndarray, np.ndarray]] = {}  # (grasp config, far, lazy) → that part of its exit line
        self._grow_goal = False  # whose turn it is to extend toward the sample (RRT-Connect's swap)
        self._direct_tried = False
        self._by_index = {t.index: t for t in self.targets}  # the targets the hints were solved for
        self._grew_at = 0  # the last cycle in which a tree gained a node
        self.fallback: _Fallback | None = None  # the safety net, once the fast path stalled
        self.fallback_from = fallback_from
        self.found_by_fallback = False  # the last grasp search() returned was reached by it
        self._hand_axis = approach_axis(self.kin.robot, self.kin.group)  # TCP frame: the goal tree's exit lines
        self._target_xyz: np.ndarray | None = None  # every target's TCP position, for _note_tcp
        self._blocked_postures: dict[int, int] = {}  # GraspTarget.index -> fallback goals given up for it
        self._next_tcp_note = 0.0

    # -- the two kinds of cycle -------------------------------------------------------------
    def _approach(self, target: GraspTarget) -> int | None:
        """ExtendToGrasp / ApproachToTarget. Returns the goal node index when the grasp is reached."""
        tree, o = self.tree, self.opt
        i = tree.nearest_tcp(target.T_target)
        steps, reached = steer_to_pose(
            self.kin, tree.q[i], target.T_target, inverse=self.inverse,
            max_step_pos=o.tcp_step_pos, max_step_rot=o.tcp_step_rot, max_joint_step=o.max_joint_step,
            tol_pos=o.goal_tolerance_pos, tol_rot=o.goal_tolerance_rot, max_iters=o.max_approach_steps,
            lower=self.lower, upper=self.upper, nullspace_gain=o.nullspace_gain)
        if len(steps) == 0:
            if reached:  # the node itself already holds the grasp
                return i
            tree.fails[i] += 1
            self.failed_approaches += 1
            return None
        k, tight = self.motion.free_prefix_tight(tree.q[i], steps, tight_from=tree.tight[i], tight_to=reached)
        if k < len(steps) or not reached:
            tree.fails[i] += 1  # blocked or stalled: prefer other nodes for the next approach
            self.failed_approaches += 1
        if k == 0:
            return None
        self._grew_at = self.cycles
        last = tree.add(steps[:k], i, self.kin.fk(steps[:k]), tight)
        if self.progress is not None:
            self.progress.tcp_distance(self.kin.group, float(np.linalg.norm(tree.tcp_pos[last] - target.T_target[:3, 3])))
        return last if (reached and k == len(steps)) else None

    def _hints_due(self) -> bool:
        after = self.opt.ik_hint_after
        return after is not None and self.failed_approaches >= after

    def _compute_hints(self) -> None:
        seen: list[tuple[np.ndarray, np.ndarray]] = []  # (solutions, verdicts) the IK's keep test checked

        def keep(q: np.ndarray) -> np.ndarray:
            seen.append((q, self.motion.check_configs(q)))
            return seen[-1][1]

        q, which = self.ik(self.targets, keep)
        self.ik_reachable = len(q) > 0
        # the solutions the IK kept are checked already (a second check cost G1's hints half their time:
        # its upper arm beside the torso goes to FCL); those of a later full IK are not
        free = (seen[-1][1] if seen and seen[-1][0] is q else self.motion.check_configs(q)) if len(q) else np.zeros(0, dtype=bool)
        q, which = q[free], which[free]
        # per grasp, the HINTS_PER_GRASP solutions nearest the start: a far posture lengthens the path
        order = np.lexsort((np.linalg.norm(q - self.q_start, axis=1), which))
        q, which = q[order], which[order]
        rank = np.arange(len(which)) - np.searchsorted(which, which)
        keep = rank < max(HINTS_PER_GRASP, -(-MIN_HINTS // max(len(np.unique(which)), 1)))
        self.hints = q[keep]
        self.hint_targets = np.array([self.targets[k].index for k in which[keep]], dtype=np.int64)

    def adopt_hints(self, hints: np.ndarray, hint_targets: np.ndarray) -> None:
        """Use IK hints another search of the same arm and grasps computed (no IK of our own)."""
        self.hints = np.asarray(hints, dtype=float)
        self.hint_targets = np.asarray(hint_targets, dtype=np.int64)
        self.ik_reachable = True

    def _sample(self, targets: list[GraspTarget]) -> np.ndarray:
        """Connect's q_rand: uniform, or (with IK hints) sometimes a hint of a grasp still wanted."""
        if self.hints is not None and len(self.hints) and self.rng.random() < self.opt.ik_hint_bias:
            live = self._live_hints(targets)
            if len(live):
                return self.hints[live[int(self.rng.integers(len(live)))]]
        return self.rng.uniform(self.lower, self.upper)

    def _grow(self, tree: Tree, i: int, q_to: np.ndarray, fk: bool, to_root: bool = False) -> tuple[int, bool]:
        """Greedy Connect of node i toward q_to in λ steps until an obstacle: (last node, reached q_to);
        last node = i when not even the first step is free. Only roots (the start, IK solutions) and
        nodes reached from them through tight samples may be tight ends of the motion
        (MotionValidator.free_prefix, Tree.tight); to_root: q_to is a root."""
        pts = interpolate_steps(tree.q[i], q_to, self.opt.joint_step)
        k, tight = self.motion.free_prefix_tight(tree.q[i], pts, tight_from=tree.tight[i], tight_to=to_root)
        if k == 0:
            tree.fails[i] += 1
            return i, False
        self._grew_at = self.cycles
        last = tree.add(pts[:k], i, self.kin.fk(pts[:k]) if fk else None, tight)
        if fk and self.progress is not None:
            self._note_tcp(tree, last)
        return last, k == len(pts)

    def _note_tcp(self, tree: Tree, node: int) -> None:
        """Progress's TCP distance from a node a Connect added: a search whose approaches are all blocked
        at once (a caged object) still says how near its tree came. At most every TCP_NOTE_PERIOD: the
        node is measured against every target (10^5 grasps: 0.5 ms)."""
        now = time.perf_counter()
        if now < self._next_tcp_note:
            return
        self._next_tcp_note = now + TCP_NOTE_PERIOD
        if self._target_xyz is None:
            self._target_xyz = np.array([t.T_target[:3, 3] for t in self.targets])
        self.progress.tcp_distance(self.kin.group,
                                   float(np.min(np.linalg.norm(self._target_xyz - tree.tcp_pos[node], axis=1))))

    def _live_hints(self, targets: list[GraspTarget]) -> np.ndarray:
        """Indices of the hints whose target is still searched (by identity: a target that
        `accept` replaced has another pose, which the hint does not hold)."""
        wanted = {id(t) for t in targets}
        return np.array([k for k, ti in enumerate(self.hint_targets) if id(self._by_index[int(ti)]) in wanted],
                        dtype=np.int64)

    def _goal_tree_for(self, targets: list[GraspTarget]) -> Tree | None:
        """The goal tree rooted at the hints of `targets` (re-rooted when the searched set changes)."""
        if self.hints is None:
            return None
        wanted = tuple(sorted(id(t) for t in targets))
        if self.goal_tree is None or wanted != self._goal_for:
            self._goal_for = wanted
            live = self._live_hints(targets)
            self.goal_tree = None
            if len(live):
                hints = self.hints[live]
                self.goal_tree = Tree(hints[0])
                roots = [0]
                for h in hints[1:]:
                    roots.append(self.goal_tree.add(h[None], -1))
                self._goal_root_target = [self._by_index[int(self.hint_targets[k])] for k in live]
                self._exit_roots = roots[:EXIT_ROOTS]
        # the fallback's goal tree has them already, lazily checked: drawn here too, with the validator,
        # they cost a search in a shelf more than the rest of it (Panda bookshelf_tall)
        if self.goal_tree is not None and self._exit_roots and self.cycles >= EXIT_AFTER_CYCLES and self.fallback is None:
            for r in self._exit_roots:
                self._add_exit(self.goal_tree, r)
            self._exit_roots = []
        return self.goal_tree

    def _add_exit(self, tree: Tree, root: int) -> None:
        """Grow root's branch along its exit line, near part and far part (_exit_line)."""
        q = tree.q[root]
        W, tight = self._exit_line(q)
        end = tree.add(W, root, None, tight)
        W, tight = self._exit_line(q, far=True)
        tree.add(W, end, None, tight)

    def _exit_line(self, q: np.ndarray, far: bool = False,
                   lazy: LazyMotion | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The straight TCP line from the grasp configuration q backwards along the hand's axis
        (orientation held), as far as it is free: (waypoints, tight). Its near part runs EXIT_DISTANCE;
        far: its continuation to EXIT_FAR from the near part's end, only when the near part is free all
        the way (empty otherwise). Built part by part: a line blocked near the grasp (a cage) costs
        no more inverse kinematics than its near part. Each part is kept per grasp configuration: the
        goal trees of later restarts and the fallback's root at the same hints, and a far part starts where
        its near part ended (Fetch shelves and box: a fifth of the near parts were drawn twice). lazy:
        checked on it (the fallback's goal tree, whose edges are validated once a path uses them) instead
        of the validator: a hand inside a shelf keeps no margin from its boards, so the validator refines
        nearly every sample of the line with exact checks (Panda bookshelf_tall: two thirds of a plan's
        time), mostly for lines no path takes."""
        key = (q.tobytes(), far, lazy is not None)
        if key in self._exits:
            return self._exits[key]
        T0 = self.kin.fk(q)
        d = -(T0[:3, :3] @ self._hand_axis)
        start, tight_from, length = q, True, EXIT_DISTANCE
        W, tight = np.zeros((0, len(q))), np.zeros(0, dtype=bool)
        if far:
            near, near_tight = self._exit_line(q, lazy=lazy)
            if len(near) < int(np.ceil(EXIT_DISTANCE / LINE_STEP - 1e-9)) or EXIT_FAR <= EXIT_DISTANCE:
                start = None
            else:
                T0 = T0.copy()
                T0[:3, 3] += EXIT_DISTANCE * d / np.linalg.norm(d)
                start, tight_from, length = near[-1], bool(near_tight[-1]), EXIT_FAR - EXIT_DISTANCE
        if start is not None:
            coarse = {"step": EXIT_FAR_STEP, "tol_pos": EXIT_FAR_TOL} if far else {}
            W = straight_line(self.kin, start, d, length, self.lower, self.upper, inverse=self.inverse, T0=T0,
                              **coarse).waypoints
            if len(W):
                k, tight = (lazy or self.motion).free_prefix_tight(start, W, tight_from=tight_from, tight_to=False)
                W = W[:k]
        self._exits[key] = (W, tight)
        return W, tight

    def _join(self, goal: Tree, s: int, g: int) -> tuple[int, GraspTarget]:
        """Start-tree node s and goal-tree node g hold the same configuration: the goal tree's branch
        from g to its root (an IK solution of a grasp) is appended to the start tree."""
        rest = goal.path_indices(g)[::-1][1:]
        q = goal.q[rest]
        end = self.tree.add(q, s, self.kin.fk(q), goal.tight[rest]) if len(rest) else s
        return end, self._goal_root_target[int(goal.root[g])]

    def _connect(self, targets: list[GraspTarget]) -> tuple[int, GraspTarget] | None:
        """Connect(q_near, q_rand): extend in λ steps toward a sample until an obstacle; with a goal
        tree, the trees take turns extending and the other one is pulled toward the new node."""
        tree, goal = self.tree, self._goal_tree_for(targets)
        if goal is not None and self._grow_goal:
            self._grow_goal = False
            q_rand = self.rng.uniform(self.lower, self.upper)
            j = goal.nearest(q_rand)
            g, _ = self._grow(goal, j, q_rand, fk=False)
            if g == j:
                return None
            s, met = self._grow(tree, tree.nearest(goal.q[g]), goal.q[g], fk=True, to_root=goal.parent[g] < 0)
            return self._join(goal, s, g) if met else None
        self._grow_goal = True
        q_rand = self._sample(targets)
        i = tree.nearest(q_rand)
        s, _ = self._grow(tree, i, q_rand, fk=True)
        if goal is None or s == i:
            return None
        g, met = self._grow(goal, goal.nearest(tree.q[s]), tree.q[s], fk=False, to_root=tree.parent[s] < 0)
        return self._join(goal, s, g) if met else None

    def _direct(self, targets: list[GraspTarget]) -> tuple[int, GraspTarget] | None:
        """The straight joint motion from the start to one of the nearest IK solutions, if one is free."""
        live = self._live_hints(targets)
        near = live[np.argsort(np.linalg.norm(self.hints[live] - self.q_start, axis=1))][:DIRECT_TRIES]
        for h in near:
            if self.motion.check_edge(self.q_start, self.hints[h]):
                return self.tree.add(self.hints[h][None], 0, self.kin.fk(self.hints[h][None]), np.ones(1, bool)), \
                    self._by_index[int(self.hint_targets[h])]
        return None

    # -- the search ----------------------------------------------------------------------------
    def start(self, q_start: np.ndarray) -> PlanResult | None:
        """Root the tree; returns a failed result when the start itself is unusable."""
        q_start = np.asarray(q_start, dtype=float)
        if np.any(q_start < self.lower - 1e-9) or np.any(q_start > self.upper + 1e-9):
            return PlanResult(PlanStatus.INVALID_START, "start configuration is outside the joint limits")
        if not self.motion.check_configs(q_start[None])[0]:
            return PlanResult(PlanStatus.START_IN_COLLISION, "start configuration is in collision")
        self.q_start = q_start
        self.tree = Tree(q_start, self.kin.fk(q_start))
        self.cycles = 0
        self.restarts = 0
        self._since_restart = 0
        self.goal_tree = None
        self._grew_at = 0
        self.fallback = None
        self._fast_checks = 0  # the fast path's configuration checks since the fallback joined
        return None

    def search(self, term: Termination, targets: list[GraspTarget] | None = None) -> tuple[int, GraspTarget] | None:
        """Run cycles until a grasp is reached (goal node, target) or the termination fires."""
        targets = self.targets if targets is None else targets
        self.found_by_fallback = False
        while targets and not term.should_stop(self.cycles):
            self.cycles += 1
            if self.progress is not None:
                self.progress.iterations += 1
            self._since_restart += 1
            if self.ik is not None and self.hints is None and self._hints_due():
                self._compute_hints()
            if self.hints is not None and not self._direct_tried:
                self._direct_tried = True
                hit = self._direct(targets)
                if hit is not None and self._accepted(*hit, targets):
                    return hit
            if self.fallback is None and self.ik is not None and self._stalled(targets):
                self.fallback = _Fallback(self, np.random.default_rng(self.rng.integers(2**63)))
            if self.fallback is not None and self._fallback_turn():
                hit = self.fallback.cycle(targets)
                if hit is not None and self._accepted(*hit, targets, fallback=True):
                    self.found_by_fallback = True
                    return hit
                continue
            checks = self.motion.checker.stats.configs_checked
            hit = self._fast_cycle(targets)
            if self.fallback is not None:
                self._fast_checks += max(1, self.motion.checker.stats.configs_checked - checks)  # >= 1: turns go round
            if hit is not None:
                return hit
        return None

    def _fallback_turn(self) -> bool:
        """Is the next cycle the fallback's (FALLBACK_SHARE of the checks since it joined)?"""
        return self._fast_checks >= (1.0 - FALLBACK_SHARE) * (self._fast_checks + self.fallback.checks)

    def _fast_cycle(self, targets: list[GraspTarget]) -> tuple[int, GraspTarget] | None:
        """One cycle of the fast path: a restart when due, then an approach to a grasp or a Connect."""
        if self.opt.restart_cycles and self._since_restart > self.opt.restart_cycles:
            # Restart (Wedge & Branicky): a tree that has not reached a grasp in this many cycles
            # has usually grown into a pocket; a fresh one cuts the heavy tail of search times.
            self.tree = Tree(self.q_start, self.kin.fk(self.q_start))
            self.goal_tree = None
            self.restarts += 1
            self._since_restart = 0
        if self.rng.random() <= self.opt.f_extend:
            t = targets[int(self.rng.integers(len(targets)))]
            goal = self._approach(t)
            if goal is not None and self._accepted(goal, t, targets):
                return goal, t
        else:
            hit = self._connect(targets)
            if hit is not None and self._accepted(*hit, targets):
                return hit
        return None

    def fallback_report(self) -> dict:
        """For a result's extra: fallback = "rrt_connect" when the last grasp reached came from the
        safety net, fallback_cycles = the cycles it ran (0: the fast path never stalled),
        fallback_cut_edges = the edges of its lazy paths the validator refused."""
        out = {"fallback_cycles": self.fallback.cycles if self.fallback is not None else 0,
               "fallback_cut_edges": self.fallback.cut_edges if self.fallback is not None else 0}
        if self.found_by_fallback:
            out["fallback"] = "rrt_connect"
        return out

    def _stalled(self, targets: list[GraspTarget]) -> bool:
        """Has the fast path stopped making progress (the module's safety net)?"""
        if self.fallback_from is not None and self.cycles >= self.fallback_from:
            return True
        return (self.cycles - self._grew_at >= STALL_CYCLES or self.restarts > 0
                or (self.hints is not None and self.ik_reachable and len(self._live_hints(targets)) == 0))

    def _accepted(self, goal: int, t: GraspTarget, targets: list[GraspTarget], fallback: bool = False) -> bool:
        """Is reaching t at tree node goal a solution (the `accept` hook)? If not, t leaves the
        searched list, or is replaced by the target accept returned. A grasp the fallback reached in an
        IK posture whose approach or retreat is blocked stays searched for FALLBACK_POSTURE_TRIES such
        postures: only that goal configuration is given up (the fast path, steering the TCP onto the
        grasp, arrives in other postures; the fallback's IK goals are a few fixed ones)."""
        verdict = Outcome.accepted() if self.accept is None else self.accept(self.tree.q[goal], t)
        if verdict.ok:
            if self.progress is not None:
                self.progress.solutions += 1
            return True
        tries = self._blocked_postures.get(t.index, 0)
        if fallback and verdict.verdict is Verdict.REJECTED and tries < FALLBACK_POSTURE_TRIES:
            self._blocked_postures[t.index] = tries + 1
            self.fallback.forget_reached()
            return False
        # this grasp cannot be completed from here: try the others (by identity: == compares arrays)
        del targets[next(k for k, x in enumerate(targets) if x is t)]
        if verdict.verdict is Verdict.RETRY:
            targets.append(verdict.value)
        return False

    def plan(self, q_start: np.ndarray, term: Termination) -> PlanResult:
        """The whole GIRRT: one path from q_start to the first grasp reached."""
        failed = self.start(q_start)
        if failed is not None:
            failed.planning_time = term.elapsed()
            return failed
        found = self.search(term)
        res = PlanResult(PlanStatus.SUCCESS, iterations=self.cycles, tree_size=self.tree.size,
                         planning_time=term.elapsed(), extra=self.fallback_report())
        if found is None:
            res.status = term.stop_status()
            res.message = {PlanStatus.TIMED_OUT: "no grasp reached before the timeout",
                           PlanStatus.CANCELLED: "planning was cancelled"}.get(
                res.status, f"no grasp reached within {self.cycles} cycles")
            return res
        goal, target = found
        res.path, res.target = self.tree.path_to(goal), target
        return res


class _Fallback:
    """GraspRRT's safety net: RRT-Connect from the start to collision-free IK solutions of the grasps
    still searched — the arm's hints first, then batches of IK from fresh random starts (its first
    cycle and every FALLBACK_IK_EVERY-th, every quarter of that while it has none, as long as it has
    fewer than max_goal_configs). Its start tree lives on
    while the searched grasps change; its goal tree is rooted again for the new set. Goal roots get the near
    part of their exit line at once (Panda's open shelves: most plans within three cycles, through it) and
    the far part from its EXIT_AFTER_CYCLES-th cycle."""

    def __init__(self, arm: GraspRRT, rng: np.random.Generator):
        # the arm owns its fallback: a weak reference back, so that no cycle keeps a finished search (and the
        # request's checker, whose pooled fcl objects come back only when it goes) until the garbage collector runs
        self.arm, self.rng = weakref.proxy(arm), rng
        self.lazy = LazyMotion(arm.motion)
        self.rrt = GoalRRT("rrt_connect", replace(arm.problem.seeded(rng), motion=self.lazy),
                           extend_steps=FALLBACK_EXTEND_STEPS, lazy=True)
        self.start = Tree(arm.q_start)
        self._start_valid: set[int] = set()  # start-tree nodes whose edge from their parent passed validation
        self.search: LazyConnectSearch | None = None
        self.goal_targets: list[GraspTarget] = []  # per goal root, in order: the grasp it holds
        self._far: list[tuple[int, int]] = []  # (goal root, near line's end) whose far line is due
        self._for: tuple[int, ...] = ()
        self.cycles = 0
        self._cut_before = 0  # edges the searches before this one cut
        self.checks = 0  # configuration checks of its cycles

    @property
    def cut_edges(self) -> int:
        """Edges of lazy paths that failed validation, over every search."""
        return self._cut_before + (self.search.cut_edges if self.search is not None else 0)

    def _add(self, q: np.ndarray, which: list[GraspTarget]) -> None:
        """More goal configurations, each a root of the goal tree; the first EXIT_ROOTS of them start
        with their exit line, as the fast path's goal tree does, on the lazy check (drawn once per
        configuration: a goal tree rooted again for a new set of grasps reuses them)."""
        if len(q):
            self.search.add_goals(q)
            self.goal_targets += which
            goal = self.search.goal
            for r in self.search.goal_roots[-len(q):][:EXIT_ROOTS]:
                W, tight = self.arm._exit_line(goal.q[r], lazy=self.lazy)
                self._far.append((r, goal.add(W, r, None, tight)))

    def _draw_far(self) -> None:
        """The far parts of the exit lines due (not below a node cut meanwhile: a goal configuration given
        up, forget_reached, or an edge the validator refused)."""
        goal = self.search.goal
        for r, end in self._far:
            if np.isfinite(goal.sq[end]):
                W, tight = self.arm._exit_line(goal.q[r], far=True, lazy=self.lazy)
                goal.add(W, end, None, tight)
        self._far = []

    def forget_reached(self) -> None:
        """Give up the goal configuration the last path ended at (its grasp cannot be completed in that
        posture): it and the goal-tree nodes below it leave the search."""
        self.search.goal.cut(self.search.goal_roots[self.search.reached])

    def cycle(self, targets: list[GraspTarget]) -> tuple[int, GraspTarget] | None:
        """One cycle (_cycle), its configuration checks counted (the arm's share between it and the fast path)."""
        stats = self.arm.motion.checker.stats
        before = stats.configs_checked
        try:
            return self._cycle(targets)
        finally:
            self.checks += max(1, stats.configs_checked - before)  # >= 1: a cycle without checks costs a turn

    def _cycle(self, targets: list[GraspTarget]) -> tuple[int, GraspTarget] | None:
        """One RRT-Connect cycle (or IK batch); the arm's tree node holding the grasp once the trees meet."""
        arm = self.arm
        self.cycles += 1
        wanted = tuple(sorted(id(t) for t in targets))
        if self.search is None or wanted != self._for:
            self._for = wanted
            self._cut_before = self.cut_edges
            # a new goal tree; the start tree's proven edges stay proven
            self.search = LazyConnectSearch(self.rrt, self.start, np.empty((0, len(arm.q_start))),
                                            valid={self.start: self._start_valid})
            self.goal_targets, self._far = [], []
            if arm.hints is not None:
                live = arm._live_hints(targets)
                self._add(arm.hints[live], [arm._by_index[int(arm.hint_targets[k])] for k in live])
        if self._far and self.cycles >= EXIT_AFTER_CYCLES:
            self._draw_far()
        every = FALLBACK_IK_EVERY if self.goal_targets else FALLBACK_IK_EVERY // 4  # sooner while it has none
        # with goal configurations (the hints) it first searches: a batch of IK costs ~25 ms (Panda), as
        # much as a whole plan into an open shelf
        phase = 0 if self.goal_targets else 1 % every
        if self.cycles % every == phase and len(self.goal_targets) < arm.opt.max_goal_configs:
            q, which = arm.ik(targets, arm.motion.check_configs, self.rng)
            free = arm.motion.check_configs(q) if len(q) else np.zeros(0, dtype=bool)
            self._add(q[free], [targets[int(w)] for w in which[free]])
            return None
        path = self.search.cycle()
        if path is None:
            return None
        target = self.goal_targets[self.search.reached]
        end = arm.tree.add(path[1:], 0, arm.kin.fk(path[1:]), np.ones(len(path) - 1, dtype=bool))
        return end, target
