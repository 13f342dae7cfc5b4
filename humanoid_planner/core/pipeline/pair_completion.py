"""DAGRRT's pair completed as MoveIt's pick completes one grasp: both hands approach at once (each along its
own line; the shorter waits at its end), then retreat by the same world displacement with the object in
the hands.

The pair is completed when DAGRRT pairs it (its `complete` hook: `PairCompleter.complete`), from the
exact pre-grasp poses; a pair whose lines fail in the reached postures is tried in other postures of
its two grasps (`pair_other_postures`, from each arm's `Completion.postures`), and skipped when none
works. `PairCompleter` owns what the pairing learns on the way: the completed pairs, why the others
failed, and the validators it builds (the pair's, and the ones with the object in the hands).
"""
from __future__ import annotations

import functools
from collections import Counter
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.pipeline.completion import BRANCH_TRIES, Completion, GraspLines, pre_grasp_targets, world_direction
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.pipeline.problem import DualProblem, HeldMotions, ProblemBuilder
from humanoid_planner.core.planners.cartesian import (STEER_TOL_POS, STEER_TOL_ROT, GripperTranslation, LineResult,
                                                      parallel_lines, straight_line)
from humanoid_planner.core.planners.common import GraspTarget, Outcome
from humanoid_planner.core.planners.motion import MotionValidator


@dataclass(frozen=True)
class PairLines:
    """The pair's accepted lines: both hands' approach waypoints at once, then the two-handed retreat."""

    approach: np.ndarray  # (a, n_left + n_right), the pre-grasp configuration excluded
    approach_distance: float
    retreat: np.ndarray  # (r, n_left + n_right), the grasp configuration excluded
    retreat_distance: float


@dataclass(frozen=True)
class PairSides:
    """The two arms' side of the pair lines: kinematics, motion limits, and the IK inverse the lines use."""

    kins: tuple
    limits: tuple
    inverse: str = "wln"


def pair_lines(sides: PairSides, q_ends, approach_dirs, approach: GripperTranslation | None,
               pair_motion: MotionValidator, retreat: GripperTranslation | None, retreat_dir: np.ndarray | None,
               held_motion: MotionValidator | None) -> Outcome[PairLines]:
    """DAGRRT's pair: from both pre-grasp configurations (exact), both approach lines at once (the
    shorter waits), then the retreat of both TCPs by the same displacements; or why not."""
    appr = np.zeros((0, sum(len(q) for q in q_ends)))
    a_dist = 0.0
    q_grasp = list(q_ends)
    if approach is not None and approach.desired_distance > 0:
        lines = [straight_line(k, q, d, approach.desired_distance, lo, hi, inverse=sides.inverse)
                 for k, q, d, (lo, hi) in zip(sides.kins, q_ends, approach_dirs, sides.limits)]
        if any(line.reason != "complete" for line in lines):
            bad = [line for line in lines if line.reason != "complete"][0]
            return Outcome.rejected(f"the straight approach of the paired grasps stops after {bad.distance * 100:.1f} cm "
                                    f"({bad.reason})")
        appr = pair_approach([line.waypoints for line in lines], np.concatenate(q_ends), pair_motion)
        if appr is None:
            return Outcome.rejected("the straight approach of the paired grasps is blocked")
        a_dist = approach.desired_distance
        q_grasp = [line.waypoints[-1] for line in lines]
    back = pair_retreat(sides, q_grasp, retreat, retreat_dir, held_motion)
    if not back.ok:
        return Outcome.rejected(back.reason)
    return Outcome.accepted(PairLines(appr, a_dist, *back.value))


def pair_approach(lines: Sequence[np.ndarray], q0: np.ndarray, pair_motion: MotionValidator) -> np.ndarray | None:
    """Both hands' approach waypoints at once (the shorter line waits at its end), or None when the
    pair's motion is blocked."""
    m = max(len(w) for w in lines)
    if m == 0:
        return np.zeros((0, len(q0)))
    appr = np.hstack([np.vstack([w, np.repeat(w[-1:], m - len(w), axis=0)]) for w in lines])
    return appr if pair_motion.free_prefix(q0, appr) == len(appr) else None


def pair_retreat(sides: PairSides, q_grasp, retreat: GripperTranslation | None, retreat_dir: np.ndarray | None,
                 held_motion: MotionValidator | None) -> Outcome[tuple[np.ndarray, float]]:
    """Both TCPs lifted by the same world displacement from the grasp configurations (at least
    min_distance): (waypoints, distance), or why not."""
    if retreat is None or retreat.desired_distance <= 0:
        return Outcome.accepted((np.zeros((0, sum(len(q) for q in q_grasp))), 0.0))
    rl = parallel_lines(list(sides.kins), q_grasp, retreat_dir, retreat.desired_distance, list(sides.limits),
                        validate=held_motion.free_prefix if held_motion is not None else None, inverse=sides.inverse)
    if rl.distance < retreat.min_distance - 1e-9:
        return Outcome.rejected(f"the two-handed retreat stops after {rl.distance * 100:.1f} cm ({rl.reason}), short of "
                                f"min_distance {retreat.min_distance * 100:.1f} cm")
    return Outcome.accepted((rl.waypoints, rl.distance))


