"""Checkers reuse their python-fcl objects (core/collision/fcl_objects.py): python-fcl leaks 32 bytes
of native memory for every CollisionObject it frees, so a node that built new ones for every checker
grew without bound under load."""
from __future__ import annotations

import gc

import fcl
import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.collision.fcl_objects import CollisionObjectPool
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import AttachedObject, SceneObject, SceneSnapshot, Shape, VoxelLayer

from .shapes import pose


@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.preset("dual_arm")


@pytest.fixture
def constructions(monkeypatch) -> list[int]:
    """Counts every fcl.CollisionObject constructed (the code reaches the class through the fcl module)."""
    made = [0]

    class Counted(fcl.CollisionObject):
        def __init__(self, *args, **kwargs):
            made[0] += 1

    monkeypatch.setattr(fcl, "CollisionObject", Counted)
    return made


def scene(k: int, robot: RobotModel) -> SceneSnapshot:
    """Scene version k: boxes, a cylinder and a sphere whose poses and sizes change with k, a cloud
    layer, and a box held in the left hand (attached objects ride on the robot)."""
    s = 0.05 + 0.01 * (k % 7)
    objects = (SceneObject("box", pose(0.6, 0.1 * (k % 5), 0.4), (Shape("box", np.eye(4), (s, 2 * s, s)),)),
               SceneObject("can", pose(0.5, -0.3, 0.3 + 0.01 * k), (Shape("cylinder", np.eye(4), (0.2, s)),)),
               SceneObject("ball", pose(-0.5, 0.0, 0.5), (Shape("sphere", np.eye(4), (s,)),)))
    link = robot.group("left_arm").tip_link
    held = AttachedObject("held", link, pose(0.0, 0.0, 0.05), (Shape("box", np.eye(4), (0.04, 0.04, s)),),
                          frozenset({link}))
    cells = np.array([[30, 0, 20], [30, 1, 20 + k % 3]], dtype=np.int32)
    return SceneSnapshot(k, robot.root_link, objects, VoxelLayer(0.02, cells), (held,))


def test_checkers_of_changing_scenes_make_no_new_fcl_objects(robot, constructions):
    rng = np.random.default_rng(0)
    q_ref = robot.home.copy()

    def check(k: int) -> None:
        ch = CollisionChecker(robot, scene(k, robot), "left_arm", q_ref + 0.01 * (k % 3), CheckerSettings(padding=0.01))
        idx = ch.joint_indices
        ch.check_configs(rng.uniform(robot.lower[idx], robot.upper[idx], size=(64, len(idx))))

    # each gc.collect below frees the checker just used (its objects go back to the pool); it looks at
    # what this test made, not at the whole test run's heap (frozen: seconds of collections in a full run)
    gc.collect()
    gc.freeze()
    try:
        for k in range(15):  # every variant of the scene: which objects are in the arm's reach changes with k
            check(k)
            gc.collect()
        first = constructions[0]
        assert first > 30  # robot shapes, hulls, scene shapes, the held box, the cloud's cube
        for k in range(15, 30):
            check(k)
            gc.collect()
        assert constructions[0] == first  # every later checker borrowed the earlier ones' objects
    finally:
        gc.unfreeze()


def test_a_resized_primitive_decides_as_a_new_one():
    pool = CollisionObjectPool()

    class Owner:
        pass

    ball = fcl.CollisionObject(fcl.Sphere(0.1), fcl.Transform(np.eye(3), np.array([0.0, 0.0, 0.5])))
    big = Owner()
    obj = pool.loan(big).primitive("box", (1.0, 1.0, 1.0))
    assert fcl.collide(obj, ball, fcl.CollisionRequest(), fcl.CollisionResult()) == 1
    del big  # back to the pool ...
    small = Owner()
    again = pool.loan(small).primitive("box", (0.2, 0.2, 0.2), pose(0.0, 0.0, 0.1))
    assert again is obj and pool.created == 1  # ... and lent again, resized and moved
    d = fcl.distance(again, ball, fcl.DistanceRequest(), fcl.DistanceResult())
    assert d == pytest.approx(0.4 - 0.2, abs=1e-9)  # box top at z = 0.2, ball bottom at 0.4
    manager = fcl.DynamicAABBTreeCollisionManager()  # the broad phase sees the new size too
    manager.registerObjects([again])
    manager.setup()
    data = fcl.CollisionData(request=fcl.CollisionRequest())
    manager.collide(ball, data, fcl.defaultCollisionCallback)
    assert not data.result.is_collision
