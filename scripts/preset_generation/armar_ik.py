"""The GIRRT paper's closed-form IK of the 7-DoF ARMAR-III arm (eq. 3–14), misprints fixed.

The arm is redundant: the elbow can swing on a circle around the shoulder–wrist line.  Given the TCP
pose in the arm's base frame Sigma_0 and a swivel angle on that circle (the redundancy parameter of
Fig. 3), the elbow position p4 fixes ^0T_4 (eq. 3), q1..q4 follow from eq. 6, 7, 9, 10 and q5..q7
from ^4T_7 = ^0T_4⁻¹ ^0T_7 (eq. 4, 11–14).

Fixes to the printed equations (config/robots/README.md, verified here by FK):
- eq. 1 element (2,3) is −s_α c_θ (the printed +s_α c_θ is not a rotation);
- eq. 3 a_4 = (r_w − p_4)/‖r_w − p_4‖ (the parentheses are missing in print);
- eq. 12 q5 = atan2(−o_ey, −o_ex) is the branch that eq. 13–14 were derived for; the (+,+) branch is
  q5 + π, and it is a solution too once q6 and q7 are recomputed from it (we return both);
- "(11)" in the list of IK equations means (10).
Every candidate is checked by forward kinematics and against the joint limits, so a wrong branch can
never be returned.  l_s = 0 (ARMAR-III's shoulder axes intersect); the formulas assume it.

The left arm of the armar3 preset is the mirror image of the tabulated right arm (dh_tables.mirror_arm):
^0T_7,left(q) = F · ^0T_7,right(q) · F_y, so its IK is the right arm's on F · T · F_y.
"""
from __future__ import annotations

import numpy as np

from preset_generation.dh_tables import (ARMAR3_L_F, ARMAR3_L_H, ARMAR3_L_S, ARMAR3_L_U, ARMAR3_LEFT, ARMAR3_RIGHT, DHArm, dh_chain,
                        dh_matrix)

_F = np.diag([1.0, 1.0, -1.0, 1.0])
_FY = np.diag([1.0, -1.0, 1.0, 1.0])
_TWO_PI = 2.0 * np.pi


def arm_table(side: str) -> DHArm:
    if side == "right":
        return ARMAR3_RIGHT
    if side == "left":
        return ARMAR3_LEFT
    raise ValueError(f"side must be 'left' or 'right', got {side!r}")


def arm_fk(q: np.ndarray, side: str = "right") -> np.ndarray:
    """TCP pose in Sigma_0 by the D-H product (same as the preset's URDF), (7,) or (N, 7)."""
    return dh_chain(arm_table(side), q)


def _to_right(T: np.ndarray, side: str) -> np.ndarray:
    return T if side == "right" else _F @ T @ _FY


