"""Rigid transforms shared by the whole core.

Conventions (the only ones used anywhere in the package):
- homogeneous 4x4 float64 matrices, batched as (..., 4, 4);
- quaternions ordered (x, y, z, w) as in geometry_msgs;
- a pose error is a 6-vector (dx, dy, dz, rx, ry, rz): position difference and the rotation
  vector (axis * angle) that takes the current orientation to the target, both in the world frame.
"""
from __future__ import annotations

import math

import numpy as np

QUAT_NORM_TOLERANCE = 1e-3
"""|‖q‖ - 1| above this is "clearly non-unit" and rejected; below it we normalize."""


class InvalidQuaternion(ValueError):
    """A quaternion that is zero, non-finite or clearly not unit length."""


def checked_unit_quaternion(q: np.ndarray | list[float], tol: float = QUAT_NORM_TOLERANCE) -> np.ndarray:
    """Return q normalized; raise InvalidQuaternion when it is not finite or |‖q‖-1| > tol."""
    return np.array(checked_unit_quaternion_tuple(q, tol))


def checked_unit_quaternion_tuple(q, tol: float = QUAT_NORM_TOLERANCE) -> tuple[float, float, float, float]:
    """checked_unit_quaternion as four Python floats (every scene pose goes through here: on floats,
    four numbers cost a tenth of numpy's calls)."""
    vals = q.tolist() if isinstance(q, np.ndarray) else list(q)
    try:
        vals = [float(v) for v in vals]
    except (TypeError, ValueError):
        raise InvalidQuaternion(f"quaternion must be 4 finite numbers, got {vals}") from None
    if len(vals) != 4 or not all(map(math.isfinite, vals)):
        raise InvalidQuaternion(f"quaternion must be 4 finite numbers, got {vals}")
    x, y, z, w = vals
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(n) or abs(n - 1.0) > tol:
        raise InvalidQuaternion(f"quaternion norm is {n:.6g}, expected 1 (tolerance {tol})")
    return x / n, y / n, z / n, w / n


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) xyzw unit quaternions -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix -> xyzw unit quaternion with w >= 0 (Shepperd's method: the largest of
    w, x, y, z is recovered first, so the division is well conditioned). Written out because scipy's
    Rotation.from_matrix costs ~100x more per single matrix, and every scene object's message needs one."""
    return np.array(matrix_to_quat_tuple(R))


def matrix_to_quat_tuple(R: np.ndarray) -> tuple[float, float, float, float]:
    """matrix_to_quat as four Python floats: on floats throughout, a third of numpy's per-call cost
    (a message per scene object)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = (row[:3] for row in np.asarray(R, dtype=float)[:3].tolist())
    tr = m00 + m11 + m22
    if tr >= max(m00, m11, m22):
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        f = 0.25 / w
        q = ((m21 - m12) * f, (m02 - m20) * f, (m10 - m01) * f, w)
    elif m00 >= m11 and m00 >= m22:
        x = 0.5 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        f = 0.25 / x
        q = (x, (m01 + m10) * f, (m02 + m20) * f, (m21 - m12) * f)
    elif m11 >= m22:
        y = 0.5 * math.sqrt(max(1.0 - m00 + m11 - m22, 0.0))
        f = 0.25 / y
        q = ((m01 + m10) * f, y, (m12 + m21) * f, (m02 - m20) * f)
    else:
        z = 0.5 * math.sqrt(max(1.0 - m00 - m11 + m22, 0.0))
        f = 0.25 / z
        q = ((m02 + m20) * f, (m12 + m21) * f, z, (m10 - m01) * f)
    n = math.sqrt(sum(v * v for v in q))
    if q[3] < 0:
        n = -n
    return q[0] / n, q[1] / n, q[2] / n, q[3] / n


def pose_to_matrix(position: np.ndarray | list[float], quat_xyzw: np.ndarray | list[float]) -> np.ndarray:
    """Position + xyzw quaternion -> 4x4 matrix (the quaternion is assumed already checked). On Python
    floats, quat_to_matrix's formula for one pose: numpy's per-call cost made it 10x slower."""
    x, y, z, w = quat_xyzw.tolist() if isinstance(quat_xyzw, np.ndarray) else (float(v) for v in quat_xyzw)
    px, py, pz = position.tolist() if isinstance(position, np.ndarray) else (float(v) for v in position)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), px],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), py],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), pz],
                     [0.0, 0.0, 0.0, 1.0]])


def matrix_to_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """4x4 matrix -> (position (3,), xyzw quaternion (4,))."""
    return np.array(T[:3, 3], dtype=float), matrix_to_quat(T[:3, :3])


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 3) rotation vectors (axis * angle), batched.

    A single (3, 3) matrix takes a scalar path (the Jacobian loops call this once per step, where
    numpy's per-call overhead on 3-vectors would cost more than the arithmetic); same formulas.
    """
    R = np.asarray(R, dtype=float)
    if R.ndim == 2:
        return np.array(_rotation_vector_3x3(R.tolist()))
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    cos = np.clip((tr - 1.0) / 2.0, -1.0, 1.0)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    # v = 2 sin(angle) axis: sin from |v| and the angle from atan2 stay accurate near π, where
    # arccos of the trace loses half the digits
    s = np.minimum(np.linalg.norm(v, axis=-1) / 2.0, 1.0)
    angle = np.arctan2(s, cos)
    out = np.empty(R.shape[:-2] + (3,))
    small = s > 1e-6
    scale = np.where(small, angle / np.where(small, 2.0 * s, 1.0), 0.5)  # angle→0: v/2 is the rotation vector
    out[...] = v * scale[..., None]
    near_pi = (~small) & (cos < 0)
    if np.any(near_pi):  # angle ≈ π: axis from the diagonal of R + I
        for idx in zip(*np.nonzero(near_pi)):
            out[idx] = _rotation_vector_3x3(R[idx].tolist())
    return out


