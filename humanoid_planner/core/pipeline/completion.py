"""Completing a grasp as MoveIt's pick does: a straight approach onto it and a retreat holding the object.

The planners aim at pre-grasp poses (each grasp backed off along its approach direction); when one
is reached, `Completion.accept` settles the TCP exactly on the pre-grasp pose, runs the straight line
onto the grasp (checked with the target object allowed to touch only the hand's links, like the
reach) and the retreat line from the grasp (the object attached to the TCP link, touching only the
hand, checked against the world and the rest of the robot). Whether the lines are free depends on
the arm's posture, so a grasp whose lines fail in the reached posture is first tried in other IK
postures (single arm: `_branches`, joined to the reached configuration by a free joint motion);
failing that it is dropped — or retried once from the point the approach cleared, when that is still
at least `min_distance` — and the search goes on toward the others (GraspRRT's `accept` hook, also in DAGRRT's arms). DAGRRT's
pair is completed when it is paired (its `complete` hook, `pair_lines`): both hands approach at once
(each along its own line; the shorter waits at its end), then retreat by the same world
displacement; a pair whose lines fail in the reached postures is tried in other postures of its two
grasps (`pair_other_postures`, the same `_branches`), and skipped when none works.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.ik.solver import solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.cartesian import (END_TOL_POS, LINE_STEP, STEER_TOL_POS, STEER_TOL_ROT, GripperTranslation,
                                                      LineResult, parallel_lines, straight_line)
from humanoid_planner.core.planners.common import GraspTarget
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.scene.types import SceneSnapshot, attach

BRANCH_SEEDS = 16  # IK starts per grasp when the reached posture's lines fail (the reached one first)
BRANCH_IK_ITERATIONS = 40  # most solutions converge by then; the slow rest are not needed (1/3 of the IK's cost)
BRANCH_TRIES = 6  # free solutions, nearest the reached posture first, whose lines are tried

MotionFactory = Callable[[SceneSnapshot, "str | tuple[str, ...]", str], MotionValidator]
"""(scene, group(s), grasped object id) → a motion validator of those groups in that scene."""


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
class Completed:
    """The accepted lines of one grasp: pre-grasp settle steps, approach and retreat waypoints."""

    settle: np.ndarray  # (k, n) from the reached node to the exact pre-grasp pose
    approach: np.ndarray  # (a, n) waypoints onto the grasp (pre-grasp excluded)
    approach_distance: float
    retreat: np.ndarray  # (r, n) waypoints from the grasp (grasp excluded)
    retreat_distance: float


class Completion:
    """Approach + retreat for one arm's grasp targets (one per plan request)."""

    def __init__(self, robot: RobotModel, scene: SceneSnapshot, group: str, kin: GroupKinematics, start: np.ndarray,
                 lower: np.ndarray, upper: np.ndarray, motion: MotionValidator, make_motion: MotionFactory,
                 object_id: str, approach: GripperTranslation | None, retreat: GripperTranslation | None,
                 inverse: str = "wln", retry_shorter: bool = True, repair_branches: bool = True):
        """retry_shorter: a blocked approach may be retried once, shorter (single arm; DAGRRT's arms
        keep the desired distance, so that the pair is completed with the targets they reached)."""
        self.robot, self.scene, self.group, self.kin = robot, scene, group, kin
        self.start, self.lower, self.upper, self.motion = start, lower, upper, motion
        self.make_motion, self.object_id, self.inverse = make_motion, object_id, inverse
        self.approach, self.retreat, self.retry_shorter = approach, retreat, retry_shorter
        self.repair_branches = repair_branches
        self.tip = robot.group(group).tip_link
        self.hands = robot.hand_links(group)
        self.grasp_of: dict[int, GraspTarget] = {}
        self.direction: dict[int, np.ndarray] = {}
        self.retried: set[int] = set()
        self.dropped: dict[int, str] = {}  # grasp index → why
        self.done: dict[int, Completed] = {}
        self._held: dict[int, MotionValidator] = {}
        self._branch_cache: dict[int, list[Completed]] = {}

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
            self._held[index] = self.make_motion(held_scene(self.scene, self.object_id, self.tip,
                                                            self.grasp_of[index].T_target, self.hands), self.group, "")
        return self._held[index]

    def _approach_line(self, q_node: np.ndarray, t: GraspTarget) -> tuple[np.ndarray, LineResult] | str:
        D = self.distance(t)
        settle = steer_to_pose(self.kin, q_node, t.T_target, inverse=self.inverse, tol_pos=STEER_TOL_POS,
                               tol_rot=STEER_TOL_ROT, max_iters=25, lower=self.lower, upper=self.upper)
        if not settle.reached:
            return "the pre-grasp pose could not be held exactly"
        if len(settle.steps) and self.motion.free_prefix(q_node, settle.steps) < len(settle.steps):
            return "the pre-grasp pose is blocked"
        q_pre = settle.last(q_node)
        line = straight_line(self.kin, q_pre, self.direction[t.index], D, self.lower, self.upper,
                             validate=self.motion.free_prefix, inverse=self.inverse, T0=t.T_target)
        return settle.steps, line

    def accept(self, q_node: np.ndarray, t: GraspTarget) -> bool | GraspTarget | None:
        """A planner reached pre-grasp target t at q_node: True when its approach and retreat work
        (stored in `done`), a replacement target (a shorter approach) or None (the grasp is dropped).

        Whether the lines are free depends on the arm's posture, not only on the grasp (an elbow
        under a box blocks the lift of one IK branch and not of another): before a grasp is given
        up, `_other_branch` looks for another posture of it whose lines are free and that the
        reached configuration joins by a free straight joint motion."""
        verdict = self._accept(q_node, t)
        if verdict is None and self.repair_branches and self._other_branch(q_node, t):
            return True
        return verdict

    def _accept(self, q_node: np.ndarray, t: GraspTarget) -> bool | GraspTarget | None:
        i = t.index
        D = self.distance(t)
        settle, line = np.zeros((0, len(q_node))), None
        if D > 0:
            out = self._approach_line(q_node, t)
            if isinstance(out, str):
                self.dropped[i] = out
                return None
            settle, line = out
            if line.reason != "complete":
                return self._shorter(t, line)
            q_grasp = line.waypoints[-1] if len(line.waypoints) else settle[-1] if len(settle) else q_node
        else:
            q_grasp = q_node
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
                return None
            back, r_dist = rl.waypoints, rl.distance
        approach = line.waypoints if line is not None else np.zeros((0, len(q_node)))
        self.done[i] = Completed(settle, approach, line.distance if line is not None else 0.0, back, r_dist)
        return True

    def _other_branch(self, q_node: np.ndarray, t: GraspTarget) -> bool:
        """Another posture of t's grasp whose lines are free (`_branches`) and whose pre-grasp q_node
        reaches by a free straight joint motion (nearest first) becomes the grasp's completion."""
        i = t.index
        cands = self._branches(t, q_node)
        for k in np.argsort([np.linalg.norm(c.settle[-1] - q_node) for c in cands]):
            c = cands[k]
            if self.motion.check_edge(q_node, c.settle[-1]):
                self.done[i] = c
                self.dropped.pop(i, None)
                return True
        return False

    def _branches(self, t: GraspTarget, q_near: np.ndarray) -> list[Completed]:
        """Postures of t's grasp (IK from q_near and random starts, at most BRANCH_TRIES free ones,
        nearest first) whose lines clear min_distance: the approach, run backwards from the grasp,
        as long as it is free up to t's distance, and the retreat. Each Completed's settle is its
        pre-grasp configuration. Computed once per grasp (the lines do not depend on q_near)."""
        i = t.index
        if i in self._branch_cache:
            return self._branch_cache[i]
        T_g = self.grasp_of[i].T_target
        n = len(q_near)
        starts = np.vstack([q_near[None], np.random.default_rng(i).uniform(self.lower, self.upper,
                                                                           size=(BRANCH_SEEDS - 1, n))])
        q, ok, _ = solve_ik_batch(self.kin, np.repeat(T_g[None], BRANCH_SEEDS, axis=0), starts, self.lower, self.upper,
                                  tol_pos=END_TOL_POS * 10, tol_rot=STEER_TOL_ROT, iterations=BRANCH_IK_ITERATIONS)
        q = q[ok]
        out: list[Completed] = []
        self._branch_cache[i] = out
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
            out.append(Completed(q_pre[None], appr, a_dist, back_l, r_dist))
        return out

    def _shorter(self, t: GraspTarget, line: LineResult) -> GraspTarget | None:
        """The approach from t stopped short: once per grasp, a new pre-grasp just past where it
        stopped, if that still leaves min_distance; otherwise the grasp is dropped."""
        i = t.index
        D = self.distance(t)
        D_new = D - line.distance - LINE_STEP
        D_min = self.approach.min_distance
        why = f"the straight approach is blocked after {line.distance * 100:.1f} of {D * 100:.1f} cm ({line.reason})"
        if not self.retry_shorter or i in self.retried or D_new < D_min - 1e-9:
            self.dropped[i] = why
            return None
        self.retried.add(i)
        D_new = max(D_new, D_min)
        g = self.grasp_of[i]
        return GraspTarget(i, g.grasp, backed_off(g.T_target, self.direction[i], D_new))

    def failure(self) -> str:
        """Why no grasp could be completed, once every grasp was dropped."""
        reasons = sorted(set(self.dropped.values()))
        kinds = " and ".join(k for k, x in (("approach", self.approach), ("retreat", self.retreat)) if x is not None)
        return (f"the straight {kinds} is infeasible at every grasp of the set ({len(self.dropped)} tried): "
                + "; ".join(reasons[:3]))


