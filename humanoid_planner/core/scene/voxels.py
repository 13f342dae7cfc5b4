"""Point cloud → the planning scene's point-cloud layer (README "The point-cloud layer"), in numpy, without ROS.

`cloud_to_layer` takes the points of one cloud in its sensor frame and:
1. drops points that are NaN/inf or farther than `max_range` from the sensor;
2. moves them into the planning frame (T_world_sensor, from the robot's FK for a link frame);
3. removes points on the robot — within `self_padding` of its collision geometry at the cloud's
   joint state (MoveIt's self-filter) — and within `object_padding` of any scene object, so that the
   object to be grasped does not become an obstacle to its own grasps;
4. turns what is left into the occupied cubes of a fixed lattice of `voxel_size` (a `VoxelLayer`).

The filters test points, not cells, but only the points of cells near a solid are tested: the
cells of the cloud (a few thousand for an organized depth image) are culled against each solid's
bounding sphere first.

Padding: a point p that survives makes the cube around it occupied, and that cube reaches up to
√3·voxel_size from p. The default self padding (5 cm) is that (3.5 cm at 2 cm cells) plus the
checker's own margin along edges (7.5 mm) and some noise, so that what remains of the robot's own
points never touches the robot where it stood.

Shapes are tested exactly where that is cheap (boxes, spheres, cylinders; cones as their cylinder);
meshes through a containing shape: robot links through their sphere covers (≤ 2 cm beyond the
surface, shared with the collision checker), scene meshes through their bounding box.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from humanoid_planner.core.collision.geometry import RobotCollisionModel, mesh_obb
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneObject, VoxelLayer

_KEY_BITS = 21  # bits per axis of a cell key: three axes fit one int64 (63 bits)
_KEY_OFFSET = 1 << (_KEY_BITS - 1)  # cell indices in [-2^20, 2^20): ±21 km at 2 cm
_KEY_MASK = (1 << _KEY_BITS) - 1


class CloudError(ValueError):
    """A cloud that cannot be used (malformed, or settings out of range); the layer is unchanged."""


@dataclass(frozen=True)
class CloudSettings:
    """Node parameters of the point-cloud layer (m)."""

    voxel_size: float = 0.02
    max_range: float = 3.0
    self_padding: float = 0.05
    object_padding: float = 0.02

    def __post_init__(self) -> None:
        for name in ("voxel_size", "max_range"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise CloudError(f"{name} must be a positive finite number, got {v}")
        for name in ("self_padding", "object_padding"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise CloudError(f"{name} must be a finite number >= 0, got {v}")


@dataclass
class CloudStats:
    """What happened to one cloud's points (for logs and the benchmark)."""

    points: int = 0  # in the message
    used: int = 0  # finite and within max_range
    on_robot: int = 0  # removed by the self-filter
    in_objects: int = 0  # removed as points of scene objects
    cells: int = 0  # occupied cells of the layer
    seconds: float = 0.0
    stages: dict = field(default_factory=dict)  # seconds per stage


@dataclass(frozen=True)
class Solid:
    """A point test: `kind` box (params: half extents), sphere (radius), cylinder (radius, half length)
    or spheres (centres (S, 3) and radii (S,), world frame); pose 4x4 in the world; a bounding
    sphere (world centre, radius) for culling."""

    kind: str
    pose: np.ndarray
    params: tuple
    center: np.ndarray
    radius: float

    def near(self, points: np.ndarray, pad: float) -> np.ndarray:
        """(P, 3) world points → (P,) bool: within `pad` of the solid (inside included)."""
        if self.kind == "spheres":
            C, r = self.params
            d = points[:, None, :] - C[None]
            return np.any(np.einsum("psi,psi->ps", d, d) <= (r + pad) ** 2, axis=1)
        R = self.pose[:3, :3]
        local = _affine(points, R.T, -R.T @ self.pose[:3, 3])
        if self.kind == "sphere":
            return np.einsum("pi,pi->p", local, local) <= (self.params[0] + pad) ** 2
        if self.kind == "box":
            e = np.maximum(np.abs(local) - np.asarray(self.params[0]), 0.0)
            return np.einsum("pi,pi->p", e, e) <= pad * pad
        if self.kind == "cylinder":
            radius, half = self.params
            er = np.maximum(np.hypot(local[:, 0], local[:, 1]) - radius, 0.0)
            ez = np.maximum(np.abs(local[:, 2]) - half, 0.0)
            return er * er + ez * ez <= pad * pad
        raise ValueError(f"unknown solid kind {self.kind!r}")


