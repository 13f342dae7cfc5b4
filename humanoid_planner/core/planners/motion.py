"""Straight-line motions checked with a guarantee, not a hope.

A motion q0 → q1 is checked at samples close enough that no point of the robot moves more than
`max_point_motion` (m) between two consecutive samples. How far a point of a link may move is
bounded per link (the checker's prefilter unit) by Σ_j |Δq_j| · r_uj, r_uj bounding the distance
of the unit's points from joint j's axis (CollisionChecker.unit_levers, triangle inequality along the
chain). Two samples whose clearances are c_a and c_b cover the motion between them when c_a + c_b is
at least how far a point may move from one to the other — relative to the scene, or for two links
relative to each other (at most the sum of their bounds: the joints between them are a subset). So
every sample keeps half of its unit's bound more than the required clearance, against the scene
and the fixed links, and the sum of both halves between two moving links (the checker's edge
margins): every configuration between two samples is then free too, and a path that passes here
passes an exact check at any resolution.

The margins are asked of the samples between configurations, never of the configurations
themselves: whether a start, a goal or a tree node collides is decided with the user's padding
only (``check_configs``). A sample that is free but misses its margins is *tight*: a start 0.8 mm
from a table, a grasp next to an obstacle, Baxter's elbow cylinders 10 µm apart at its zero pose,
or a motion that passes a few millimetres from a box on its way (TALOS's gripper between two boxes,
iCub's chest sliding over its root link as the torso turns). Such a run of samples is checked again
without the margins, and every interval next to a tight sample is bisected, each half asking half
the margins of its ends; a half whose ends both keep them is free (the guarantee above). What is
still unproven then (a passage a few millimetres wide; links that slide along each other a hair
apart keep no margin at any scale) is decided by the exact check of its points, 1/2**MAX_REFINE of
a sample interval apart (≤ 1.9 mm of point motion, ≤ 0.0025 rad at the defaults): a discrete check,
8× finer than the edge resolution and 4× finer than core.verification's. A run is refined where the
motion passes close by (samples that keep their margins follow it) or where it holds a configuration
the problem gives (or one a search reached from one through tight samples). A run that leads into
a collision, or that ends the motion at a configuration the search made up, blocks before it: the
search places its own nodes elsewhere.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from humanoid_planner.core.collision.checker import coarse_to_fine
from humanoid_planner.core.planners import kernels as search_kernels


MAX_REFINE = 3
"""An interval next to a tight sample is decided, where no margin proves it, by its points 1/2**MAX_REFINE
of it apart (1/8 of its motion, ~2 mm at the default 1.5 cm), each checked without margins."""

PROOF_LEVELS = 1
"""Of those bisections, the ones whose points are checked with margins (the proof); the points of what
is still unproven after them are checked without margins, 1/2**MAX_REFINE of an interval apart. The
verdict does not depend on it (a proven piece's points are all free; a piece holding a point that
collides is never proven), only the cost: deeper proof levels re-check the same points with ever
smaller margins, and mostly prove nothing where one level did not. Measured over 22 Panda plans
(shelves, cage, under a table): 1, 2, 3 levels check 8.7k, 9.3k, 12.0k configurations in the
refinement, 645, 1007, 1323 of them through FCL; TALOS: 374, 469, 556 through FCL."""


class MotionValidator:
    """Configurations and straight motions of one group (or concatenated groups) against a checker
    built with margin >= max_point_motion / 2."""

    def __init__(self, checker, max_point_motion: float, chunk: int = 96, first_chunk: int = 16):
        """Samples are checked in batches of `chunk`; while most of the checker's verdicts need exact
        FCL (meshes the sphere covers cannot decide: ~0.1 ms each), batches start at first_chunk and
        double, so a blocked motion stops after few checks. Measured: TALOS table_shelf 3.3k instead
        of 5.1k checks per plan (median, same searches); on armar3, where spheres decide almost
        everything, small batches cost more in numpy calls than they save (boxes6 median 121 vs 101 ms)."""
        if max_point_motion <= 0:
            raise ValueError("max_point_motion must be > 0")
        if checker.margin < max_point_motion / 2 - 1e-12:
            raise ValueError("the checker's margin must be at least max_point_motion / 2")
        self.checker = checker
        self.levers = checker.unit_levers.T  # (n, U)
        self._levers_rows = np.ascontiguousarray(self.levers, dtype=float)  # as the compiled sampling reads them
        self.max_point_motion = float(max_point_motion)
        self.resolution = float(checker.edge_resolution)
        self.chunk = chunk
        self.first_chunk = min(first_chunk, chunk)

    def _batches(self, n: int, first: int | None = None, costly: bool | None = None):
        """[lo, hi) ranges of n samples: first (default first_chunk) then doubling up to chunk while most
        checks are exact or colliding (a blocked motion then stops after few checks: Fetch's tucked start,
        where three configurations in four collide, checked 96 samples per blocked motion), else chunk.
        costly: whether to start small (None: from the checker's statistics, as above)."""
        st = self.checker.stats
        if costly is None:
            costly = 2 * (st.exact_checks + st.level2_colliding) > st.configs_checked
        lo, c = 0, (first or self.first_chunk) if costly else self.chunk
        while lo < n:
            yield lo, min(lo + c, n)
            lo, c = lo + c, min(2 * c, self.chunk)

    def check_configs(self, q: np.ndarray) -> np.ndarray:
        """(N, n) → (N,) bool: which configurations are collision-free (the user's padding only)."""
        return self.checker.check_configs(q)

    def steps(self, d: np.ndarray) -> np.ndarray:
        """Samples per segment for joint displacements d (M, n) (at least 1)."""
        d = np.abs(np.atleast_2d(d))
        if self.levers.shape[1]:
            # one broadcast product, not a BLAS call (slow for such small shapes when busy) nor a numpy
            # call per joint (a search computes this for every extension: 11k times per Fetch plan)
            moved = (d[:, :, None] * self.levers[None]).sum(axis=1).max(axis=1)
        else:
            moved = np.zeros(len(d))
        k = np.maximum(np.max(d, axis=1) / self.resolution, moved / self.max_point_motion)
        return np.maximum(1, np.ceil(k - 1e-9)).astype(np.int64)

    # ------------------------------------------------------------------ samples and their margins
    def _point_margins(self, pts: np.ndarray) -> np.ndarray:
        """(K, U) edge margins of consecutive samples pts (K, n): each keeps those of both its intervals."""
        gaps = self.checker.edge_margins(np.diff(pts, axis=0))
        z = np.zeros((1, gaps.shape[1]))
        return np.maximum(np.vstack([z, gaps]), np.vstack([gaps, z]))

    def _screen(self, pts: np.ndarray, margins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Consecutive samples with their margins, for a motion that must be free as a whole. Returns
        (free, tight): free = may be passed, tight = collision-free but not with the margins (checked
        again without them; _refine then decides the intervals next to them)."""
        ok = self.checker.check_configs(pts, margins)
        free, tight = ok.copy(), np.zeros(len(ok), dtype=bool)
        if not ok.all():
            tight[~ok] = self.checker.check_configs(pts[~ok])
            free |= tight
        return free, tight

    def _refine(self, pts: np.ndarray, tight: np.ndarray, known: np.ndarray) -> int:
        """Consecutive samples pts (K+1, n); tight marks those free only without their margins, known
        those screened (the others are checked here as needed). Bisects every interval next to a
        tight sample PROOF_LEVELS times (each half asking half the margins of its ends); the points of
        the pieces still unproven, 1/2**MAX_REFINE of a sample interval apart, are checked without
        margins. Returns the first interval that cannot be proven free (K: none).

        Each configuration is checked once per level, however many pieces it ends. A motion that slides
        along something a hair away keeps no margin at any level (Panda's hand 0.7 mm over a shelf
        board for five edges into a grasp): checking each piece's ends apart at each of three proof
        levels cost 39 checks per interval there, 11 now."""
        k = len(pts) - 1
        S = 1 << MAX_REFINE  # a point: (interval j, s / S of the way along it); s == S is (j + 1, 0)
        live = sorted({j for i in np.nonzero(tight)[0] for j in (i - 1, i) if 0 <= j < k})
        if not live:
            return k
        # the finest level whose margins a point keeps (it then keeps those of every finer level); the
        # screened samples that are not tight keep their own (level 0), the others none yet
        kept: dict[tuple[int, int], int] = {}
        for j in live:
            for i in (j, j + 1):
                if known[i] and not tight[i]:
                    kept[(i, 0)] = 0
        never = MAX_REFINE + 1

        def key(j: int, s: int) -> tuple[int, int]:
            return (j + 1, 0) if s == S else (j, s)

        pieces = [(j, 0, S) for j in live]  # unproven: (interval, from s, to s)
        for level in range(1, PROOF_LEVELS + 1):
            if not pieces:
                break
            want: dict[tuple[int, int], tuple[int, int, np.ndarray]] = {}
            # a piece after `level` bisections asks its interval's margins halved `level` times
            margins = dict(zip(live, self.checker.edge_margins((pts[np.add(live, 1)] - pts[live]) / (1 << level))))
            for j, lo, hi in pieces:
                for s in (lo, (lo + hi) // 2, hi):
                    p = key(j, s)
                    if kept.get(p, never) > level:
                        mar = margins[j]
                        if p in want:  # an end of two intervals: the margins of both
                            mar = np.maximum(mar, want[p][2])
                        want[p] = (j, s, mar)
            if want:
                todo = list(want.values())
                ok = self.checker.check_configs(np.array([self._point(pts, j, s, S) for j, s, _ in todo]),
                                                np.array([m for _, _, m in todo]))
                for p, good in zip(want, ok):
                    if good:
                        kept[p] = level
            pieces = [(j, a, b) for j, lo, hi in pieces for a, b in ((lo, (lo + hi) // 2), ((lo + hi) // 2, hi))
                      if kept.get(key(j, a), never) > level or kept.get(key(j, b), never) > level]
        if not pieces:
            return k
        # What no margin proved is decided by its points 1/S of an interval apart, checked without margins
        # (a point that keeps some margins is free; so is a screened tight sample).
        bare: dict[tuple[int, int], tuple[int, int]] = {}
        for j, lo, hi in pieces:
            for s in range(lo, hi + 1):
                p = key(j, s)
                if p not in kept and not (p[1] == 0 and known[p[0]] and tight[p[0]]):
                    bare.setdefault(p, (j, s))
        free: dict[tuple[int, int], bool] = {}
        if bare:
            ok = self.checker.check_configs(np.array([self._point(pts, j, s, S) for j, s in bare.values()]))
            free = dict(zip(bare, ok.tolist()))
        first = k
        for j, lo, hi in pieces:
            if not all(free.get(key(j, s), True) for s in range(lo, hi + 1)):
                first = min(first, j)
        return first

    @staticmethod
    def _point(pts: np.ndarray, j: int, s: int, S: int) -> np.ndarray:
        """The configuration s / S of the way along interval j of pts."""
        return pts[j] if s == 0 else pts[j + 1] if s == S else pts[j] + (s / S) * (pts[j + 1] - pts[j])

    def _first_blocked(self, pts: np.ndarray, ends: np.ndarray) -> tuple[int, np.ndarray]:
        """Consecutive samples pts (K+1, n), pts[0] taken as free, ends marking the configurations
        that may be tight: the first interval that is not free (K: none), and which samples are tight
        (free only without their margins). Screens in chunks; each run of samples that miss their
        margins is checked again without them, stopping at a collision, and taken as tight when the
        motion passes on out of it or an end lies in it (the module docstring)."""
        k = len(pts) - 1
        margins = self._point_margins(pts)
        ok = np.zeros(len(pts), dtype=bool)  # keeps its margins
        bare = np.zeros(len(pts), dtype=bool)  # free without them (known where a screened sample misses them)
        tight = np.zeros(len(pts), dtype=bool)
        batches = self._batches(len(pts))
        screened = 0

        def screen_past(i: int) -> bool:
            """Screen the next chunk if sample i is not screened yet (its samples that miss their margins
            are checked again without them, in one batch); False when every one is."""
            nonlocal screened
            if i < screened:
                return True
            if screened == len(pts):
                return False
            lo, hi = next(batches)
            ok[lo:hi] = self.checker.check_configs(pts[lo:hi], margins[lo:hi])
            miss = lo + np.flatnonzero(~ok[lo:hi])
            if len(miss):
                bare[miss] = self.checker.check_configs(pts[miss])
            screened = hi
            return True

        def next_with(i: int, keeps: bool) -> int:
            """The first sample from i on that keeps its margins (keeps) or misses them; len(pts): none."""
            while screen_past(i):
                hit = np.nonzero(ok[i:screened] == keeps)[0]
                if len(hit):
                    return i + int(hit[0])
                i = screened
            return len(pts)

        def run_from(a: int) -> tuple[int, bool]:
            """The run of samples from a that miss their margins but are free: (its end, whether that is
            a collision). The end is the first sample that keeps its margins (len(pts): none) or collides."""
            i = a
            while screen_past(i):
                hit = np.flatnonzero(ok[i:screened] | ~bare[i:screened])
                if len(hit):
                    j = i + int(hit[0])
                    return j, not ok[j]
                i = screened
            return len(pts), False

        blocked, a = k, 0
        while (a := next_with(a, False)) < len(pts):
            if a == 0 and not ends[0]:
                return 0, tight  # pts[0] misses its margins and may not be tight: the search placed it there
            b, hit = run_from(a)
            if hit:
                if not ends[a:b].any():
                    blocked = a - 1  # the run leads into an obstacle, not to or from an end: stop before it
                    break
                tight[a:b] = True  # a configuration the problem gives next to the obstacle (a grasp)
                blocked = b - 1
                break
            if b == len(pts) and not ends[a:].any():
                blocked = a - 1  # it ends next to something, at a configuration the search made up
                break
            tight[a:b] = True  # the motion passes close by (samples that keep their margins follow), or holds an end
            a = b
        if tight[:blocked + 2].any():
            e = min(blocked + 2, len(pts))
            blocked = min(blocked, self._refine(pts[:e], tight[:e], np.ones(e, dtype=bool)))
        return max(blocked, 0), tight

    def samples(self, q_from: np.ndarray, waypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q_from and the samples of q_from → waypoints (K+1, n), and the segment each ends (q_from: -1):
        `steps` per segment, evenly spaced; compiled (planners/kernels.polyline), as a search samples every
        extension, where numpy's calls cost more than checking the samples."""
        return search_kernels.polyline(np.ascontiguousarray(q_from, dtype=float),
                                       np.ascontiguousarray(np.atleast_2d(waypoints), dtype=float),
                                       self._levers_rows, self.resolution, self.max_point_motion)

    # ------------------------------------------------------------------ motions
    def free_prefix(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                    tight_to: bool = True) -> int:
        """How many leading waypoints of the polyline q_from → waypoints[0] → … are reachable
        collision-free (q_from taken as a free configuration). Samples are checked in order, in
        batched chunks, stopping at the first chunk with a collision.

        tight_from / tight_to: may q_from / the last waypoint be tight (free, but within the edge
        margins of something), so that the motion next to it is refined? Yes for configurations the
        problem gives (a start, a grasp's IK solution, a reached grasp) and for those a search reached
        from them through tight samples (`free_prefix_tight`); a search passes False for the ones it
        makes up elsewhere (a tree node, a random sample), which it can place elsewhere. Measured
        on G1 boxes6: a tree Connect that stopped next to a box then re-checked ~16 samples without
        margins and bisected ~30 more before making no progress, two thirds of a blocked Connect's
        checks."""
        return self.free_prefix_tight(q_from, waypoints, tight_from, tight_to)[0]

    def free_prefix_tight(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                          tight_to: bool = True) -> tuple[int, np.ndarray]:
        """free_prefix, and which of the reachable waypoints are tight ((k,) bool): those lie in a
        stretch of samples that keep no margin (next to a tight end, links that slide along each
        other, a motion passing close by something), so a search may take them as tight ends too and
        walk on out of the stretch."""
        if len(waypoints) == 0:
            return 0, np.zeros(0, dtype=bool)
        pts, seg = self.samples(q_from, waypoints)
        ends = np.zeros(len(pts), dtype=bool)
        ends[[0, -1]] = tight_from, tight_to  # where a motion starts or ends; not each waypoint (a tree's steps)
        j, tight = self._first_blocked(pts, ends)
        k = len(waypoints) if j == len(pts) - 1 else int(seg[j + 1])
        at = np.searchsorted(seg, np.arange(k), side="right") - 1  # the sample of each waypoint
        return k, tight[at]

    def edges_keep_margins(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """Per straight motion A[i] → B[i]: does every one of its samples, both ends included, keep its edge
        margins? One batched check for them all. Such a motion is free by free_prefix's guarantee with
        nothing tight to refine, exactly as free_prefix(A[i], [B[i]]) would find it; a motion that does not
        may still be free (tight ends, refinement): free_prefix decides it. For a lazy search's path,
        whose edges nearly all keep their margins: one call instead of one per edge (Panda cage, ~80 edges
        per path: its validation 81 → 63 ms per plan; what is left is the few tight edges by the grasp)."""
        parts = [self.samples(a, b[None])[0] for a, b in zip(A, B)]
        if not parts:
            return np.zeros(0, dtype=bool)
        ok = self.checker.check_configs(np.vstack(parts), np.vstack([self._point_margins(p) for p in parts]))
        return np.logical_and.reduceat(ok, np.cumsum([0] + [len(p) for p in parts[:-1]]))

    def polylines_free(self, polylines: Sequence[np.ndarray]) -> bool:
        """Are all these polylines ((m, n) each, the first point included) free? One batched check
        (the few tight samples, if any, are then refined per polyline)."""
        polylines = [np.asarray(p, dtype=float) for p in polylines if len(p)]
        if not polylines:
            return True
        if not self.check_configs(np.vstack([p[:1] for p in polylines])).all():
            return False
        parts = [self.samples(p[0], p[1:])[0] for p in polylines if len(p) > 1]
        if not parts:
            return True
        for p, x in zip([p for p in polylines if len(p) > 1], parts):
            free, tight = self._screen(x, self._point_margins(x))
            free[0] = True  # the first points were decided above; only how they are left counts
            if not free.all() or (tight.any() and self._refine(x, tight, np.ones(len(x), bool)) < len(x) - 1):
                return False
        return True

    def check_edge(self, q0: np.ndarray, q1: np.ndarray, first: int | None = None) -> bool:
        """Is the straight motion q0 → q1 free (q0 taken as a free configuration)? Coarse-to-fine
        (q0 is in the first batch only to learn whether it is tight), early exit at a collision.
        first: samples in the first batch (then doubling) whatever the checks cost so far, for callers
        whose motions are mostly blocked (shortcut candidates); None: `_batches`' choice."""
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        n = int(self.steps((q1 - q0)[None])[0])
        order = np.r_[0, coarse_to_fine(n)]
        step = (q1 - q0) / n
        margins = self.checker.edge_margins(step)
        ok = np.ones(n + 1, dtype=bool)
        for lo, hi in self._batches(n + 1, first, True if first else None):
            k = order[lo:hi]
            ok[k] = self.checker.check_configs(q0 + k[:, None] * step, np.repeat(margins, len(k), axis=0))
            miss = k[~ok[k] & (k > 0)]
            if len(miss) and not self.checker.check_configs(q0 + miss[:, None] * step).all():
                return False  # a sample collides
        if ok.all():
            return True
        # samples that are free but miss their margins (an end, or the motion passes close by
        # something): refine next to them. The batches above screened every sample and proved each
        # one past q0 that misses its margins free without them, so they are tight as they stand
        # (screening the motion again would repeat the exact check of every tight sample: 10-30 % of
        # the exact checks of free shortcut edges in Panda's MotionBenchMaker cage).
        tight = ~ok
        if tight[0]:
            tight[0] = bool(self.checker.check_configs(q0[None])[0])
        pts = q0 + np.arange(n + 1)[:, None] * step
        return bool(not tight.any() or self._refine(pts, tight, np.ones(n + 1, bool)) == n)


LAZY_FIRST_CHUNK = 4
"""Samples in a lazy extension's first batch while checks are costly (then doubling, as
MotionValidator._batches). The checker stops at the first colliding sample inside a batch too
(CollisionChecker.first_collision); a batch bounds how far it checks past a sample only FCL can decide
before FCL decides it: a lazy search in clutter is mostly blocked at once (Fetch's small shelves and
cage, MotionBenchMaker: 3 extensions in 4 stop in their first 0.1 rad)."""


class LazyMotion:
    """What a lazy search grows its trees with: the validator's own samples (`MotionValidator.steps`),
    each decided by the checker with the user's padding only — no margins, no refinement, every
    configuration a valid motion end however close to something. A plain sampling planner's check,
    so a search on it is exactly as complete as the reference RRT-Connect; its paths are not proven
    between samples, so a path found on it counts only once `validate_edge` (the validator, both
    ends taken as tight) accepted each of its edges. Same interface as MotionValidator's search calls."""

    def __init__(self, validator: MotionValidator):
        self.validator = validator
        self.checker = validator.checker

    def check_configs(self, q: np.ndarray) -> np.ndarray:
        return self.validator.check_configs(q)

    def free_prefix_tight(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                          tight_to: bool = True) -> tuple[int, np.ndarray]:
        """How many leading waypoints of q_from → waypoints[0] → … have every sample free (q_from taken
        as free), in the validator's batches with an early stop; no waypoint tight (tight_*: unused)."""
        if len(waypoints) == 0:
            return 0, np.zeros(0, dtype=bool)
        v = self.validator
        pts, seg = v.samples(q_from, waypoints)
        bad = self.checker.first_collision(pts[1:], list(v._batches(len(pts) - 1, LAZY_FIRST_CHUNK)))
        k = len(waypoints) if bad == len(pts) - 1 else int(seg[bad + 1])  # the waypoints before the segment of the first collision
        return k, np.zeros(k, dtype=bool)

    def free_prefix(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                    tight_to: bool = True) -> int:
        return self.free_prefix_tight(q_from, waypoints)[0]

    def check_edge(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        return self.free_prefix(q0, np.asarray(q1, float)[None]) == 1

    def validate_edge(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        """Is q0 → q1 free by the validator's guarantee? Both ends are configurations checked free,
        so both may be tight: the margins are asked of the samples between them only."""
        return self.validator.free_prefix(q0, np.asarray(q1, float)[None], True, True) == 1

    def first_invalid_edge(self, A: np.ndarray, B: np.ndarray) -> int:
        """The first of the motions A[i] → B[i] validate_edge refuses (len(A): none), all screened in one
        batch first (MotionValidator.edges_keep_margins): only those that miss a margin there go to
        validate_edge, in order."""
        keeps = self.validator.edges_keep_margins(A, B)
        for i in np.flatnonzero(~keeps):
            if not self.validate_edge(A[i], B[i]):
                return int(i)
        return len(A)


class SampledMotion:
    """The reference: what a plain sampling planner checks (MoveIt's and OMPL's discrete motion
    validation): samples no farther apart than the checker's edge_resolution, each decided by the
    checker with the user's padding only, nothing asked of what lies between them. No margins,
    no guarantee between samples: for measuring the planners' completeness (what a plain
    RRT-Connect solves), not for plans. Same interface as MotionValidator's search calls."""

    def __init__(self, checker):
        self.checker = checker

    def check_configs(self, q: np.ndarray) -> np.ndarray:
        return self.checker.check_configs(q)

    def check_edge(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        return self.checker.check_edge(q0, q1)

    def free_prefix(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                    tight_to: bool = True) -> int:
        """How many leading waypoints of q_from → waypoints[0] → … are reachable (tight_*: unused)."""
        prev = np.vstack([np.asarray(q_from, float)[None], np.asarray(waypoints, float)[:-1]])
        for k, (a, b) in enumerate(zip(prev, waypoints)):
            if not self.checker.check_edge(a, b):
                return k
        return len(waypoints)

    def free_prefix_tight(self, q_from: np.ndarray, waypoints: np.ndarray, tight_from: bool = True,
                          tight_to: bool = True) -> tuple[int, np.ndarray]:
        """free_prefix, and no waypoint tight (this check keeps no margins to be tight within)."""
        k = self.free_prefix(q_from, waypoints)
        return k, np.zeros(k, dtype=bool)