def pair_other_postures(comps: Sequence[Completion], q_pair: np.ndarray, q_pre: Sequence[np.ndarray],
                        targets: Sequence[GraspTarget], pair_motion: MotionValidator,
                        retreat: GripperTranslation | None, retreat_dir: np.ndarray | None,
                        held_motion: MotionValidator | None) -> Outcome[tuple[np.ndarray, PairLines]]:
    """DAGRRT's pair whose lines fail in the reached postures (`pair_lines`), completed as GIRRT's
    grasps are (`Completion.accept`): per arm, the reached posture (when its own approach is free)
    and the other postures of its grasp (`Completion.postures`: approach free for >= min_distance);
    the combinations, nearest to the reached pair first (at most BRANCH_TRIES whose joint motion from
    q_pair is free), with both approaches at once and the two-handed retreat (same displacement).
    Accepted with (the pair's pre-grasp configuration, its lines); the approach distance is the
    shorter of the two hands' (each at least min_distance)."""
    sides = PairSides(tuple(c.kin for c in comps), tuple((c.lower, c.upper) for c in comps), comps[0].inverse)
    cands: list[list[GraspLines]] = []
    for comp, q, t in zip(comps, q_pre, targets):
        own: list[GraspLines] = []
        n = len(q)
        out = (comp.approach_line(q, t) if comp.distance(t) > 0
               else Outcome.accepted((np.zeros((0, n)), LineResult(np.zeros((0, n)), 0.0, "complete"))))
        if out.ok and out.value[1].reason == "complete":
            own.append(GraspLines(q[None], out.value[1].waypoints, out.value[1].distance, np.zeros((0, n)), 0.0))
        cands.append(own + comp.postures(t, q))
    q_ref = np.concatenate(q_pre)
    combos = sorted(((a, b) for a in range(len(cands[0])) for b in range(len(cands[1]))),
                    key=lambda ab: float(np.linalg.norm(np.concatenate([cands[0][ab[0]].settle[-1],
                                                                        cands[1][ab[1]].settle[-1]]) - q_ref)))
    tried = 0
    for a, b in combos:
        c = (cands[0][a], cands[1][b])
        if all(len(ci.settle) and np.array_equal(ci.settle[-1], q) for ci, q in zip(c, q_pre)):
            continue  # the reached pair itself: pair_lines failed on it
        qp = np.concatenate([ci.settle[-1] for ci in c])
        if not pair_motion.check_edge(q_pair, qp):
            continue
        tried += 1
        appr = pair_approach([ci.approach for ci in c], qp, pair_motion)
        if appr is not None:
            q_grasp = [ci.approach[-1] if len(ci.approach) else ci.settle[-1] for ci in c]
            back = pair_retreat(sides, q_grasp, retreat, retreat_dir, held_motion)
            if back.ok:
                return Outcome.accepted((qp, PairLines(appr, min(ci.approach_distance for ci in c), *back.value)))
        if tried >= BRANCH_TRIES:
            break
    return Outcome.rejected("no other posture of the two grasps completes the pair")


