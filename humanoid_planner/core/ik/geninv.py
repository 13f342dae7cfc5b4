"""Generalized inverses of the 6×n Jacobian and the Jacobian-steered pose-reaching loop.

- Weighted least-norm (WLN), the GIRRT paper eq. 26–28 (Chan & Dubey's method): a joint-limit cost H(θ), and
  a diagonal weight w_i = 1 + |∂H/∂θ_i| while joint i moves toward a limit (|∂H/∂θ_i| grows), else 1.
  Eq. 28 as printed reads "if |∂H/∂θ_i| ≥ 0", which is always true; the Δ of the original method was
  lost in print, and we implement Δ|∂H/∂θ_i| ≥ 0 (the previous step's gradient is passed in).
- SVD pseudo-inverse, the DAGRRT paper eq. 9–12, with damping only near singularities (Maciejewski & Klein):
  λ² = (1 − (σ_min/ε)²) λ_max² when σ_min < ε, else 0; J⁺ = Σ σ_i / (σ_i² + λ²) v_i u_iᵀ.
- steer_to_pose: the inner loop of GIRRT's ExtendToGrasp (the GIRRT paper Alg. 2) and DAGRRT's
  ApproachToTarget (the DAGRRT paper Alg. 4): Δx = LimitStepSize(x_target − x), Δq = J⁺ Δx, q += Δq, until
  the TCP is within tolerance.  It returns every intermediate configuration, because the planners add
  each collision-free one to their tree.

Pose-error convention (core/transforms.pose_error): a 6-vector, position difference then the rotation
vector (axis·angle) taking the current orientation to the target, both in the root (world) frame,
which matches the Jacobian's rows (linear velocity, then angular velocity, in the root frame).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
from scipy.linalg.lapack import dgesdd as _gesdd

from humanoid_planner.core.transforms import pose_error

DEFAULT_EPS = 0.05       # σ_min below which damping starts (Jacobian units: m/rad and rad/rad)
DEFAULT_LAM_MAX = 0.05   # damping at an exact singularity; bounds |Δq| by |Δx| / (2 λ_max)
# (both: small next to an arm's usual singular values, ~0.1-1, so damping acts only near a singularity)


# ----------------------------------------------------------------------------- joint-limit cost (eq. 26)
def _finite_range(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    return np.isfinite(lower) & np.isfinite(upper) & (upper > lower)


def joint_limit_cost(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """H(θ) = Σ (θmax − θmin)² / (4 (θmax − θ)(θ − θmin)), eq. 26; n at mid-range (each term 1), ∞ at a limit. Batched."""
    q = np.asarray(q, dtype=float)
    ok = _finite_range(lower, upper)
    lo, hi = np.where(ok, lower, -1.0), np.where(ok, upper, 1.0)
    qq = np.where(ok, q, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = 4.0 * (hi - qq) * (qq - lo)
        h = np.where(den > 0, (hi - lo) ** 2 / np.where(den > 0, den, 1.0), np.inf)
    return np.sum(np.where(ok, h, 0.0), axis=-1)


class _JointLimits:
    """The joint-limit terms of eq. 26–28 with their per-limits constants computed once.

    steer_to_pose builds one per approach and evaluates it every step; the public functions build
    one per call.  Joints without a finite range get the stand-in range (−1, 1) at q = 0 and a
    zero gradient.
    """

    __slots__ = ("ok", "all_ok", "lo", "hi", "quarter_range2")

    def __init__(self, lower: np.ndarray, upper: np.ndarray):
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        self.ok = _finite_range(lower, upper)
        self.all_ok = bool(np.all(self.ok))
        self.lo, self.hi = np.where(self.ok, lower, -1.0), np.where(self.ok, upper, 1.0)
        self.quarter_range2 = (self.hi - self.lo) ** 2 / 4.0

    def _gradient(self, q: np.ndarray) -> tuple[np.ndarray, bool]:
        """(∂H/∂θ, whether it is all finite); the common all-strictly-inside case skips the masks."""
        q = np.asarray(q, dtype=float)
        qq = q if self.all_ok else np.where(self.ok, q, 0.0)
        a, b = self.hi - qq, qq - self.lo          # both > 0 ⇔ strictly inside (both < 0 is impossible)
        ab = a * b
        num = self.quarter_range2 * (b - a)        # (θmax − θmin)² (2θ − θmax − θmin) / 4
        if ab.size and ab.min() > 1e-100:          # (the bound keeps (ab)² from underflowing to 0)
            g, finite = num / (ab * ab), True
        else:
            inside = (a > 0.0) & (b > 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                g = np.where(inside, num / np.where(inside, ab * ab, 1.0), np.where(qq >= self.hi, np.inf, -np.inf))
            finite = bool(np.all(np.isfinite(g)))
        return (g if self.all_ok else np.where(self.ok, g, 0.0)), finite

    def gradient(self, q: np.ndarray) -> np.ndarray:
        """∂H/∂θ (see joint_limit_gradient)."""
        return self._gradient(q)[0]

    def weights(self, q: np.ndarray, prev_grad: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 28 (see wln_weights)."""
        grad, finite = self._gradient(q)
        mag = np.abs(grad)
        if prev_grad is None:
            return 1.0 + mag, grad
        if finite:  # no inf - inf: Δ|∂H/∂θ| ≥ 0 is |∂H/∂θ| ≥ |prev|, and mag·[toward] is mag or 0
            return 1.0 + mag * (mag >= np.abs(prev_grad)), grad
        with np.errstate(invalid="ignore"):
            # at a limit on both steps: inf - inf = nan → False, so w = 1 and the joint may leave it
            toward = (mag - np.abs(prev_grad)) >= 0
        return np.where(toward, 1.0 + mag, 1.0), grad


