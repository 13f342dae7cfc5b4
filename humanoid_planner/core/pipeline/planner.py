"""The product's core entry point: a grasp request (or a joint-space goal) in, a checked,
time-parameterized plan out.

`GraspPlanner` (one per robot, reused across requests) builds the problem for one request — grasp
targets in the planning frame or a goal configuration, the group's kinematics, a collision checker
over a frozen scene snapshot — runs the planner, shortcuts the path and times it. The ROS node only
converts messages to these types and back.
"""
from __future__ import annotations

import functools
from collections import Counter
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from humanoid_planner.core.pipeline.arm_process import ArmJob, ArmWorkerPool
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.pipeline.validation import (RequestRefused, check_dual_request, check_grasp_request,
                                                     check_state_request)
from humanoid_planner.core.grasp.quality import DualGraspScorer
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.planners.baselines import GoalRRT
from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.pipeline.completion import (Completion, held_scene, pair_lines, pair_other_postures, pre_grasp_targets,
                                                        world_direction)
from humanoid_planner.core.planners.cartesian import STEER_TOL_POS, STEER_TOL_ROT, GripperTranslation
from humanoid_planner.core.planners.common import (GraspTarget, PlannerOptions, PlanResult, PlanStatus, Progress, Termination,
                                                  substream)
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.planners.dagrrt import DAGRRT
from humanoid_planner.core.planners.grasp_rrt import GraspRRT
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot
from humanoid_planner.core.postprocess.smoothing import smooth_path
from humanoid_planner.core.postprocess.timing import TimedTrajectory, join, time_parameterize
from humanoid_planner.core.transforms import pose_distance

LINE_PATH_TOLERANCE = 0.005  # rad: corner blends along a straight TCP line (its waypoints are nearly collinear)
REACHABILITY_PROBE = 0.25  # s of GIRRT search before the (cheap) reachability test is run
EXTEND_RANGE_SHARE = 0.2
"""Joint goals: an RRT-Extend goes this share of the group's joint-space extent (the norm of its
limit ranges) toward its sample, OMPL's RRT-Connect default. ARMAR-III left_arm_torso (2.1 rad), home
to 20 random free states of boxes6, 3 s each: 19 solved, mean 2.7k configurations checked per solved
plan (4 rad: the same; 1 rad: 3.8k; 0.5 rad: 4.4k and 18 solved); the thesis's single 0.1 rad step
solved 17."""
HELPER_STREAM = 5  # appended to the right arm's seed for the planning thread's second search of it (DAGRRT)


@dataclass
class GraspPlanRequest:
    """One plan_grasp request in core terms (the ROS layer has already checked the message)."""

    group: str
    start: np.ndarray  # full robot configuration (RobotModel.joint_names order)
    object_pose: np.ndarray  # 4x4 T_world_object
    grasps: Sequence[GraspSpec]
    object_id: str = ""  # scene object being grasped: no obstacle for the grasping hand
    planner: str = "girrt"
    timeout: float = 5.0
    velocity_scaling: float = 1.0
    acceleration_scaling: float = 1.0
    seed: int | None = None
    approach: GripperTranslation | None = None  # pre_grasp_approach: a straight TCP line onto the grasp
    retreat: GripperTranslation | None = None  # post_grasp_retreat: a straight TCP line away, object in hand


@dataclass
class DualGraspPlanRequest:
    """One plan_dual_grasp request in core terms."""

    left_group: str
    right_group: str
    start: np.ndarray
    object_pose: np.ndarray
    left_grasps: Sequence[GraspSpec]
    right_grasps: Sequence[GraspSpec]
    object_id: str = ""
    planner: str = "dagrrt"
    min_grasp_score: float = 0.0  # <= 0: the planner default
    timeout: float = 5.0
    velocity_scaling: float = 1.0
    acceleration_scaling: float = 1.0
    seed: int | None = None
    approach: GripperTranslation | None = None  # each hand along its own direction (same for both)
    retreat: GripperTranslation | None = None  # both TCPs by the same world displacement


