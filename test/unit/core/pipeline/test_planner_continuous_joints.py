"""Continuous joints (URDF type continuous) are unbounded, as MoveIt treats them: a start value anywhere
(at ±π, past it by rounding, several turns off) is accepted as given, and the plan moves within the turn
centred on it (RobotModel.motion_limits), so the trajectory's first point is the start a controller reported.
On PR2's right arm (example-robot-data), whose forearm and wrist roll joints are continuous."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.pipeline.validation import RequestRefused, check_start
from humanoid_planner.core.planners.common import PlannerOptions
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import example_robots_dir

GROUP = "right_arm"


@pytest.fixture(scope="module")
def pr2() -> RobotModel:
    try:
        d = example_robots_dir() / "pr2_description"
    except FileNotFoundError as e:
        pytest.skip(str(e))
    return RobotModel.from_urdf_srdf(d / "urdf/pr2.urdf", d / "srdf/pr2.srdf")


def _q(robot: RobotModel, **values: float) -> np.ndarray:
    q = robot.home.copy()
    for name, v in values.items():
        q[robot.joint_names.index(name)] = v
    return q


def test_continuous_joints_are_marked_and_bounded_by_the_turn_around_the_start(pr2):
    cont = {n for n, c in zip(pr2.joint_names, pr2.continuous) if c}
    assert {"r_forearm_roll_joint", "r_wrist_roll_joint"} <= cont
    assert "r_upper_arm_roll_joint" not in cont  # revolute, with limits
    idx = pr2.group_joint_indices(GROUP)
    q = _q(pr2, r_forearm_roll_joint=4.0)
    lo, hi = pr2.motion_limits(idx, q[idx])
    k = list(idx).index(pr2.joint_names.index("r_forearm_roll_joint"))
    assert (lo[k], hi[k]) == pytest.approx((4.0 - np.pi, 4.0 + np.pi))
    bounded = ~pr2.continuous[idx]
    assert np.array_equal(lo[bounded], pr2.lower[idx][bounded]) and np.array_equal(hi[bounded], pr2.upper[idx][bounded])
    # clipping leaves a continuous joint where it is (FK is periodic in it: clipping would move the arm)
    assert pr2.clip(q)[pr2.joint_names.index("r_forearm_roll_joint")] == 4.0


@pytest.mark.parametrize("value", [-np.pi, np.pi, -3.14159265 - 1e-4, 3.1416, 4.0, -7.0])
def test_a_continuous_start_at_or_past_pi_is_accepted_as_given(pr2, value):
    """The refusal seen in the field: `upperarm_roll_joint=-3.1416 not in [-3.1416, 3.1416]`."""
    q = _q(pr2, r_forearm_roll_joint=value)
    assert np.array_equal(check_start(pr2, q), q)


def test_bounded_joints_keep_their_limits_and_slack(pr2):
    i = pr2.joint_names.index("r_upper_arm_roll_joint")
    for past in (1e-7, 2.6e-6, 5e-5):  # a bound or a state rounded (3.14159, 3.1416 for π): clipped
        q = _q(pr2, r_upper_arm_roll_joint=pr2.upper[i] + past)
        assert check_start(pr2, q)[i] == pr2.upper[i]
    with pytest.raises(RequestRefused, match="r_upper_arm_roll_joint"):
        check_start(pr2, _q(pr2, r_upper_arm_roll_joint=pr2.upper[i] + 1e-3))
    with pytest.raises(RequestRefused, match="finite"):
        check_start(pr2, _q(pr2, r_forearm_roll_joint=np.inf))


@pytest.mark.parametrize("value,turn", [(-3.14159265 - 1e-4, -0.5), (4.0, 0.5), (-7.0, 0.4)])
def test_a_plan_from_a_continuous_start_past_pi_starts_there_and_turns_the_short_way(pr2, value, turn):
    """The grasp is the TCP pose with the roll joint `turn` further (across -π for the first case): the
    trajectory starts at the start value as given and the joint stays within half a turn of it."""
    start = _q(pr2, r_elbow_flex_joint=-1.0, r_forearm_roll_joint=value)
    goal = start.copy()
    for name, v in (("r_shoulder_pan_joint", -0.3), ("r_elbow_flex_joint", -0.6), ("r_forearm_roll_joint", value + turn)):
        goal[pr2.joint_names.index(name)] = v
    T = pr2.link_poses(goal, [pr2.group(GROUP).tip_link])[0]
    scene = SceneSnapshot(0, pr2.root_link, ())
    req = GraspPlanRequest(GROUP, start, T, (GraspSpec("g", "", np.eye(4)),), "", "girrt", 60.0, seed=1)
    plan = GraspPlanner(pr2, replace(PlannerOptions(), max_cycles=300)).plan_grasp(scene, req)
    assert plan.ok, plan.message
    idx = pr2.group_joint_indices(GROUP)
    assert np.array_equal(plan.trajectory.positions[0], start[idx])
    assert verify_plan(pr2, scene, (GROUP,), start, plan, (T,)) == []
    k = list(idx).index(pr2.joint_names.index("r_forearm_roll_joint"))
    assert np.all(np.abs(plan.trajectory.positions[:, k] - value) <= np.pi + 1e-9)
