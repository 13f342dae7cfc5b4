"""Synthetic point clouds of a scene's boxes, for the demo, the tests and the benchmark (no ROS).

- `box_surface_points`: points on a box's faces on a regular grid (what a scanner that saw every
  face would give);
- `render_depth`: an organized depth cloud of boxes seen by a pinhole camera (ray casting, numpy),
  in the camera's optical frame (z forward, x right, y down, as ROS's `*_optical_frame`), NaN where
  a ray hits nothing — the shape of a 640 × 480 depth camera's PointCloud2;
- `look_at`: a camera pose from its position and a point it looks at.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.scene.types import SceneObject


def box_surface_points(pose: np.ndarray, size, spacing: float = 0.01) -> np.ndarray:
    """(P, 3) world points on the six faces of a box (pose 4x4, full sizes), about `spacing` apart."""
    size = np.asarray(size, dtype=float)
    half = size / 2
    out = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        ua = np.linspace(-half[a], half[a], max(2, int(np.ceil(size[a] / spacing)) + 1))
        ub = np.linspace(-half[b], half[b], max(2, int(np.ceil(size[b] / spacing)) + 1))
        A, B = np.meshgrid(ua, ub, indexing="ij")
        for sign in (-1.0, 1.0):
            P = np.zeros((A.size, 3))
            P[:, a], P[:, b], P[:, axis] = A.ravel(), B.ravel(), sign * half[axis]
            out.append(P)
    P = np.concatenate(out)
    return P @ pose[:3, :3].T + pose[:3, 3]


def scene_boxes(objects: tuple[SceneObject, ...], skip: tuple[str, ...] = ()) -> list[tuple[np.ndarray, np.ndarray]]:
    """(world pose, full size) of every box shape of the objects not in `skip`."""
    return [(np.asarray(o.pose) @ np.asarray(s.pose), np.asarray(s.dims, dtype=float))
            for o in objects if o.id not in skip for s in o.shapes if s.kind == "box"]


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World pose of a camera optical frame at `eye` whose z axis points at `target` (y down)."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


def render_depth(boxes: list[tuple[np.ndarray, np.ndarray]], T_world_camera: np.ndarray, width: int = 640,
                 height: int = 480, fov_x: float = np.radians(70.0), max_depth: float = 10.0) -> np.ndarray:
    """(height, width, 3) float32 points in the camera optical frame: each pixel's ray against the
    boxes (slab test), the nearest hit; NaN where nothing is hit within max_depth."""
    f = 0.5 * width / np.tan(0.5 * fov_x)
    u, v = np.meshgrid(np.arange(width) + 0.5 - 0.5 * width, np.arange(height) + 0.5 - 0.5 * height)
    rays = np.stack([u / f, v / f, np.ones_like(u)], axis=-1).reshape(-1, 3)  # z = 1: t is the depth
    R, o = T_world_camera[:3, :3], T_world_camera[:3, 3]
    d_world = rays @ R.T
    depth = np.full(len(rays), np.inf)
    for pose, size in boxes:
        Rb, tb = pose[:3, :3], pose[:3, 3]
        o_l = (o - tb) @ Rb
        d_l = d_world @ Rb
        half = 0.5 * np.asarray(size, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-half - o_l) / d_l
            t2 = (half - o_l) / d_l
        lo = np.nanmax(np.minimum(t1, t2), axis=1)
        hi = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (hi >= np.maximum(lo, 0.0)) & (lo > 0.0)
        depth = np.where(hit & (lo < depth), lo, depth)
    depth[depth > max_depth] = np.inf
    pts = rays * depth[:, None]
    pts[~np.isfinite(depth)] = np.nan
    return pts.reshape(height, width, 3).astype(np.float32)


__all__ = ["box_surface_points", "look_at", "render_depth", "scene_boxes"]
