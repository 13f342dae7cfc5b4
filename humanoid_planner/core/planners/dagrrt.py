"""DAGRRT (DAGRRT paper, Alg. 1): two per-arm GRRTs run side by side; their grasp solutions are paired.

Each arm keeps searching after a solution (dropping the grasp it just reached, so the next
solution differs) and reports every new single-arm path. A new path is paired with every path the
other arm has found; a pair is accepted when GraspScore of the union of both hands' contacts is
above gs_min and the two motions, executed together on one timeline (CreatePath), do not collide
with each other. With two workers one arm runs in a worker process and the other in the planning
thread (plan_with_worker), or both in threads; with one (`workers=1`) they are interleaved, for
measuring the parallel speed-up.

Each arm's path is shortcut (DAGRRT paper, Fig. 7) by its own checker before it is paired, not the
14-DoF pair afterwards: a 7-DoF edge costs a quarter of a pair edge (the pair checks both arms
against everything), the shortened paths are as short (measured: same median length), and in
process mode the work runs in the arm's worker while the other arm still searches. The pairing
then checks the shortened motions arm against arm — what is executed is what was checked.
"""
from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from functools import partial
from typing import Callable, Iterator, Sequence

import numpy as np

from humanoid_planner.core.planners.arm_messages import Done, Found, Reachable, Solution
from humanoid_planner.core.planners.common import GraspTarget, Outcome, PlanResult, PlanStatus, Termination, substream
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.planners.grasp_rrt import GraspRRT
from humanoid_planner.core.postprocess.smoothing import SHORTCUT_FIRST_BATCH, smooth_path

SLICE_CYCLES = 25  # cycles per arm per turn when interleaving in one thread: short enough for both arms to progress
# together, long enough that the switch (a Termination per turn) costs nothing; changes seeded plans with workers=1
SHORTCUT_STREAM = 7  # appended to an arm's seed for its shortcutting generator: a label, not a knob (any value
# gives an independent generator, another value other seeded plans)


@dataclass
class ArmSolution:
    arm: int  # 0 = left, 1 = right
    path: np.ndarray
    target: GraspTarget
    shortcut: bool = False  # path already shortened by the arm (process workers do it before sending)
    by: GraspRRT | None = None  # the search in this process that found it (and shortcuts it)
    fallback: bool = False  # reached by the arm search's safety net (GraspRRT.found_by_fallback)


def shortcut_rng(seed) -> np.random.Generator:
    """The generator an arm shortcuts its solutions with, apart from its search's (same plan in every mode)."""
    return np.random.default_rng(substream(seed, SHORTCUT_STREAM))


def shortcut_arm_path(arm: GraspRRT, path: np.ndarray, rng: np.random.Generator, budget: float) -> np.ndarray:
    """One arm's solution shortened against everything but the other arm's motion (its own checker)."""
    return smooth_path(path, partial(arm.motion.check_edge, first=SHORTCUT_FIRST_BATCH), rng, budget,
                       arm.opt.smoothing_max_iterations)


def create_path(path_l: np.ndarray, path_r: np.ndarray) -> np.ndarray:
    """CreatePath: both arm paths on one timeline (normalized arc length), concatenated per point.

    The merged breakpoints include every vertex of both paths, so straight segments of the merged
    path are exactly the two arms' own (already collision-checked) segments executed together.
    """
    def arclen(p: np.ndarray) -> np.ndarray:
        d = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        return d / d[-1] if d[-1] > 0 else np.linspace(0.0, 1.0, len(p))

    sl, sr = arclen(path_l), arclen(path_r)
    s = np.unique(np.concatenate([sl, sr]))

    def at(p: np.ndarray, sp: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(s, sp, p[:, j]) for j in range(p.shape[1])], axis=1)

    return np.hstack([at(path_l, sl), at(path_r, sr)])


@dataclass(frozen=True)
class PairChecks:
    """What makes two arm solutions a pair: a score above min_score, motions that do not collide on
    one timeline, and (optional) a completion."""

    motion: Callable[[], MotionValidator]  # builds the validator of the two arms' motions together, when first needed
    score: Callable[[GraspTarget, GraspTarget], float]
    min_score: float
    complete: Callable[[np.ndarray, GraspTarget, GraspTarget], Outcome] | None = None
    """complete(q_end, left target, right target): whether a scored, collision-free pair can also be
    completed (straight approach and retreat: pipeline.pair_completion); a pair that cannot is skipped
    like a colliding one."""


