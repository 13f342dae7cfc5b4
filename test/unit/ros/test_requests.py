"""plan_grasp / plan_dual_grasp requests (ros.requests), no ROS graph: a good request becomes the core
request with the node's defaults filled in; each kind of bad field gets its ErrorCode and a message
that names it; a plan becomes a response whose trajectory is the plan's."""
from __future__ import annotations

import math

import numpy as np
import pytest
from sensor_msgs.msg import JointState

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlan
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.postprocess.timing import time_parameterize
from humanoid_planner.ros.frames import Frames
from humanoid_planner.ros.message_dict import dict_to_msg
from humanoid_planner.ros.requests import (ERROR_CODES, ERROR_NAMES, RequestDefaults, RequestError, fill_response,
                                           prepare_plan_dual_grasp, prepare_plan_grasp, start_state)
from humanoid_planner.scenarios import OBJECT_ID, make_scenario
from humanoid_planner_interfaces.msg import ErrorCode
from humanoid_planner_interfaces.srv import PlanDualGrasp, PlanGrasp

DEFAULTS = RequestDefaults(default_timeout=4.0, min_grasp_score=0.002, max_timeout=30.0)


@pytest.fixture(scope="module")
def world():
    robot = RobotModel.preset("armar3")
    sc = make_scenario(robot, "empty", 0, hand="both")
    return robot, sc, Frames(robot, robot.root_link, ("world",))


def single(world, **fields):
    robot, sc, frames = world
    return prepare_plan_grasp(robot, dict_to_msg(PlanGrasp.Request, {"group": "left_arm", "object_id": OBJECT_ID,
                                                                      **fields}), sc.scene, None, DEFAULTS, frames)


def dual(world, **fields):
    robot, sc, frames = world
    data = {"left_group": "left_arm", "right_group": "right_arm", "object_id": OBJECT_ID, **fields}
    return prepare_plan_dual_grasp(robot, dict_to_msg(PlanDualGrasp.Request, data), sc.scene, None, DEFAULTS, frames)


def test_a_good_request_gets_the_defaults(world):
    robot, sc, _ = world
    prep = single(world)
    core = prep.core
    assert prep.kind == "plan_grasp" and prep.groups == ("left_arm",) and prep.snapshot is sc.scene
    assert (core.planner, core.timeout, core.velocity_scaling, core.seed) == ("girrt", 4.0, 1.0, None)
    np.testing.assert_array_equal(core.start, robot.home)
    np.testing.assert_array_equal(core.object_pose, sc.object_pose)
    assert tuple(core.grasps) == sc.scene.get(OBJECT_ID).grasps  # the object's own grasp set
    d = dual(world, seed=7, timeout=100.0, min_grasp_score=-1.0).core
    assert (d.planner, d.seed, d.timeout, d.min_grasp_score) == ("dagrrt", 7, 30.0, 0.002)  # timeout clamped


def test_clamped_timeout_is_said(world):
    assert single(world, timeout=100.0).notes and not single(world, timeout=10.0).notes


BAD_SINGLE = [
    ({"group": "torso_and_legs"}, ErrorCode.INVALID_GROUP_NAME, "unknown planning group"),
    ({"planner": "prm"}, ErrorCode.FAILURE, "unknown planner 'prm'"),
    ({"timeout": -1.0}, ErrorCode.FAILURE, "timeout"),
    ({"timeout": math.nan}, ErrorCode.FAILURE, "timeout"),
    ({"max_velocity_scaling": 1.5}, ErrorCode.FAILURE, "max_velocity_scaling"),
    ({"max_acceleration_scaling": 1e-9}, ErrorCode.FAILURE, "max_acceleration_scaling"),
    ({"start_state": {"name": ["no_joint"], "position": [0.0]}}, ErrorCode.INVALID_ROBOT_STATE, "unknown joint"),
    ({"start_state": {"name": ["left_shoulder_1_joint"], "position": []}}, ErrorCode.INVALID_ROBOT_STATE, "positions"),
    ({"start_state": {"name": ["left_shoulder_1_joint"], "position": [math.inf]}}, ErrorCode.INVALID_ROBOT_STATE,
     "NaN or inf"),
    ({"start_state": {"name": ["left_shoulder_1_joint"], "position": [50.0]}}, ErrorCode.INVALID_ROBOT_STATE,
     "left_shoulder_1_joint=50"),
    ({"object_id": "ghost"}, ErrorCode.INVALID_OBJECT_NAME, "'ghost' is not in the planning scene"),
    ({"object_id": "", "object_pose": {"header": {"frame_id": "odom"}, "pose": {"orientation": {"w": 1.0}}}},
     ErrorCode.FRAME_TRANSFORM_FAILURE, "'odom'"),
    ({"object_id": "", "object_pose": {"pose": {"orientation": {"w": 1.0}}}}, ErrorCode.INVALID_GOAL_CONSTRAINTS,
     "no grasps"),
    ({"object_id": "", "object_pose": {"pose": {"orientation": {"w": 0.0}}}, "grasps": [{"id": "g"}]},
     ErrorCode.INVALID_GOAL_CONSTRAINTS, "object_pose"),
    ({"grasps": [{"id": "g", "hand": "right_arm", "tcp_in_object": {"orientation": {"w": 1.0}}}]},
     ErrorCode.INVALID_GOAL_CONSTRAINTS, "may be used by group 'left_arm'"),
]