def _solid(kind: str, pose: np.ndarray, params: tuple, local_radius: float) -> Solid:
    return Solid(kind, pose, params, pose[:3, 3].copy(), float(local_radius))


def _spheres(C: np.ndarray, r: np.ndarray) -> Solid:
    c = 0.5 * (C.min(0) + C.max(0))
    return Solid("spheres", np.eye(4), (C, r), c, float((np.linalg.norm(C - c, axis=1) + r).max()))


def robot_solids(robot: RobotModel, q_full: np.ndarray) -> list[Solid]:
    """The robot's collision shapes at configuration q_full (RobotModel.joint_names order)."""
    model = RobotCollisionModel.for_robot(robot)
    names = list(model.links)
    if not names:
        return []
    poses = robot.link_poses(np.asarray(q_full, dtype=float), names)
    out = []
    for name, T_link in zip(names, poses):
        lc = model.links[name]
        for g, cover in zip(lc.shapes, lc.covers):
            T = T_link @ g.origin
            if g.kind == "box":
                half = 0.5 * np.asarray(g.dims, float)
                out.append(_solid("box", T, (half,), np.linalg.norm(half)))
            elif g.kind == "sphere":
                out.append(_solid("sphere", T, (g.dims[0],), g.dims[0]))
            elif g.kind == "cylinder":
                r, length = g.dims
                out.append(_solid("cylinder", T, (r, 0.5 * length), np.hypot(r, 0.5 * length)))
            else:  # mesh: its sphere cover (link frame) contains it
                out.append(_spheres(cover.centers @ T_link[:3, :3].T + T_link[:3, 3], cover.radii))
    return out


def object_solids(objects: tuple[SceneObject, ...]) -> list[Solid]:
    """Scene objects' shapes as point tests (cones as their cylinder, meshes as their bounding box)."""
    out = []
    for o in objects:
        for s in o.shapes:
            T = np.asarray(o.pose, float) @ np.asarray(s.pose, float)
            if s.kind == "box":
                half = 0.5 * np.asarray(s.dims, float)
                out.append(_solid("box", T, (half,), np.linalg.norm(half)))
            elif s.kind == "sphere":
                out.append(_solid("sphere", T, (s.dims[0],), s.dims[0]))
            elif s.kind in ("cylinder", "cone"):  # shape_msgs: (height, radius)
                h, r = s.dims
                out.append(_solid("cylinder", T, (r, 0.5 * h), np.hypot(r, 0.5 * h)))
            else:
                pose, half = mesh_obb(s.vertices)
                out.append(_solid("box", T @ pose, (half,), np.linalg.norm(half)))
    return out