def _rotation_vector_3x3(R: list[list[float]]) -> tuple[float, float, float]:
    """One rotation matrix (nested lists) -> rotation vector, in scalars; the batched path's formulas."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    cos = min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0)
    vx, vy, vz = r21 - r12, r02 - r20, r10 - r01
    s = min(math.sqrt(vx * vx + vy * vy + vz * vz) / 2.0, 1.0)
    angle = math.atan2(s, cos)
    if s > 1e-6:
        scale = angle / (2.0 * s)
    elif not cos < 0:
        scale = 0.5  # angle→0: v/2 is the rotation vector
    else:  # angle ≈ π: v vanishes; the axis is the row of (R + I)/2 with the largest diagonal entry
        B = [[(r00 + 1.0) / 2.0, r01 / 2.0, r02 / 2.0],
             [r10 / 2.0, (r11 + 1.0) / 2.0, r12 / 2.0],
             [r20 / 2.0, r21 / 2.0, (r22 + 1.0) / 2.0]]
        ax, ay, az = B[max(range(3), key=lambda i: B[i][i])]   # first maximum, as np.argmax
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        return ax / norm * angle, ay / norm * angle, az / norm * angle
    return vx * scale, vy * scale, vz * scale


def pose_error(T_current: np.ndarray, T_target: np.ndarray) -> np.ndarray:
    """(..., 4, 4) current and target poses -> (..., 6) error (position, rotation vector), world frame."""
    T_current = np.asarray(T_current, dtype=float)
    T_target = np.asarray(T_target, dtype=float)
    if T_current.ndim == 2 and T_target.ndim == 2:  # one pair: scalar rotation vector (see rotation_vector)
        e = np.empty(6)
        np.subtract(T_target[:3, 3], T_current[:3, 3], out=e[:3])
        e[3:] = _rotation_vector_3x3(T_target[:3, :3].dot(T_current[:3, :3].T).tolist())
        return e
    R_err = T_target[..., :3, :3] @ np.swapaxes(T_current[..., :3, :3], -1, -2)
    dp = T_target[..., :3, 3] - T_current[..., :3, 3]
    return np.concatenate([dp, rotation_vector(R_err)], axis=-1)


def pose_distance(T_a: np.ndarray, T_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position distance (m) and rotation angle (rad) between poses, batched."""
    e = pose_error(T_a, T_b)
    return np.linalg.norm(e[..., :3], axis=-1), np.linalg.norm(e[..., 3:], axis=-1)


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms."""
    T = np.asarray(T, dtype=float)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out
