"""Placing what the hands hold (MoveIt's place): carry an attached object to one of several candidate
placements, lower it the last straight stretch, and back the hand(s) away once it is released.

A placement P (the object's pose in the planning frame) is a TCP goal P · T_object_tcp, where
T_object_tcp is where the hand holds the object (from the attachment, at the start state). So one
arm's place is a grasp plan whose grasp set is the placements' TCP goals: `GraspPlanner.plan_grasp`
searches it (GIRRT: the placements are its goal set) with the object attached in the snapshot (the
checker carries it) and the pre-place approach as the grasp's straight approach.

Two hands holding one object form a closed chain that two independently planned arms (DAGRRT) would
break, so the two-handed carry is a sequence of straight object motions — up to a carry height,
across above the pre-place pose, down onto it, then the approach — each made by both TCPs moving by
the same world displacement (`parallel_lines`): the hands keep their relative pose by construction.
It keeps the object's orientation; placements that turn it are refused.

The object may touch its support (a scene object under it at the placement), as a hand may touch the
object it grasps, but only at the end of the descent: the carry is searched with the supports as
obstacles to the object, and only the descent (one arm: its last TOUCH_STRETCH) is checked with them
touchable, so that no carry passes the object through a board it may stand on. What supports a
placement is found here (`supports`).
After the release the hand(s) retreat alone, the object left at the placement: a hand may touch it only
on the retreat's first stretch, until the first waypoint clear of it (it held the object there; the
hands' collision models reach several cm into what they hold); from there on the object is an
obstacle like any other, so the retreat ends clear of it by the padding, where a next plan may start
(`Release`). Planning never changes the scene: the client detaches the object after executing.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from typing import Sequence

import fcl
import numpy as np

from humanoid_planner.core.collision.geometry import fcl_from_shape, fcl_transform, scene_bodies
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.completion import world_direction
from humanoid_planner.core.pipeline.pair_completion import pair_approach
from humanoid_planner.core.pipeline.planner import GraspPlan, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.pipeline.plans import LINE_PATH_TOLERANCE, colliding_pairs_text
from humanoid_planner.core.pipeline.validation import (SINGLE_ARM_PLANNERS, RequestRefused, check_dual_groups,
                                                     check_group, check_planner, check_start, check_translation)
from humanoid_planner.core.planners.cartesian import GripperTranslation, LineResult, parallel_lines, straight_line
from humanoid_planner.core.planners.common import PlanStatus, Progress, Termination
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.postprocess.timing import TimedTrajectory, join
from humanoid_planner.core.scene.types import AttachedObject, GraspSpec, SceneObject, SceneSnapshot

PLACE_PLANNERS = SINGLE_ARM_PLANNERS
DUAL_PLACE_PLANNERS = ("parallel_lines",)
"""The two-handed carry: straight object motions, both TCPs displaced alike (see the module docstring)."""
SUPPORT_GAP = 0.005  # m: a scene object this close under a placed object supports it (may touch it)
TOUCH_STRETCH = 0.01
"""m (plus the padding): the last stretch of a one-arm descent, the only one checked with the object
allowed to touch its support. More than the checker's margin (half of max_point_motion), so that the
search, which keeps the object off the support, reaches the point where this stretch starts."""
CARRY_HEIGHTS = (0.0, 0.05, 0.15, 0.30)  # m above the higher of start and pre-place: two-handed carries tried
ORIENTATION_TOL = float(np.radians(1.0))  # rad: a two-handed placement must keep the object's orientation
DUAL_PATH_TOLERANCE = 0.001
"""rad: corner blends of the two-handed carry. Each arm's blend leaves its own line, so the hands'
relative pose drifts by up to this times the arm's reach (~0.6 m: 0.6 mm); LINE_PATH_TOLERANCE
(5 mrad) would allow 3 mm."""
DOWN = (0.0, 0.0, -1.0)  # the planning frame's gravity direction (z up, as ROS's REP 103): a placement comes down


@dataclass
class PlaceRequest:
    """One plan_place (or, with right_group, plan_dual_place) request in core terms."""

    group: str  # dual: the left group
    start: np.ndarray  # full robot configuration (RobotModel.joint_names order)
    object_id: str  # an attached object, held by the group's hand (dual: by both hands)
    placements: Sequence[np.ndarray]  # candidate 4x4 T_world_object: the goal set
    right_group: str = ""
    planner: str = "girrt"
    timeout: float = 5.0
    velocity_scaling: float = 1.0
    acceleration_scaling: float = 1.0
    seed: int | None = None
    approach: GripperTranslation | None = None  # frame "": the planning frame; zero direction: its -z
    retreat: GripperTranslation | None = None  # frame "": the TCP frame; zero direction: its -z

    @property
    def groups(self) -> tuple[str, ...]:
        return (self.group, self.right_group) if self.right_group else (self.group,)

    @property
    def object_pose(self) -> np.ndarray:
        """The placements' TCP goals (PlacePlan.grasps) are planning-frame poses: T_world_tcp = I · goal."""
        return np.eye(4)


