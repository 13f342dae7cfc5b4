"""Time parameterization of a joint-space path within velocity and acceleration limits.

The planners return piecewise-linear paths whose straight segments were collision-checked. A
cubic spline through the waypoints would leave those segments by an unbounded amount (0.1 rad on
a 20-waypoint random walk with 0.3 rad steps, more on long shortcut segments), and a spline
through densely resampled segments rings at every corner, which made toppra's constant-
acceleration output exceed the acceleration limit by 2-3x. So the path is built the way TOTG
(Kunz & Stilman 2012, MoveIt's default) builds it: straight segments joined by circular blends
whose distance from the corner waypoint is at most ``path_tolerance``. Straight parts are followed
exactly; ``TimedTrajectory.max_deviation`` bounds how far the blends leave the checked path, so
the planner can re-check the samples (or retry with ``path_tolerance=0``). A blend lies inside
the triangle spanned by its corner, so it cannot overshoot joint limits the waypoints respect.

toppra (TOPP-RA, seidel solver, constant-acceleration interpolation) finds the time-optimal
speed along that path. toppra only enforces limits at its gridpoints, and inside a blend the
direction turns between them, so the result is checked on a dense grid and again on the output
samples and their finite differences; any overshoot (typically < 1 %) slows the whole piece down
uniformly (time x k divides velocity by k and acceleration by k^2), so limits are never exceeded. Where toppra fails, and for single straight segments (where it
would give the same answer), an exact trapezoidal profile that stops at each waypoint is used.
The robot also stops at sharp reversals (turn > 175 degrees), where a blend is meaningless.
"""
from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import toppra  # imported eagerly: its first import (matplotlib) costs ~0.2 s, not a plan's budget
from toppra import algorithm, constraint

DEFAULT_PATH_TOLERANCE = 0.05
"""rad: how far (joint-space Euclidean) a corner blend may pass from its waypoint."""

DEFAULT_SAMPLE_DT = 0.02
"""s: output sampling period (50 Hz), coarsened when the trajectory would exceed max_points."""

DEFAULT_MAX_POINTS = 400
"""Cap on JointTrajectory points (a few hundred stay well under DDS message limits)."""

DEFAULT_MAX_GRIDPOINTS = 60
"""Target toppra gridpoints; cost is ~25-30 us each. Junctions and blends add what they need (a
20-waypoint 10-DoF path gets ~250, ~8-15 ms); 10x more gridpoints shortened trajectories by
only 1-4% in our measurements."""

ARC_GRID_ANGLE = math.radians(15.0)
"""One toppra gridpoint per this much turn inside a blend (at least 2): the direction rotates
there, so a joint's share of the motion, and its limit, changes between gridpoints."""

LINE_GRIDPOINTS = 4
"""Interior gridpoints per straight part: room to speed up, cruise and brake before a blend."""

BLEND_POINT_ANGLE = math.radians(2.0)
"""Turn between consecutive points of TimedTrajectory.blends."""

STOP_TURN_ANGLE = math.radians(175.0)
"""Turns sharper than this stop at the waypoint instead of blending (blend radius would be ~0)."""

STRAIGHT_ANGLE = 1e-6
"""rad: gentler turns are joined without a blend (a velocity kink of ~1e-6 relative)."""

MIN_BLEND_RADIUS = 1e-4
"""rad: smaller blends are stops (their curvature forces near-zero speed anyway)."""

CHECK_MARGIN = 1e-3
"""Slow down until the checked samples are this far under the limits, leaving room for the peaks
between samples (measured < 1e-5 relative)."""

DUPLICATE_TOL = 1e-9
"""rad: consecutive waypoints closer than this are merged."""

_log = logging.getLogger(__name__)
logging.getLogger("toppra").setLevel(logging.ERROR)  # it warns on every failure we handle