class PairCompleter:
    """The pair checks of one dual request: the pair's motion validators, DAGRRT's `complete` hook, and
    what it settled — per completed pair (left, right grasp index) its pre-grasp configuration and
    lines, and how often each reason made a pair incomplete."""

    def __init__(self, problem: DualProblem, builder: ProblemBuilder, approach: GripperTranslation | None,
                 retreat: GripperTranslation | None):
        """approach: None or a positive desired distance; retreat: as requested (None: no lift)."""
        self.problem, self.builder = problem, builder
        self.approach, self.retreat = approach, retreat
        r = builder.robot
        self.scene, self.groups, self.start, self.object_id = problem.scene, problem.groups, problem.start, problem.object_id
        self.tips = tuple(r.group(g).tip_link for g in self.groups)
        self.grasps = tuple({t.index: t for t in ts} for ts in problem.grasps)
        self.hands = r.hand_links(self.groups[0]) + r.hand_links(self.groups[1])
        idxs = [r.group_joint_indices(g) for g in self.groups]
        self.n_left = len(idxs[0])
        pre = [pre_grasp_targets(r, list(ts), approach, tip, self.start) for ts, tip in zip(problem.grasps, self.tips)]
        self.targets = tuple(ts for ts, _ in pre)  # what the arms aim at (GraspTarget.index keys the grasp)
        self.directions = tuple(d for _, d in pre)  # approach direction per grasp index (zeros without one)
        self.sides = PairSides(tuple(GroupKinematics(r, g, self.start) for g in self.groups),
                               tuple(r.motion_limits(i, self.start[i]) for i in idxs))
        self.completed: dict[tuple[int, int], tuple[np.ndarray, PairLines]] = {}
        self.incomplete: Counter[str] = Counter()
        self._postures: dict[int, Completion] = {}
        self._pair_motion: MotionValidator | None = None
        self._held = HeldMotions(builder, self.scene, self.groups, self.start, self.object_id, self.hands)

    @property
    def pair_motion(self) -> MotionValidator:
        """Both arms against everything, built when first needed: only the corner blends of the final
        trajectory and the pair's lines need it (each arm's path is checked by its own validator, the
        other arm at its start pose included; pairing checks only arm against arm: `cross_motion`)."""
        if self._pair_motion is None:
            self._pair_motion = self.builder.motion(self.scene, self.groups, self.start, self.object_id, self.hands)
        return self._pair_motion

    def cross_motion(self) -> MotionValidator:
        """DAGRRT's pairing validator: one arm's links against the other's only."""
        return self.builder.motion(self.scene, self.groups, self.start, self.object_id, self.hands, cross_only=True)

    @functools.lru_cache(maxsize=None)  # noqa: B019 - one completer per request; its grasps are few
    def held(self, left_index: int) -> MotionValidator:
        """Both arms with the object in the left hand at left grasp `left_index`, both hands touching."""
        return self._held.at(self.grasps[0][left_index].T_target)

    def postures(self, k: int) -> Completion:
        """Arm k's grasps' other IK postures (`Completion.postures`), for pairs whose lines fail; its
        own validator (a checker serves one thread, and the arm's search may run in another)."""
        if k not in self._postures:
            own = self.builder.arm(self.scene, self.groups[k], self.start, self.problem.grasps[k],
                                   np.random.default_rng(0), object_id=self.object_id)
            comp = Completion(own, self.approach, None, retry_shorter=False)
            comp.pre_targets(list(self.grasps[k].values()))
            self._postures[k] = comp
        return self._postures[k]

    def complete(self, q_pair: np.ndarray, lt: GraspTarget, rt: GraspTarget) -> Outcome[None]:
        """DAGRRT's hook: the pair's straight approach (both hands at once) and retreat (same
        displacement), from the exact pre-grasp poses; stored in `completed` when they work."""
        out = self._complete(q_pair, lt, rt)
        if not out.ok:
            self.incomplete[out.reason] += 1
        return out

    def _complete(self, q_pair: np.ndarray, lt: GraspTarget, rt: GraspTarget) -> Outcome[None]:
        pm = self.pair_motion
        nl = self.n_left
        settled = []
        for k, (q_k, t) in enumerate(((q_pair[:nl], lt), (q_pair[nl:], rt))):
            lo, hi = self.sides.limits[k]
            st = steer_to_pose(self.sides.kins[k], q_k, t.T_target, inverse="wln", tol_pos=STEER_TOL_POS,
                               tol_rot=STEER_TOL_ROT, max_iters=25, lower=lo, upper=hi)
            if not st.reached:
                return Outcome.rejected("a pre-grasp pose could not be held exactly")
            settled.append(st.last(q_k))
        q_pre = np.concatenate(settled)
        if pm.free_prefix(q_pair, q_pre[None]) < 1:
            return Outcome.rejected("the exact pre-grasp poses collide")
        r_dir, held_lt = None, None  # the lift's direction and motion validator (object in the hands)
        if self.retreat is not None:
            r_dir = world_direction(self.builder.robot, self.retreat, False, self.tips[0],
                                    self.grasps[0][lt.index].T_target, self.start)
            held_lt = self.held(lt.index)
        dirs = [self.directions[0].get(lt.index), self.directions[1].get(rt.index)]
        out = pair_lines(self.sides, settled, dirs, self.approach, pm, self.retreat, r_dir, held_lt)
        if out.ok:
            lines = out.value
        else:
            # as GIRRT's accept: other IK postures of the two grasps before the pair is given up
            other = pair_other_postures([self.postures(0), self.postures(1)], q_pair, settled, (lt, rt), pm,
                                        self.retreat, r_dir, held_lt)
            if not other.ok:
                return Outcome.rejected(out.reason)
            q_pre, lines = other.value
        self.completed[(lt.index, rt.index)] = (q_pre, lines)
        return Outcome.accepted()

    def failure(self) -> str:
        """Why pairs could not be completed, the most frequent reasons first ("" when none failed)."""
        return "; ".join(f"{why} ({n}x)" for why, n in self.incomplete.most_common(3))