@dataclass
class PlacePlan(GraspPlan):
    """A GraspPlan whose `grasps` are the reached placement's TCP goal(s), and which placement it is."""

    place_index: int = -1


def with_default(gt: GripperTranslation | None, frame: str) -> GripperTranslation | None:
    """A place translation with its defaults made explicit: frame "" -> `frame`, a zero direction -> -z."""
    if gt is None:
        return None
    d = np.asarray(gt.direction, float)
    zero = d.shape == (3,) and np.all(d == 0.0)
    return replace(gt, frame=gt.frame or frame, direction=DOWN if zero else gt.direction)


def attached(robot: RobotModel, scene: SceneSnapshot, object_id: str, groups: Sequence[str]) -> AttachedObject:
    """The attached object the request moves, held by each group's hand; RequestRefused (INVALID_OBJECT)
    naming what is wrong. Two hands hold it when it is attached to a link of one and touches (touch_links)
    a link of the other."""
    if not object_id:
        raise RequestRefused(PlanStatus.INVALID_OBJECT, "object_id is empty: name the attached object to place")
    att = next((a for a in scene.attached if a.id == object_id), None)
    if att is None:
        held = ", ".join(repr(a.id) for a in scene.attached) or "none"
        where = (" (it is in the world: attach it first, on attached_collision_object)" if scene.get(object_id)
                 else "")
        raise RequestRefused(PlanStatus.INVALID_OBJECT,
                             f"object_id {object_id!r} is not attached to the robot{where}; attached: {held}")
    holders = [g for g in groups if att.link in robot.hand_links(g) or att.link == robot.group(g).tip_link]
    if not holders:
        raise RequestRefused(PlanStatus.INVALID_OBJECT,
                             f"object {object_id!r} is attached to link {att.link!r}, which is not in the hand of "
                             f"{' or '.join(repr(g) for g in groups)}")
    for g in groups:
        if g not in holders and not (att.touch_links & set(robot.hand_links(g))):
            raise RequestRefused(PlanStatus.INVALID_OBJECT,
                                 f"object {object_id!r} is held by the hand of {holders[0]!r} only: for two hands, "
                                 f"attach it with a link of {g!r}'s hand among its touch_links")
    return att


def object_in_tcp(robot: RobotModel, att: AttachedObject, group: str, start: np.ndarray) -> np.ndarray:
    """T_tcp_object: where the group's TCP holds the object (the hand is rigid below its TCP's joint)."""
    T_tcp, T_link = robot.link_poses(start, [robot.group(group).tip_link, att.link])
    return np.linalg.inv(T_tcp) @ T_link @ att.pose


def _placed(att: AttachedObject, P: np.ndarray) -> SceneObject:
    return SceneObject(att.id, np.asarray(P, float), att.shapes, att.grasps)


def supports(scene: SceneSnapshot, att: AttachedObject, P: np.ndarray,
             gap: float = SUPPORT_GAP) -> tuple[frozenset[str], tuple[str, ...]]:
    """(the scene objects supporting the object at placement P, those it collides with there). A support
    comes within `gap` of it and is clear of it once the object is raised by `gap` (planning frame +z):
    what it rests on, penetrating it at most `gap`."""
    up = np.array(P, float)
    up[2, 3] += gap
    mine = [(fcl_from_shape(s), s.pose) for s in att.shapes]
    near: dict[str, list[bool]] = {}
    dreq, creq = fcl.DistanceRequest(), fcl.CollisionRequest()
    for sb in scene_bodies(scene.objects):
        other = fcl.CollisionObject(fcl_from_shape(sb.shape), fcl_transform(sb.pose))
        for geom, T in mine:
            at = fcl.CollisionObject(geom, fcl_transform(P @ T))
            d = fcl.distance(at, other, dreq, fcl.DistanceResult())
            if d > gap:
                continue
            raised = fcl.collide(fcl.CollisionObject(geom, fcl_transform(up @ T)), other, creq, fcl.CollisionResult())
            near.setdefault(sb.object_id, []).append(raised == 0 or d > 0)
    support = frozenset(o for o, ok in near.items() if all(ok))
    return support, tuple(sorted(o for o in near if o not in support))


