"""core/collision/voxels.py through the checker: cells are obstacles wherever the surface they were
seen on is, plans go around an obstacle the planner knows only as points, and the target's own
points (filtered out) do not block its grasps."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import CLOUD_GROUP as GROUP
from conftest import WALL_SIZE, wall_problem
from conftest import cloud_layer as _layer

from humanoid_planner.clouds import box_surface_points, scene_boxes
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.scene.types import SceneSnapshot
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import OBJECT_ID, make_scenario


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def problem(robot):
    return wall_problem(robot)[0]


def test_checker_cells_cover_the_obstacles_they_come_from(robot):
    sc = make_scenario(robot, "boxes6", 3)
    target = sc.scene.get(OBJECT_ID)
    pts = np.concatenate([box_surface_points(p, s, 0.01) for p, s in scene_boxes(sc.scene.objects, (OBJECT_ID,))])
    layer, _ = _layer(pts, robot, objects=(target,))
    cloud = SceneSnapshot(1, sc.scene.frame, (target,), layer)
    boxes = CollisionChecker(robot, sc.scene, GROUP, robot.home, CheckerSettings(grasp_object_id=OBJECT_ID))
    cells = CollisionChecker(robot, cloud, GROUP, robot.home, CheckerSettings(grasp_object_id=OBJECT_ID))
    bare = CollisionChecker(robot, SceneSnapshot(1, sc.scene.frame, (target,)), GROUP, robot.home,
                            CheckerSettings(grasp_object_id=OBJECT_ID))
    assert cells.summary()["voxel_cells"] == len(layer) > 100
    idx = robot.group_joint_indices(GROUP)
    Q = np.random.default_rng(1).uniform(robot.lower[idx], robot.upper[idx], size=(1500, len(idx)))
    ok_boxes, ok_cells, ok_bare = boxes.check_configs(Q), cells.check_configs(Q), bare.check_configs(Q)
    assert not np.any(~ok_boxes & ok_cells)  # what hits a box hits its cells
    assert np.sum(ok_bare & ~ok_cells) > 50  # and the cells are obstacles at all
    # the batched path agrees with the exact one (FCL against every cell a shape's cover reaches)
    assert [cells.exact_check(q) for q in Q[:300]] == ok_cells[:300].tolist()


def test_plan_goes_around_a_box_seen_only_as_points(robot, problem):
    _, target, wall, walled = wall_problem(robot)
    planner = GraspPlanner(robot)

    def plan(scene, seed):
        req = GraspPlanRequest(GROUP, robot.home.copy(), problem.object_pose, problem.left_grasps, OBJECT_ID,
                               "girrt", 10.0, seed=seed)
        p = planner.plan_grasp(scene, req)
        assert p.ok, p.message
        return p, verify_plan(robot, walled, (GROUP,), robot.home, p,
                              (problem.object_pose @ p.grasps[0].tcp_in_object,), object_id=OBJECT_ID)

    # the wall is in the way: plans made without it run into it
    assert plan(problem.scene, 1)[1] and plan(problem.scene, 2)[1]
    layer, stats = _layer(box_surface_points(wall.pose, WALL_SIZE, 0.01), robot, objects=(target,))
    assert stats.on_robot == 0 and stats.in_objects == 0 and len(layer) > 100
    for seed in (1, 2):
        _, problems = plan(SceneSnapshot(3, problem.scene.frame, (target,), layer), seed)
        assert problems == [], problems  # verified against the wall itself


def test_target_points_do_not_block_its_grasps(robot, problem):
    """Points all over the target: with them filtered out its grasp is planned; the cells they
    would have made collide with that grasp."""
    target = problem.scene.get(OBJECT_ID)
    (pose, size), = scene_boxes((target,))
    pts = box_surface_points(pose, size, 0.005)
    layer, stats = _layer(pts, robot, objects=(target,))
    assert stats.in_objects == stats.used == len(pts) and len(layer) == 0
    req = GraspPlanRequest(GROUP, robot.home.copy(), problem.object_pose, problem.left_grasps, OBJECT_ID, "girrt",
                           10.0, seed=2)
    plan = GraspPlanner(robot).plan_grasp(SceneSnapshot(1, problem.scene.frame, (target,), layer), req)
    assert plan.ok, plan.message
    raw, _ = _layer(pts, robot)
    blocked = CollisionChecker(robot, SceneSnapshot(1, problem.scene.frame, (target,), raw), GROUP, robot.home,
                               CheckerSettings(grasp_object_id=OBJECT_ID))
    assert len(raw) > 50 and not blocked.check_config(plan.path[-1])