def held_scene(scene: SceneSnapshot, object_id: str, link: str, T_link: np.ndarray, touch) -> SceneSnapshot:
    """The scene with the grasped object taken out of the world and attached to `link` (pose T_link),
    as it is once the hand has closed; unchanged when there is no scene object to hold."""
    obj = scene.get(object_id) if object_id else None
    if obj is None:
        return scene
    held = attach(obj, link, T_link, touch)
    return replace(scene, objects=tuple(o for o in scene.objects if o.id != object_id),
                   attached=scene.attached + (held,))


def pair_lines(kins, q_ends, approach_dirs, approach: GripperTranslation | None, pair_motion: MotionValidator,
               retreat: GripperTranslation | None, retreat_dir: np.ndarray | None, held_motion: MotionValidator | None,
               limits, inverse: str) -> tuple[np.ndarray, float, np.ndarray, float] | str:
    """DAGRRT's pair: from both pre-grasp configurations (exact), both approach lines at once (the
    shorter waits), then the retreat of both TCPs by the same displacements. Returns (approach
    waypoints, distance, retreat waypoints, distance) or why not."""
    appr = np.zeros((0, sum(len(q) for q in q_ends)))
    a_dist = 0.0
    q_grasp = list(q_ends)
    if approach is not None and approach.desired_distance > 0:
        lines = [straight_line(k, q, d, approach.desired_distance, lo, hi, inverse=inverse)
                 for k, q, d, (lo, hi) in zip(kins, q_ends, approach_dirs, limits)]
        if any(line.reason != "complete" for line in lines):
            bad = [line for line in lines if line.reason != "complete"][0]
            return f"the straight approach of the paired grasps stops after {bad.distance * 100:.1f} cm ({bad.reason})"
        appr = _pair_approach([line.waypoints for line in lines], np.concatenate(q_ends), pair_motion)
        if appr is None:
            return "the straight approach of the paired grasps is blocked"
        a_dist = approach.desired_distance
        q_grasp = [line.waypoints[-1] for line in lines]
    back = _pair_retreat(kins, q_grasp, retreat, retreat_dir, held_motion, limits, inverse)
    if isinstance(back, str):
        return back
    return (appr, a_dist) + back