def stamp(plan: GraspPlan, scene: SceneSnapshot, t0: float, place_index: int = -1) -> PlacePlan:
    out = PlacePlan(**{f.name: getattr(plan, f.name) for f in fields(GraspPlan)}, place_index=place_index)
    out.scene_version, out.planning_time = scene.version, time.perf_counter() - t0
    return out


@dataclass
class PlaceSetup:
    start: np.ndarray
    att: AttachedObject
    carry: SceneSnapshot  # the object attached, touching its placements' supports allowed (the descent)
    strict: SceneSnapshot  # the object attached as given: the supports are obstacles to it (the carry)
    goals: dict[int, np.ndarray]  # placement index -> its pose, for the placements free at their pose
    supports: frozenset[str]  # the scene objects the object may touch at the end of the descent
    approach: GripperTranslation | None
    retreat: GripperTranslation | None


def check_place_request(robot: RobotModel, planning_frame: str, req: PlaceRequest, given=None) -> np.ndarray:
    """The checks that need no scene (the node runs them before it queues a request); the clipped start."""
    if req.right_group:
        check_dual_groups(robot, req.group, req.right_group)
        check_planner(req.planner, DUAL_PLACE_PLANNERS)
    else:
        check_group(robot, req.group)
        check_planner(req.planner, PLACE_PLANNERS)
    start = check_start(robot, req.start, given)
    if not len(req.placements):
        raise RequestRefused(PlanStatus.INVALID_GOAL, "no placements: place_poses is empty")
    for i, P in enumerate(req.placements):
        P = np.asarray(P, float)
        if P.shape != (4, 4) or not np.all(np.isfinite(P)):
            raise RequestRefused(PlanStatus.INVALID_GOAL, f"place_poses[{i}] is not a finite pose")
    check_translation(robot, planning_frame, with_default(req.approach, planning_frame), "pre_place_approach")
    check_translation(robot, planning_frame, with_default(req.retreat, robot.group(req.group).tip_link),
                      "post_place_retreat")
    return start


def setup(robot: RobotModel, scene: SceneSnapshot, req: PlaceRequest) -> PlaceSetup:
    start = check_place_request(robot, scene.frame, req)
    att = attached(robot, scene, req.object_id, req.groups)
    goals, clash, allowed = {}, [], set()
    for i, P in enumerate(req.placements):
        support, hits = supports(scene, att, np.asarray(P, float))
        if hits:
            clash.append(f"place_poses[{i}]: {req.object_id!r} with {', '.join(repr(h) for h in hits)}")
        else:
            goals[i] = np.asarray(P, float)
            allowed |= support
    if not goals:
        raise RequestRefused(PlanStatus.INVALID_GOAL, "every placement puts the object in collision: "
                             + "; ".join(clash[:4]) + (f" and {len(clash) - 4} more" if len(clash) > 4 else ""))
    held = replace(att, touch_links=att.touch_links | allowed)
    carry = replace(scene, attached=tuple(held if a.id == att.id else a for a in scene.attached))
    return PlaceSetup(start, att, carry, scene, goals, frozenset(allowed), with_default(req.approach, scene.frame),
                  req.retreat)


def _released(s: PlaceSetup, index: int) -> SceneSnapshot:
    """After the release: the object stands at placement `index` in the world, the robot holds nothing of it."""
    return replace(s.carry, objects=s.carry.objects + (_placed(s.att, s.goals[index]),),
                   attached=tuple(a for a in s.carry.attached if a.id != s.att.id))


