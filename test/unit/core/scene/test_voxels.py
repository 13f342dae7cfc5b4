"""core/scene/voxels.py: a cloud → the cells of the point-cloud layer (NaN, range, sensor frame,
the robot's own points, the scene objects' points), and the scene's layer with its versions."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import cloud_layer as _layer

from humanoid_planner.clouds import box_surface_points, look_at
from humanoid_planner.core.collision.geometry import RobotCollisionModel
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner.core.scene.types import SceneObject, Shape, VoxelLayer
from humanoid_planner.core.scene.voxels import CloudError, CloudSettings, robot_solids


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.preset("armar3")


def T(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    M = np.eye(4)
    M[:3, 3] = (x, y, z)
    return M


def _cells(layer) -> set:
    return set(map(tuple, layer.cells.tolist()))


def _shape_surface(solid, n: int, rng) -> np.ndarray:
    """Points on a robot solid's surface (world frame)."""
    if solid.kind == "box":
        P = box_surface_points(solid.pose, 2 * np.asarray(solid.params[0]), 0.01)
        return P
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    if solid.kind == "sphere":
        local = u * solid.params[0]
    else:  # cylinder: the side
        r, half = solid.params
        a = rng.uniform(0, 2 * np.pi, n)
        local = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-half, half, n)])
    return local @ solid.pose[:3, :3].T + solid.pose[:3, 3]


# ----------------------------------------------------------------------------- scene layer
def test_scene_layer_replaces_and_counts_versions():
    scene = PlanningScene("base_link")
    assert scene.snapshot().voxels is None
    layer = VoxelLayer(0.02, np.array([[0, 0, 0], [1, 2, 3]]))
    assert scene.set_voxels(layer) == 1
    snap = scene.snapshot()
    assert snap.version == 1 and len(snap.voxels) == 2 and snap.voxels.cells.dtype == np.int32
    np.testing.assert_allclose(snap.voxels.centers[1], [0.03, 0.05, 0.07])
    assert scene.set_voxels(VoxelLayer(0.02, np.zeros((0, 3), int))) == 2  # an empty cloud clears the layer
    assert len(scene.snapshot().voxels) == 0 and len(snap.voxels) == 2  # the old snapshot keeps its layer
    for bad in (VoxelLayer(0.0, np.zeros((1, 3), int)), VoxelLayer(np.nan, np.zeros((1, 3), int)),
                VoxelLayer(0.02, np.zeros((1, 2), int)), VoxelLayer(0.02, np.zeros((1, 3)))):
        with pytest.raises(SceneUpdateError):
            scene.set_voxels(bad)
    assert scene.version == 2


def test_cells_range_nan_inf():
    pts = [[0.011, 0.0, 0.0], [0.019, 0.001, 0.002],  # one cell
           [-0.001, 0.0, 0.0],  # the cell below zero
           [np.nan, 0.0, 0.0], [np.inf, 0.0, 0.0], [0.0, -np.inf, 0.0],  # dropped
           [2.9, 0.0, 0.0], [3.1, 0.0, 0.0]]  # within / beyond 3 m from the sensor
    layer, stats = _layer(pts, max_range=3.0)
    assert _cells(layer) == {(0, 0, 0), (-1, 0, 0), (145, 0, 0)}
    assert (stats.points, stats.used, stats.cells) == (8, 4, 3)
    layer, _ = _layer(pts, max_range=3.0, voxel_size=0.05)
    assert _cells(layer) == {(0, 0, 0), (-1, 0, 0), (58, 0, 0)}
    empty, stats = _layer(np.zeros((0, 3)))
    assert len(empty) == 0 and stats.cells == 0
    with pytest.raises(CloudError):
        CloudSettings(voxel_size=0.0)
    with pytest.raises(CloudError):
        _layer(np.zeros((4, 2)))


def test_sensor_frame_transform():
    rng = np.random.default_rng(3)
    world = rng.uniform(-1, 1, size=(2000, 3))
    T_ws = look_at([0.3, -0.5, 1.6], [0.5, 0.2, 0.9])
    sensor = (world - T_ws[:3, 3]) @ T_ws[:3, :3]  # the same points in the sensor frame
    a, _ = _layer(world, max_range=10.0)
    b, _ = _layer(sensor, max_range=10.0, T_world_sensor=T_ws)
    assert len(a) > 100 and _cells(a) == _cells(b)
    # range counts from the sensor, not from the planning frame's origin
    c, _ = _layer(sensor, max_range=0.5, T_world_sensor=T_ws)
    d = np.linalg.norm(world - T_ws[:3, 3], axis=1)
    assert _cells(c) == _cells(_layer(world[d <= 0.5])[0])


def test_cloud_of_the_robots_own_arm_leaves_no_cell_on_it(robot):
    rng = np.random.default_rng(0)
    q = robot.home.copy()
    q[robot.group_joint_indices("left_arm")] = [0.2, -0.6, 0.3, 1.0, 0.5, 0.2, -0.1]
    arm = robot.moving_links("left_arm")
    solids = [s for link in arm for s in robot_solids_of(robot, q, link)]
    pts = np.concatenate([_shape_surface(s, 400, rng) for s in solids])
    unfiltered, _ = _layer(pts)
    assert len(unfiltered) > 100
    layer, stats = _layer(pts, robot, q)
    assert len(layer) == 0 and stats.on_robot == len(pts)
    # at home the arm is elsewhere: its points stay (the filter uses the cloud's joint state)
    assert len(_layer(pts, robot, robot.home)[0]) > 0.5 * len(unfiltered)


def robot_solids_of(robot, q, link):
    """robot_solids restricted to one link (same order as RobotCollisionModel)."""
    model = RobotCollisionModel.for_robot(robot)
    out, i = [], 0
    solids = robot_solids(robot, q)
    for name, lc in model.links.items():
        n = len(lc.shapes)
        if name == link:
            out = solids[i:i + n]
        i += n
    return out


def test_points_inside_scene_objects_removed():
    box = SceneObject("target", T(0.5, 0.0, 1.0), (Shape("box", np.eye(4), (0.06, 0.06, 0.2)),))
    ball = SceneObject("ball", T(0.0, 0.5, 1.0), (Shape("sphere", np.eye(4), (0.05,)),))
    pts = np.concatenate([box_surface_points(box.pose, (0.06, 0.06, 0.2), 0.005),
                          box_surface_points(ball.pose, (0.1, 0.1, 0.1), 0.01)])  # the ball's box: corners stay
    layer, stats = _layer(pts, objects=(box, ball))
    centers = layer.centers
    assert stats.in_objects > 0 and len(layer) > 0
    assert np.all(np.linalg.norm(centers - ball.pose[:3, 3], axis=1) > 0.05)  # only the corners remain
    assert np.all(np.abs(centers - box.pose[:3, 3]).max(1) > 0.1 - 1e-9)  # nothing of the box
