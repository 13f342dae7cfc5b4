"""The product's core entry point: a grasp request (or a joint-space goal) in, a checked,
time-parameterized plan out.

`GraspPlanner` (one per robot, reused across requests) hands each request to its pipeline — single.py
(GIRRT, the baselines), dual.py (DAGRRT), or the joint-space goal here — which builds the problem
(problem.py: grasp targets in the planning frame, the group's kinematics, a collision checker over a
frozen scene snapshot), runs the planner, and finishes the path (plans.Finisher: shortcut, timing).
The ROS node only converts messages to these types and back.
"""
from __future__ import annotations

import threading
import time
from functools import partial
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from humanoid_planner.core.collision import pair_tables
from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.arm_process import ArmWorkerPool
from humanoid_planner.core.pipeline.completion import Finish
from humanoid_planner.core.pipeline.dual import DualArmPipeline
from humanoid_planner.core.pipeline.plans import (DualGraspPlanRequest, Finisher, GraspPlan, GraspPlanRequest,
                                                StatePlanRequest, colliding_pairs_text)
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.pipeline.single import SingleArmPipeline
from humanoid_planner.core.pipeline.validation import RequestRefused, check_state_request
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.baselines import GoalRRT
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions, PlanResult, PlanStatus, Progress, Termination
from humanoid_planner.core.planners.motion import LazyMotion, MotionValidator
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot

REFUSED = (PlanStatus.INVALID_REQUEST, PlanStatus.INVALID_GROUP, PlanStatus.INVALID_START, PlanStatus.INVALID_GOAL,
           PlanStatus.INVALID_OBJECT, PlanStatus.INVALID_FRAME)
"""Answers to requests that could not be set up (an unknown group, a malformed start): no start state to
report on."""

__all__ = ["DualGraspPlanRequest", "GraspPlan", "GraspPlanRequest", "GraspPlanner", "StatePlanRequest"]

EXTEND_RANGE_SHARE = 0.2
"""Joint goals: an RRT-Extend goes this share of the group's joint-space extent (the norm of its
limit ranges) toward its sample, OMPL's RRT-Connect default. ARMAR-III left_arm_torso (2.1 rad), home
to 20 random free states of boxes6, 3 s each: 19 solved, mean 2.7k configurations checked per solved
plan (4 rad: the same; 1 rad: 3.8k; 0.5 rad: 4.4k and 18 solved); the thesis's single 0.1 rad step
solved 17."""