@dataclass
class StatePlanRequest:
    """One plan_to_state request in core terms: the group(s) to a joint-space goal, given either as an
    SRDF group_state name or as joint values (validation.state_goal)."""

    group: str
    start: np.ndarray  # full robot configuration (RobotModel.joint_names order)
    named_state: str = ""
    goal: Mapping[str, float] | None = None  # joint name -> value, every joint of the group(s)
    right_group: str = ""  # a second group moved with `group` on one timeline (no shared joint)
    planner: str = "rrt_connect"
    timeout: float = 5.0
    velocity_scaling: float = 1.0
    acceleration_scaling: float = 1.0
    seed: int | None = None

    @property
    def groups(self) -> tuple[str, ...]:
        return (self.group, self.right_group) if self.right_group else (self.group,)


@dataclass
class GraspPlan:
    """The answer: status, and on success the timed trajectory and what it reaches."""

    status: PlanStatus
    message: str = ""
    joint_names: tuple[str, ...] = ()
    path: np.ndarray | None = None  # geometric path after shortcutting (M, n)
    trajectory: TimedTrajectory | None = None
    grasps: tuple[GraspSpec, ...] = ()  # reached grasp(s): (grasp,) or (left, right)
    tcp_poses: tuple[np.ndarray, ...] = ()  # 4x4 TCP pose(s) at the last point
    grasp_score: float = 0.0
    planning_time: float = 0.0
    iterations: int = 0
    scene_version: int = 0
    stats: dict = field(default_factory=dict)
    approach_distance: float = 0.0  # m achieved by the final straight approach (0: none asked)
    approach_path: np.ndarray | None = None  # (K, n): pre-grasp configuration, then the line's waypoints
    approach_time: float = 0.0  # s into `trajectory` where the straight approach starts
    retreat_distance: float = 0.0  # m
    retreat_path: np.ndarray | None = None  # (K, n): the grasp configuration, then the line's waypoints
    retreat_trajectory: TimedTrajectory | None = None  # starts where `trajectory` ends

    @property
    def ok(self) -> bool:
        return self.status is PlanStatus.SUCCESS


@dataclass
class SingleArmProblem:
    """A validated one-group request, set up: where every single-arm pipeline starts (ours and the
    benchmark's OMPL peer), so both plan the same problem with the same checker."""

    start: np.ndarray  # full robot configuration, clipped to the limits
    targets: list[GraspTarget]
    rng: np.random.Generator
    idx: np.ndarray  # the group's joint indices
    lower: np.ndarray
    upper: np.ndarray
    kin: GroupKinematics
    motion: MotionValidator

    @property
    def q0(self) -> np.ndarray:
        return self.start[self.idx]

    def new_plan(self, robot: RobotModel) -> GraspPlan:
        return GraspPlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(robot.joint_names[i] for i in self.idx))


