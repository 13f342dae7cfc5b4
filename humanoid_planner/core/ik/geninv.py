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

The formulas and the loop are compiled (ik/kernels.py); the functions here call those kernels (a batch one
row at a time), so each formula has one implementation.

Pose-error convention (core/transforms.pose_error): a 6-vector, position difference then the rotation
vector (axis·angle) taking the current orientation to the target, both in the root (world) frame,
which matches the Jacobian's rows (linear velocity, then angular velocity, in the root frame).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from humanoid_planner.core.ik import kernels as ik_kernels

DEFAULT_EPS = 0.05       # σ_min below which damping starts (Jacobian units: m/rad and rad/rad)
DEFAULT_LAM_MAX = 0.05   # damping at an exact singularity; bounds |Δq| by |Δx| / (2 λ_max)
# (both: small next to an arm's usual singular values, ~0.1-1, so damping acts only near a singularity)
DEFAULT_MAX_JOINT_STEP = 0.1  # rad (m): the most a joint moves in one step
DEFAULT_STALL_ITERS = 15      # steps without net progress before a steer gives up
STEER_STATUS = ("reached", "max_iters", "joint_limit", "stalled")  # by ik_kernels.steer's status code


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


def _rows(a: np.ndarray, n: int) -> np.ndarray:
    """a (..., n) as rows (-1, n) the kernels take."""
    return ik_kernels.c_array(np.asarray(a, dtype=float).reshape(-1, n))


