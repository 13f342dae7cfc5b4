"""The frames the node accepts in a pose: the planning frame (or "" for it, or a name that coincides
with it, e.g. the URDF root when the planning frame is `world`) and every link of the robot.

A link frame is resolved with the robot's forward kinematics at the latest `joint_states` (its usable
entries over the home pose, clipped to the limits; the home pose before the first message). This is
the one resolver of the node: object poses of plan requests, CollisionObject headers and point
clouds go through `Frames.pose`; other frames raise FrameError (requests answer
FRAME_TRANSFORM_FAILURE, scene messages are rejected).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from sensor_msgs.msg import JointState

from humanoid_planner.core.model.robot import RobotModel


class FrameError(ValueError):
    """A frame the node cannot express in the planning frame."""


def configuration(robot: RobotModel, latest: JointState | None) -> np.ndarray:
    """The robot's configuration now: the latest joint_states (known joints, finite values) over the
    home pose, clipped to the limits (continuous joints as reported: they have none)."""
    q = np.array(robot.home, dtype=float)
    if latest is not None:
        index = {n: i for i, n in enumerate(robot.joint_names)}
        for name, p in zip(latest.name, latest.position):
            i = index.get(name)
            if i is not None and math.isfinite(float(p)):
                q[i] = float(p)
    return robot.clip(q)


class Frames:
    """frame name -> T_planning_frame (4x4) for the planning frame's names and the robot's links."""

    def __init__(self, robot: RobotModel, planning_frame: str, aliases: tuple[str, ...] = (),
                 latest_joint_state: Callable[[], JointState | None] = lambda: None):
        self.robot = robot
        self.names = (planning_frame, *aliases)  # names of the planning frame itself; [0] is the planning frame
        self._latest = latest_joint_state

    @property
    def planning_frame(self) -> str:
        return self.names[0]

    def is_planning(self, frame: str) -> bool:
        """"" or a name of the planning frame (no transform needed)."""
        return not frame or frame in self.names

    def configuration(self) -> np.ndarray:
        return configuration(self.robot, self._latest())

    def pose(self, frame: str, q: np.ndarray | None = None) -> np.ndarray:
        """T_planning_frame of `frame` (at q, default: the current configuration); FrameError if unknown."""
        if self.is_planning(frame):
            return np.eye(4)
        if frame in self.robot.link_names:
            return self.robot.link_poses(self.configuration() if q is None else q, [frame])[0]
        raise FrameError(f"frame {frame!r} is neither the planning frame {self.planning_frame!r} nor a link of the "
                         f"robot {self.robot.name!r}")
