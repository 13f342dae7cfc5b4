"""Value checks shared by the planning scene and the plan requests: a pose is a finite rigid transform,
a grasp is usable data (finite contacts, unit normals, friction >= 0), a grasp set's ids are unique.

Both the scene (an object's grasps, on every update) and request validation (a request's own grasps,
pipeline/validation.py) run them, and the pipeline imports the scene's modules: so they live here, in
the scene stage, importing nothing of the pipeline (no import circle). They raise SceneUpdateError;
validation.py turns it into a request's refusal.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from humanoid_planner.core.scene.types import GraspSpec

RIGID_TOLERANCE = 1e-6
"""Largest |R^T R - I| entry and |det R - 1| accepted for a pose's rotation block: a rotation sent as
float64 (or a quaternion normalized in float32) passes, a skewed or scaled one does not."""



class SceneUpdateError(ValueError):
    """A value that cannot be accepted: by the scene (the update is not applied; the scene is unchanged),
    or in a request (validation.py refuses the request)."""


class SceneStateError(SceneUpdateError):
    """An update refused for the scene's state (its object absent, or attached), not for its content:
    any update of that object the scene saw just before would have been refused the same way."""


def frozen(a, dtype=float) -> np.ndarray:
    """A read-only copy: checked values are shared between threads and snapshots."""
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def check_rigid(T, what: str) -> np.ndarray:
    """Return T as a read-only 4x4 float array; raise SceneUpdateError unless it is a finite rigid transform."""
    try:
        T = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as e:
        raise SceneUpdateError(f"{what}: not a 4x4 matrix ({e})") from None
    if T.shape != (4, 4):
        raise SceneUpdateError(f"{what}: expected a 4x4 matrix, got shape {T.shape}")
    # on Python floats: 16 numbers cost a tenth of numpy's calls (every scene pose goes through here)
    rows = T.tolist()
    flat = rows[0] + rows[1] + rows[2] + rows[3]
    if not all(map(math.isfinite, flat)):
        raise SceneUpdateError(f"{what}: contains NaN or inf")
    a, b, c, _, d, e, f, _, g, h, i, _ = flat[:12]
    gram_error = max(abs(a * a + d * d + g * g - 1.0), abs(b * b + e * e + h * h - 1.0), abs(c * c + f * f + i * i - 1.0),
                     abs(a * b + d * e + g * h), abs(a * c + d * f + g * i), abs(b * c + e * f + h * i))  # |R^T R - I|
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if gram_error > RIGID_TOLERANCE or abs(det - 1.0) > RIGID_TOLERANCE or rows[3] != [0.0, 0.0, 0.0, 1.0]:
        raise SceneUpdateError(f"{what}: not a rigid transform (rotation block must be orthonormal, det +1)")
    return frozen(T)


def check_grasp(g: GraspSpec, what: str) -> GraspSpec:
    """Validate one grasp; return a copy with read-only arrays and unit normals."""
    if not isinstance(g, GraspSpec):
        raise SceneUpdateError(f"{what}: expected a GraspSpec, got {type(g).__name__}")
    tcp = check_rigid(g.tcp_in_object, f"{what} tcp_in_object")
    C = np.asarray(g.contacts, dtype=float).reshape(-1, 3) if np.size(g.contacts) else np.zeros((0, 3))
    N = np.asarray(g.normals, dtype=float).reshape(-1, 3) if np.size(g.normals) else np.zeros((0, 3))
    if len(C) != len(N):
        raise SceneUpdateError(f"{what}: {len(C)} contacts but {len(N)} normals (must be the same)")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(N))):
        raise SceneUpdateError(f"{what}: contacts or normals contain NaN or inf")
    with np.errstate(over="ignore"):
        norms = np.linalg.norm(N, axis=1)
    if np.any(norms < 1e-9):
        raise SceneUpdateError(f"{what}: a contact normal has zero length")
    if not np.all(np.isfinite(norms)):
        raise SceneUpdateError(f"{what}: a contact normal is too long (its length overflows a float64)")
    friction = float(g.friction)
    if not np.isfinite(friction) or friction < 0.0:
        raise SceneUpdateError(f"{what}: friction must be a finite number >= 0, got {g.friction}")
    return GraspSpec(id=str(g.id), hand=str(g.hand), tcp_in_object=tcp, contacts=frozen(C),
                     normals=frozen(N / norms[:, None]) if len(N) else frozen(N), friction=friction)


def name_grasps(grasps: tuple[GraspSpec, ...], first: int = 0) -> tuple[GraspSpec, ...]:
    """Grasps without an id named "#<k>" (k: position in the set, counting from `first`)."""
    return tuple(g if g.id else replace(g, id=f"#{first + k}") for k, g in enumerate(grasps))


def check_grasp_ids(grasps: tuple[GraspSpec, ...], where: str) -> None:
    """Raise SceneUpdateError when two grasps share an id (after `name_grasps`, none is empty)."""
    seen: set[str] = set()
    for g in grasps:
        if g.id in seen:
            raise SceneUpdateError(f"{where}: grasp id {g.id!r} appears more than once")
        seen.add(g.id)
