"""What goes into and comes out of the pipeline — requests in core terms, the `GraspPlan` answer — and the
last stage every pipeline shares (`Finisher`: shortcutting, time parameterization, the straight lines
appended).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from typing import Callable, Mapping, Protocol, Sequence

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlannerOptions, PlanStatus, Termination
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.postprocess.smoothing import SHORTCUT_FIRST_BATCH, smooth_path
from humanoid_planner.core.postprocess.timing import TimedTrajectory, join, time_parameterize
from humanoid_planner.core.scene.types import GraspSpec

LINE_PATH_TOLERANCE = 0.005  # rad: corner blends along a straight TCP line (its waypoints are nearly collinear)



class Timing(Protocol):
    """What a request says about timing (every request type has these fields)."""

    velocity_scaling: float
    acceleration_scaling: float


class StraightLines(Protocol):
    """A grasp's (or a pair's) accepted straight lines: completion.GraspLines, pair_completion.PairLines."""

    approach: np.ndarray  # waypoints onto the grasp, the pre-grasp configuration excluded
    approach_distance: float
    retreat: np.ndarray  # waypoints from the grasp, the grasp configuration excluded
    retreat_distance: float


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
    search_validator: object = field(default=None, repr=False, compare=False)
    """One arm: the MotionValidator the search checked with, free once the plan returns; a caller that
    checks more motions in nearly the same scene derives its checker from this one (CollisionChecker.
    exempting: plan_place's set-down) instead of building another. Not for the answer."""

    @property
    def ok(self) -> bool:
        return self.status is PlanStatus.SUCCESS

    def __getstate__(self) -> dict:
        """Pickled (to or from another process) without search_validator: fcl objects do not pickle."""
        return {**self.__dict__, "search_validator": None}


class Finisher:
    """The last stage of every pipeline: shortcut, time-parameterize, append the straight lines."""

    def __init__(self, robot: RobotModel, options: PlannerOptions):
        self.robot = robot
        self.options = options

    def finish(self, plan: GraspPlan, path: np.ndarray, motion: MotionValidator, idx: np.ndarray,
               req: Timing, term: Termination, rng: np.random.Generator | None) -> GraspPlan:
        """Shortcut with `rng` (None: already done — DAGRRT's arms shorten their own paths) and
        time-parameterize; corner blends are kept only where they stay collision-free."""
        o = self.options
        # iteration-bounded (deterministic for a seed); the time cap only binds near the deadline
        budget = max(0.0, term.remaining())
        t0 = time.perf_counter()
        plan.stats["search_time"] = term.elapsed()
        if rng is not None:
            term.phase("shortcutting")
            path = smooth_path(path, partial(motion.check_edge, first=SHORTCUT_FIRST_BATCH), rng, budget,
                               o.smoothing_max_iterations)
        t1 = time.perf_counter()
        term.phase("timing")
        traj = self.time(path, motion, idx, req)
        plan.path, plan.trajectory = path, traj
        plan.stats.update(trajectory_method=traj.method, smoothing_time=t1 - t0, timing_time=time.perf_counter() - t1)
        return plan

    def time(self, path: np.ndarray, motion: MotionValidator, idx: np.ndarray, req: Timing, **kw) -> TimedTrajectory:
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

    def add_lines(self, plan: GraspPlan, lines: StraightLines, motion: MotionValidator,
                  held: Callable[[], MotionValidator], idx: np.ndarray,
                  req: "GraspPlanRequest | DualGraspPlanRequest") -> GraspPlan:
        """Append the timed straight approach to the (timed) reach, and time the retreat after it."""
        approach, a_dist, retreat, r_dist = lines.approach, lines.approach_distance, lines.retreat, lines.retreat_distance
        end = plan.path[-1]
        if len(approach):
            plan.approach_path = np.vstack([end[None], approach])
            plan.approach_time = plan.trajectory.duration
            plan.trajectory = join(plan.trajectory, self.time(plan.approach_path, motion, idx, req,
                                                               path_tolerance=LINE_PATH_TOLERANCE))
            plan.path = np.vstack([plan.path, approach])
            plan.approach_distance = a_dist
        if req.retreat is not None:
            plan.retreat_path = np.vstack([plan.path[-1][None], retreat])
            plan.retreat_trajectory = self.time(plan.retreat_path, held(), idx, req, path_tolerance=LINE_PATH_TOLERANCE)
            plan.retreat_distance = r_dist
        return plan


def colliding_pairs_text(pairs: Sequence[tuple[str, str]], shown: int = 4) -> str:
    """Colliding pairs for a message: "'a' with 'b', ..." (the first few, and how many more)."""
    if not pairs:
        return "the exact check names no pair"
    text = ", ".join(f"{a!r} with {b!r}" for a, b in pairs[:shown])
    return text + (f" and {len(pairs) - shown} more pair(s)" if len(pairs) > shown else "")