def _pair_approach(lines: Sequence[np.ndarray], q0: np.ndarray, pair_motion: MotionValidator) -> np.ndarray | None:
    """Both hands' approach waypoints at once (the shorter line waits at its end), or None when the
    pair's motion is blocked."""
    m = max(len(w) for w in lines)
    if m == 0:
        return np.zeros((0, len(q0)))
    appr = np.hstack([np.vstack([w, np.repeat(w[-1:], m - len(w), axis=0)]) for w in lines])
    return appr if pair_motion.free_prefix(q0, appr) == len(appr) else None


def _pair_retreat(kins, q_grasp, retreat: GripperTranslation | None, retreat_dir: np.ndarray | None,
                  held_motion: MotionValidator | None, limits, inverse: str) -> tuple[np.ndarray, float] | str:
    """Both TCPs lifted by the same world displacement from the grasp configurations (at least
    min_distance), or why not."""
    if retreat is None or retreat.desired_distance <= 0:
        return np.zeros((0, sum(len(q) for q in q_grasp))), 0.0
    rl = parallel_lines(kins, q_grasp, retreat_dir, retreat.desired_distance, limits,
                        validate=held_motion.free_prefix if held_motion is not None else None, inverse=inverse)
    if rl.distance < retreat.min_distance - 1e-9:
        return (f"the two-handed retreat stops after {rl.distance * 100:.1f} cm ({rl.reason}), short of "
                f"min_distance {retreat.min_distance * 100:.1f} cm")
    return rl.waypoints, rl.distance


