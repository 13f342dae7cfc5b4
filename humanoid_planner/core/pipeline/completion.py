"""Completing a grasp as MoveIt's pick does: a straight approach onto it and a retreat holding the object.

The planners aim at pre-grasp poses (each grasp backed off along its approach direction); when one
is reached, `Completion.accept` settles the TCP exactly on the pre-grasp pose, runs the straight line
onto the grasp (checked with the target object allowed to touch only the hand's links, like the
reach) and the retreat line from the grasp (the object attached to the TCP link, touching only the
hand, checked against the world and the rest of the robot). Whether the lines are free depends on
the arm's posture, so a grasp whose lines fail in the reached posture is first tried in other IK
postures (single arm: `postures`, joined to the reached configuration by a free joint motion);
failing that it is dropped — or retried once from the point the approach cleared, when that is still
at least `min_distance` — and the search goes on toward the others (GraspRRT's `accept` hook, also in
DAGRRT's arms). DAGRRT's pair is completed in pair_completion.py, from the same postures.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.ik.solver import solve_ik_batch
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.cartesian import (END_TOL_POS, LINE_STEP, STEER_TOL_POS, STEER_TOL_ROT, GripperTranslation,
                                                      LineResult, straight_line)
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.common import GraspTarget, Outcome, Verdict
from humanoid_planner.core.planners.motion import MotionValidator

BRANCH_SEEDS = 16  # IK starts per grasp when the reached posture's lines fail (the reached one first)
BRANCH_IK_ITERATIONS = 40  # most solutions converge by then; the slow rest are not needed (1/3 of the IK's cost)
BRANCH_TRIES = 6  # free solutions, nearest the reached posture first, whose lines are tried

Finish = Callable[[np.ndarray, int, MotionValidator], "str | None"]
"""finish(grasp configuration, grasp index, the search's validator): why the grasp cannot be completed
from there beyond its approach and retreat, or None."""


def world_direction(robot: RobotModel, gt: GripperTranslation, default_tcp: bool, tip: str, T_tcp: np.ndarray,
                    start: np.ndarray) -> np.ndarray:
    """gt's direction as a planning-frame unit vector: the TCP frame (T_tcp) for "" when
    default_tcp (approach) or for the TCP link; a robot link's frame at the start state."""
    d = gt.unit
    if gt.frame == tip or (gt.frame == "" and default_tcp):
        return T_tcp[:3, :3] @ d
    if gt.frame == "" or gt.frame == robot.root_link or gt.frame not in robot.link_names:
        return d  # the planning frame (validation.check_translation refused any other)
    return robot.link_poses(start, [gt.frame])[0][:3, :3] @ d


def backed_off(T: np.ndarray, direction: np.ndarray, distance: float) -> np.ndarray:
    """T moved `distance` back along the (world) approach direction: the pre-grasp pose."""
    out = np.array(T, dtype=float)
    out[:3, 3] -= distance * direction
    return out


def pre_grasp_targets(robot: RobotModel, targets: list[GraspTarget], approach: GripperTranslation | None, tip: str,
                      start: np.ndarray, distance: float | None = None) -> tuple[list[GraspTarget], dict[int, np.ndarray]]:
    """Each grasp target backed off along its approach direction (`distance`, default the desired
    one), and that world direction per GraspTarget.index (zero vectors without an approach)."""
    if approach is None:
        return list(targets), {t.index: np.zeros(3) for t in targets}
    D = approach.desired_distance if distance is None else distance
    dirs = {t.index: world_direction(robot, approach, True, tip, t.T_target, start) for t in targets}
    return [GraspTarget(t.index, t.grasp, backed_off(t.T_target, dirs[t.index], D)) for t in targets], dirs


@dataclass
class GraspLines:
    """The accepted lines of one grasp: pre-grasp settle steps, approach and retreat waypoints."""

    settle: np.ndarray  # (k, n) from the reached node to the exact pre-grasp pose
    approach: np.ndarray  # (a, n) waypoints onto the grasp (pre-grasp excluded)
    approach_distance: float
    retreat: np.ndarray  # (r, n) waypoints from the grasp (grasp excluded)
    retreat_distance: float


class Completion:
    """Approach + retreat for one arm's grasp targets (one per plan request)."""

    def __init__(self, problem: ArmProblem, approach: GripperTranslation | None, retreat: GripperTranslation | None,
                 retry_shorter: bool = True, repair_postures: bool = True, finish: Finish | None = None):
        """problem: the arm's (its `held` builds the retreat's validator; its targets are the grasps);
        retry_shorter: a blocked approach may be retried once, shorter (single arm; DAGRRT's arms
        keep the desired distance, so that the pair is completed with the targets they reached);
        repair_postures: try other IK postures of a grasp whose lines fail in the reached one;
        finish: what else must work from the grasp configuration (plan_place: the set-down and the
        retreat after the release), checked in the reached posture and in the others tried."""
        if problem.kin is None or problem.start is None:
            raise ValueError("Completion needs the arm's kinematics and start configuration")
        self.problem = problem
        self.robot, self.kin, self.start = problem.kin.robot, problem.kin, problem.start
        self.lower, self.upper, self.motion = problem.lower, problem.upper, problem.motion
        self.inverse = "wln"  # the lines' steering: weighted least-norm (joint limits), for GIRRT's and GRRT's arms alike
        self.approach, self.retreat, self.retry_shorter = approach, retreat, retry_shorter
        self.repair_postures = repair_postures
        self.finish = finish
        self.tip = problem.kin.tip_link
        self.grasp_of: dict[int, GraspTarget] = {}
        self.direction: dict[int, np.ndarray] = {}
        self.retried: set[int] = set()
        self.dropped: dict[int, str] = {}  # grasp index → why
        self.lines: dict[int, GraspLines] = {}  # grasp index → its accepted lines
        self._held: dict[int, MotionValidator] = {}
        self._posture_cache: dict[int, list[GraspLines]] = {}

    # ------------------------------------------------------------------ targets
    def pre_targets(self, targets: list[GraspTarget]) -> list[GraspTarget]:
        """The planners' targets: each grasp backed off by the approach's desired distance."""
        out, dirs = pre_grasp_targets(self.robot, targets, self.approach, self.tip, self.start)
        for t in targets:
            self.grasp_of[t.index] = t
            self.direction[t.index] = dirs[t.index]
        return out

    def fallback_targets(self, live: list[GraspTarget]) -> list[GraspTarget]:
        """Pre-grasps at min_distance for the live grasps still aimed at a longer approach: added
        when the desired pre-grasps are hard to reach (e.g. inside clutter)."""
        if self.approach is None or self.approach.min_distance >= self.approach.desired_distance:
            return []
        D = self.approach.min_distance
        return [GraspTarget(t.index, t.grasp, backed_off(self.grasp_of[t.index].T_target, self.direction[t.index], D))
                for t in live if self.distance(t) > D + 1e-9]

    def distance(self, t: GraspTarget) -> float:
        """How far target t is backed off from its grasp (the approach it stands for)."""
        return float(np.linalg.norm(self.grasp_of[t.index].T_target[:3, 3] - t.T_target[:3, 3]))

    def grasp_target(self, t: GraspTarget) -> GraspTarget:
        return self.grasp_of[t.index]

    # ------------------------------------------------------------------ lines
    def held_motion(self, index: int) -> MotionValidator:
        """The arm with the target attached to its TCP link at grasp `index` (no grasped object in
        the world any more): what the retreat is checked with. One per grasp, built once."""
        if index not in self._held:
            if self.problem.held is None:
                raise ValueError("the arm problem has no held-object validator (ProblemBuilder.arm builds one)")
            self._held[index] = self.problem.held(self.grasp_of[index].T_target)
        return self._held[index]

    def approach_line(self, q_node: np.ndarray, t: GraspTarget) -> Outcome[tuple[np.ndarray, LineResult]]:
        """From q_node (at pre-grasp target t, within tolerance): the steps that settle the TCP exactly on
        t, and the straight line from there onto the grasp, as far as it is free (its reason says why
        it stopped). Rejected when the pre-grasp cannot be held exactly or is blocked."""
        D = self.distance(t)
        settle = steer_to_pose(self.kin, q_node, t.T_target, inverse=self.inverse, tol_pos=STEER_TOL_POS,
                               tol_rot=STEER_TOL_ROT, max_iters=25, lower=self.lower, upper=self.upper)
        if not settle.reached:
            return Outcome.rejected("the pre-grasp pose could not be held exactly")
        if len(settle.steps) and self.motion.free_prefix(q_node, settle.steps) < len(settle.steps):
            return Outcome.rejected("the pre-grasp pose is blocked")
        q_pre = settle.last(q_node)
        line = straight_line(self.kin, q_pre, self.direction[t.index], D, self.lower, self.upper,
                             validate=self.motion.free_prefix, inverse=self.inverse, T0=t.T_target)
        return Outcome.accepted((settle.steps, line))

    def accept(self, q_node: np.ndarray, t: GraspTarget) -> Outcome[GraspTarget]:
        """A planner reached pre-grasp target t at q_node: accepted when its approach and retreat work
        (stored in `lines`), RETRY with a replacement target (a shorter approach), or rejected (the
        grasp is dropped, the reason kept in `dropped`).

        Whether the lines are free depends on the arm's posture, not only on the grasp (an elbow
        under a box blocks the lift of one IK posture and not of another): before a grasp is given
        up, `_other_posture` looks for another posture of it whose lines are free and that the
        reached configuration joins by a free straight joint motion."""
        verdict = self.accept_here(q_node, t)
        if verdict.verdict is Verdict.REJECTED and self.repair_postures and self._other_posture(q_node, t):
            return Outcome.accepted()
        return verdict

    def accept_here(self, q_node: np.ndarray, t: GraspTarget) -> Outcome[GraspTarget]:
        """accept without looking at other postures: the lines from the reached posture only."""
        i = t.index
        D = self.distance(t)
        settle, line = np.zeros((0, len(q_node))), None
        if D > 0:
            out = self.approach_line(q_node, t)
            if not out.ok:
                self.dropped[i] = out.reason
                return out
            settle, line = out.value
            if line.reason != "complete":
                return self._shorter(t, line)
            q_grasp = line.waypoints[-1] if len(line.waypoints) else settle[-1] if len(settle) else q_node
        else:
            q_grasp = q_node
        why = self.finish(q_grasp, i, self.motion) if self.finish is not None else None
        if why:
            self.dropped[i] = why
            return Outcome.rejected(why)
        back = np.zeros((0, len(q_node)))
        r_dist = 0.0
        if self.retreat is not None and self.retreat.desired_distance > 0:
            T_g = self.kin.fk(q_grasp)
            d = world_direction(self.robot, self.retreat, False, self.tip, T_g, self.start)
            rl = straight_line(self.kin, q_grasp, d, self.retreat.desired_distance, self.lower, self.upper,
                               validate=self.held_motion(i).free_prefix, inverse=self.inverse, T0=T_g)
            if rl.distance < self.retreat.min_distance - 1e-9:
                self.dropped[i] = (f"the retreat stops after {rl.distance * 100:.1f} cm ({rl.reason}), "
                                   f"short of min_distance {self.retreat.min_distance * 100:.1f} cm")
                return Outcome.rejected(self.dropped[i])
            back, r_dist = rl.waypoints, rl.distance
        approach = line.waypoints if line is not None else np.zeros((0, len(q_node)))
        self.lines[i] = GraspLines(settle, approach, line.distance if line is not None else 0.0, back, r_dist)
        return Outcome.accepted()

    def _other_posture(self, q_node: np.ndarray, t: GraspTarget) -> bool:
        """Another posture of t's grasp whose lines are free (`postures`) and whose pre-grasp q_node
        reaches by a free straight joint motion (nearest first) becomes the grasp's completion."""
        i = t.index
        cands = self.postures(t, q_node)
        for k in np.argsort([np.linalg.norm(c.settle[-1] - q_node) for c in cands]):
            c = cands[k]
            if self.motion.check_edge(q_node, c.settle[-1]):
                self.lines[i] = c
                self.dropped.pop(i, None)
                return True
        return False

    def postures(self, t: GraspTarget, q_near: np.ndarray) -> list[GraspLines]:
        """Postures of t's grasp (IK from q_near and random starts, at most BRANCH_TRIES free ones,
        nearest first) whose lines clear min_distance: the approach, run backwards from the grasp,
        as long as it is free up to t's distance, and the retreat. Each one's settle is its
        pre-grasp configuration. Computed once per grasp (the lines do not depend on q_near)."""
        i = t.index
        if i in self._posture_cache:
            return self._posture_cache[i]
        T_g = self.grasp_of[i].T_target
        n = len(q_near)
        starts = np.vstack([q_near[None], np.random.default_rng(i).uniform(self.lower, self.upper,
                                                                           size=(BRANCH_SEEDS - 1, n))])
        q, ok, _ = solve_ik_batch(self.kin, np.repeat(T_g[None], BRANCH_SEEDS, axis=0), starts, self.lower, self.upper,
                                  tol_pos=END_TOL_POS * 10, tol_rot=STEER_TOL_ROT, iterations=BRANCH_IK_ITERATIONS)
        q = q[ok]
        out: list[GraspLines] = []
        self._posture_cache[i] = out
        if len(q) == 0:
            return out
        q = q[np.unique(np.round(q, 2), axis=0, return_index=True)[1]]
        q = q[self.motion.check_configs(q)]
        q = q[np.argsort(np.linalg.norm(q - q_near, axis=1))][:BRANCH_TRIES]
        a_min = self.approach.min_distance if self.approach is not None else 0.0
        D = self.distance(t)
        lift = self.retreat is not None and self.retreat.desired_distance > 0
        d = world_direction(self.robot, self.retreat, False, self.tip, T_g, self.start) if lift else None
        for qg in q:
            back_l, r_dist = np.zeros((0, n)), 0.0
            if lift:  # first: the lift fails most
                rl = straight_line(self.kin, qg, d, self.retreat.desired_distance, self.lower, self.upper,
                                   validate=self.held_motion(i).free_prefix, inverse=self.inverse, T0=T_g)
                if rl.distance < self.retreat.min_distance - 1e-9:
                    continue
                back_l, r_dist = rl.waypoints, rl.distance
            appr, a_dist, q_pre = np.zeros((0, n)), 0.0, qg
            if D > 0:
                back = straight_line(self.kin, qg, -self.direction[i], D, self.lower, self.upper,
                                     validate=self.motion.free_prefix, inverse=self.inverse, T0=T_g)
                if back.distance < a_min - 1e-9 or len(back.waypoints) == 0:
                    continue
                # the approach is the backward line reversed: its end (the pre-grasp) ... the grasp
                appr = np.vstack([back.waypoints[:-1][::-1], qg[None]])
                a_dist, q_pre = back.distance, back.waypoints[-1]
            if self.finish is not None and self.finish(qg, i, self.motion):
                continue
            out.append(GraspLines(q_pre[None], appr, a_dist, back_l, r_dist))
        return out

    def _shorter(self, t: GraspTarget, line: LineResult) -> Outcome[GraspTarget]:
        """The approach from t stopped short: once per grasp, a new pre-grasp just past where it
        stopped, if that still leaves min_distance; otherwise the grasp is dropped."""
        i = t.index
        D = self.distance(t)
        D_new = D - line.distance - LINE_STEP
        D_min = self.approach.min_distance
        why = f"the straight approach is blocked after {line.distance * 100:.1f} of {D * 100:.1f} cm ({line.reason})"
        if not self.retry_shorter or i in self.retried or D_new < D_min - 1e-9:
            self.dropped[i] = why
            return Outcome.rejected(why)
        self.retried.add(i)
        D_new = max(D_new, D_min)
        g = self.grasp_of[i]
        return Outcome.retry(GraspTarget(i, g.grasp, backed_off(g.T_target, self.direction[i], D_new)), why)

    def failure(self) -> str:
        """Why no grasp could be completed, once every grasp was dropped."""
        reasons = sorted(set(self.dropped.values()))
        kinds = " and ".join(k for k, x in (("approach", self.approach), ("retreat", self.retreat)) if x is not None)
        lines = f"the straight {kinds}" if kinds else "the completion"
        if kinds and self.finish is not None:
            lines += " or what follows it"
        return (f"{lines} is infeasible at every grasp of the set ({len(self.dropped)} tried): "
                + "; ".join(reasons[:3]))