def _affine(points: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(P, 3) points → points @ R.T + t in float64, column by column: numpy's matmul hands an
    (P, 3) @ (3, 3) product to BLAS, which took 60–100 ms for 150k points here (threads contending
    on a loaded 2-core machine); nine multiply-adds take about 2 ms."""
    out = np.empty((len(points), 3))
    x, y, z = (points[:, i].astype(np.float64) for i in range(3))
    for i in range(3):
        out[:, i] = R[i, 0] * x + R[i, 1] * y + R[i, 2] * z + t[i]
    return out


def _decode(keys: np.ndarray) -> np.ndarray:
    return np.stack([(keys >> (2 * _KEY_BITS)) & _KEY_MASK, (keys >> _KEY_BITS) & _KEY_MASK, keys & _KEY_MASK],
                    axis=1) - _KEY_OFFSET


def _remove_near(points: np.ndarray, inv: np.ndarray, cell_centers: np.ndarray, keep: np.ndarray,
                 solids: list[Solid], pad: float, cell_reach: float) -> int:
    """Clear keep[i] for the points within pad of a solid; returns how many were cleared. Only the
    points of cells whose centre is within (bounding radius + pad + cell_reach) of a solid are tested."""
    if not solids or len(points) == 0:
        return 0
    C = np.array([s.center for s in solids])
    R = np.array([s.radius for s in solids]) + pad + cell_reach
    d2 = sum((cell_centers[:, None, i] - C[None, :, i]) ** 2 for i in range(3))
    near_cells = d2 <= R * R  # (cells, solids)
    cand = np.nonzero(near_cells.any(1)[inv] & keep)[0]
    if len(cand) == 0:
        return 0
    removed = 0
    for j, s in enumerate(solids):
        sel = cand[near_cells[inv[cand], j] & keep[cand]]
        if len(sel):
            hit = sel[s.near(points[sel], pad)]
            keep[hit] = False
            removed += len(hit)
    return removed


def cloud_to_layer(points: np.ndarray, T_world_sensor: np.ndarray, settings: CloudSettings,
                   robot: list[Solid] = (), objects: list[Solid] = ()) -> tuple[VoxelLayer, CloudStats]:
    """One cloud ((P, 3) points in the sensor frame) → the layer that replaces the previous one.

    robot / objects: `robot_solids` at the cloud's joint state and `object_solids` of the scene.
    """
    t0 = time.perf_counter()
    stats = CloudStats(points=len(points))
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 3:
        raise CloudError(f"expected (P, 3) points, got shape {p.shape}")
    with np.errstate(invalid="ignore", over="ignore"):  # NaN compares False, inf is out of range
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        ok = x * x + y * y + z * z <= settings.max_range ** 2
    T = np.asarray(T_world_sensor, dtype=float)
    p = _affine(p[ok], T[:3, :3], T[:3, 3])
    stats.used = len(p)
    t1 = time.perf_counter()
    v = settings.voxel_size
    idx = np.floor(p / v).astype(np.int64)
    if len(idx) and (idx.min() < -_KEY_OFFSET or idx.max() >= _KEY_OFFSET):
        raise CloudError("points too far from the planning frame's origin for the voxel lattice")
    keys = ((idx[:, 0] + _KEY_OFFSET) << (2 * _KEY_BITS)) | ((idx[:, 1] + _KEY_OFFSET) << _KEY_BITS) \
        | (idx[:, 2] + _KEY_OFFSET)
    uniq, inv = np.unique(keys, return_inverse=True)
    centers = (_decode(uniq) + 0.5) * v
    t2 = time.perf_counter()
    keep = np.ones(len(p), dtype=bool)
    reach = 0.5 * np.sqrt(3.0) * v
    stats.on_robot = _remove_near(p, inv, centers, keep, list(robot), settings.self_padding, reach)
    stats.in_objects = _remove_near(p, inv, centers, keep, list(objects), settings.object_padding, reach)
    t3 = time.perf_counter()
    occupied = np.bincount(inv[keep], minlength=len(uniq)) > 0 if len(uniq) else np.zeros(0, dtype=bool)
    cells = _decode(uniq[occupied]).astype(np.int32)
    cells.setflags(write=False)
    stats.cells = len(cells)
    stats.seconds = time.perf_counter() - t0
    stats.stages = {"finite_range_transform": t1 - t0, "cells": t2 - t1, "filters": t3 - t2,
                    "layer": stats.seconds - (t3 - t0)}
    return VoxelLayer(float(v), cells), stats


__all__ = ["CloudError", "CloudSettings", "CloudStats", "Solid", "cloud_to_layer", "object_solids", "robot_solids"]
