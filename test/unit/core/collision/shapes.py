"""Pose and containment helpers shared by the collision tests."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.geometry import BoundingBox


def pose(x=0.0, y=0.0, z=0.0, R=None) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    if R is not None:
        T[:3, :3] = R
    return T


def rot(axis, angle) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(axis, float) / np.linalg.norm(axis) * angle).as_matrix()


def inside_cover(points, cover, tol=1e-9) -> np.ndarray:
    d = np.linalg.norm(points[:, None, :] - cover.centers[None], axis=2) - cover.radii[None]
    return d.min(1) <= tol


def in_rounded_box(points, box: BoundingBox, tol=1e-9) -> np.ndarray:
    local = (points - box.pose[:3, 3]) @ box.pose[:3, :3]
    return np.linalg.norm(np.maximum(np.abs(local) - box.half, 0), axis=1) <= box.rounding + tol

