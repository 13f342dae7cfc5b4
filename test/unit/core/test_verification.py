"""Independent plan checks (core.verification) on the small 3-DoF test arm: a sound plan passes, and
each kind of fault (start, limits, time, speed, missed grasp, collision) is reported."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlan
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.postprocess.timing import time_parameterize
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.verification import dense, verify_plan

GROUPS = ("arm",)


@pytest.fixture(scope="module")
def arm(test_robot_description):
    """(robot, start, plan, target): shoulder and elbow swing from home to (0.8, -0.6, 0.3)."""
    robot = RobotModel.from_urdf_srdf(*test_robot_description)
    start = robot.home.copy()
    path = np.array([start, [0.4, -0.3, 0.15], [0.8, -0.6, 0.3]])
    traj = time_parameterize(path, robot.max_velocity, robot.max_acceleration, path_tolerance=0.0,
                             position_limits=(robot.lower, robot.upper))
    plan = GraspPlan(PlanStatus.SUCCESS, joint_names=robot.joint_names, path=path, trajectory=traj)
    target = robot.link_poses(path[-1], ["tcp"])[0]
    return robot, start, plan, target


def box_at(p, size=0.06) -> SceneSnapshot:
    T = np.eye(4)
    T[:3, 3] = p
    return SceneSnapshot(1, "base_link", (SceneObject("box", T, (Shape("box", np.eye(4), (size,) * 3),)),))


EMPTY = SceneSnapshot(1, "base_link")


def test_dense_interpolates_within_the_resolution():
    path = np.array([[0.0, 0.0], [0.1, -0.05], [0.1, -0.05], [0.0, 0.3]])
    d = dense(path, 0.01)
    np.testing.assert_array_equal(d[0], path[0])
    np.testing.assert_allclose(d[-1], path[-1])
    assert np.max(np.abs(np.diff(d, axis=0))) <= 0.01 + 1e-12
    assert len(d) == 1 + 10 + 1 + 35


def test_a_sound_plan_passes(arm):
    robot, start, plan, target = arm
    assert verify_plan(robot, EMPTY, GROUPS, start, plan, (target,)) == []
    far = box_at([0.5, 0.5, 0.0])  # nowhere near the arm
    assert verify_plan(robot, far, GROUPS, start, plan, (target,)) == []


def test_a_colliding_path_is_reported(arm):
    robot, start, plan, target = arm
    mid = robot.link_poses(plan.path[1], ["forearm"])[0] @ np.array([0, 0, 0.125, 1.0])  # on the forearm, mid-motion
    problems = verify_plan(robot, box_at(mid[:3]), GROUPS, start, plan, (target,))
    assert len(problems) == 1 and problems[0].startswith("collision at configuration")
    # the grasped object may touch the hand, nothing else
    tcp = box_at(target[:3, 3], 0.03)
    assert verify_plan(robot, tcp, GROUPS, start, plan, (target,), object_id="box") == []
    assert any("collision" in p for p in verify_plan(robot, tcp, GROUPS, start, plan, (target,)))


def test_missed_grasp_wrong_start_and_bad_timing_are_reported(arm):
    robot, start, plan, target = arm
    off = target.copy()
    off[:3, 3] += [0.0, 0.0, 0.01]
    assert verify_plan(robot, EMPTY, GROUPS, start, plan, (off,)) == ["arm: TCP misses the grasp by 10.00 mm / 0.00 deg"]
    other = start + [0.1, 0.0, 0.0]
    problems = verify_plan(robot, EMPTY, GROUPS, other, plan, (target,))
    assert "trajectory does not start at the start state" in problems and "path does not start at the start state" in problems
    t = plan.trajectory
    fast = dataclasses.replace(plan, trajectory=dataclasses.replace(t, times=t.times / 2, velocities=t.velocities * 2,
                                                                     accelerations=t.accelerations * 4))
    problems = verify_plan(robot, EMPTY, GROUPS, start, fast, (target,))
    assert [p.split(":")[0] for p in problems] == ["velocity limit exceeded", "acceleration limit exceeded"]
    stalled = dataclasses.replace(plan, trajectory=dataclasses.replace(t, times=np.r_[t.times[:2], t.times[1:-1]]))
    assert "times are not strictly increasing from 0" in verify_plan(robot, EMPTY, GROUPS, start, stalled, (target,))


def test_leaving_the_joint_limits_is_reported(arm):
    robot, start, plan, target = arm
    t = plan.trajectory
    pos = t.positions.copy()
    pos[len(pos) // 2, 2] = robot.upper[2] + 0.01  # the wrist, mid-trajectory
    out = dataclasses.replace(plan, trajectory=dataclasses.replace(t, positions=pos))
    assert "trajectory leaves the joint limits" in verify_plan(robot, EMPTY, GROUPS, start, out, (target,))