def pair_other_postures(comps: Sequence[Completion], q_pair: np.ndarray, q_pre: Sequence[np.ndarray],
                        targets: Sequence[GraspTarget], pair_motion: MotionValidator,
                        retreat: GripperTranslation | None, retreat_dir: np.ndarray | None,
                        held_motion: MotionValidator | None, limits,
                        inverse: str) -> tuple[np.ndarray, tuple[np.ndarray, float, np.ndarray, float]] | None:
    """DAGRRT's pair whose lines fail in the reached postures (`pair_lines`), completed as GIRRT's
    grasps are (`Completion.accept`): per arm, the reached posture (when its own approach is free)
    and the other postures of its grasp (`Completion._branches`: approach free for >= min_distance);
    the combinations, nearest to the reached pair first (at most BRANCH_TRIES whose joint motion from
    q_pair is free), with both approaches at once and the two-handed retreat (same displacement).
    Returns (the pair's pre-grasp configuration, (approach, distance, retreat, distance)) or None.
    The approach distance is the shorter of the two hands' (each at least min_distance)."""
    cands: list[list[Completed]] = []
    for comp, q, t in zip(comps, q_pre, targets):
        own: list[Completed] = []
        n = len(q)
        out = comp._approach_line(q, t) if comp.distance(t) > 0 else (np.zeros((0, n)), LineResult(np.zeros((0, n)), 0.0, "complete"))
        if not isinstance(out, str) and out[1].reason == "complete":
            own.append(Completed(q[None], out[1].waypoints, out[1].distance, np.zeros((0, n)), 0.0))
        cands.append(own + comp._branches(t, q))
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
        appr = _pair_approach([ci.approach for ci in c], qp, pair_motion)
        if appr is not None:
            q_grasp = [ci.approach[-1] if len(ci.approach) else ci.settle[-1] for ci in c]
            back = _pair_retreat([comp.kin for comp in comps], q_grasp, retreat, retreat_dir,
                                 held_motion, limits, inverse)
            if not isinstance(back, str):
                return qp, (appr, min(ci.approach_distance for ci in c)) + back
        if tried >= BRANCH_TRIES:
            break
    return None