class GraspPlanner:
    """Plans grasps for one robot. Thread-safe: every request builds its own problem."""

    def __init__(self, robot: RobotModel, options: PlannerOptions | None = None, *, workers: int = 2,
                 parallel: str = "process"):
        """workers: DAGRRT arms side by side (2) or interleaved in one thread (1); parallel: how two
        arms run side by side — 'process' (the right arm in a worker process, the left in the
        planning thread: real parallelism) or 'thread' (two threads sharing the interpreter lock)."""
        if parallel not in ("process", "thread"):
            raise ValueError(f"parallel must be 'process' or 'thread', got {parallel!r}")
        self.robot = robot
        self.options = options or PlannerOptions()
        self.workers = workers
        self.parallel = parallel
        self.problems = ProblemBuilder(robot, self.options)
        self._pool: ArmWorkerPool | None = None
        self._closed = False
        self._pool_lock = threading.Lock()

    def _arm_pool(self) -> ArmWorkerPool:
        with self._pool_lock:
            if self._closed:
                raise RuntimeError("the planner is closed")
            if self._pool is None:
                self._pool = ArmWorkerPool(self.robot, self.options)
            return self._pool

    def warm_up(self) -> None:
        """Pay the first-use costs now rather than in the first request: the robot's collision model
        (seconds on a mesh robot: TALOS 2-3 s), which every later checker of this robot shares, and
        DAGRRT's arm process (which builds its own before it reports ready)."""
        self.problems.warm_up()
        if self.workers >= 2 and self.parallel == "process":
            self._arm_pool().warm_up()

    def close(self) -> None:
        """Stop the arm process (a daemon, so it also ends with this process); a warm-up still starting
        it gives up, and none starts later."""
        with self._pool_lock:
            self._closed = True
            if self._pool is not None:
                self._pool.close()
                self._pool = None

    # ----------------------------------------------------------------------------- helpers
    def targets(self, object_pose: np.ndarray, grasps: Sequence[GraspSpec], group: str) -> list[GraspTarget]:
        return [GraspTarget(i, g, object_pose @ g.tcp_in_object) for i, g in enumerate(grasps)
                if self.robot.hand_usable_by(g.hand, group)]

    def finish(self, plan: GraspPlan, path: np.ndarray, motion: MotionValidator, idx: np.ndarray,
                req, term: Termination, rng: np.random.Generator | None) -> GraspPlan:
        """Shortcut with `rng` (None: already done — DAGRRT's arms shorten their own paths) and
        time-parameterize; corner blends are kept only where they stay collision-free."""
        o = self.options
        # iteration-bounded (deterministic for a seed); the time cap only binds near the deadline
        budget = max(0.0, term.remaining())
        t0 = time.perf_counter()
        plan.stats["search_time"] = term.elapsed()
        if rng is not None:
            term.phase("shortcutting")
            path = smooth_path(path, motion.check_edge, rng, budget, o.smoothing_max_iterations)
        t1 = time.perf_counter()
        term.phase("timing")
        traj = self._time(path, motion, idx, req)
        plan.path, plan.trajectory = path, traj
        plan.stats.update(trajectory_method=traj.method, smoothing_time=t1 - t0, timing_time=time.perf_counter() - t1)
        return plan

    def _time(self, path: np.ndarray, motion: MotionValidator, idx: np.ndarray, req, **kw) -> TimedTrajectory:
        """Time-parameterize; corner blends are kept only where they stay collision-free."""
        r = self.robot
        timing = dict(velocity_scaling=req.velocity_scaling, acceleration_scaling=req.acceleration_scaling,
                      position_limits=r.motion_limits(idx, path[0]), **kw)
        traj = time_parameterize(path, r.max_velocity[idx], r.max_acceleration[idx], **timing)
        if traj.max_deviation > 0 and not motion.polylines_free(traj.blends):
            # a blend cuts a corner into an obstacle: stop at every waypoint, exactly on the checked path
            timing["path_tolerance"] = 0.0
            traj = time_parameterize(path, r.max_velocity[idx], r.max_acceleration[idx], **timing)
        return traj

    def _add_lines(self, plan: GraspPlan, approach: np.ndarray, a_dist: float, retreat: np.ndarray, r_dist: float,
                   motion: MotionValidator, held: Callable[[], MotionValidator], idx: np.ndarray, req) -> GraspPlan:
        """Append the timed straight approach to the (timed) reach, and time the retreat after it."""
        end = plan.path[-1]
        if len(approach):
            plan.approach_path = np.vstack([end[None], approach])
            plan.approach_time = plan.trajectory.duration
            plan.trajectory = join(plan.trajectory, self._time(plan.approach_path, motion, idx, req,
                                                               path_tolerance=LINE_PATH_TOLERANCE))
            plan.path = np.vstack([plan.path, approach])
            plan.approach_distance = a_dist
        if req.retreat is not None:
            plan.retreat_path = np.vstack([plan.path[-1][None], retreat])
            plan.retreat_trajectory = self._time(plan.retreat_path, held(), idx, req, path_tolerance=LINE_PATH_TOLERANCE)
            plan.retreat_distance = r_dist
        return plan

    # ----------------------------------------------------------------------------- single arm
    def plan_grasp(self, scene: SceneSnapshot, req: GraspPlanRequest, cancel: threading.Event | None = None,
                   progress: Progress | None = None) -> GraspPlan:
        """progress: where the plan reports its phase and search figures while it runs (optional)."""
        return self._timed(self._plan_grasp, scene, req, cancel, progress)

    @staticmethod
    def _timed(plan_fn, scene: SceneSnapshot, req, cancel, progress: Progress | None) -> GraspPlan:
        """Run a planning function and stamp its answer with the scene version and the time it took."""
        t0 = time.perf_counter()
        plan = plan_fn(scene, req, cancel, progress)
        plan.scene_version = scene.version
        plan.planning_time = time.perf_counter() - t0
        return plan

    def _plan_grasp(self, scene: SceneSnapshot, req: GraspPlanRequest, cancel, progress: Progress | None) -> GraspPlan:
        r, o = self.robot, self.options
        term = Termination(req.timeout, cancel, progress=progress)
        term.phase("searching")
        prob = self.single_arm_problem(scene, req)
        if isinstance(prob, GraspPlan):
            return prob
        targets, rng, idx, lower, upper = prob.targets, prob.rng, prob.idx, prob.lower, prob.upper
        kin, motion, q0 = prob.kin, prob.motion, prob.q0
        plan = prob.new_plan(r)
        opts = replace(o, seed=req.seed)
        done = None
        if req.approach is not None or req.retreat is not None:
            done = Completion(r, scene, req.group, kin, prob.start, lower, upper, motion,
                              lambda sc, g, oid: self.problems.motion(sc, g, prob.start, oid, r.hand_links(req.group)),
                              req.object_id, req.approach, req.retreat)
            targets = done.pre_targets(targets)
        if req.planner == "girrt":
            res = self._run_girrt(kin, motion, lower, upper, targets, opts, rng, q0, term,
                                  accept=done.accept if done is not None else None,
                                  fallback=done.fallback_targets if done is not None else None)
        else:
            res = self._run_baseline(req.planner, kin, motion, lower, upper, targets, opts, rng, q0, term)
        plan.iterations = res.iterations
        plan.stats = {"tree_size": res.tree_size, **res.extra, **motion.checker.summary()}
        if done is not None and not res.ok and done.dropped and len(done.dropped) == len(targets) \
                and res.status is not PlanStatus.TIMED_OUT:
            plan.status, plan.message = PlanStatus.PLANNING_FAILED, done.failure()
            return plan
        if not res.ok:
            plan.status, plan.message = res.status, res.message
            return plan
        T_end = kin.fk(res.path[-1])
        target = res.target if res.target is not None else self._closest_target(T_end, targets)
        if done is not None and req.planner != "girrt" and done.accept(res.path[-1], target) is not True:
            plan.status, plan.message = PlanStatus.PLANNING_FAILED, done.failure()
            return plan
        plan.status = PlanStatus.SUCCESS
        plan.grasps, plan.tcp_poses = (target.grasp,), (T_end,)
        if done is None:
            return self.finish(plan, res.path, motion, idx, req, term, rng)
        c = done.done[target.index]
        plan = self.finish(plan, np.vstack([res.path, c.settle]), motion, idx, req, term, rng)
        plan = self._add_lines(plan, c.approach, c.approach_distance, c.retreat, c.retreat_distance, motion,
                               lambda: done.held_motion(target.index), idx, req)
        plan.tcp_poses = (kin.fk(plan.path[-1]),)
        return plan

    def single_arm_problem(self, scene: SceneSnapshot, req: GraspPlanRequest) -> SingleArmProblem | GraspPlan:
        """The request checked (validation.check_grasp_request), kinematics and collision checker built;
        or the refusal."""
        r = self.robot
        try:
            start = check_grasp_request(r, scene.frame, req)
        except RequestRefused as e:
            return GraspPlan(e.status, e.message)
        targets = self.targets(req.object_pose, req.grasps, req.group)
        idx = r.group_joint_indices(req.group)
        return SingleArmProblem(start, targets, np.random.default_rng(req.seed), idx, *r.motion_limits(idx, start[idx]),
                                GroupKinematics(r, req.group, start),
                                self.problems.motion(scene, req.group, start, req.object_id, r.hand_links(req.group)))

    @staticmethod
    def _closest_target(T: np.ndarray, targets: list[GraspTarget]) -> GraspTarget:
        d = [sum(pose_distance(T, t.T_target)) for t in targets]
        return targets[int(np.argmin(d))]

    def _run_girrt(self, kin, motion, lower, upper, targets, opts, rng, q0, term: Termination,
                   accept=None, fallback=None) -> PlanResult:
        """accept: GraspRRT's (completing each reached grasp); fallback(live targets) → targets added
        after the probe time (pre-grasps at the approach's min_distance)."""
        planner = GraspRRT(kin, motion, lower, upper, targets, opts, rng, inverse="wln",
                           ik=self.problems.ik_hints(kin, q0, lower, upper, opts.seed), accept=accept)
        planner.progress = term.progress
        failed = planner.start(q0)
        if failed is not None:
            return failed
        live = list(targets)  # searched targets: those whose approach fails leave (or are replaced)
        probe = Termination(min(REACHABILITY_PROBE, term.remaining()), term.cancel, max_cycles=opts.max_cycles)
        found = planner.search(probe, live)
        if found is None and live and not term.should_stop(planner.cycles):
            # skipped when the IK hints have shown a grasp reachable already; its own generator: how
            # many probe cycles fit in the time must not change the search's draws
            sols = q0[None] if planner.ik_reachable else self.problems.reachable(
                kin, targets, q0, lower, upper, np.random.default_rng(opts.seed))[0]
            if len(sols) == 0:
                return PlanResult(PlanStatus.NO_IK_SOLUTION,
                                  f"none of the {len(targets)} grasps is reachable by the group (inverse kinematics "
                                  "has no solution within the joint limits)", iterations=planner.cycles,
                                  tree_size=planner.tree.size)
            if fallback is not None:
                live += fallback(live)
            rest = Termination(term.remaining(), term.cancel, max_cycles=opts.max_cycles)
            found = planner.search(rest, live)
        res = PlanResult(PlanStatus.SUCCESS, iterations=planner.cycles, tree_size=planner.tree.size,
                         extra=planner.fallback_report())
        if found is None:
            res.status = term.stop_status() if term.should_stop() else PlanStatus.PLANNING_FAILED
            res.message = ("no grasp reached before the timeout" if res.status is PlanStatus.TIMED_OUT
                           else f"no grasp reached within {planner.cycles} cycles")
            return res
        goal, res.target = found
        res.path = planner.tree.path_to(goal)
        return res

    def goal_configs(self, kin, motion: MotionValidator, targets: Sequence[GraspTarget], q0: np.ndarray, lower,
                     upper, rng: np.random.Generator) -> tuple[np.ndarray, PlanResult | None]:
        """"IK first": distinct collision-free IK solutions of the grasp set (at most max_goal_configs),
        or the failed result that says why there are none. Shared by the baselines and the OMPL peer."""
        if not motion.check_configs(q0[None])[0]:
            return np.empty((0, len(q0))), PlanResult(PlanStatus.START_IN_COLLISION, "start configuration is in collision")
        sols, _ = self.problems.reachable(kin, targets, q0, lower, upper, rng)
        if len(sols) == 0:
            return sols, PlanResult(PlanStatus.NO_IK_SOLUTION,
                                    f"none of the {len(targets)} grasps is reachable by the group")
        sols = sols[motion.check_configs(sols)]
        if len(sols) == 0:
            return sols, PlanResult(PlanStatus.PLANNING_FAILED, "every inverse-kinematics solution of the grasps collides")
        keep = np.unique(np.round(sols, 3), axis=0, return_index=True)[1][: self.options.max_goal_configs]
        return sols[keep], None

    def _run_baseline(self, name, kin, motion, lower, upper, targets, opts, rng, q0, term) -> PlanResult:
        goals, failed = self.goal_configs(kin, motion, targets, q0, lower, upper, rng)
        if failed is not None:
            return failed
        return GoalRRT(name, motion, lower, upper, opts, rng).plan(q0, goals, term)

    # ----------------------------------------------------------------------------- joint-space goal
    def plan_to_state(self, scene: SceneSnapshot, req: StatePlanRequest, cancel: threading.Event | None = None,
                      progress: Progress | None = None) -> GraspPlan:
        """The group(s) to a goal configuration: the straight motion when it is free, else the request's
        planner (RRT-Connect by default) with the goal as the goal tree's root; then the same
        shortcutting and timing as a grasp. Attached objects ride along and are checked (the
        snapshot's checker carries them). A goal that collides is refused (INVALID_GOAL) naming the
        pairs, a start that collides likewise (START_IN_COLLISION)."""
        return self._timed(self._plan_to_state, scene, req, cancel, progress)

    def _plan_to_state(self, scene: SceneSnapshot, req: StatePlanRequest, cancel,
                       progress: Progress | None) -> GraspPlan:
        r = self.robot
        term = Termination(req.timeout, cancel, progress=progress)
        term.phase("searching")
        try:
            start, goal = check_state_request(r, scene.frame, req)
        except RequestRefused as e:
            return GraspPlan(e.status, e.message)
        groups = req.groups
        idx = np.concatenate([r.group_joint_indices(g) for g in groups])
        plan = GraspPlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(r.joint_names[i] for i in idx))
        motion = self.problems.motion(scene, groups if len(groups) > 1 else groups[0], start, "", ())
        q0 = start[idx]
        free = motion.check_configs(np.vstack([q0, goal]))
        for ok, q, status, what in ((free[0], q0, PlanStatus.START_IN_COLLISION, "the start state"),
                                    (free[1], goal, PlanStatus.INVALID_GOAL, "the goal")):
            if not ok:
                plan.status, plan.message = status, f"{what} is in collision: {_pairs(motion.checker.colliding_pairs(q))}"
                return plan
        rng = np.random.default_rng(req.seed)
        if motion.free_prefix(q0, goal[None]) == 1:  # nothing to search: the straight motion is free
            res = PlanResult(PlanStatus.SUCCESS, path=np.vstack([q0, goal]), tree_size=2)
        else:
            opts = replace(self.options, seed=req.seed)
            lower, upper = r.lower[idx], r.upper[idx]
            reach = EXTEND_RANGE_SHARE * float(np.linalg.norm(upper - lower))
            steps = max(1, int(np.ceil(reach / opts.joint_step)))
            res = GoalRRT(req.planner, motion, lower, upper, opts, rng, extend_steps=steps).plan(q0, goal[None], term)
        plan.iterations = res.iterations
        plan.stats = {"tree_size": res.tree_size, **res.extra, **motion.checker.summary()}
        if not res.ok:
            plan.status, plan.message = res.status, res.message.replace("a goal configuration", "the goal")
            return plan
        plan.status = PlanStatus.SUCCESS
        return self.finish(plan, res.path, motion, idx, req, term, rng)

    # ----------------------------------------------------------------------------- dual arm
    def plan_dual_grasp(self, scene: SceneSnapshot, req: DualGraspPlanRequest, cancel: threading.Event | None = None,
                        progress: Progress | None = None) -> GraspPlan:
        """progress: as plan_grasp's (arms searched in the arm process do not report to it)."""
        return self._timed(self._plan_dual, scene, req, cancel, progress)

    def _plan_dual(self, scene: SceneSnapshot, req: DualGraspPlanRequest, cancel,
                   progress: Progress | None) -> GraspPlan:
        r, o = self.robot, self.options
        try:
            start = check_dual_request(r, scene.frame, req)
        except RequestRefused as e:
            return GraspPlan(e.status, e.message)
        tl = self.targets(req.object_pose, req.left_grasps, req.left_group)
        tr = self.targets(req.object_pose, req.right_grasps, req.right_group)
        # with an approach, the arms aim at the pre-grasp poses (GraspTarget.index keys the real grasp)
        tips = [r.group(g).tip_link for g in (req.left_group, req.right_group)]
        grasp_t = [{t.index: t for t in ts} for ts in (tl, tr)]
        approach = req.approach if req.approach is not None and req.approach.desired_distance > 0 else None
        (tl, dirs_l), (tr, dirs_r) = (pre_grasp_targets(r, ts, approach, tips[k], start) for k, ts in enumerate((tl, tr)))
        a_dirs = (dirs_l, dirs_r)
        term = Termination(req.timeout, cancel, progress=progress)
        term.phase("searching")
        opts = replace(o, seed=req.seed, ik_hint_after=o.dual_ik_hint_after)
        gs_min = req.min_grasp_score if req.min_grasp_score > 0 else o.min_grasp_score
        groups = (req.left_group, req.right_group)
        kins = [GroupKinematics(r, g, start) for g in groups]
        idxs = [r.group_joint_indices(g) for g in groups]
        idx = np.concatenate(idxs)
        limits = [r.motion_limits(i, start[i]) for i in idxs]
        hands = [r.hand_links(g) for g in groups]
        both = hands[0] + hands[1]
        # The full checker of both arms is needed only for the corner blends of the final trajectory:
        # each arm's start and path are checked by the arm's own checker (the other arm at its start
        # pose included), and pairing checks only arm against arm.
        pair_motion = functools.cache(lambda: self.problems.motion(scene, groups, start, req.object_id, both))

        def make_arm(k: int, seed) -> GraspRRT:
            lo, hi = limits[k]
            motion = self.problems.motion(scene, groups[k], start, req.object_id, hands[k])
            accept = None
            if approach is not None:  # the arm drops grasps whose straight approach fails, as GIRRT does
                comp = Completion(r, scene, groups[k], kins[k], start, lo, hi, motion,
                                  lambda sc, g, oid: self.problems.motion(sc, g, start, oid, hands[k]), req.object_id,
                                  approach, None, retry_shorter=False, repair_branches=False)
                comp.pre_targets(list(grasp_t[k].values()))
                accept = comp.accept
            arm = GraspRRT(kins[k], motion, lo, hi, (tl, tr)[k], opts, np.random.default_rng(seed), inverse=o.dual_inverse,
                           ik=self.problems.ik_hints(kins[k], start[idxs[k]], lo, hi, seed), accept=accept)
            arm.progress = progress
            return arm

        def make_planner(remote: int | None) -> DAGRRT:
            arms = [None if k == remote else make_arm(k, arm_seeds[k]) for k in (0, 1)]
            return DAGRRT(arms[0], arms[1], lambda: self.problems.motion(scene, groups, start, req.object_id, both, cross_only=True),
                          lambda a, b: scorer(a.grasp, b.grasp).epsilon, gs_min, workers=self.workers,
                          seeds=tuple(arm_seeds),
                          complete=complete if req.approach is not None or req.retreat is not None else None)

        nl = len(idxs[0])
        completed: dict[tuple[int, int], tuple] = {}  # (left, right) grasp index -> settled pre-grasps, lines
        incomplete: Counter[str] = Counter()  # why pairs could not be completed -> how often
        held = functools.lru_cache(maxsize=None)(  # the object in the left hand at left grasp i, both hands touching
            lambda i: self.problems.motion(held_scene(scene, req.object_id, tips[0], grasp_t[0][i].T_target, both),
                                           groups, start, "", both))

        @functools.cache
        def postures(k: int) -> Completion:
            """Arm k's grasps' other IK postures (`Completion._branches`), for pairs whose lines fail."""
            lo, hi = limits[k]
            comp = Completion(r, scene, groups[k], kins[k], start, lo, hi,
                              self.problems.motion(scene, groups[k], start, req.object_id, hands[k]),
                              lambda sc, g, oid: self.problems.motion(sc, g, start, oid, hands[k]), req.object_id,
                              approach, None, retry_shorter=False)
            comp.pre_targets(list(grasp_t[k].values()))
            return comp

        def complete(q_pair: np.ndarray, lt: GraspTarget, rt: GraspTarget) -> bool:
            """The pair's straight approach (both hands at once) and retreat (same displacement), from
            the exact pre-grasp poses; stored in `completed` when they work."""
            pm = pair_motion()
            settled = []
            for k, (q_k, t) in enumerate(((q_pair[:nl], lt), (q_pair[nl:], rt))):
                st = steer_to_pose(kins[k], q_k, t.T_target, inverse="wln", tol_pos=STEER_TOL_POS,
                                   tol_rot=STEER_TOL_ROT, max_iters=25, lower=limits[k][0], upper=limits[k][1])
                if not st.reached:
                    incomplete["a pre-grasp pose could not be held exactly"] += 1
                    return False
                settled.append(st.last(q_k))
            q_pre = np.concatenate(settled)
            if pm.free_prefix(q_pair, q_pre[None]) < 1:
                incomplete["the exact pre-grasp poses collide"] += 1
                return False
            r_dir, held_lt = None, None  # the lift's direction and motion validator (object in the hands)
            if req.retreat is not None:
                r_dir = world_direction(r, req.retreat, False, tips[0], grasp_t[0][lt.index].T_target, start)
                held_lt = held(lt.index)
            out = pair_lines(kins, settled, [a_dirs[0].get(lt.index), a_dirs[1].get(rt.index)], req.approach, pm,
                             req.retreat, r_dir, held_lt, limits, "wln")
            if isinstance(out, str):
                # as GIRRT's accept: other IK postures of the two grasps before the pair is given up
                other = pair_other_postures([postures(0), postures(1)], q_pair, settled, (lt, rt), pm, req.retreat,
                                            r_dir, held_lt, limits, "wln")
                if other is None:
                    incomplete[out] += 1
                    return False
                q_pre, out = other
            completed[(lt.index, rt.index)] = (q_pre, out)
            return True

        def unreachable(k: int) -> bool:
            """No grasp of arm k has an inverse-kinematics solution (collisions ignored)."""
            lo, hi = limits[k]
            ik_rng = np.random.default_rng(substream(req.seed, 3 + k))
            for seeds in (8, None):
                if len(self.problems.reachable(kins[k], (tl, tr)[k], start[idxs[k]], lo, hi, ik_rng, seeds=seeds)[0]):
                    return False
            return True

        no_ik = "none of the {} hand's grasps is reachable (inverse kinematics has no solution within the limits)"
        for side, ts in (("left", tl), ("right", tr)):
            if all(len(t.grasp.contacts) < o.min_contacts_per_hand for t in ts):
                return GraspPlan(PlanStatus.GRASP_QUALITY_TOO_LOW,
                                 f"no {side} grasp has the {o.min_contacts_per_hand} contact(s) per hand GraspScore "
                                 "needs, so no pair can score above the minimum")
        scorer = DualGraspScorer(o.friction, min_contacts_per_hand=o.min_contacts_per_hand, cone_edges=o.cone_edges)
        arm_seeds = [substream(req.seed, sub) for sub in (1, 2)]
        # the arms start at once; an arm still without a solution after the probe time is tested for
        # reachability while the search goes on, so unreachable sets still fail fast (every mode alike)
        run = None
        if self.workers >= 2 and self.parallel == "process":
            # the right arm goes to the worker; this thread searches the left and does the set-up,
            # pairing and timing (with two cores, one worker keeps both busy and neither waits),
            # and once its arm is done it searches the right arm too. A worker that is busy with
            # another plan, starting or dead is not waited for: this plan runs both arms in threads
            job = ArmJob(0, scene, groups[1], start, tr, req.object_id, hands[1], opts, arm_seeds[1],
                         max(0.0, term.remaining()), o.dual_inverse, approach, list(grasp_t[1].values()))
            run = self._arm_pool().try_start([job])
        if run is not None:
            with run:
                res = make_planner(remote=1).plan_with_worker(
                    run, (start[idxs[0]], start[idxs[1]]), tr, term, unreachable, REACHABILITY_PROBE,
                    idle=[pair_motion], helper=lambda: make_arm(1, substream(arm_seeds[1], HELPER_STREAM)))
        else:
            res = make_planner(remote=None).plan(start[idxs[0]], start[idxs[1]], term, unreachable, REACHABILITY_PROBE)
        res.extra["arm_process"] = run is not None
        if res.extra.get("unreachable") is not None:
            return GraspPlan(PlanStatus.NO_IK_SOLUTION, no_ik.format(("left", "right")[res.extra["unreachable"]]))
        plan = GraspPlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(r.joint_names[i] for i in idx),
                         iterations=res.iterations, stats={"tree_size": res.tree_size, **res.extra})
        if not res.ok:
            plan.status, plan.message = res.status, res.message
            if incomplete:
                plan.message += "; " + "; ".join(f"{why} ({n}x)" for why, n in incomplete.most_common(3))
            return plan
        q_end = res.path[-1]
        plan.status = PlanStatus.SUCCESS
        plan.grasps = (res.target.grasp, res.extra["right_target"].grasp)
        plan.tcp_poses = (kins[0].fk(q_end[:nl]), kins[1].fk(q_end[nl:]))
        plan.grasp_score = float(res.extra["grasp_score"])
        if req.approach is None and req.retreat is None:
            return self.finish(plan, res.path, pair_motion(), idx, req, term, None)
        # the pair was completed when it was accepted: settle on the pre-grasps, approach, retreat
        q_pre, (appr, a_dist, back, r_dist) = completed[(res.target.index, res.extra["right_target"].index)]
        pm = pair_motion()
        plan = self.finish(plan, np.vstack([res.path, q_pre[None]]), pm, idx, req, term, None)
        plan = self._add_lines(plan, appr, a_dist, back, r_dist, pm, lambda: held(res.target.index), idx, req)
        plan.tcp_poses = (kins[0].fk(plan.path[-1][:nl]), kins[1].fk(plan.path[-1][nl:]))
        return plan


def _pairs(pairs: Sequence[tuple[str, str]], shown: int = 4) -> str:
    """Colliding pairs for a message: "'a' with 'b', ..." (the first few, and how many more)."""
    if not pairs:
        return "the exact check names no pair"
    text = ", ".join(f"{a!r} with {b!r}" for a, b in pairs[:shown])
    return text + (f" and {len(pairs) - shown} more pair(s)" if len(pairs) > shown else "")
