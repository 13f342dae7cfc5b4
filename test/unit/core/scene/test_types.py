"""The scene's value types (scene.types): frozen, looked up by id, voxel cells on a fixed lattice."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanoid_planner.core.scene.types import SHAPE_KINDS, GraspSpec, SceneObject, SceneSnapshot, Shape, VoxelLayer


def test_snapshot_get_and_immutability():
    box = Shape("box", np.eye(4), (0.1, 0.2, 0.3))
    a, b = SceneObject("a", np.eye(4), (box,)), SceneObject("b", np.eye(4))
    snap = SceneSnapshot(7, "base_link", (a, b))
    assert snap.get("b") is b and snap.get("a") is a and snap.get("c") is None
    assert snap.voxels is None and SceneSnapshot(0, "f").objects == ()
    for obj, name in ((snap, "version"), (a, "id"), (box, "dims")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, name, None)
    assert set(SHAPE_KINDS) == {"box", "sphere", "cylinder", "cone", "mesh"}


def test_grasp_defaults_have_no_contacts():
    g = GraspSpec("g0", "", np.eye(4))
    assert g.contacts.shape == g.normals.shape == (0, 3) and g.friction == 0.0
    assert g.contacts is not GraspSpec("g1", "", np.eye(4)).contacts  # no shared mutable default


def test_voxel_centers_and_identity():
    cells = np.array([[0, 0, 0], [-1, 2, 3]], dtype=np.int32)
    layer = VoxelLayer(0.05, cells)
    assert len(layer) == 2
    np.testing.assert_allclose(layer.centers, [[0.025, 0.025, 0.025], [-0.025, 0.125, 0.175]])
    assert layer != VoxelLayer(0.05, cells.copy())  # compared by identity: caches key on the layer
    assert layer == layer


def test_objects_near_is_the_ball_test_of_every_object_and_cached():
    """objects_near keeps exactly the objects whose bounding ball comes within the gap of some ball
    (its first pass around all balls drops none of them), also right at the gap; same answer object
    for the same balls."""
    rng = np.random.default_rng(5)
    objects = tuple(SceneObject(f"o{i}", np.block([[np.eye(3), rng.uniform(-3, 3, (3, 1))], [np.zeros((1, 3)), 1.0]]),
                                (Shape("box", np.eye(4), tuple(rng.uniform(0.01, 0.3, 3))),)) for i in range(400))
    snap = SceneSnapshot(1, "f", objects)
    centres, radii = rng.uniform(-1, 1, (7, 3)), rng.uniform(0.1, 0.8, 7)
    oc, orad = snap.object_spheres
    gaps = np.linalg.norm(oc[:, None] - centres[None], axis=-1) - radii[None] - orad[:, None]
    for gap in (0.0, 0.05, float(np.sort(gaps.min(axis=1))[200])):  # the last: one object exactly at the gap
        near = snap.objects_near(centres, radii, gap)
        np.testing.assert_array_equal(near, (gaps <= gap).any(axis=1))
        assert 0 < near.sum() < len(objects) and snap.objects_near(centres, radii, gap) is near
    assert not SceneSnapshot(2, "f").objects_near(centres, radii, 0.1).size
