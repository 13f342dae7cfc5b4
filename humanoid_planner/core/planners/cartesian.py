"""Straight-line TCP motions: the approach onto a grasp and the retreat (lift) after it.

What MoveIt's pick does with `computeCartesianPath`, built on the project's own generalized inverses
(`steer_to_pose`'s loop, compiled for a whole line: ik_kernels.line; weighted least-norm by default: it
keeps joints off their limits, and clips to them): the line is cut into waypoints `step` apart, the TCP is steered onto each one with the
orientation held, and the line stops at the first waypoint that cannot be reached (joint limits, a
singularity) or that leaves the line. Between waypoints the arm moves linearly in joint space, so
every segment is sampled and its TCP must stay within `tol_pos` / `tol_rot` of the line (2 mm /
1°); `validate` (a collision check of the polyline) cuts the line at the first blocked waypoint.

Several arms along one displacement (a two-handed lift): `parallel_lines` computes each arm's line
through the same displacements and keeps the prefix every arm achieved, so at every waypoint every
TCP has moved by the same world vector.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from humanoid_planner.core.ik import kernels as ik_kernels
from humanoid_planner.core.ik.geninv import DEFAULT_EPS, DEFAULT_LAM_MAX, DEFAULT_MAX_JOINT_STEP, DEFAULT_STALL_ITERS

LINE_STEP = 0.025  # m between waypoints
LINE_TOL_POS = 0.002  # m: largest TCP distance from the line
LINE_TOL_ROT = float(np.radians(1.0))  # rad: largest TCP rotation away from the line's orientation
STEER_TOL_POS = 2e-4  # m: each waypoint is reached this closely
STEER_TOL_ROT = float(np.radians(0.1))
END_TOL_POS = 1e-5  # m: the line's last waypoint
WAYPOINT_STEP_ROT = 0.05  # rad: a waypoint's steps turn the TCP at most this much (the position: `step`)
WAYPOINT_ITERS = 25  # steps at most onto one waypoint
SEGMENT_SAMPLES = 4  # samples per segment when checking that the TCP stays on the line
LINE_REASONS = ("complete", "ik", "deviation")  # by ik_kernels.line's reason code
# (the tolerances above: a line's TCP error stays well under a grasp's goal tolerance, 2 mm / 1 deg by default)


@dataclass(frozen=True)
class GripperTranslation:
    """MoveIt's GripperTranslation: a straight TCP segment of `desired_distance` (at least
    `min_distance`) along `direction`, given in `frame`: "" = the default (the TCP frame for an
    approach, the planning frame for a retreat), the TCP link, the planning frame, or a robot link
    (at the start state)."""

    direction: tuple[float, float, float]
    desired_distance: float
    min_distance: float = 0.0
    frame: str = ""

    def problem(self) -> str | None:
        """Why this translation cannot be used, or None."""
        d = np.asarray(self.direction, float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
            return f"direction must be a non-zero finite 3-vector, got {np.asarray(self.direction).tolist()}"
        if not (np.isfinite(self.desired_distance) and np.isfinite(self.min_distance)):
            return "desired_distance and min_distance must be finite"
        if self.desired_distance < 0 or self.min_distance < 0:
            return "desired_distance and min_distance must be >= 0"
        if self.min_distance > self.desired_distance + 1e-9:
            return f"min_distance {self.min_distance} exceeds desired_distance {self.desired_distance}"
        return None

    @property
    def unit(self) -> np.ndarray:
        d = np.asarray(self.direction, float)
        return d / np.linalg.norm(d)


@dataclass
class LineResult:
    """A line from q0: waypoints (K, n), q0 excluded; distance achieved (m); why it stopped."""

    waypoints: np.ndarray
    distance: float
    reason: str  # "complete", "ik" (limits / singularity), "deviation", "blocked"

    @property
    def path(self) -> np.ndarray:
        return self.waypoints


def line_deviation(kin, q_path: np.ndarray, T0: np.ndarray, direction: np.ndarray,
                   samples: int = SEGMENT_SAMPLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per segment of q_path (M, n), the largest TCP distance (m) from the line through T0 along
    `direction`, the largest rotation (rad) from T0's orientation, and the largest advance along
    the line (m): sampled `samples` times per segment (joint-space interpolation; compiled)."""
    q_path = ik_kernels.c_array(np.atleast_2d(q_path))
    d = np.asarray(direction, float)
    return ik_kernels.line_deviation(q_path, ik_kernels.c_array(T0), d / np.linalg.norm(d),
                                     int(samples), *kin.chain_arrays)