class Release:
    """Validates a retreat after the release (straight_line's / pair_approach's `free_prefix`): the
    hand may touch the released object up to the first waypoint clear of it (the stretch where it
    leaves what it held), never after; everything else is an obstacle all along. A retreat whose
    waypoints never clear the object gets no waypoint (`why` says so): it would end touching it."""

    def __init__(self, touching: MotionValidator, clear: MotionValidator):
        self.touching = touching  # the hand may touch the released object
        self.clear = clear  # the object is an obstacle like any other
        self.why = ""

    def free_prefix(self, q0: np.ndarray, waypoints: np.ndarray) -> int:
        W = np.asarray(waypoints, float)
        n = self.touching.free_prefix(q0, W)
        if n == 0:
            return 0
        off = self.clear.check_configs(W[:n])
        if not off.any():
            self.why = (f"the hand still touches the released object {n} waypoint(s) back: "
                        f"{colliding_pairs_text(self.clear.checker.colliding_pairs(W[n - 1]))}")
            return 0
        j = int(np.argmax(off))
        return j + 1 + self.clear.free_prefix(W[j], W[j + 1:n])


def _exempting(motion: MotionValidator, pairs) -> MotionValidator:
    """`motion` with the named body pairs no longer checked; its checker's geometry shared, not built
    again (a checker build is most of a place plan's set-up). Used one after the other, never at once."""
    return MotionValidator(motion.checker.exempting(pairs), motion.max_point_motion)


def _onto(s: PlaceSetup, carry: MotionValidator) -> MotionValidator:
    """The set-down's validator from the carry's: the object may touch its placements' supports."""
    return _exempting(carry, [(s.att.id, o) for o in s.supports])


def _release(planner: GraspPlanner, s: PlaceSetup, index: int, groups: str | tuple[str, ...], hands) -> Release:
    """The retreat's validators after the release at placement `index` (the object standing there)."""
    clear = planner.problems.motion(_released(s, index), groups, s.start, "", ())
    return Release(_exempting(clear, [(h, s.att.id) for h in hands]), clear)


# ------------------------------------------------------------------------------------------ one arm
def plan_place(planner: GraspPlanner, scene: SceneSnapshot, req: PlaceRequest, cancel=None,
               progress: Progress | None = None) -> PlacePlan:
    """One arm: GIRRT (or a baseline) to the placements' TCP goals with the object attached, the
    pre-place approach as the last straight stretch, then the retreat of the hand alone. GIRRT checks
    the set-down and the retreat of each placement it reaches (`PlaceLines.blocked`, Completion's
    finish hook), in the reached posture and then in others, and searches on without a placement
    blocked in all of them; a baseline's path ends at one goal, so a placement blocked there is left
    out and the search runs again (while time remains)."""
    if req.right_group:
        return plan_dual_place(planner, scene, req, cancel, progress)
    t0 = time.perf_counter()
    r = planner.robot
    try:
        s = setup(r, scene, req)
    except RequestRefused as e:
        return stamp(GraspPlan(e.status, e.message), scene, t0)
    term = Termination(req.timeout, cancel, progress=progress)
    T_obj_tcp = np.linalg.inv(object_in_tcp(r, s.att, req.group, s.start))
    # searched: each placement raised by the touch stretch, the descent shortened by as much, the
    # supports obstacles; without a descent that long the search itself must let the object touch them
    touch, approach, searched = touch_stretch(s, planner.options.collision_padding)
    lines = PlaceLines(planner, s, req.group, touch)
    goals = {f"place_poses[{i}]": i for i in s.goals}
    blocked: list[str] = []
    plan = GraspPlan(PlanStatus.PLANNING_FAILED)
    while goals:
        grasps = [GraspSpec(name, "", raised(s.goals[i], s.approach, touch) @ T_obj_tcp) for name, i in goals.items()]
        greq = GraspPlanRequest(req.group, s.start, np.eye(4), grasps, planner=req.planner,
                                timeout=max(term.remaining(), 1e-3), velocity_scaling=req.velocity_scaling,
                                acceleration_scaling=req.acceleration_scaling, seed=req.seed, approach=approach)
        order = list(goals.values())  # GraspTarget.index -> placement
        finish = None if req.planner != "girrt" else (
            lambda q, k, search, order=order: lines.blocked(q, order[k], search))
        plan = planner.plan_grasp(searched, greq, cancel, progress, finish=finish)
        search, plan.search_validator = plan.search_validator, None
        if not plan.ok:
            plan.message = plan.message.replace("grasp", "placement")
            if blocked:
                plan.message += "; blocked at " + "; ".join(blocked)
            return stamp(plan, scene, t0)
        index = goals.pop(plan.grasps[0].id)
        why = set_down(planner, s, req, plan, touch, search, lines) if touch > 0 else None
        if why is None:
            plan.grasps = (GraspSpec(plan.grasps[0].id, "", s.goals[index] @ T_obj_tcp),)
            why = retreat(planner, s, req, plan, index, lines)
        if why is None:
            return stamp(plan, scene, t0, index)
        blocked.append(f"place_poses[{index}] ({why})")
        if term.should_stop():
            break
    return stamp(GraspPlan(PlanStatus.PLANNING_FAILED, "blocked at " + "; ".join(blocked)), scene, t0)