def joint_limit_gradient(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """∂H/∂θ_i = (θmax − θmin)² (2θ_i − θmax − θmin) / (4 (θmax − θ_i)² (θ_i − θmin)²).

    ±∞ at (or beyond) a limit, 0 for joints without a finite range. Batched over leading axes.
    """
    return _JointLimits(lower, upper).gradient(q)


def wln_weights(q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                prev_grad: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 28: (w, ∂H/∂θ). w_i = 1 + |∂H/∂θ_i| if Δ|∂H/∂θ_i| ≥ 0 (toward a limit, or no previous step), else 1."""
    return _JointLimits(lower, upper).weights(q, prev_grad)


# ----------------------------------------------------------------------------- inverses
def _svd(J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD.  One matrix goes straight to LAPACK's gesdd, the routine np.linalg.svd runs, without
    the gufunc's per-call overhead (which is most of the time for a 6×n Jacobian)."""
    if J.ndim == 2 and J.size:
        U, S, Vt, info = _gesdd(J, compute_uv=1, full_matrices=0)
        if info == 0:
            return U, S, Vt
    return np.linalg.svd(J, full_matrices=False)  # batches, and the error np.linalg raises on failure


def damped_svd_pinv(J: np.ndarray, eps: float = DEFAULT_EPS, lam_max: float = DEFAULT_LAM_MAX) -> np.ndarray:
    """The DAGRRT paper's eq. 9–12: J⁺ = V diag(σ/(σ² + λ²)) Uᵀ, λ > 0 only when σ_min < eps. (m, n) or (N, m, n)."""
    J = np.asarray(J, dtype=float)
    U, S, Vt = _svd(J)
    if J.ndim == 2 and S.size:  # one matrix: λ² in scalars, and no masks unless some σ² + λ² is 0
        smin = float(S[-1])
        if smin < eps:
            den = S * S + (1.0 - (smin / eps) ** 2) * lam_max ** 2
        else:
            den = S * S
        inv = S / den if float(den[-1]) > 0.0 else np.where(den > 0, S / np.where(den > 0, den, 1.0), 0.0)
        return (Vt.T * inv).dot(U.T)
    smin = S[..., -1:]
    lam2 = np.where(smin < eps, (1.0 - (smin / eps) ** 2) * lam_max ** 2, 0.0)
    den = S * S + lam2
    inv = np.where(den > 0, S / np.where(den > 0, den, 1.0), 0.0)
    return np.swapaxes(Vt, -1, -2) @ (inv[..., :, None] * np.swapaxes(U, -1, -2))


def wln_pinv(J: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             prev_grad: np.ndarray | None = None, *, eps: float = DEFAULT_EPS,
             lam_max: float = DEFAULT_LAM_MAX) -> tuple[np.ndarray, np.ndarray]:
    """The GIRRT paper's eq. 27: (J⁺_WLN = W⁻¹Jᵀ(J W⁻¹ Jᵀ)⁻¹, ∂H/∂θ to pass back as prev_grad next step). Batched.

    Computed as W^-½ · pinv(J W^-½) with the damped SVD, which equals eq. 27 whenever J W⁻¹ Jᵀ is
    well conditioned and stays bounded near singularities (the paper's "damping WLN").  A joint at
    its limit being pushed further in gets w = ∞, i.e. it does not move.
    """
    return _wln_pinv(J, q, _JointLimits(lower, upper), prev_grad, eps, lam_max)


def _wln_pinv(J: np.ndarray, q: np.ndarray, limits: _JointLimits, prev_grad: np.ndarray | None,
              eps: float, lam_max: float) -> tuple[np.ndarray, np.ndarray]:
    w, grad = limits.weights(q, prev_grad)
    s = 1.0 / np.sqrt(w)                                       # W^-½; w ≥ 1, and w = ∞ gives exactly 0
    Jw = np.asarray(J, dtype=float) * s[..., None, :]
    return s[..., :, None] * damped_svd_pinv(Jw, eps, lam_max), grad


# ----------------------------------------------------------------------------- pose reaching
@dataclass
class SteerResult:
    """Outcome of steer_to_pose; unpacks as (steps, reached) for callers that need only those.

    steps excludes the start configuration; every step is inside the joint limits.
    """

    steps: np.ndarray          # (k, n)
    status: str                # 'reached' | 'joint_limit' | 'stalled' | 'max_iters' | 'invalid'
    pos_error: float           # m, at the last configuration (the start if k == 0)
    rot_error: float           # rad
    iterations: int
    fk_end: tuple[np.ndarray, np.ndarray] | None = None  # (TCP pose, Jacobian) at the last configuration, if reached

    @property
    def reached(self) -> bool:
        return self.status == "reached"

    def last(self, q0: np.ndarray) -> np.ndarray:
        """The final configuration (q0 when no step was taken)."""
        return self.steps[-1] if len(self.steps) else np.asarray(q0, dtype=float)

    def __iter__(self) -> Iterator:
        return iter((self.steps, self.reached))


def steer_to_pose(kin, q0: np.ndarray, T_target: np.ndarray, *, inverse: str = "wln",
                  max_step_pos: float = 0.02, max_step_rot: float = 0.1, max_joint_step: float = 0.1,
                  tol_pos: float = 1e-3, tol_rot: float = float(np.radians(0.5)), max_iters: int = 300,
                  lower: np.ndarray | None = None, upper: np.ndarray | None = None,
                  eps: float = DEFAULT_EPS, lam_max: float = DEFAULT_LAM_MAX, stall_iters: int = 15,
                  nullspace_gain: float = 0.0, is_valid: Callable[[np.ndarray], bool] | None = None,
                  fk_start: tuple[np.ndarray, np.ndarray] | None = None) -> SteerResult:
    """Step the group's TCP toward T_target (root frame) with the Jacobian's generalized inverse.

    kin: a GroupKinematics (fk_jacobian, lower, upper, n).  Each iteration: e = pose_error(FK(q),
    T_target); LimitStepSize scales e so that its position part is at most max_step_pos (m) and its
    rotation part at most max_step_rot (rad); Δq = J⁺ e ('wln': the GIRRT paper eq. 27, 'svd': the DAGRRT paper
    eq. 12), plus, if nullspace_gain > 0, the gradient-projection term −k(I − J⁺J)∇H(θ) of the GIRRT paper
    eq. 24 (joint-limit avoidance in the null space; off by default, as in both papers' loops),
    scaled so that no joint moves more than max_joint_step; q = clip(q + Δq, limits).
    Stops when the error is within (tol_pos, tol_rot) ('reached'); when clipping leaves no motion
    ('joint_limit'); when the error, counted in full steps (ep/max_step_pos + er/max_step_rot), has
    not dropped over the last stall_iters steps ('stalled', or 'joint_limit' if a joint sits at a limit); after max_iters steps ('max_iters'); or at the
    first step is_valid rejects ('invalid'; that step is not returned) — e.g. a collision check.
    fk_start: kin.fk_jacobian at q0 (within the limits) when the caller has it — a line's previous waypoint
    ended on it (SteerResult.fk_end): one of the few evaluations a short steer makes.
    """
    if inverse not in ("wln", "svd"):
        raise ValueError(f"inverse must be 'wln' or 'svd', got {inverse!r}")
    lo = np.asarray(kin.lower if lower is None else lower, dtype=float)
    hi = np.asarray(kin.upper if upper is None else upper, dtype=float)
    limits = _JointLimits(lo, hi)
    q = np.clip(np.asarray(q0, dtype=float), lo, hi)
    n = q.shape[0]
    T_target = np.asarray(T_target, dtype=float)
    steps: list[np.ndarray] = []
    grad = None   # ∂H/∂θ at q ('wln': eq. 28's previous gradient on the next step)
    history: list[float] = []
    # One step costs tens of µs, so it works on Python floats wherever numpy would only add call overhead.
    for it in range(max_iters + 1):
        T, J = fk_start if it == 0 and fk_start is not None else kin.fk_jacobian(q)
        e = pose_error(T, T_target)
        ex, ey, ez, rx, ry, rz = e.tolist()
        ep, er = math.sqrt(ex * ex + ey * ey + ez * ez), math.sqrt(rx * rx + ry * ry + rz * rz)
        if ep <= tol_pos and er <= tol_rot:
            return SteerResult(_stack(steps, n), "reached", ep, er, it, (T, J))
        if it == max_iters:
            return SteerResult(_stack(steps, n), "max_iters", ep, er, it)
        # progress in "full steps still to go"; stalled = no net progress over the last stall_iters steps
        history.append(ep / max_step_pos + er / max_step_rot)
        if len(history) > stall_iters and history[-1] >= history[-1 - stall_iters] * (1.0 - 1e-3):
            return SteerResult(_stack(steps, n), _blocked(q, lo, hi), ep, er, it)
        scale = min(1.0, max_step_pos / ep if ep > 0 else math.inf, max_step_rot / er if er > 0 else math.inf)
        if inverse == "wln":
            Jp, grad = _wln_pinv(J, q, limits, grad, eps, lam_max)
        else:
            Jp = damped_svd_pinv(J, eps, lam_max)
        dq = Jp.dot(e * scale if scale < 1.0 else e)
        if nullspace_gain > 0.0:  # the GIRRT paper eq. 24 (Liégeois): descend H(θ) without moving the TCP
            z = -nullspace_gain * np.clip(grad if inverse == "wln" else limits.gradient(q), -1e6, 1e6)
            zmax = float(np.max(np.abs(z)))
            if zmax > 0.5 * max_joint_step:
                z *= 0.5 * max_joint_step / zmax
            dq += z - Jp @ (J @ z)
        m = max(map(abs, dq.tolist()))
        if m > max_joint_step:
            dq *= max_joint_step / m
        q_new = np.minimum(np.maximum(q + dq, lo), hi)          # clip to the limits
        if max(map(abs, (q_new - q).tolist())) < 1e-12:
            return SteerResult(_stack(steps, n), _blocked(q, lo, hi), ep, er, it)
        if is_valid is not None and not is_valid(q_new):
            return SteerResult(_stack(steps, n), "invalid", ep, er, it)
        steps.append(q_new)
        q = q_new
    raise AssertionError("unreachable")  # pragma: no cover


def _blocked(q: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float = 1e-9) -> str:
    return "joint_limit" if bool(np.any((q <= lo + tol) | (q >= hi - tol))) else "stalled"


def _stack(steps: list[np.ndarray], n: int) -> np.ndarray:
    return np.array(steps) if steps else np.empty((0, n))