@pytest.mark.parametrize("fields,code,words", BAD_SINGLE)
def test_bad_fields_get_their_code_and_a_message_naming_them(world, fields, code, words):
    with pytest.raises(RequestError) as e:
        single(world, **fields)
    assert (ERROR_NAMES[e.value.code], words in e.value.message) == (ERROR_NAMES[code], True), e.value.message


def test_dual_groups_must_be_disjoint_and_scores_finite(world):
    with pytest.raises(RequestError) as e:
        dual(world, left_group="left_arm_torso", right_group="right_arm_torso")
    assert e.value.code == ErrorCode.INVALID_GROUP_NAME and "share joint" in e.value.message
    with pytest.raises(RequestError) as e:
        dual(world, min_grasp_score=math.inf)
    assert e.value.code == ErrorCode.FAILURE and "min_grasp_score" in e.value.message


def test_start_state_merges_request_over_joint_states_over_home(world):
    robot, _, _ = world
    i, j = robot.joint_names.index("left_shoulder_1_joint"), robot.joint_names.index("left_shoulder_2_joint")
    latest = JointState(name=[robot.joint_names[i], robot.joint_names[j], "unknown"], position=[0.1, 0.2, 9.0])
    q = start_state(robot, JointState(name=[robot.joint_names[j]], position=[0.3]), latest)
    assert (q[i], q[j]) == (0.1, 0.3)
    rest = np.delete(np.arange(robot.dof), [i, j])
    np.testing.assert_array_equal(q[rest], robot.home[rest])


def test_every_plan_status_has_an_error_code():
    assert set(ERROR_CODES) == set(PlanStatus)
    assert ERROR_NAMES[ErrorCode.SUCCESS] == "SUCCESS"


def test_a_plan_becomes_a_response_with_its_trajectory(world):
    robot, sc, frames = world
    prep = single(world)
    idx = robot.group_joint_indices("left_arm")
    path = np.array([robot.home[idx], robot.home[idx] + 0.2])
    traj = time_parameterize(path, robot.max_velocity[idx], robot.max_acceleration[idx])
    grasp = prep.core.grasps[0]
    plan = GraspPlan(PlanStatus.SUCCESS, joint_names=tuple(robot.joint_names[k] for k in idx), path=path,
                     trajectory=traj, grasps=(grasp,), tcp_poses=(np.eye(4),), iterations=12, scene_version=3)
    resp = fill_response(PlanGrasp.Response(), plan, frames.planning_frame, dual=False)
    assert resp.error_code.val == ErrorCode.SUCCESS and resp.iterations == 12 and resp.scene_version == 3
    t = resp.trajectory
    assert t.header.frame_id == frames.planning_frame and list(t.joint_names) == list(plan.joint_names)
    assert len(t.points) == len(traj.times) and resp.grasp.id == grasp.id
    np.testing.assert_allclose([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in t.points],
                               traj.times, atol=1e-9)
    np.testing.assert_allclose([list(p.positions) for p in t.points], traj.positions)
    failed = fill_response(PlanGrasp.Response(), GraspPlan(PlanStatus.NO_IK_SOLUTION, "none reachable"), frames.planning_frame,
                           dual=False)
    assert failed.error_code.val == ErrorCode.NO_IK_SOLUTION and not failed.trajectory.points
    assert failed.message == "none reachable"
