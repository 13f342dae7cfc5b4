"""clouds.py: synthetic depth images of boxes."""
from __future__ import annotations

import numpy as np

from humanoid_planner.clouds import look_at, render_depth


def T(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    M = np.eye(4)
    M[:3, 3] = (x, y, z)
    return M


def test_render_depth_sees_the_nearest_face():
    box = (T(1.0, 0.0, 0.0), np.array([0.2, 0.4, 0.4]))
    cam = look_at([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    pts = render_depth([box], cam, 64, 48, fov_x=np.radians(40))
    assert pts.shape == (48, 64, 3) and pts.dtype == np.float32
    hit = np.isfinite(pts[..., 2])
    assert 0 < hit.sum() < hit.size
    np.testing.assert_allclose(pts[hit][:, 2], 0.9, atol=1e-5)  # the face at x = 0.9, along the optical axis
    world = pts[hit] @ cam[:3, :3].T + cam[:3, 3]
    np.testing.assert_allclose(world[:, 0], 0.9, atol=1e-5)
    assert np.all(np.abs(world[:, 1:]) <= 0.2 + 1e-6)