@dataclass(frozen=True)
class TimedTrajectory:
    """A sampled trajectory: starts and ends at rest at the first and last waypoint.

    ``max_deviation`` bounds the joint-space (Euclidean) distance of the motion from the
    piecewise-linear input path (0 when it follows it exactly). ``method`` is "toppra",
    "trapezoidal" (stops at every waypoint), "mixed" or "static" (nothing to move).
    """

    times: np.ndarray  # (K,) strictly increasing, times[0] == 0
    positions: np.ndarray  # (K, n)
    velocities: np.ndarray  # (K, n)
    accelerations: np.ndarray  # (K, n)
    max_deviation: float = 0.0
    method: str = "static"
    blends: tuple[np.ndarray, ...] = ()
    """Points along every corner blend, in order ((m, n) each; the first and last lie on the straight
    segments): the only parts of the motion off the input path, so the only ones to re-check."""

    @property
    def duration(self) -> float:
        return float(self.times[-1])


class _Piece(Protocol):
    """A rest-to-rest part of the trajectory."""

    duration: float
    deviation: float
    method: str
    end: np.ndarray

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


# --- exact straight-line profile ---------------------------------------------------------------

class _Trapezoid:
    """Time-optimal rest-to-rest motion along one straight segment (trapezoid or triangle).

    The path parameter u in [0, 1] gets the tightest of the per-joint limits, so every joint
    stays within its own velocity and acceleration limit exactly.
    """

    method = "trapezoidal"
    deviation = 0.0

    def __init__(self, a: np.ndarray, b: np.ndarray, vlim: np.ndarray, alim: np.ndarray) -> None:
        self.a, self.end, self.delta = a, b, b - a
        d = np.abs(self.delta)
        moving = d > 0
        self.v = float(np.min(vlim[moving] / d[moving]))
        self.acc = float(np.min(alim[moving] / d[moving]))
        if self.v * self.v >= self.acc:  # never reaches cruise speed: triangle
            self.t_acc = math.sqrt(1.0 / self.acc)
            self.v = self.acc * self.t_acc
            self.duration = 2.0 * self.t_acc
        else:
            self.t_acc = self.v / self.acc
            self.duration = self.t_acc + 1.0 / self.v

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.clip(t, 0.0, self.duration)
        T, ta, v, a = self.duration, self.t_acc, self.v, self.acc
        td = T - t
        acc_phase, dec_phase = t < ta, td < ta
        u = np.where(acc_phase, 0.5 * a * t * t, np.where(dec_phase, 1.0 - 0.5 * a * td * td,
                                                        0.5 * a * ta * ta + v * (t - ta)))
        ud = np.where(acc_phase, a * t, np.where(dec_phase, a * td, v))
        udd = np.where(acc_phase, a, np.where(dec_phase, -a, 0.0))
        return (self.a + u[:, None] * self.delta, ud[:, None] * self.delta,
                udd[:, None] * self.delta)


# --- blended path (lines + circular arcs) ------------------------------------------------------

