"""The papers' D-H tables (scripts/preset_generation/dh_tables.py): the D-H matrix is the standard
product Rz(θ)·Tz(d)·Tx(a)·Rx(α), batched as one at a time, and a mirrored arm reaches the mirror image."""
from __future__ import annotations

import numpy as np
import pytest

from preset_generation.dh_tables import (ARMAR3_LEFT, ARMAR3_RIGHT, DUAL_LEFT, DUAL_RIGHT, MIRROR_Y, dh_chain,
                                         dh_matrix, rot_x, rot_z, trans)


def test_dh_matrix_is_the_standard_product_and_batches():
    rng = np.random.default_rng(0)
    thetas = rng.uniform(-np.pi, np.pi, 20)
    for d, a, alpha in rng.uniform(-1, 1, (5, 3)):
        batch = dh_matrix(thetas, d, a, alpha)
        for th, A in zip(thetas, batch):
            np.testing.assert_allclose(A, rot_z(th) @ trans(0, 0, d) @ trans(a, 0, 0) @ rot_x(alpha), atol=1e-12)
            np.testing.assert_array_equal(dh_matrix(th, d, a, alpha), A)
        R = batch[:, :3, :3]
        np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)


def test_mirrored_arm_reaches_the_mirror_image():
    """ARMAR-III's left arm is mirror_arm(right): the same q puts the TCP at the mirror image across the
    sagittal plane (y -> -y), with the same limits."""
    right, left = ARMAR3_RIGHT, ARMAR3_LEFT
    lo, hi = (np.array([getattr(j, k) for j in right.joints]) for k in ("lower", "upper"))
    assert [j.lower for j in left.joints] == list(lo) and [j.upper for j in left.joints] == list(hi)
    q = np.random.default_rng(1).uniform(lo, hi, (50, len(lo)))
    tr, tl = right.base @ dh_chain(right, q), left.base @ dh_chain(left, q)
    np.testing.assert_allclose(tl[:, :3, 3], (MIRROR_Y[:3, :3] @ tr[:, :3, 3].T).T, atol=1e-9)
    np.testing.assert_allclose(right.base @ dh_chain(right, q[0]), tr[0], atol=1e-12)  # batched = one at a time


@pytest.mark.parametrize("arm", [ARMAR3_RIGHT, ARMAR3_LEFT, DUAL_RIGHT, DUAL_LEFT], ids=lambda a: a.side)
def test_tables_give_rigid_tcp_frames(arm):
    q = np.random.default_rng(2).uniform([j.lower for j in arm.joints], [j.upper for j in arm.joints], (50, len(arm.joints)))
    R = (arm.base @ dh_chain(arm, q))[:, :3, :3]
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
