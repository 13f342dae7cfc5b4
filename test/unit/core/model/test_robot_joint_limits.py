"""MoveIt's joint_limits.yaml over the URDF (RobotModel joint_limits): velocity, acceleration and position
replace the URDF's where the has_* flag is true, joints the URDF does not move are left out, bad values are
refused naming the joint, and worker processes load the same limits (RobotModel.source)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel, RobotModelError


def test_limits_replace_the_urdfs_where_flagged_and_travel_with_the_source(armar3):
    j, k = "left_shoulder_1_joint", "left_elbow_joint"
    limits = {j: {"has_velocity_limits": True, "max_velocity": 0.25, "has_acceleration_limits": True,
                  "max_acceleration": 1, "has_position_limits": True, "min_position": -0.1, "max_position": 0.2,
                  "has_jerk_limits": True, "max_jerk": 50.0},
              k: {"has_velocity_limits": False, "max_velocity": 9.0, "has_acceleration_limits": True, "max_acceleration": 0.7},
              "left_gripper_joint": {"has_velocity_limits": True, "max_velocity": 1.0}}
    r = RobotModel.preset("armar3", joint_limits=limits)
    i, e = r.joint_names.index(j), r.joint_names.index(k)
    assert (r.max_velocity[i], r.max_acceleration[i], r.lower[i], r.upper[i]) == (0.25, 1.0, -0.1, 0.2)
    assert r.max_velocity[e] == armar3.max_velocity[e] and r.max_acceleration[e] == 0.7  # has_velocity_limits false
    assert armar3.max_acceleration[i] != 1.0 and armar3.max_velocity[i] != 0.25  # the URDF's own
    assert r.ignored_joint_limits == ("left_gripper_joint",)
    assert -0.1 <= r.home[i] <= 0.2  # home stays within the new limits
    again = RobotModel.from_urdf_srdf(*r.source)  # what a worker process loads
    np.testing.assert_array_equal(again.max_velocity, r.max_velocity)
    np.testing.assert_array_equal(again.lower, r.lower)
    hash(r.source)  # a cache key


@pytest.mark.parametrize("entry, message", [
    ({"has_velocity_limits": True, "max_velocity": -1}, "max_velocity=-1 must be > 0"),
    ({"has_acceleration_limits": True, "max_acceleration": math.nan}, "max_acceleration must be a finite number"),
    ({"has_acceleration_limits": True, "max_acceleration": math.inf}, "max_acceleration must be a finite number"),
    ({"has_velocity_limits": True}, "max_velocity must be a finite number, got None"),
    ({"has_velocity_limits": True, "max_velocity": "fast"}, "got 'fast'"),
    ({"has_position_limits": True, "min_position": 1.0, "max_position": 0.0}, "min_position 1 > max_position 0"),
])
def test_bad_values_are_refused_naming_the_joint(entry, message):
    with pytest.raises(RobotModelError, match="joint_limits of left_elbow_joint: ") as e:
        RobotModel.preset("armar3", joint_limits={"left_elbow_joint": entry})
    assert message in str(e.value)