def touch_stretch(s: PlaceSetup, padding: float) -> tuple[float, GripperTranslation | None, SceneSnapshot]:
    """(the descent's last stretch that may touch a support, the approach searched before it, the scene
    searched in); (0, the approach, the scene with the supports touchable) when the descent is too short."""
    touch = TOUCH_STRETCH + padding
    a = s.approach
    if a is None or a.desired_distance < touch + 1e-3:
        return 0.0, a, s.carry
    return touch, replace(a, desired_distance=a.desired_distance - touch,
                          min_distance=max(a.min_distance - touch, 0.0)), s.strict


def raised(P: np.ndarray, approach: GripperTranslation | None, touch: float) -> np.ndarray:
    """Placement P moved back along the descent by `touch` (where the search's descent ends)."""
    if touch <= 0:
        return P
    T = np.array(P, float)
    T[:3, 3] -= touch * np.asarray(approach.unit, float)
    return T


class PlaceLines:
    """One arm's straight motions at a request's placements, from a given posture, with the validators
    plan_place checks them with: the set-down (the descent's last `touch`, the object allowed to touch
    its supports), the retreat of the hand alone after the release, and the whole descent run
    backwards from the placement (`pre_place`: what proves a placement usable). Whether they are free
    depends on the arm's posture, so GIRRT's accept hook asks `blocked` for every posture it reaches or
    tries (completion.Completion's `finish`); the lines are kept per posture (the plan takes them from
    here), the retreat's validators are built once per placement."""

    def __init__(self, planner: GraspPlanner, s: PlaceSetup, group: str, touch: float = 0.0):
        r = planner.robot
        self.planner, self.s, self.group, self.touch = planner, s, group, touch
        idx = r.group_joint_indices(group)
        self.kin = GroupKinematics(r, group, s.start)
        self.lower, self.upper = r.motion_limits(idx, s.start[idx])
        self.tip = r.group(group).tip_link
        self.hands = set(r.hand_links(group)) | (s.att.touch_links & set(r.link_names))
        self._onto: MotionValidator | None = None
        self._release: dict[int, Release] = {}
        self._down: dict[bytes, LineResult] = {}
        self._back: dict[tuple[int, bytes], tuple[LineResult | None, str]] = {}

    def onto(self, search: MotionValidator | None = None) -> MotionValidator:
        """The set-down's validator: the search's (`search`, whose checker it shares) with the object
        allowed to touch its supports; without one, built for the carry scene."""
        if self._onto is None:
            self._onto = (_onto(self.s, search) if search is not None
                          else self.planner.problems.motion(self.s.carry, self.group, self.s.start, "", ()))
        return self._onto

    def release(self, index: int) -> Release:
        """The retreat's validators after the release at placement `index`."""
        if index not in self._release:
            self._release[index] = _release(self.planner, self.s, index, self.group, self.hands)
        return self._release[index]

    def _line(self, q: np.ndarray, d: np.ndarray, distance: float, validate) -> LineResult:
        return straight_line(self.kin, q, d, distance, self.lower, self.upper, validate=validate, inverse="wln",
                             T0=self.kin.fk(q))

    def down(self, q: np.ndarray, search: MotionValidator | None = None) -> LineResult:
        """The set-down from q: `touch` along the descent, the object allowed to touch its supports."""
        key = np.asarray(q, float).tobytes()
        if key not in self._down:
            self._down[key] = self._line(q, np.asarray(self.s.approach.unit, float), self.touch,
                                         self.onto(search).free_prefix)
        return self._down[key]

    def retreat(self, q_end: np.ndarray, index: int) -> tuple[LineResult | None, str]:
        """The hand's retreat from q_end (holding placement `index`), the object released: (the line,
        "") or (what it managed, why it is too short); (None, "") when no retreat is asked."""
        gt = self.s.retreat
        if gt is None:
            return None, ""
        key = (index, np.asarray(q_end, float).tobytes())
        if key not in self._back:
            rel = self.release(index)
            rel.why = ""
            d = world_direction(self.planner.robot, with_default(gt, self.tip), True, self.tip, self.kin.fk(q_end),
                                self.s.start)
            line = self._line(q_end, d, gt.desired_distance, rel.free_prefix)
            why = ""
            if line.distance < gt.min_distance - 1e-9:
                why = (f"the retreat stops after {line.distance * 100:.1f} cm ({rel.why or line.reason}), "
                       f"short of min_distance {gt.min_distance * 100:.1f} cm")
            self._back[key] = (line, why)
        return self._back[key]

    def blocked(self, q: np.ndarray, index: int, search: MotionValidator | None = None) -> str | None:
        """Why placement `index` cannot be finished from q, where the search's descent ends (`touch`
        above the placement): the set-down or the retreat after it is blocked; None when both are free."""
        q_end = q
        if self.touch > 0:
            down = self.down(q, search)
            if down.reason != "complete":
                return f"the descent stops {self.touch - down.distance:.3f} m above the placement ({down.reason})"
            q_end = down.waypoints[-1]
        return self.retreat(q_end, index)[1] or None

    def pre_place(self, q_place: np.ndarray, index: int) -> tuple[np.ndarray | None, str]:
        """From q_place, holding placement `index`: the pre-place configuration — the descent run
        backwards (the object attached, allowed to touch its supports), at least its min_distance
        and as far as its desired one — when that and the retreat are free; else (None, why)."""
        a, q_pre = self.s.approach, np.asarray(q_place, float)
        if a is not None and a.desired_distance > 0:
            up = self._line(q_pre, -np.asarray(a.unit, float), a.desired_distance, self.onto().free_prefix)
            if up.distance < a.min_distance - 1e-9 or len(up.waypoints) == 0:
                return None, (f"the descent is free for {up.distance * 100:.1f} cm ({up.reason}), short of "
                              f"min_distance {a.min_distance * 100:.1f} cm")
            q_pre = up.waypoints[-1]
        _, why = self.retreat(q_place, index)
        return (None, why) if why else (q_pre, "")