def _swivel_basis(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit shoulder→wrist direction u and the circle basis (e1, e2): swivel 0 = elbow toward Sigma_0's +x.

    In the armar3 preset Sigma_0's x points down when the torso is upright, so swivel 0 is the
    lowest elbow position (the natural one); e2 = u × e1.
    """
    u = w / np.linalg.norm(w)
    ref = np.array([1.0, 0.0, 0.0])
    if np.linalg.norm(np.cross(u, ref)) < 1e-6:
        ref = np.array([0.0, -1.0, 0.0])
    e1 = ref - (ref @ u) * u
    e1 /= np.linalg.norm(e1)
    return u, e1, np.cross(u, e1)


def _elbow_circle(w: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Centre and radius of the elbow circle for wrist centre w, None if the wrist is out of reach."""
    L = float(np.linalg.norm(w))
    lu, lf = ARMAR3_L_U, ARMAR3_L_F
    if L < 1e-9 or L > lu + lf or L < abs(lu - lf):
        return None
    along = (lu * lu - lf * lf + L * L) / (2.0 * L)
    r2 = lu * lu - along * along
    if r2 < 0:
        return None
    return along * w / L, float(np.sqrt(r2))


def wrist_center(T: np.ndarray) -> np.ndarray:
    """r_w = p − l_h·n (eq. 3): the TCP lies l_h along x_7 from the wrist centre."""
    return T[:3, 3] - ARMAR3_L_H * T[:3, 0]


def swivel_angle(q: np.ndarray, side: str = "right") -> float:
    """The swivel angle of configuration q (inverse of the elbow-circle parameterisation)."""
    arm = arm_table(side)
    q = np.asarray(q, dtype=float)
    T = np.eye(4)
    for i, j in enumerate(arm.joints[:4]):
        T = T @ dh_matrix(j.offset + q[i], j.d, j.a, j.alpha)
    tcp = arm_fk(q, side)
    p4, T07 = T[:3, 3], tcp
    if side == "left":
        p4 = _F[:3, :3] @ p4
        T07 = _to_right(T07, side)
    u, e1, e2 = _swivel_basis(wrist_center(T07))
    d = p4 - (p4 @ u) * u
    return float(np.arctan2(d @ e2, d @ e1))


def _wrap_candidates(v: float, lo: float, hi: float, tol: float) -> list[float]:
    """v, v ± 2π that lie inside [lo − tol, hi + tol] (clipped into the limits)."""
    out = []
    for k in (-1, 0, 1):
        x = v + k * _TWO_PI
        if lo - tol <= x <= hi + tol:
            out.append(min(max(x, lo), hi))
    return out


def solve(T: np.ndarray, swivel: float, side: str = "right", *, within_limits: bool = True,
          tol: float = 1e-9) -> np.ndarray:
    """All IK solutions (k, 7) for TCP pose T in Sigma_0 at one swivel angle; (0, 7) if none.

    Candidates come from both branches of eq. 6, both elbow-frame signs of eq. 3 and both wrist
    branches of eq. 12, wrapped by 2π into the limits; each one is kept only if its FK matches T to
    1e-7 (position in m, rotation entries) and, unless within_limits=False, it respects the limits.
    """
    arm_table(side)  # validates side
    T = np.asarray(T, dtype=float)
    Tr = _to_right(T, side)
    arm = arm_table("right")
    lo = np.array([j.lower for j in arm.joints])
    hi = np.array([j.upper for j in arm.joints])
    if not within_limits:  # raw branch values in (−π, π], no 2π copies
        lo, hi = np.full(7, -np.pi), np.full(7, np.pi)
    w = wrist_center(Tr)
    circle = _elbow_circle(w)
    if circle is None:
        return np.empty((0, 7))
    c, rad = circle
    u, e1, e2 = _swivel_basis(w)
    p4 = c + rad * (np.cos(swivel) * e1 + np.sin(swivel) * e2)
    a4 = w - p4
    a4 /= np.linalg.norm(a4)                      # eq. 3 with the parentheses restored
    o4_raw = np.cross(a4, -p4)                    # r_s = 0 (l_s = 0)
    if np.linalg.norm(o4_raw) < 1e-9:             # stretched arm: elbow frame undefined (q4 = 0)
        return np.empty((0, 7))
    sols: list[np.ndarray] = []
    for o_sign in (1.0, -1.0):
        o4 = o_sign * o4_raw / np.linalg.norm(o4_raw)
        n4 = np.cross(o4, a4)
        T04 = np.eye(4)
        T04[:3, 0], T04[:3, 1], T04[:3, 2], T04[:3, 3] = n4, o4, a4, p4
        for sgn in (1.0, -1.0):                   # eq. 6: atan2(±p4y, ±p4x)
            q1 = np.arctan2(sgn * p4[1], sgn * p4[0])
            c1, s1 = np.cos(q1), np.sin(q1)
            q2 = np.arctan2(-p4[2], c1 * p4[0] + s1 * p4[1] - ARMAR3_L_S)           # eq. 7
            c2, s2 = np.cos(q2), np.sin(q2)
            q3 = np.arctan2(-s1 * o4[0] + c1 * o4[1],                                # eq. 9
                            -s2 * c1 * o4[0] - s2 * s1 * o4[1] - c2 * o4[2])
            q4 = np.arctan2(c2 * c1 * n4[0] + c2 * s1 * n4[1] - s2 * n4[2],          # eq. 10
                            c2 * c1 * a4[0] + c2 * s1 * a4[1] - s2 * a4[2])
            T47 = np.linalg.solve(T04, Tr)                                           # eq. 4
            ne, oe, ae = T47[:3, 0], T47[:3, 1], T47[:3, 2]
            q5_main = np.arctan2(-oe[1], -oe[0])                                     # eq. 12, fixed branch
            for q5 in (q5_main, q5_main + np.pi):
                c5, s5 = np.cos(q5), np.sin(q5)
                q6 = np.arctan2(-oe[2], -c5 * oe[0] - s5 * oe[1])                    # eq. 13
                q7 = np.arctan2(-s5 * ne[0] + c5 * ne[1], s5 * ae[0] - c5 * ae[1])   # eq. 14
                _expand(sols, [q1, q2, q3, q4, q5, q6, q7], lo, hi, tol)
    out = [q for q in sols if _fk_matches(q, Tr)]
    if not out:
        return np.empty((0, 7))
    arr = np.unique(np.round(np.array(out), 12), axis=0)
    return arr


def _expand(sols: list[np.ndarray], q: list[float], lo: np.ndarray, hi: np.ndarray, tol: float) -> None:
    """Append every 2π-wrapped variant of q inside the limits."""
    options = [_wrap_candidates(float(v), lo[i], hi[i], tol) for i, v in enumerate(q)]
    if any(not o for o in options):
        return
    grids = np.meshgrid(*options, indexing="ij")
    sols.extend(np.stack([g.ravel() for g in grids], axis=1))


def _fk_matches(q: np.ndarray, T: np.ndarray, tol: float = 1e-7) -> bool:
    return bool(np.max(np.abs(arm_fk(q, "right") - T)) < tol)


def solve_sweep(T: np.ndarray, side: str = "right", n_swivel: int = 72, *, within_limits: bool = True) -> np.ndarray:
    """Solutions over n_swivel evenly spaced swivel angles in [−π, π), stacked (k, 7)."""
    parts = [solve(T, phi, side, within_limits=within_limits)
             for phi in np.linspace(-np.pi, np.pi, n_swivel, endpoint=False)]
    parts = [p for p in parts if len(p)]
    return np.concatenate(parts) if parts else np.empty((0, 7))