class _BlendedPath:
    """Straight segments joined by circular blends (TOTG construction), arc-length parameter s.

    Follows the toppra AbstractGeometricPath protocol (``__call__(s, order)``, ``dof``,
    ``path_interval``). A line is p0 + s*y; an arc of radius r is c + r(x cos(s/r) + y sin(s/r))
    with x, y orthonormal (y = incoming direction). A junction belongs to the piece starting there.
    """

    def __init__(self, waypoints: np.ndarray, tolerance: float) -> None:
        w = waypoints
        seg = np.diff(w, axis=0)
        length = np.linalg.norm(seg, axis=1)
        y = seg / length[:, None]
        n = w.shape[1]
        starts, kinds, p0, cx, cy, rad = [], [], [], [], [], []
        s, cur, self.deviation = 0.0, w[0], 0.0

        def add(kind: int, origin, direction, x_vec, radius: float, piece_len: float) -> None:
            nonlocal s
            starts.append(s), kinds.append(kind), p0.append(origin), cx.append(x_vec)
            cy.append(direction), rad.append(radius)
            s += piece_len

        for i in range(1, len(w) - 1):
            y0, y1 = y[i - 1], y[i]
            alpha = math.acos(float(np.clip(y0 @ y1, -1.0, 1.0)))
            if alpha < STRAIGHT_ANGLE:  # nearly straight: a plain junction, no arc
                add(0, cur, y0, np.zeros(n), 1.0, float(np.linalg.norm(w[i] - cur)))
                cur = w[i]
                continue
            ell = min(length[i - 1] / 2, length[i] / 2,
                      tolerance * math.sin(alpha / 2) / max(1 - math.cos(alpha / 2), 1e-300))
            r = ell / math.tan(alpha / 2)
            start = w[i] - ell * y0
            line_len = float(np.linalg.norm(start - cur))
            if line_len > 1e-9:  # blends may use up a whole segment; skip the remnant
                add(0, cur, y0, np.zeros(n), 1.0, line_len)
            bis = y1 - y0
            center = w[i] + bis / np.linalg.norm(bis) * (r / math.cos(alpha / 2))
            add(1, center, y0, (start - center) / r, r, alpha * r)
            self.deviation = max(self.deviation, r / math.cos(alpha / 2) - r)
            cur = w[i] + ell * y1
        line_len = float(np.linalg.norm(w[-1] - cur))
        add(0, cur, y[-1], np.zeros(n), 1.0, line_len)
        self.starts = np.array(starts)
        self.kinds = np.array(kinds)
        self.p0, self.x, self.y = np.array(p0), np.array(cx), np.array(cy)
        self.r = np.array(rad)
        self.length = s
        self.ends = np.append(self.starts[1:], s)
        self.end_point = w[-1]

    @property
    def dof(self) -> int:
        return self.p0.shape[1]

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([0.0, self.length])

    def _piece(self, s: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.starts, s, side="right") - 1, 0, len(self.starts) - 1)

    def __call__(self, s, order: int = 0) -> np.ndarray:
        scalar = np.ndim(s) == 0
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.length)
        k = self._piece(s)
        ds = (s - self.starts[k])[:, None]
        arc = (self.kinds[k] == 1)[:, None]
        r = self.r[k][:, None]
        th = ds / r
        c, sn = np.cos(th), np.sin(th)
        x, y = self.x[k], self.y[k]
        if order == 0:
            out = np.where(arc, self.p0[k] + r * (x * c + y * sn), self.p0[k] + ds * y)
        elif order == 1:
            out = np.where(arc, -x * sn + y * c, y)
        elif order == 2:
            out = np.where(arc, -(x * c + y * sn) / r, 0.0)
        else:
            raise ValueError(f"order {order} is not supported")
        return out[0] if scalar else out

    def arc_points(self) -> list[np.ndarray]:
        """Each blend as points BLEND_POINT_ANGLE of turn apart (chords within ~1.5e-4 r of the arc)."""
        out = []
        for a, b, r in zip(self.starts[self.kinds == 1], self.ends[self.kinds == 1], self.r[self.kinds == 1]):
            k = max(2, math.ceil((b - a) / r / BLEND_POINT_ANGLE))
            out.append(self(np.linspace(a, b, k + 1)))
        return out

    def gridpoints(self, budget: int) -> np.ndarray:
        """Gridpoints for toppra: both sides of every junction, one per ARC_GRID_ANGLE inside
        each blend, LINE_GRIDPOINTS inside each straight part, the rest of the budget evenly.

        A junction gets a second gridpoint just before it, so each side's curvature constrains
        only its own interval; with one gridpoint, the arc's curvature would forbid braking on
        the whole straight interval leading into it (halving the speed on coarse grids).
        """
        arcs = self.kinds == 1
        lines = ~arcs
        starts, ends = self.starts, self.ends
        per_arc = np.maximum(2, np.ceil((ends - starts) / self.r / ARC_GRID_ANGLE)).astype(int)
        inner = [np.linspace(a, b, k + 2)[1:-1]
                 for a, b, k in zip(starts[arcs], ends[arcs], per_arc[arcs])]
        inner += [np.linspace(a, b, LINE_GRIDPOINTS + 2)[1:-1]
                  for a, b in zip(starts[lines], ends[lines])]
        junctions = starts[1:]
        before = junctions - 1e-3 * (ends - starts)[:-1]
        fixed = 2 * len(junctions) + int(per_arc[arcs].sum()) + LINE_GRIDPOINTS * int(
            lines.sum()) + 2
        even = np.linspace(0.0, self.length, max(budget - fixed, 2))
        g = np.unique(np.concatenate([even, junctions, before, *inner, [self.length]]))
        keep = np.concatenate([[True], np.diff(g) > 1e-12 * max(self.length, 1.0)])
        g = g[keep]
        g[-1] = self.length
        return g