def set_down(planner: GraspPlanner, s: PlaceSetup, req: PlaceRequest, plan: GraspPlan, touch: float,
             search: MotionValidator | None = None, lines: PlaceLines | None = None) -> str | None:
    """The last `touch` of the descent, the object allowed to touch its support, appended to `plan`'s
    descent and timed with it (one straight motion); why not, when it is blocked. search: the
    validator the search checked with (the supports obstacles), whose checker the set-down's derives
    from; lines: the request's PlaceLines (where the search's accept hook left the lines it checked)."""
    r, g = planner.robot, req.group
    idx = r.group_joint_indices(g)
    lines = lines or PlaceLines(planner, s, g, touch)
    q = plan.path[-1]
    line = lines.down(q, search)
    if line.reason != "complete":
        return f"the descent stops {touch - line.distance:.3f} m above the placement ({line.reason})"
    if plan.approach_path is None:  # the search's descent was 0 long: the set-down is all of it
        plan.approach_path, plan.approach_time = q[None], plan.trajectory.duration
    descent = np.vstack([plan.approach_path, line.waypoints])
    reach = _until(plan.trajectory, plan.approach_time)
    plan.trajectory = join(reach, planner.finisher.time(descent, lines.onto(search), idx, req,
                                                        path_tolerance=LINE_PATH_TOLERANCE))
    plan.approach_path, plan.path = descent, np.vstack([plan.path, line.waypoints])
    plan.approach_distance += line.distance
    plan.tcp_poses = (lines.kin.fk(plan.path[-1]),)
    return None