def _limit_arrays(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return ik_kernels.c_array(lower), ik_kernels.c_array(upper)


def joint_limit_gradient(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """∂H/∂θ_i = (θmax − θmin)² (2θ_i − θmax − θmin) / (4 (θmax − θ_i)² (θ_i − θmin)²).

    ±∞ at (or beyond) a limit, 0 for joints without a finite range. Batched over leading axes.
    """
    q = np.asarray(q, dtype=float)
    lo, hi = _limit_arrays(lower, upper)
    Q = _rows(q, q.shape[-1])
    G = np.empty_like(Q)
    for k in range(len(Q)):
        ik_kernels.limit_gradient(Q[k], lo, hi, G[k])
    return G.reshape(q.shape)


def wln_weights(q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                prev_grad: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 28: (w, ∂H/∂θ). w_i = 1 + |∂H/∂θ_i| if Δ|∂H/∂θ_i| ≥ 0 (toward a limit, or no previous step), else 1.
    Batched over leading axes."""
    q = np.asarray(q, dtype=float)
    n = q.shape[-1]
    lo, hi = _limit_arrays(lower, upper)
    Q = _rows(q, n)
    P = Q if prev_grad is None else _rows(np.broadcast_to(prev_grad, q.shape), n)
    w, g = np.empty_like(Q), np.empty_like(Q)
    for k in range(len(Q)):
        ik_kernels.limit_weights(Q[k], lo, hi, P[k], prev_grad is not None, w[k], g[k])
    return w.reshape(q.shape), g.reshape(q.shape)


# ----------------------------------------------------------------------------- inverses
def damped_svd_pinv(J: np.ndarray, eps: float = DEFAULT_EPS, lam_max: float = DEFAULT_LAM_MAX) -> np.ndarray:
    """The DAGRRT paper's eq. 9–12: J⁺ = V diag(σ/(σ² + λ²)) Uᵀ, λ > 0 only when σ_min < eps. (m, n) or (N, m, n)."""
    J = np.asarray(J, dtype=float)
    m, n = J.shape[-2:]
    Js = ik_kernels.c_array(J.reshape(-1, m, n))
    out = np.empty((len(Js), n, m))
    for k in range(len(Js)):
        ik_kernels.damped_pinv(Js[k], float(eps), float(lam_max), out[k])
    return out.reshape(J.shape[:-2] + (n, m))


def wln_pinv(J: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             prev_grad: np.ndarray | None = None, *, eps: float = DEFAULT_EPS,
             lam_max: float = DEFAULT_LAM_MAX) -> tuple[np.ndarray, np.ndarray]:
    """The GIRRT paper's eq. 27: (J⁺_WLN = W⁻¹Jᵀ(J W⁻¹ Jᵀ)⁻¹, ∂H/∂θ to pass back as prev_grad next step). Batched.

    Computed as W^-½ · pinv(J W^-½) with the damped SVD, which equals eq. 27 whenever J W⁻¹ Jᵀ is
    well conditioned and stays bounded near singularities (the paper's "damping WLN").  A joint at
    its limit being pushed further in gets w = ∞, i.e. it does not move.
    """
    J, q = np.asarray(J, dtype=float), np.asarray(q, dtype=float)
    m, n = J.shape[-2:]
    lo, hi = _limit_arrays(lower, upper)
    Js, Q = ik_kernels.c_array(J.reshape(-1, m, n)), _rows(q, n)
    P = Q if prev_grad is None else _rows(np.broadcast_to(prev_grad, q.shape), n)
    out, g = np.empty((len(Js), n, m)), np.empty_like(Q)
    for k in range(len(Js)):
        ik_kernels.wln_pinv(Js[k], Q[k], lo, hi, P[k], prev_grad is not None, float(eps), float(lam_max), out[k], g[k])
    return out.reshape(J.shape[:-2] + (n, m)), g.reshape(q.shape)


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
                  max_step_pos: float = 0.02, max_step_rot: float = 0.1,
                  max_joint_step: float = DEFAULT_MAX_JOINT_STEP,
                  tol_pos: float = 1e-3, tol_rot: float = float(np.radians(0.5)), max_iters: int = 300,
                  lower: np.ndarray | None = None, upper: np.ndarray | None = None,
                  eps: float = DEFAULT_EPS, lam_max: float = DEFAULT_LAM_MAX,
                  stall_iters: int = DEFAULT_STALL_ITERS,
                  nullspace_gain: float = 0.0, is_valid: Callable[[np.ndarray], bool] | None = None,
                  fk_start: tuple[np.ndarray, np.ndarray] | None = None) -> SteerResult:
    """Step the group's TCP toward T_target (root frame) with the Jacobian's generalized inverse.

    kin: a GroupKinematics (its chain_arrays, lower, upper); the loop is compiled (ik_kernels.steer), and
    is_valid sees its steps afterwards, in order, up to the first it rejects.  Each iteration: e = pose_error(FK(q),
    T_target); LimitStepSize scales e so that its position part is at most max_step_pos (m) and its
    rotation part at most max_step_rot (rad); Δq = J⁺ e ('wln': the GIRRT paper eq. 27, 'svd': the DAGRRT paper
    eq. 12), plus, if nullspace_gain > 0, the gradient-projection term −k(I − J⁺J)∇H(θ) of the GIRRT paper
    eq. 24 (joint-limit avoidance in the null space; off by default, as in both papers' loops),
    scaled so that no joint moves more than max_joint_step; q = clip(q + Δq, limits).
    Stops when the error is within (tol_pos, tol_rot) ('reached'); when clipping leaves no motion
    ('joint_limit'); when the error, counted in full steps (ep/max_step_pos + er/max_step_rot), has
    not dropped over the last stall_iters steps ('stalled', or 'joint_limit' if a joint sits at a limit); after max_iters steps ('max_iters'); or at the
    first step is_valid rejects ('invalid'; that step is not returned) — e.g. a collision check.
    fk_start: (TCP pose, Jacobian) at q0 (within the limits) when the caller has it — a line's previous waypoint
    ended on it (SteerResult.fk_end): one of the few evaluations a short steer makes.
    """
    if inverse not in ("wln", "svd"):
        raise ValueError(f"inverse must be 'wln' or 'svd', got {inverse!r}")
    lo, hi = _limit_arrays(kin.lower if lower is None else lower, kin.upper if upper is None else upper)
    q0 = ik_kernels.c_array(q0)
    n = q0.shape[0]
    T, J = np.empty((4, 4)), np.empty((6, n))
    if fk_start is not None:
        T[:], J[:] = fk_start
    steps, errs = np.empty((max_iters, n)), np.empty((max_iters + 1, 2))
    k, code, it, ep, er = ik_kernels.steer(
        q0, ik_kernels.c_array(T_target), inverse == "wln", float(max_step_pos), float(max_step_rot),
        float(max_joint_step), float(tol_pos), float(tol_rot), int(max_iters), lo, hi, float(eps), float(lam_max),
        int(stall_iters), float(nullspace_gain), fk_start is not None, T, J, steps, errs, *kin.chain_arrays)
    steps = steps[:k]
    if is_valid is not None:  # the steps do not depend on it: the first one it rejects ends the branch there
        for j in range(k):
            if not is_valid(steps[j]):
                return SteerResult(steps[:j], "invalid", float(errs[j, 0]), float(errs[j, 1]), j)
    status = STEER_STATUS[code]
    return SteerResult(steps, status, ep, er, it, (T, J) if status == "reached" else None)