class _ToppraPiece:
    """Constant-acceleration interpolation of a toppra solution (same math as toppra's
    ParametrizeConstAccel, vectorized), optionally slowed down by a uniform time factor."""

    method = "toppra"

    def __init__(self, path: _BlendedPath, grid: np.ndarray, sd: np.ndarray) -> None:
        self.path, self.s = path, grid
        self.sd = np.maximum(sd, 0.0)
        ds = np.diff(grid)
        vsum = self.sd[:-1] + self.sd[1:]
        if np.any(vsum <= 0):
            raise ValueError("toppra stopped inside the path")
        self.u = (self.sd[1:] ** 2 - self.sd[:-1] ** 2) / (2 * ds)
        self.t = np.concatenate([[0.0], np.cumsum(2 * ds / vsum)])
        self.k = 1.0
        self.duration = float(self.t[-1])
        self.deviation = path.deviation
        self.end = path.end_point

    def stretch(self, k: float) -> None:
        self.k = k
        self.duration = float(self.t[-1]) * k

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tau = np.clip(np.asarray(t, dtype=float) / self.k, 0.0, self.t[-1])
        i = np.clip(np.searchsorted(self.t, tau, side="right") - 1, 0, len(self.u) - 1)
        dt = tau - self.t[i]
        s = self.s[i] + self.sd[i] * dt + 0.5 * self.u[i] * dt * dt
        sd = np.maximum(self.sd[i] + self.u[i] * dt, 0.0)
        return self._joint(s, sd, self.u[i])

    def _joint(self, s, sd, u):
        qs, qss = self.path(s, 1), self.path(s, 2)
        k = self.k
        return (self.path(s), qs * (sd / k)[:, None],
                (qss * (sd * sd)[:, None] + qs * u[:, None]) / (k * k))

    def check_samples(self, per_interval: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities, accelerations at gridpoints, inside every interval and just
        before its end (the left limit where the next piece's curvature takes over)."""
        f = np.append(np.linspace(0.0, 1.0, per_interval + 1)[:-1], 1.0 - 1e-9)
        per_interval += 1
        i = np.repeat(np.arange(len(self.u)), per_interval)
        s = self.s[i] + np.tile(f, len(self.u)) * np.diff(self.s)[i]
        # the state at s within interval i: sd^2 = sd_i^2 + 2 u (s - s_i)
        sd = np.sqrt(np.maximum(self.sd[i] ** 2 + 2 * self.u[i] * (s - self.s[i]), 0.0))
        left = self._joint(s, sd, self.u[i])
        end = self._joint(self.s[1:], self.sd[1:], self.u)  # interval ends, with their own u
        return tuple(np.vstack([a, b]) for a, b in zip(left, end))


@functools.lru_cache(maxsize=32)
def _constraints(vlim_bytes: bytes, alim_bytes: bytes) -> tuple:
    """toppra limit constraints, cached: building them formats strings (~2 ms), and they keep
    no per-path state, so plans with the same limits can share them."""
    vlim, alim = np.frombuffer(vlim_bytes), np.frombuffer(alim_bytes)
    vel = constraint.JointVelocityConstraint(np.stack([-vlim, vlim], axis=1))
    acc = constraint.JointAccelerationConstraint(
        np.stack([-alim, alim], axis=1),
        discretization_scheme=constraint.DiscretizationType.Interpolation,
    )
    return vel, acc


def _toppra_piece(path: _BlendedPath, vlim: np.ndarray, alim: np.ndarray, budget: int,
                  box: tuple[np.ndarray, np.ndarray] | None = None) -> _ToppraPiece | None:
    """Time-optimal parameterization of one blended path, or None when toppra fails or the
    motion would leave ``box`` (lower, upper)."""
    grid = path.gridpoints(budget)
    try:
        vel, acc = _constraints(vlim.tobytes(), alim.tobytes())
        inst = algorithm.TOPPRA([vel, acc], path, gridpoints=grid, solver_wrapper="seidel",
                                parametrizer="ParametrizeConstAccel")
        inst.compute_parameterization(0.0, 0.0)
        data = inst.problem_data
        if data.return_code != algorithm.ParameterizationReturnCode.Ok or data.sd_vec is None:
            return None
        piece = _ToppraPiece(path, np.asarray(data.gridpoints, float), np.asarray(data.sd_vec, float))
    except (ValueError, ArithmeticError, toppra.exceptions.ToppraError) as exc:
        _log.debug("toppra failed: %s", exc)
        return None
    if not math.isfinite(piece.duration) or piece.duration <= 0:
        return None
    q, qd, qdd = piece.check_samples()
    if not (np.all(np.isfinite(qd)) and np.all(np.isfinite(qdd))):
        return None
    if box is not None and (np.any(q < box[0] - 1e-9) or np.any(q > box[1] + 1e-9)):
        return None
    ratio = max(float(np.max(np.abs(qd) / vlim)), math.sqrt(float(np.max(np.abs(qdd) / alim))))
    if ratio > 1.0 - CHECK_MARGIN:
        piece.stretch(ratio / (1.0 - CHECK_MARGIN))
    return piece


# --- public API --------------------------------------------------------------------------------

def _vector(a, n: int, name: str) -> np.ndarray:
    v = np.asarray(a, dtype=float)
    if v.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise ValueError(f"{name} must be finite and > 0")
    return v


def _scale(x: float, name: str) -> float:
    x = float(x)
    if not (math.isfinite(x) and 0.0 < x <= 1.0):
        raise ValueError(f"{name} must be in (0, 1], got {x}")
    return x


def _dedupe(w: np.ndarray) -> np.ndarray:
    """Drop near-duplicate consecutive waypoints, keeping the first and last ones exact."""
    keep = [w[0]]
    for q in w[1:]:
        if np.linalg.norm(q - keep[-1]) > DUPLICATE_TOL:
            keep.append(q)
        elif len(keep) > 1:
            keep[-1] = q  # the later copy wins, so the path ends exactly at the last waypoint
    return np.array(keep)


def _split_at_stops(w: np.ndarray, tolerance: float) -> list[np.ndarray]:
    """Split the waypoints where the robot must stop: every corner when tolerance is 0, else
    sharp reversals and corners whose blend would be too small to matter."""
    if len(w) < 3:
        return [w]
    if tolerance <= 0:
        return [w[i:i + 2] for i in range(len(w) - 1)]
    seg = np.diff(w, axis=0)
    length = np.linalg.norm(seg, axis=1)
    y = seg / length[:, None]
    alpha = np.arccos(np.clip(np.einsum("ij,ij->i", y[:-1], y[1:]), -1.0, 1.0))
    half = np.maximum(alpha / 2, 1e-300)
    ell = np.minimum(np.minimum(length[:-1], length[1:]) / 2,
                     tolerance * np.sin(half) / np.maximum(1 - np.cos(half), 1e-300))
    radius = ell / np.tan(half)
    stop = (alpha >= STRAIGHT_ANGLE) & ((alpha > STOP_TURN_ANGLE) | (radius < MIN_BLEND_RADIUS))
    parts, start = [], 0
    for i in np.flatnonzero(stop) + 1:
        parts.append(w[start:i + 1])
        start = i
    parts.append(w[start:])
    return parts


def time_parameterize(
    waypoints: np.ndarray,
    max_velocity: np.ndarray,
    max_acceleration: np.ndarray,
    *,
    velocity_scaling: float = 1.0,
    acceleration_scaling: float = 1.0,
    path_tolerance: float = DEFAULT_PATH_TOLERANCE,
    position_limits: tuple[np.ndarray, np.ndarray] | None = None,
    sample_dt: float = DEFAULT_SAMPLE_DT,
    max_points: int = DEFAULT_MAX_POINTS,
    max_gridpoints: int = DEFAULT_MAX_GRIDPOINTS,
) -> TimedTrajectory:
    """Time-parameterize waypoints (M, n) within scaled velocity/acceleration limits (n,).

    ``path_tolerance`` (rad) is how far corner blends may leave the piecewise-linear path; 0
    follows it exactly and stops at every waypoint. A blend stays inside the triangle of its
    corner, so joint limits hold whenever the waypoints respect them; ``position_limits``
    (lower, upper) is a safety net that replaces any blend leaving them (further than the
    waypoints themselves do) by exact stops. Sampled every
    ``sample_dt`` seconds (coarser when it would exceed ``max_points``), always including the
    rest points, and never exceeds the scaled limits. Raises ValueError on malformed input.
    """
    w = np.asarray(waypoints, dtype=float)
    if w.ndim != 2 or w.shape[0] < 1 or w.shape[1] < 1:
        raise ValueError(f"waypoints must have shape (M >= 1, n >= 1), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("waypoints contain NaN or infinite values")
    n = w.shape[1]
    vlim = _vector(max_velocity, n, "max_velocity") * _scale(velocity_scaling, "velocity_scaling")
    alim = _vector(max_acceleration, n, "max_acceleration") * _scale(
        acceleration_scaling, "acceleration_scaling")
    if not (math.isfinite(path_tolerance) and path_tolerance >= 0):
        raise ValueError(f"path_tolerance must be finite and >= 0, got {path_tolerance}")
    if not (math.isfinite(sample_dt) and sample_dt > 0):
        raise ValueError(f"sample_dt must be > 0, got {sample_dt}")
    if max_points < 2 or max_gridpoints < 10:
        raise ValueError("max_points must be >= 2 and max_gridpoints >= 10")
    if position_limits is not None:
        lower, upper = (np.asarray(a, dtype=float) for a in position_limits)
        if lower.shape != (n,) or upper.shape != (n,) or np.isnan(lower).any() or np.isnan(upper).any():
            raise ValueError(f"position_limits must be (lower, upper), each of shape ({n},)")

    path = _dedupe(w)
    if len(path) == 1:
        z = np.zeros((1, n))
        return TimedTrajectory(np.zeros(1), w[:1].copy(), z, z.copy(), 0.0, "static")

    parts = _split_at_stops(path, path_tolerance)
    budget = max(max_gridpoints // len(parts), 10)
    pieces: list[_Piece] = []
    for part in parts:
        piece = None
        if len(part) > 2:
            box = None
            if position_limits is not None:
                box = (np.minimum(lower, part.min(axis=0)), np.maximum(upper, part.max(axis=0)))
            piece = _toppra_piece(_BlendedPath(part, path_tolerance), vlim, alim, budget, box)
        if piece is None:
            pieces.extend(_Trapezoid(a, b, vlim, alim) for a, b in zip(part[:-1], part[1:]))
        else:
            pieces.append(piece)
    return _sample(pieces, w[0], w[-1], vlim, alim, sample_dt, max_points)


def _overshoot(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
               vlim: np.ndarray, alim: np.ndarray) -> float:
    """Time stretch (>= 1) that brings these samples, and their finite differences, within the
    limits: stretching time by k divides velocities by k and accelerations by k^2."""
    h = np.diff(t)[:, None]
    v_fd = np.diff(q, axis=0) / h
    a_fd = 2 * (v_fd[1:] - v_fd[:-1]) / (h[1:] + h[:-1])
    v_ratio = max(float(np.max(np.abs(qd) / vlim)), float(np.max(np.abs(v_fd) / vlim)))
    a_ratio = float(np.max(np.abs(qdd) / alim))
    if len(a_fd):
        a_ratio = max(a_ratio, float(np.max(np.abs(a_fd) / alim)))
    return max(1.0, v_ratio, math.sqrt(a_ratio))


def _sample(pieces: list[_Piece], start: np.ndarray, end: np.ndarray, vlim: np.ndarray,
            alim: np.ndarray, sample_dt: float, max_points: int) -> TimedTrajectory:
    """Sample rest-to-rest pieces on one timeline; every rest point is a sample, set exactly.

    toppra pieces are checked once more on their samples (what the controller receives) and
    slowed down if a sample or a finite difference still exceeds a limit.
    """
    total = sum(p.duration for p in pieces)
    room = max_points - 1 - len(pieces)
    dt = max(sample_dt, total / room) if room > 0 else math.inf
    ts, qs, qds, qdds = [np.zeros(1)], [start[None]], [np.zeros((1, len(start)))], []
    t0 = 0.0
    for p in pieces:
        local = np.linspace(0.0, p.duration, max(1, math.ceil(p.duration / dt - 1e-9)) + 1)
        q, qd, qdd = p.evaluate(local)
        q[-1], qd[-1] = p.end, 0.0
        if p.method == "toppra":
            k = _overshoot(local, q, qd, qdd, vlim, alim)
            if k > 1.0:
                k /= 1.0 - CHECK_MARGIN
                local, qd, qdd = local * k, qd / k, qdd / (k * k)
        if not qdds:
            qdds.append(qdd[:1])
        ts.append(t0 + local[1:]), qs.append(q[1:]), qds.append(qd[1:]), qdds.append(qdd[1:])
        t0 += local[-1]
    positions = np.vstack(qs)
    positions[-1] = end
    methods = {p.method for p in pieces}
    return TimedTrajectory(
        times=np.concatenate(ts),
        positions=positions,
        velocities=np.vstack(qds),
        accelerations=np.vstack(qdds),
        max_deviation=max(p.deviation for p in pieces),
        method=methods.pop() if len(methods) == 1 else "mixed",
        blends=tuple(a for p in pieces if isinstance(p, _ToppraPiece) for a in p.path.arc_points()),
    )


def join(first: TimedTrajectory, second: TimedTrajectory) -> TimedTrajectory:
    """Two rest-to-rest trajectories one after the other (the second starts where the first ends):
    the robot stops between them, as between the stages of MoveIt's pick."""
    if len(second.times) < 2:
        return first
    if len(first.times) < 2:
        return second
    if not np.allclose(first.positions[-1], second.positions[0], atol=1e-9):
        raise ValueError("the second trajectory does not start where the first one ends")
    t0 = first.times[-1]
    methods = {first.method, second.method} - {"static"}
    return TimedTrajectory(np.concatenate([first.times, t0 + second.times[1:]]),
                           np.vstack([first.positions, second.positions[1:]]),
                           np.vstack([first.velocities, second.velocities[1:]]),
                           np.vstack([first.accelerations, second.accelerations[1:]]),
                           max(first.max_deviation, second.max_deviation),
                           methods.pop() if len(methods) == 1 else "mixed", first.blends + second.blends)