def _until(traj: TimedTrajectory, t: float) -> TimedTrajectory:
    """The part of a trajectory up to its stop at time t (a sample: where two stages were joined)."""
    k = int(np.searchsorted(traj.times, t - 1e-9))
    return TimedTrajectory(traj.times[:k + 1], traj.positions[:k + 1], traj.velocities[:k + 1],
                           traj.accelerations[:k + 1], traj.max_deviation, traj.method)


def retreat(planner: GraspPlanner, s: PlaceSetup, req: PlaceRequest, plan: GraspPlan, index: int,
            lines: PlaceLines | None = None) -> str | None:
    """Add the hand's retreat from the placement to `plan`; why not, when it stops short of min_distance."""
    if s.retreat is None:
        return None
    lines = lines or PlaceLines(planner, s, req.group)
    q_end = plan.path[-1]
    line, why = lines.retreat(q_end, index)
    if why:
        return why
    idx = planner.robot.group_joint_indices(req.group)
    plan.retreat_path = np.vstack([q_end[None], line.waypoints])
    plan.retreat_trajectory = planner.finisher.time(plan.retreat_path, lines.release(index).touching, idx, req,
                                                    path_tolerance=LINE_PATH_TOLERANCE)
    plan.retreat_distance = line.distance
    return None


# ------------------------------------------------------------------------------------------ two hands
def plan_dual_place(planner: GraspPlanner, scene: SceneSnapshot, req: PlaceRequest, cancel=None,
                    progress: Progress | None = None) -> PlacePlan:
    """Both hands: placements nearest the object first; for each, the carry heights CARRY_HEIGHTS in
    turn until the straight object motions (lift, across, down, approach) are free; then both hands'
    retreats at once, each along its own direction (the shorter waits)."""
    t0 = time.perf_counter()
    r = planner.robot
    try:
        s = setup(r, scene, req)
    except RequestRefused as e:
        return stamp(GraspPlan(e.status, e.message), scene, t0)
    term = Termination(req.timeout, cancel, progress=progress)
    term.phase("searching")
    groups = req.groups
    kins = [GroupKinematics(r, g, s.start) for g in groups]
    idxs = [r.group_joint_indices(g) for g in groups]
    idx = np.concatenate(idxs)
    limits = [r.motion_limits(i, s.start[i]) for i in idxs]
    tips = [r.group(g).tip_link for g in groups]
    hands = tuple(h for g in groups for h in r.hand_links(g))
    in_tcp = [object_in_tcp(r, s.att, g, s.start) for g in groups]
    plan = PlacePlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(r.joint_names[i] for i in idx))
    carry = planner.problems.motion(s.strict, groups, s.start, "", hands)
    onto = _onto(s, carry)
    q0 = s.start[idx]
    if not carry.check_configs(q0[None])[0]:
        plan.status = PlanStatus.START_IN_COLLISION
        plan.message = f"the start state is in collision: {carry.checker.colliding_pairs(q0)[:4]}"
        return stamp(plan, scene, t0)
    T0 = kins[0].fk(q0[:len(idxs[0])]) @ in_tcp[0]
    why: dict[int, str] = {}
    order = sorted(s.goals, key=lambda i: float(np.linalg.norm(s.goals[i][:3, 3] - T0[:3, 3])))
    for i in order:
        P = s.goals[i]
        turn = np.arccos(np.clip((np.trace(T0[:3, :3].T @ P[:3, :3]) - 1) / 2, -1.0, 1.0))
        if turn > ORIENTATION_TOL:
            why[i] = f"turns the object by {np.degrees(turn):.1f} deg (the two-handed carry keeps its orientation)"
            continue
        for h in CARRY_HEIGHTS:
            if term.should_stop():
                plan.status = term.stop_status()
                plan.message = "no placement reached before the timeout"
                return stamp(plan, scene, t0)
            plan.iterations += 1
            if progress is not None:
                progress.iterations = plan.iterations
            out = _carry(kins, limits, q0, T0[:3, 3], P[:3, 3], s.approach, h, carry, onto)
            if isinstance(out, str):
                why.setdefault(i, out)  # the most direct carry's reason (the lowest height)
                continue
            path, a_dist = out
            back = _dual_retreat(planner, s, req, kins, limits, tips, hands, path[-1], i)
            if isinstance(back, str):
                why[i] = back
                break  # another carry height ends in the same place
            plan.status, plan.place_index = PlanStatus.SUCCESS, i
            plan.path = path
            plan.trajectory = planner.finisher.time(path, onto, idx, req, path_tolerance=DUAL_PATH_TOLERANCE)
            plan.approach_distance = a_dist
            nl = len(idxs[0])
            plan.tcp_poses = (kins[0].fk(path[-1][:nl]), kins[1].fk(path[-1][nl:]))
            plan.grasps = tuple(GraspSpec(f"place_poses[{i}]", g, T) for g, T in zip(groups, plan.tcp_poses))
            plan.retreat_path, plan.retreat_distance, motion = back
            plan.retreat_trajectory = planner.finisher.time(plan.retreat_path, motion or onto, idx, req,
                                                            path_tolerance=LINE_PATH_TOLERANCE)
            if progress is not None:
                progress.solutions = 1
            return stamp(plan, scene, t0, i)
    plan.message = "no placement reached by the two-handed carry: " + "; ".join(
        f"place_poses[{i}]: {w}" for i, w in list(why.items())[:4])
    return stamp(plan, scene, t0)


