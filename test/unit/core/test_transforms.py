"""Rotation vectors and pose errors: the single-pose scalar path against the batched path and scipy."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from humanoid_planner.core.transforms import matrix_to_quat, pose_error, rotation_vector


def _rotations(rng: np.random.Generator) -> np.ndarray:
    """Random rotations plus the hard cases: angle 0, tiny, ≈ π (both sides of the 1e-6 switch), exactly π."""
    R = list(Rotation.random(300, random_state=int(rng.integers(1 << 31))).as_matrix())
    for angle in (0.0, 1e-9, 1e-6, 2e-6, np.pi - 1e-3, np.pi - 2e-6, np.pi - 1e-7, np.pi):
        for k in range(12):
            axis = np.eye(3)[k % 3] * (-1) ** k if k < 6 else rng.normal(size=3)
            R.append(Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix())
    return np.array(R)


def test_rotation_vector_single_equals_batched_and_scipy():
    R = _rotations(np.random.default_rng(0))
    batched = rotation_vector(R)
    single = np.array([rotation_vector(r) for r in R])
    assert np.max(np.abs(single - batched)) < 1e-12
    # against scipy, near π too (sin from |v|/2 and atan2, not acos of the trace, which lost ~1e-4 rad
    # at π − 2e-6); within 1e-6 of π the axis comes from R + I and its sign is arbitrary
    ref = Rotation.from_matrix(R).as_rotvec()
    off_pi = np.linalg.norm(ref, axis=1) < np.pi - 1.5e-6
    assert np.max(np.abs(single[off_pi] - ref[off_pi])) < 1e-9
    # everywhere, incl. the axis taken from R + I at π: the vector is a rotation vector of R
    assert np.max(np.abs(Rotation.from_rotvec(single).as_matrix() - R)) < 1e-5


def test_pose_error_single_equals_batched():
    rng = np.random.default_rng(1)
    R = _rotations(rng)
    Tc = np.tile(np.eye(4), (len(R), 1, 1))
    Tc[:, :3, :3] = Rotation.random(len(R), random_state=2).as_matrix()
    Tc[:, :3, 3] = rng.normal(size=(len(R), 3))
    Tt = Tc.copy()
    Tt[:, :3, :3] = R @ Tc[:, :3, :3]                     # error rotation R, incl. the π cases
    Tt[:, :3, 3] += rng.normal(size=(len(R), 3))
    batched = pose_error(Tc, Tt)
    single = np.array([pose_error(a, b) for a, b in zip(Tc, Tt)])
    assert single.shape == (len(R), 6)
    assert np.max(np.abs(single - batched)) < 1e-12
    assert np.array_equal(single[:, :3], Tt[:, :3, 3] - Tc[:, :3, 3])
    # a batch of one and mixed shapes keep the batched result's shape
    assert pose_error(Tc[:1], Tt[:1]).shape == (1, 6)
    assert pose_error(Tc[0], Tt[:3]).shape == (3, 6)


def test_matrix_to_quat_equals_scipy_up_to_sign():
    rng = np.random.default_rng(5)
    for R in _rotations(rng):
        q = matrix_to_quat(R)
        ref = Rotation.from_matrix(R).as_quat()
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1.0) < 1e-12
        assert min(np.abs(q - ref).max(), np.abs(q + ref).max()) < 1e-9
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), R, atol=1e-9)
