"""What an arm searching in another process tells DAGRRT, and what DAGRRT tells it.

DAGRRT defines this protocol (it consumes the messages); `core/pipeline/arm_process.py` runs the arm
process that sends them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# Messages from an arm process to the planning thread (pickled through the pipe). Every one names
# the job it belongs to, so a late message of an earlier job is recognised and dropped.
@dataclass(frozen=True)
class Ready:
    """The process has loaded the robot and waits for jobs."""

    job_id: int = -1


@dataclass(frozen=True)
class Reachable:
    """The arm's IK hints found free solutions: the planning thread may skip its own probe."""

    job_id: int
    hints: object  # np.ndarray of configurations
    hint_targets: object  # np.ndarray of grasp indices, one per hint


@dataclass(frozen=True)
class Found:
    """A grasp was reached; its path is being shortcut (the pair can be scored meanwhile)."""

    job_id: int
    target_index: int


@dataclass(frozen=True)
class Solution:
    """A shortcut path of the arm to the grasp `target_index`."""

    job_id: int
    path: np.ndarray
    target_index: int
    cycles: int
    tree_size: int
    fallback: bool = False  # reached by the search's safety net (GraspRRT.found_by_fallback)


@dataclass(frozen=True)
class Done:
    """The job ended. error: why it failed (None if it did not); status: a PlanStatus value when it
    failed before searching (e.g. its start in collision)."""

    job_id: int
    cycles: int
    tree_size: int
    error: str | None
    status: int | None


@dataclass(frozen=True)
class Stop:
    """From the planning thread: end job `job_id` now."""

    job_id: int


ArmMessage = Ready | Reachable | Found | Solution | Done
