"""Pose, containment and clutter helpers shared by the collision tests."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.geometry import BoundingBox
from humanoid_planner.core.scene.types import SceneObject, Shape
from humanoid_planner.scenarios import robot_frame


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


def clutter(rng: np.random.Generator, n: int, robot, arms: tuple[str, str]) -> tuple[SceneObject, ...]:
    """n boxes (3–8 cm, random orientation) uniform in front of the robot, as benchmarks/bench_clutter.py
    draws them, and a table (a body too big for the k-d tree) under them."""
    fr = robot_frame(robot, *arms)
    out = []
    for i in range(n):
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        u = rng.uniform(-1, 1, 3)
        T = np.eye(4)
        T[:3, :3] = R * np.sign(np.linalg.det(R))
        T[:3, 3] = fr.center + fr.reach * ((0.4 + 0.6 * u[0]) * fr.forward + u[1] * fr.left + 0.6 * u[2] * fr.up)
        out.append(SceneObject(f"b{i}", T, (Shape("box", np.eye(4), tuple(rng.uniform(0.03, 0.08, 3))),)))
    T = np.eye(4)
    T[:3, 3] = fr.center + fr.reach * (0.6 * fr.forward - 0.7 * fr.up)
    return (*out, SceneObject("table", T, (Shape("box", np.eye(4), (0.8, 1.2, 0.04)),)))