@dataclass(frozen=True)
class StateProblem:
    """A checked joint-goal request (GraspPlanner.state_problem): start and goal of the groups' joints `idx`,
    their motion validator, and the answer to fill."""

    q0: np.ndarray
    goal: np.ndarray
    idx: np.ndarray
    motion: MotionValidator
    plan: GraspPlan


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
        self._pool: ArmWorkerPool | None = None
        self._closed = False
        self._pool_lock = threading.Lock()
        self.assemble(ProblemBuilder(robot, self.options), Finisher(robot, self.options))

    def assemble(self, problems: ProblemBuilder, finisher: Finisher) -> None:
        """Build the pipelines on these two stages (a benchmark passes instrumented ones)."""
        self.problems, self.finisher = problems, finisher
        self.single = SingleArmPipeline(problems, finisher)
        self.dual = DualArmPipeline(problems, finisher, self.workers, self.parallel, self._arm_pool)

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

    def targets(self, object_pose: np.ndarray, grasps: Sequence[GraspSpec], group: str) -> list[GraspTarget]:
        """The grasps `group`'s hand may use, as TCP targets in the planning frame (ProblemBuilder.targets)."""
        return self.problems.targets(object_pose, grasps, group)

    def _timed(self, plan_fn, scene: SceneSnapshot, req, cancel, progress: Progress | None) -> GraspPlan:
        """Run a pipeline and stamp its answer with the scene version, the time it took and the
        collisions the plan can neither make nor remove (fixed_collisions)."""
        t0 = time.perf_counter()
        term = Termination(req.timeout, cancel, progress=progress)
        term.phase("searching")
        with pair_tables.BUILDER.planning():  # a table built meanwhile in this process takes a quarter of the time
            plan = plan_fn(scene, req, term)
        plan.scene_version = scene.version
        plan.planning_time = time.perf_counter() - t0
        groups = req.groups if isinstance(req, StatePlanRequest) else (
            (req.left_group, req.right_group) if isinstance(req, DualGraspPlanRequest) else (req.group,))
        if plan.status not in REFUSED:
            search = plan.search_validator  # one arm: the search's own checker, built at this start already
            fixed = (search.checker.fixed_collisions() if search is not None and search.checker.groups == groups
                     else self.fixed_collisions(scene, groups, req.start))
            if fixed:
                plan.stats["fixed_collisions"] = [f"{a}–{b}" for a, b in fixed]
        return plan

    def fixed_collisions(self, scene: SceneSnapshot, groups: str | tuple[str, ...],
                         start: np.ndarray) -> tuple[tuple[str, str], ...]:
        """Colliding pairs at `start` whose relative pose no joint of `groups` changes: links neither
        moves (or that move rigidly together), and such links against the scene. The group's checker
        never counts them against a configuration (no motion makes or removes them), so a plan goes
        ahead; MoveIt would call such a start in collision, so the answer says which they are
        (GraspPlan.stats["fixed_collisions"], the node's response message and log)."""
        groups = (groups,) if isinstance(groups, str) else tuple(dict.fromkeys(groups))
        ch = CollisionChecker(self.robot, scene, groups if len(groups) > 1 else groups[0], start)
        return ch.fixed_collisions()

    # ----------------------------------------------------------------------------- grasps
    def plan_grasp(self, scene: SceneSnapshot, req: GraspPlanRequest, cancel: threading.Event | None = None,
                   progress: Progress | None = None, *, finish: Finish | None = None) -> GraspPlan:
        """progress: where the plan reports its phase and search figures while it runs (optional);
        finish: what else must work from a reached grasp (completion.Finish; plan_place's set-down and retreat)."""
        return self._timed(partial(self.single.plan, finish=finish), scene, req, cancel, progress)

    def plan_dual_grasp(self, scene: SceneSnapshot, req: DualGraspPlanRequest, cancel: threading.Event | None = None,
                        progress: Progress | None = None) -> GraspPlan:
        """progress: as plan_grasp's (arms searched in the arm process do not report to it)."""
        return self._timed(self.dual.plan, scene, req, cancel, progress)

    # ----------------------------------------------------------------------------- joint-space goal
    def plan_to_state(self, scene: SceneSnapshot, req: StatePlanRequest, cancel: threading.Event | None = None,
                      progress: Progress | None = None) -> GraspPlan:
        """The group(s) to a goal configuration: the straight motion when it is free, else the request's
        planner (RRT-Connect by default) with the goal as the goal tree's root; then the same
        shortcutting and timing as a grasp. Attached objects ride along and are checked (the
        snapshot's checker carries them). A goal that collides is refused (INVALID_GOAL) naming the
        pairs, a start that collides likewise (START_IN_COLLISION)."""
        return self._timed(self._plan_to_state, scene, req, cancel, progress)

    def state_problem(self, scene: SceneSnapshot, req: StatePlanRequest) -> "StateProblem | GraspPlan":
        """A joint-goal request set up (checked start and goal, the groups' joints, their motion validator,
        the answer to fill), or the answer refusing it: a start or goal in collision names the pairs.
        Shared by plan_to_state and its benchmark peer, so both plan the same problem."""
        r = self.robot
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
                plan.status, plan.message = status, f"{what} is in collision: {colliding_pairs_text(motion.checker.colliding_pairs(q))}"
                return plan
        return StateProblem(q0, goal, idx, motion, plan)

    def _plan_to_state(self, scene: SceneSnapshot, req: StatePlanRequest, term: Termination) -> GraspPlan:
        r = self.robot
        prob = self.state_problem(scene, req)
        if isinstance(prob, GraspPlan):
            return prob
        q0, goal, idx, motion, plan = prob.q0, prob.goal, prob.idx, prob.motion, prob.plan
        rng = np.random.default_rng(req.seed)
        if motion.free_prefix(q0, goal[None]) == 1:  # nothing to search: the straight motion is free
            res = PlanResult(PlanStatus.SUCCESS, path=np.vstack([q0, goal]), tree_size=2)
        else:
            problem = ArmProblem(None, motion, r.lower[idx], r.upper[idx], replace(self.options, seed=req.seed), rng)
            reach = EXTEND_RANGE_SHARE * float(np.linalg.norm(problem.upper - problem.lower))
            steps = max(1, int(np.ceil(reach / problem.options.joint_step)))
            # RRT-Connect searches lazily, as GraspRRT's fallback (baselines.LazyConnectSearch); the thesis's
            # baselines on the validator, as written
            lazy = req.planner == "rrt_connect"
            if lazy:
                problem = replace(problem, motion=LazyMotion(motion))
            res = GoalRRT(req.planner, problem, extend_steps=steps, lazy=lazy).plan(q0, goal[None], term)
        plan.iterations = res.iterations
        plan.stats = {"tree_size": res.tree_size, **res.extra, **motion.checker.summary()}
        if not res.ok:
            plan.status, plan.message = res.status, res.message.replace("a goal configuration", "the goal")
            return plan
        plan.status = PlanStatus.SUCCESS
        return self.finisher.finish(plan, res.path, motion, idx, req, term, rng)