class DAGRRT:
    """Dual-arm grasp planner over two GraspRRT searches: in two threads, interleaved, or one of them in a
    worker process (that arm is None here)."""

    def __init__(self, left: GraspRRT | None, right: GraspRRT | None, checks: PairChecks, workers: int = 2,
                 seeds: tuple = (None, None)):
        """checks: what makes two arm solutions a pair; seeds: the arms' seeds, for their shortcutting
        generators (in-process arms)."""
        self.arms = (left, right)
        self._shortcut_rngs = tuple(shortcut_rng(s) for s in seeds)
        self._pairing = checks.motion
        self._pair_motion: MotionValidator | None = None
        self.score = checks.score
        self.min_score = checks.min_score
        self.workers = workers
        self.pairs_tested = 0
        self.pairs_low_score = 0
        self.pairs_colliding = 0
        self.pairs_incomplete = 0
        self.complete = checks.complete

    def _arm_loop(self, k: int, term: Termination, stop: threading.Event, out: "queue.Queue[ArmSolution | None]") -> None:
        arm = self.arms[k]
        remaining = list(arm.targets)
        local = Termination(term.remaining(), stop, max_cycles=arm.opt.max_cycles)
        try:
            while remaining and not stop.is_set() and not term.should_stop():
                found = arm.search(local, remaining)
                if found is None:
                    break
                goal, target = found
                sol = ArmSolution(k, arm.tree.path_to(goal), target, by=arm, fallback=arm.found_by_fallback)
                self._shortcut(sol, term)  # here, not in the pairing thread: a checker serves one thread
                out.put(sol)
                remaining = [t for t in remaining if t.index != target.index]
        finally:
            out.put(None)  # this arm is done

    @property
    def pair_motion(self) -> MotionValidator:
        if self._pair_motion is None:
            self._pair_motion = self._pairing()
        return self._pair_motion

    def _shortcut(self, sol: ArmSolution, term: Termination) -> None:
        """Shorten an in-process arm's solution (with the checker of the search that found it, so only
        in that search's thread); the one-thread modes do it when a solution is first paired."""
        if not sol.shortcut:
            sol.path = shortcut_arm_path(sol.by, sol.path, self._shortcut_rngs[sol.arm], term.remaining())
            sol.shortcut = True

    def _pair(self, new: ArmSolution, others: list[ArmSolution], term: Termination) -> tuple[np.ndarray, ArmSolution, ArmSolution, float] | None:
        for o in others:
            left, right = (new, o) if new.arm == 0 else (o, new)
            self.pairs_tested += 1
            s = self.score(left.target, right.target)
            if not s > self.min_score:
                self.pairs_low_score += 1
                continue
            self._shortcut(left, term)
            self._shortcut(right, term)
            merged = create_path(left.path, right.path)
            if self.pair_motion.free_prefix(merged[0], merged[1:]) != len(merged) - 1:
                self.pairs_colliding += 1
                continue
            if self.complete is not None and not self.complete(merged[-1], left.target, right.target).ok:
                self.pairs_incomplete += 1
                continue
            return merged, left, right, s
        return None

    def plan(self, q_left: np.ndarray, q_right: np.ndarray, term: Termination,
             unreachable: Callable[[int], bool] | None = None, probe: float = 0.25) -> PlanResult:
        """Both arms in this process: two threads (workers >= 2) or interleaved slices (workers=1).
        unreachable/probe as in plan_with_worker, so every mode does the same work."""
        for arm, q in zip(self.arms, (q_left, q_right)):
            failed = arm.start(q)
            if failed is not None:
                failed.planning_time = term.elapsed()
                return failed
        sols: tuple[list[ArmSolution], list[ArmSolution]] = ([], [])
        prober = _Probe(unreachable, probe, term, sols, known=lambda k: self.arms[k].ik_reachable)
        stop = threading.Event()
        found = None
        if self.workers >= 2:
            out: queue.Queue = queue.Queue()
            threads = [threading.Thread(target=self._arm_loop, args=(k, term, stop, out), daemon=True) for k in (0, 1)]
            for t in threads:
                t.start()
            finished = 0
            while finished < 2 and found is None:
                try:
                    item = out.get(timeout=max(0.001, min(0.05, term.remaining())))
                except queue.Empty:
                    if term.should_stop() or prober():
                        break
                    continue
                if item is None:
                    finished += 1
                    continue
                sols[item.arm].append(item)
                found = self._pair(item, sols[1 - item.arm], term)
            stop.set()
            for t in threads:
                t.join()
        else:
            found = self._interleaved(term, sols, prober)
        if found is None and not term.cancel.is_set():
            prober(at_end=True)
        res = self._result(found, sols, term, sum(a.cycles for a in self.arms), sum(a.tree.size for a in self.arms))
        res.extra["unreachable"] = prober.hopeless
        return res

    def _result(self, found, sols, term: Termination, cycles: int, size: int, errors=()) -> PlanResult:
        res = PlanResult(PlanStatus.SUCCESS, iterations=cycles, tree_size=size, planning_time=term.elapsed(),
                         extra={"fallback_cycles": sum(a.fallback.cycles for a in self.arms
                                                       if a is not None and a.fallback is not None),
                                "pairs_tested": self.pairs_tested, "pairs_low_score": self.pairs_low_score,
                                "pairs_colliding": self.pairs_colliding, "pairs_incomplete": self.pairs_incomplete,
                                "solutions": (len(sols[0]), len(sols[1]))})
        if found is None:
            if term.cancel.is_set():  # cancelled (shutdown, watchdog): say so, whatever the pairs scored
                res.status, res.message = PlanStatus.CANCELLED, "cancelled"
            elif errors:
                res.status = PlanStatus.INTERNAL_ERROR
                res.message = "internal error: the arm search failed: " + "; ".join(errors)
            elif self.pairs_tested and self.pairs_low_score == self.pairs_tested:
                res.status = PlanStatus.GRASP_QUALITY_TOO_LOW
                res.message = f"no pair of reached grasps scores above {self.min_score} ({self.pairs_tested} pairs tried)"
            else:
                res.status = term.stop_status()
                res.message = (f"no compatible pair of arm motions found (left {len(sols[0])}, right {len(sols[1])} "
                               f"solutions, {self.pairs_colliding} colliding pairs"
                               + (f", {self.pairs_incomplete} pairs whose straight approach or retreat failed"
                                  if self.pairs_incomplete else "") + ")")
            return res
        merged, left, right, s = found
        res.path = merged
        res.target = left.target
        res.extra.update(right_target=right.target, grasp_score=s)
        if left.fallback or right.fallback:
            res.extra["fallback"] = "rrt_connect"
        return res

    def plan_with_worker(self, run, q_start: tuple[np.ndarray, np.ndarray], remote_targets: list[GraspTarget],
                         term: Termination, unreachable: Callable[[int], bool] | None = None, probe: float = 0.25,
                         idle: Sequence[Callable[[], object]] = (),
                         helper: Callable[[], GraspRRT] | None = None) -> PlanResult:
        """The same pairing, with the arm that is None in self.arms searched by a worker process
        (`run`: pipeline.arm_process.ArmRun of its job, already started) and the other here, one cycle at a
        time between looks at the worker's messages.

        While this arm has a solution and the remote one none, this thread does not search on (the
        interleaved mode's rule: turns go to the arm without one); it prepares the pairing instead —
        shortcuts its solution, builds the pair checker, runs the caller's `idle` work — and then
        helps: `helper()` is a second search of the remote arm (its own random stream), started from
        the IK hints the worker sent, whose solutions count like the worker's (OR-parallelism, as
        OMPL's ParallelPlan: the first path wins).
        Start states within the limits were checked by the caller; the worker sends its solutions
        shortcut. An arm without a solution after `probe` seconds is tested once with
        `unreachable(k)`; if it is, the search stops and extra["unreachable"] = k.
        """
        r = self.arms.index(None)
        loc = 1 - r
        arm = self.arms[loc]
        sols: tuple[list[ArmSolution], list[ArmSolution]] = ([], [])
        by_index = {t.index: t for t in remote_targets}
        hints: list[tuple[np.ndarray, np.ndarray]] = []  # the worker's IK hints, once it sent them
        prober = _Probe(unreachable, probe, term, sols, known=lambda k: arm.ik_reachable if k == loc else bool(hints))
        failed = arm.start(q_start[loc])
        if failed is not None:
            failed.planning_time = term.elapsed()
            return failed
        remaining = list(arm.targets)
        chores = self._idle_chores(sols[loc], term, idle)
        helping: GraspRRT | None = None
        help_left = list(remote_targets)
        found, errors = None, []
        while found is None and not term.should_stop() and prober() is None:
            if run.finished and (not sols[r] or not remaining):
                break  # the worker's arm ended without a solution, or neither arm has anything left
            local_turn = bool(remaining) and not (sols[loc] and not sols[r])
            chore = not local_turn and next(chores, False)
            if not (local_turn or chore) and helper is not None and hints and helping is None and not sols[r]:
                helping = helper()
                if helping.start(q_start[r]) is None:
                    helping.adopt_hints(*hints[0])
                else:
                    help_left = []
            help_turn = not (local_turn or chore) and helping is not None and bool(help_left) and not sols[r]
            busy = local_turn or chore or help_turn
            for k, msg in run.events(0.0 if busy else min(0.05, term.remaining())):
                if isinstance(msg, Solution):
                    sol = ArmSolution(r, msg.path, by_index[msg.target_index], shortcut=True, fallback=msg.fallback)
                    sols[r].append(sol)
                    found = self._pair(sol, sols[loc], term)
                    if found is not None:
                        break
                elif isinstance(msg, Found):  # score it while the arm process shortcuts the path (memoized)
                    theirs = by_index[msg.target_index]
                    for mine in sols[loc]:
                        self.score(*((mine.target, theirs) if loc == 0 else (theirs, mine.target)))
                elif isinstance(msg, Reachable):
                    hints.append((msg.hints, msg.hint_targets))
                elif isinstance(msg, Done) and msg.error:
                    if msg.status is not None and msg.status != PlanStatus.PLANNING_FAILED.value:
                        return PlanResult(PlanStatus(msg.status), msg.error, planning_time=term.elapsed())
                    errors.append(msg.error)
            if found is not None or not (local_turn or help_turn):
                continue
            searcher, todo, side = (arm, remaining, loc) if local_turn else (helping, help_left, r)
            hit = searcher.search(Termination(term.remaining(), term.cancel, max_cycles=searcher.cycles + 1), todo)
            if hit is None:
                if searcher.cycles >= searcher.opt.max_cycles:
                    todo.clear()
                continue
            goal, target = hit
            sol = ArmSolution(side, searcher.tree.path_to(goal), target, by=searcher, fallback=searcher.found_by_fallback)
            sols[side].append(sol)
            todo[:] = [t for t in todo if t.index != target.index]
            found = self._pair(sol, sols[r] if side == loc else sols[loc], term)
        if found is None and not term.cancel.is_set():
            prober(at_end=True)
        cycles, size, _ = run.stats()[0]
        extra_c, extra_s = (helping.cycles, helping.tree.size) if helping is not None and helping.tree else (0, 0)
        res = self._result(found, sols, term, arm.cycles + cycles + extra_c, arm.tree.size + size + extra_s, errors)
        res.extra["unreachable"] = prober.hopeless
        res.extra["helper_cycles"] = extra_c
        return res

    def _idle_chores(self, mine: list[ArmSolution], term: Termination,
                     extra: Sequence[Callable[[], object]]) -> Iterator[bool]:
        """One piece of the work a pairing will need per step (each a few ms), for the waiting thread.
        (Scoring this arm's grasps against all remote ones ahead was tried: 8 Qhull runs delay the
        helper search by 19 ms to save 2.4 ms per pair tested.)"""
        extra = list(extra)
        while True:
            todo = next((s for s in mine if not s.shortcut), None)
            if todo is not None:
                self._shortcut(todo, term)
            elif self._pair_motion is None:
                self.pair_motion  # noqa: B018 (builds it)
            elif extra:
                extra.pop(0)()
            else:
                return
            yield True

    def _interleaved(self, term: Termination, sols, prober: "_Probe") -> tuple | None:
        remaining = [list(a.targets) for a in self.arms]
        while not term.should_stop() and any(remaining) and prober() is None:
            for k, arm in enumerate(self.arms):
                if not remaining[k] or (sols[k] and not sols[1 - k] and remaining[1 - k]):
                    continue  # nothing left, or this arm has a solution and the other none: all turns to it
                local = Termination(term.remaining(), term.cancel, max_cycles=arm.cycles + SLICE_CYCLES)
                found = arm.search(local, remaining[k])
                if found is None:
                    if local.max_cycles is not None and arm.cycles < local.max_cycles and not term.should_stop():
                        remaining[k] = []  # this arm has nothing left to reach
                    continue
                goal, target = found
                sol = ArmSolution(k, arm.tree.path_to(goal), target, by=arm, fallback=arm.found_by_fallback)
                sols[k].append(sol)
                remaining[k] = [t for t in remaining[k] if t.index != target.index]
                pair = self._pair(sol, sols[1 - k], term)
                if pair is not None:
                    return pair
        return None


