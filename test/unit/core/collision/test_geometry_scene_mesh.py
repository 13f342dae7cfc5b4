"""Scene meshes (geometry.scene_mesh): built once per Shape object, big ones split into pieces, same verdicts."""
from __future__ import annotations

import numpy as np
import trimesh

from humanoid_planner.core.collision import geometry
from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.planning_scene import Operation, PlanningScene, SceneUpdate
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape


def sphere_mesh(radius: float = 0.12, subdivisions: int = 5) -> Shape:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)  # 20,480 triangles
    return Shape("mesh", np.eye(4), (), np.asarray(m.vertices), np.asarray(m.faces))


def at(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def test_big_meshes_are_split_into_pieces_that_hold_every_triangle_once():
    s = sphere_mesh()
    mesh = geometry.scene_mesh(s)
    assert mesh.geometry is None and len(mesh.pieces) >= len(s.triangles) // geometry.MESH_PIECE_TRIANGLES
    tris = {tuple(np.round(s.vertices[t], 9).ravel()) for t in s.triangles}
    got = [tuple(np.round(p.vertices[t], 9).ravel()) for p in mesh.pieces for t in p.triangles]
    assert len(got) == len(tris) and set(got) == tris
    assert all(len(p.triangles) <= geometry.MESH_PIECE_TRIANGLES for p in mesh.pieces)
    assert all(len(p.vertices) == len(np.unique(p.triangles)) for p in mesh.pieces)  # only the vertices used
    box = geometry.shape_box(s)  # contains every vertex
    local = (s.vertices - box.pose[:3, 3]) @ box.pose[:3, :3]
    assert np.all(np.abs(local) <= box.half + box.rounding + 1e-9)


def test_a_mesh_is_built_once_whatever_the_number_of_checkers(monkeypatch):
    robot = RobotModel.preset("armar3")
    obj = SceneObject("scan", at(0.45, 0.25, 1.0), (sphere_mesh(),))
    snap = SceneSnapshot(1, robot.root_link, (obj,))
    built = []
    real = geometry.fcl_mesh
    monkeypatch.setattr(geometry, "fcl_mesh", lambda v, t: built.append(len(t)) or real(v, t))
    for _ in range(3):
        CollisionChecker(robot, snap, "left_arm_torso", robot.home).check_configs(robot.home[None, :10])
    pieces = len(geometry.scene_mesh(obj.shapes[0]).pieces)
    assert len(built) <= pieces  # the first checker built them (or an earlier test did), the others none


def test_split_meshes_give_the_verdicts_of_the_whole_mesh(monkeypatch):
    robot = RobotModel.preset("armar3")
    group = "left_arm_torso"
    obj = SceneObject("scan", at(0.45, 0.25, 1.0), (sphere_mesh(),))
    snap = SceneSnapshot(1, robot.root_link, (obj,))
    split = CollisionChecker(robot, snap, group, robot.home)
    idx = split.joint_indices
    rng = np.random.default_rng(3)
    q = rng.uniform(robot.lower[idx], robot.upper[idx], size=(300, len(idx)))
    got = np.array([split.exact_check(x) for x in q])
    monkeypatch.setattr(geometry, "MESH_PIECE_TRIANGLES", 10**9)
    whole_obj = SceneObject("scan", obj.pose, (sphere_mesh(),))  # a new Shape: built whole
    assert geometry.scene_mesh(whole_obj.shapes[0]).pieces == ()
    whole = CollisionChecker(robot, SceneSnapshot(1, robot.root_link, (whole_obj,)), group, robot.home)
    want = np.array([whole.exact_check(x) for x in q])
    assert 0 < want.sum() < len(q)  # both kinds of answer are tested
    assert np.array_equal(got, want)
    assert np.array_equal(split.check_configs(q), want)


def test_the_scene_prepares_meshes_before_they_become_visible():
    seen: list[int] = []
    scene = PlanningScene("base", prepare_shapes=lambda shapes: seen.append(scene.version))
    scene.apply(SceneUpdate(Operation.ADD, "scan", at(1, 0, 0), (sphere_mesh(subdivisions=1),)))
    assert seen == [0] and scene.version == 1  # prepared while the scene still showed version 0

    def refuse(shapes):
        raise MemoryError("too big")

    scene = PlanningScene("base", prepare_shapes=refuse)
    try:
        scene.apply(SceneUpdate(Operation.ADD, "scan", at(1, 0, 0), (sphere_mesh(subdivisions=1),)))
    except ValueError as e:
        assert "could not be prepared" in str(e)
    else:
        raise AssertionError("the update was not refused")
    assert scene.version == 0 and len(scene) == 0
