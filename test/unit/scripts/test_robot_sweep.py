"""The conformance sweep's machinery (scripts/robot_sweep.py) on small robots, one problem each.

Generation, the reference RRT-Connect, GIRRT and the verification end to end, in process: Panda (its own
SRDF) and UR5 (planner_setup's SRDF, merged with its own). The full sweep is `make sweep`.
"""
from __future__ import annotations

import numpy as np
import pytest

import robot_sweep as rs  # scripts/ is on pytest's pythonpath
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.planners.motion import SampledMotion
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import example_robots_dir


@pytest.fixture(scope="module", autouse=True)
def _robots():
    try:
        example_robots_dir()
    except FileNotFoundError as e:
        pytest.skip(str(e))


@pytest.mark.parametrize("name, srdf", [("panda", "own"), ("ur5", "planner_setup + own")])
def test_sweep_solves_and_verifies_the_reference_solvable_problem(name, srdf):
    rec = rs.sweep_robot(name, problems=1, budget=10.0, ref_budget=20.0, samples=200, parallel="thread")
    assert "error" not in rec, rec.get("error")
    assert rec["srdf"] == srdf
    (g,) = rec["groups"]
    assert g["kind"] == "single" and g["generated"] == 1 and not g["not_generated"]
    assert g["solvable"] == 1, g["problems"]  # these problems are within the reference's reach
    (p,) = g["problems"]
    assert p["ok"] and p["verify_problems"] == [], p
    assert g["solved"] == g["solvable"] and g["time_median"] is not None


@pytest.fixture(scope="module")
def panda():
    robot = rs.load_entry("panda", 0).robot
    return robot, rs.single_problem(robot, "arm", 0)


def test_generated_problem_keeps_obstacles_clear_of_start_and_goal(panda):
    robot, prob = panda
    assert prob.obstacles, "no table or box was placed"
    configs = np.vstack([robot.home[robot.group_joint_indices("arm")], prob.goals])
    ch = CollisionChecker(robot, prob.scene, "arm", robot.home,
                          CheckerSettings(padding=rs.CLEARANCE * 0.99, grasp_object_id=rs.OBJECT_ID,
                                          hand_links=robot.hand_links("arm")))
    assert ch.check_configs(configs).all() and not ch.fixed_collisions()
    # the first grasp is the goal configuration's own TCP pose
    q_goal = robot.expand("arm", prob.goals[0], robot.home)
    T_tcp = robot.link_poses(q_goal, [robot.group("arm").tip_link])[0]
    assert np.allclose(prob.object_pose @ prob.grasps[0][0].tcp_in_object, T_tcp, atol=1e-9)


def test_reference_motion_stops_at_the_first_blocked_waypoint(panda):
    robot, prob = panda
    idx = robot.group_joint_indices("arm")
    T_goal = prob.object_pose @ prob.grasps[0][0].tcp_in_object
    wall = SceneObject("wall", np.eye(4), (Shape("box", T_goal, (0.1, 0.1, 0.1)),))  # where the goal's hand is
    ch = CollisionChecker(robot, SceneSnapshot(1, robot.root_link, (wall,)), "arm", robot.home,
                          CheckerSettings(edge_resolution=rs.REF_RESOLUTION))
    motion = SampledMotion(ch)
    q0 = robot.home[idx]
    assert not ch.check_config(prob.goals[0])
    assert motion.free_prefix(q0, np.vstack([q0 + 0.01, q0 + 0.02])) == 2
    assert motion.free_prefix(q0, np.vstack([q0 + 0.01, prob.goals[0], q0])) == 1
