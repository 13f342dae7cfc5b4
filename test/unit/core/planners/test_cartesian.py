"""Straight TCP lines (approach, retreat): on the line within 2 mm / 1 deg, inside the joint limits,
checked by core.verification's generic FK."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.cartesian import GripperTranslation, parallel_lines, straight_line
from humanoid_planner.core.verification import verify_straight


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


def test_straight_line_keeps_to_the_line_within_the_limits(armar3):
    r = armar3
    kin = GroupKinematics(r, "left_arm", r.home)
    idx = r.group_joint_indices("left_arm")
    lo, hi = r.lower[idx], r.upper[idx]
    q0 = r.home[idx]
    d = np.array([0.3, 0.2, 1.0])
    line = straight_line(kin, q0, d, 0.10, lo, hi)
    assert line.reason == "complete" and line.distance == pytest.approx(0.10)
    assert np.all(line.waypoints >= lo) and np.all(line.waypoints <= hi)
    assert verify_straight(r, ("left_arm",), r.home, np.vstack([q0, line.waypoints]), d, min_distance=0.10) == []
    # far beyond the arm's reach the line stops where the arm gives out, still on the line
    far = straight_line(kin, q0, d, 2.0, lo, hi)
    assert far.reason in ("ik", "deviation") and 0.05 < far.distance < 2.0
    assert verify_straight(r, ("left_arm",), r.home, np.vstack([q0, far.waypoints]), d) == []


def test_parallel_lines_move_both_tcps_by_the_same_displacement(armar3):
    r = armar3
    groups = ("left_arm", "right_arm")
    kins = [GroupKinematics(r, g, r.home) for g in groups]
    idx = [r.group_joint_indices(g) for g in groups]
    line = parallel_lines(kins, [r.home[i] for i in idx], (0, 0, 1), 0.08, [(r.lower[i], r.upper[i]) for i in idx])
    assert line.reason == "complete" and line.distance == pytest.approx(0.08)
    path = np.vstack([np.concatenate([r.home[i] for i in idx]), line.waypoints])
    assert verify_straight(r, groups, r.home, path, (0, 0, 1), min_distance=0.08) == []


def test_translation_problems_are_named():
    assert GripperTranslation((0, 0, 1), 0.1, 0.05).problem() is None
    assert "direction" in GripperTranslation((0, 0, 0), 0.1).problem()
    assert "finite" in GripperTranslation((0, 0, 1), float("nan")).problem()
    assert "min_distance" in GripperTranslation((0, 0, 1), 0.1, 0.2).problem()