def _carry(kins, limits, q0: np.ndarray, p0: np.ndarray, p_goal: np.ndarray, approach: GripperTranslation | None,
           height: float, motion, onto) -> tuple[np.ndarray, float] | str:
    """Both hands move the object p0 -> up -> across -> down to the pre-place point -> approach onto
    p_goal, every stretch straight with both TCPs displaced alike, checked by `motion` (the last one
    by `onto`, where the object may touch its support); (joint path from q0, approach distance) or
    why it stops."""
    D, d = 0.0, np.zeros(3)
    if approach is not None and approach.desired_distance > 0:
        D, d = float(approach.desired_distance), approach.unit  # planning frame (with_default)
    pre = p_goal - D * d
    top = max(p0[2], pre[2]) + height
    points = [p0, np.array([p0[0], p0[1], top]), np.array([pre[0], pre[1], top]), pre, p_goal]
    n = [len(lim[0]) for lim in limits]
    q = [q0[:n[0]], q0[n[0]:]]
    path = [q0[None]]
    moves = [k for k in range(len(points) - 1) if np.linalg.norm(points[k + 1] - points[k]) >= 1e-6]
    for k in moves:
        step = points[k + 1] - points[k]
        dist = float(np.linalg.norm(step))
        last = k == moves[-1]  # onto the placement: the object may touch its support
        line = parallel_lines(kins, q, step / dist, dist, limits, validate=(onto if last else motion).free_prefix)
        if line.reason != "complete":
            what = ("the lift", "the move across", "the descent", "the approach")[k]
            return f"{what} stops after {line.distance * 100:.1f} of {dist * 100:.1f} cm ({line.reason})"
        path.append(line.waypoints)
        q = [line.waypoints[-1][:n[0]], line.waypoints[-1][n[0]:]]
    return np.vstack(path), D


def _dual_retreat(planner: GraspPlanner, s: PlaceSetup, req: PlaceRequest, kins, limits, tips, hands,
                  q_end: np.ndarray, index: int) -> tuple[np.ndarray, float, MotionValidator | None] | str:
    """Both hands back from the released object, each along its own direction (TCP -z by default),
    at once: (joint path from q_end, the shorter distance, the validator to time it with) or why not."""
    gt = s.retreat
    if gt is None:
        return q_end[None], 0.0, None
    r = planner.robot
    n0 = len(limits[0][0])
    qs = [q_end[:n0], q_end[n0:]]
    lines = []
    for kin, q, (lo, hi), tip in zip(kins, qs, limits, tips):
        T = kin.fk(q)
        d = world_direction(r, with_default(gt, tip), True, tip, T, s.start)
        lines.append(straight_line(kin, q, d, gt.desired_distance, lo, hi, inverse="wln", T0=T))
    dist = min(line.distance for line in lines)
    if dist < gt.min_distance - 1e-9:
        return f"the retreat stops after {dist * 100:.1f} cm, short of min_distance {gt.min_distance * 100:.1f} cm"
    release = _release(planner, s, index, req.groups, hands)
    way = pair_approach([line.waypoints for line in lines], q_end, release)
    if way is None:
        return "the retreat after the release is blocked" + (f" ({release.why})" if release.why else "")
    return np.vstack([q_end[None], way]), dist, release.touching