def straight_line(kin, q0: np.ndarray, direction: np.ndarray, distance: float, lower: np.ndarray,
                  upper: np.ndarray, *, validate: Callable[[np.ndarray, np.ndarray], int] | None = None,
                  step: float = LINE_STEP, inverse: str = "wln", tol_pos: float = LINE_TOL_POS,
                  tol_rot: float = LINE_TOL_ROT, T0: np.ndarray | None = None) -> LineResult:
    """Move the TCP of `kin` from its pose at q0 (or T0, a pose q0 holds within the steering
    tolerance) `distance` m along the world `direction`, orientation held.

    validate(q0, waypoints) → how many leading waypoints are free (MotionValidator.free_prefix)."""
    d = np.asarray(direction, float)
    n = float(np.linalg.norm(d))
    if not (n > 1e-9 and np.isfinite(n)):
        raise ValueError("the line direction must be a non-zero finite vector")
    d = d / n
    q0 = np.asarray(q0, float)
    T0 = kin.fk(q0) if T0 is None else np.asarray(T0, float)
    k = max(1, int(np.ceil(distance / step - 1e-9))) if distance > 0 else 0
    s = distance * np.arange(1, k + 1) / max(k, 1)
    if inverse not in ("wln", "svd"):
        raise ValueError(f"inverse must be 'wln' or 'svd', got {inverse!r}")
    lo, hi = ik_kernels.c_array(lower), ik_kernels.c_array(upper)
    # each waypoint: steer_to_pose's loop with these settings, from where the last one ended; then line_deviation
    W, m, code = ik_kernels.line(ik_kernels.c_array(q0), ik_kernels.c_array(T0), d, s, inverse == "wln",
                                 float(step), WAYPOINT_STEP_ROT, DEFAULT_MAX_JOINT_STEP, STEER_TOL_POS, END_TOL_POS,
                                 STEER_TOL_ROT, WAYPOINT_ITERS, lo, hi, DEFAULT_EPS, DEFAULT_LAM_MAX,
                                 DEFAULT_STALL_ITERS, float(tol_pos), float(tol_rot), SEGMENT_SAMPLES, *kin.chain_arrays)
    W, reason = W[:m], LINE_REASONS[code]
    if validate is not None and len(W):
        free = int(validate(q0, W))
        if free < len(W):
            W, reason = W[:free], "blocked"
    return LineResult(W, float(s[len(W) - 1]) if len(W) else 0.0, reason)


def parallel_lines(kins, q0s, direction: np.ndarray, distance: float, limits, *,
                   validate: Callable[[np.ndarray, np.ndarray], int] | None = None,
                   step: float = LINE_STEP, inverse: str = "wln") -> LineResult:
    """Several TCPs (one per kinematics) moved by the same world displacement at every waypoint:
    each arm's line, the common prefix, concatenated joints (arm order); validate sees the
    concatenated configurations."""
    lines = [straight_line(k, q, direction, distance, lo, hi, step=step, inverse=inverse)
             for k, q, (lo, hi) in zip(kins, q0s, limits)]
    m = min(len(line.waypoints) for line in lines)
    W = np.hstack([line.waypoints[:m] for line in lines]) if m else np.zeros((0, sum(len(q) for q in q0s)))
    reason = next((line.reason for line in lines if len(line.waypoints) == m and line.reason != "complete"), "complete")
    q0 = np.concatenate(q0s)
    if validate is not None and len(W):
        free = int(validate(q0, W))
        if free < len(W):
            W, reason = W[:free], "blocked"
    k_all = max(1, int(np.ceil(distance / step - 1e-9))) if distance > 0 else 0
    return LineResult(W, distance * len(W) / k_all if k_all else 0.0, reason)