class _Probe:
    """Reachability probe shared by every mode: an arm still without a solution `after` seconds
    into the request is tested once with `unreachable(k)` (batched IK, collisions ignored), so a
    grasp set no arm configuration reaches fails in well under a second, not at the timeout. Arms
    whose IK hints already found a solution (`known(k)`) are not tested."""

    def __init__(self, unreachable: Callable[[int], bool] | None, after: float, term: Termination,
                 sols: tuple[list[ArmSolution], list[ArmSolution]], known: Callable[[int], bool] | None = None):
        self.unreachable, self.after, self.term, self.sols = unreachable, after, term, sols
        self.known = known
        self.tested: set[int] = set()
        self.hopeless: int | None = None

    def __call__(self, at_end: bool = False) -> int | None:
        """The arm found unreachable (now or before), else None. at_end: the search ended without a pair
        (before `after`, too): an arm without a solution is tested now, so the answer says why, however
        fast the arms gave up."""
        if self.hopeless is not None or self.unreachable is None or (self.term.elapsed() < self.after and not at_end):
            return self.hopeless
        for k in (0, 1):
            if not self.sols[k] and k not in self.tested and not (self.known is not None and self.known(k)):
                self.tested.add(k)
                if self.unreachable(k):
                    self.hopeless = k
                    break
        return self.hopeless
