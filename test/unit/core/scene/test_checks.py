"""Value checks of poses and grasps (scene/checks.py), shared by the scene and request validation."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.scene.checks import SceneUpdateError, check_grasp, check_grasp_ids, check_rigid, name_grasps
from humanoid_planner.core.scene.types import GraspSpec


def test_check_rigid_returns_a_read_only_copy_and_refuses_what_is_not_rigid():
    T = np.eye(4)
    T[:3, 3] = (0.1, 0.2, 0.3)
    out = check_rigid(T, "pose")
    assert np.array_equal(out, T) and not out.flags.writeable
    for bad, why in ((np.eye(3), "shape"), (np.diag([1.0, 1.0, 2.0, 1.0]), "rigid"), (np.full((4, 4), np.nan), "NaN")):
        with pytest.raises(SceneUpdateError, match=why):
            check_rigid(bad, "pose")


def test_check_grasp_makes_unit_normals_and_refuses_bad_contacts():
    g = check_grasp(GraspSpec("a", "", np.eye(4), np.zeros((1, 3)), np.array([[0.0, 0.0, 2.0]]), 0.5), "g")
    assert np.allclose(g.normals, [[0, 0, 1]]) and not g.normals.flags.writeable
    with pytest.raises(SceneUpdateError, match="2 contacts but 1 normals"):
        check_grasp(GraspSpec("a", "", np.eye(4), np.zeros((2, 3)), np.ones((1, 3)), 0.5), "g")
    with pytest.raises(SceneUpdateError, match="zero length"):
        check_grasp(GraspSpec("a", "", np.eye(4), np.zeros((1, 3)), np.zeros((1, 3)), 0.5), "g")
    with pytest.raises(SceneUpdateError, match="friction"):
        check_grasp(GraspSpec("a", "", np.eye(4), friction=-1.0), "g")


def test_grasps_without_an_id_are_named_by_position_and_ids_must_be_unique():
    named = name_grasps((GraspSpec("", "", np.eye(4)), GraspSpec("x", "", np.eye(4))), first=3)
    assert [g.id for g in named] == ["#3", "x"]
    check_grasp_ids(named, "grasps")
    with pytest.raises(SceneUpdateError, match="more than once"):
        check_grasp_ids(named + (GraspSpec("x", "", np.eye(4)),), "grasps")
