"""One arm's planning problem: what every planner of an arm (GraspRRT, the baselines, GraspRRT's fallback)
and the grasp completion read, in one frozen value instead of seven positional arguments.

`pipeline.problem.ProblemBuilder.arm` builds it for the planning thread, DAGRRT's arm process, the
benchmark's OMPL peer and the tests, so they all plan the same problem with the same checker.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions
from humanoid_planner.core.planners.motion import MotionValidator

HeldMotion = Callable[[np.ndarray], MotionValidator]
"""T_tcp at a grasp → the arm's motion validator with the grasped object attached to its TCP link there."""


@dataclass(frozen=True)
class ArmProblem:
    """A group's kinematics, motion validator and joint limits, the grasp targets it aims at, the
    options and the random stream of one search.

    `rng` is shared, not copied: the pipeline shortcuts the found path with the generator the search
    drew from, so a seed fixes the whole plan. kin is None for a joint-space problem of several groups
    (the baselines need no TCP)."""

    kin: GroupKinematics | None
    motion: MotionValidator
    lower: np.ndarray
    upper: np.ndarray
    options: PlannerOptions
    rng: np.random.Generator
    targets: tuple[GraspTarget, ...] = ()
    start: np.ndarray | None = None  # the full robot configuration the problem was set up at
    held: HeldMotion | None = None  # for retreats with the object in hand (None: nothing to hold)

    @property
    def idx(self) -> np.ndarray:
        """The group's joint indices in the full configuration."""
        if self.kin is None:
            raise ValueError("a problem without kinematics has no group joint indices")
        return self.kin.joint_indices

    @property
    def q0(self) -> np.ndarray:
        """The group's start configuration."""
        if self.start is None:
            raise ValueError("the problem has no start configuration")
        return self.start[self.idx]

    def seeded(self, rng: np.random.Generator) -> "ArmProblem":
        """The same problem searched with another random stream (a second search of one arm)."""
        return replace(self, rng=rng)
