"""Generalized inverses (the GIRRT paper eq. 26–28, the DAGRRT paper eq. 9–12) and steer_to_pose."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanoid_planner.core.ik import geninv
from humanoid_planner.core.ik.geninv import (SteerResult, damped_svd_pinv, joint_limit_cost, joint_limit_gradient,
                                          steer_to_pose, wln_pinv, wln_weights)
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_distance, pose_error
from ..model.test_kinematics import TOY_SRDF, TOY_URDF

LOWER = np.array([-1.0, -2.0, 0.0, -0.5])
UPPER = np.array([1.0, 0.5, 2.5, 3.0])


# ----------------------------------------------------------------------------- H(θ) and W (eq. 26, 28)
def test_cost_is_n_at_mid_range_and_infinite_at_limits():
    mid = (LOWER + UPPER) / 2
    assert joint_limit_cost(mid, LOWER, UPPER) == pytest.approx(4.0)     # each term is 1 at mid-range
    assert np.allclose(joint_limit_gradient(mid, LOWER, UPPER), 0.0)
    at = mid.copy()
    at[2] = UPPER[2]
    assert joint_limit_cost(at, LOWER, UPPER) == np.inf
    assert joint_limit_gradient(at, LOWER, UPPER)[2] == np.inf
    at[2] = LOWER[2] - 0.1
    assert joint_limit_gradient(at, LOWER, UPPER)[2] == -np.inf


def test_gradient_equals_finite_differences():
    rng = np.random.default_rng(0)
    for _ in range(100):
        q = rng.uniform(LOWER + 0.05, UPPER - 0.05)
        g = joint_limit_gradient(q, LOWER, UPPER)
        h = 1e-7
        fd = np.array([(joint_limit_cost(q + h * e, LOWER, UPPER) - joint_limit_cost(q - h * e, LOWER, UPPER)) / (2 * h)
                       for e in np.eye(4)])
        assert np.allclose(g, fd, rtol=1e-5, atol=1e-5)


def test_weights_grow_toward_either_limit_as_eq28_says():
    """w_i = 1 + |∂H/∂θ_i|: 1 at mid-range, strictly growing toward each limit, unbounded at it."""
    lo, hi = np.array([-1.0]), np.array([2.0])
    mid = 0.5
    for direction, limit in ((+1, hi[0]), (-1, lo[0])):
        qs = mid + direction * np.linspace(0.0, 1.5 - 1e-6, 200)
        w = np.array([wln_weights(np.array([x]), lo, hi)[0][0] for x in qs])
        assert w[0] == pytest.approx(1.0)
        assert np.all(np.diff(w) > 0)
        assert w[-1] > 1e6
    assert wln_weights(np.array([hi[0]]), lo, hi)[0][0] == np.inf


def test_weights_apply_only_when_moving_toward_a_limit():
    """Δ|∂H/∂θ_i| ≥ 0 → 1 + |∂H/∂θ_i|; moving away (|∂H/∂θ_i| shrinking) → 1."""
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    _, g_prev = wln_weights(np.array([0.5, 0.5]), lo, hi)
    w, g = wln_weights(np.array([0.7, 0.3]), lo, hi, g_prev)   # joint 0 toward +1, joint 1 back to mid
    assert w[0] == pytest.approx(1.0 + abs(g[0])) and w[0] > 1.0
    assert w[1] == 1.0
    # crossing the middle toward the other limit counts as "toward" once |∂H| grows again
    _, g_prev = wln_weights(np.array([0.05, 0.0]), lo, hi)
    w, _ = wln_weights(np.array([-0.3, 0.0]), lo, hi, g_prev)
    assert w[0] > 1.0 and w[1] == 1.0
    # unbounded joints never get a weight
    w, g = wln_weights(np.array([10.0]), np.array([-np.inf]), np.array([np.inf]))
    assert w[0] == 1.0 and g[0] == 0.0


# ----------------------------------------------------------------------------- inverses
def test_wln_pinv_is_eq27_when_well_conditioned():
    rng = np.random.default_rng(1)
    lo, hi = -np.ones(7), np.ones(7)
    for _ in range(50):
        J = rng.normal(size=(6, 7))
        q = rng.uniform(-0.9, 0.9, 7)
        Jp, _ = wln_pinv(J, q, lo, hi, eps=1e-9)
        w, _ = wln_weights(q, lo, hi)
        Winv = np.diag(1.0 / w)
        ref = Winv @ J.T @ np.linalg.inv(J @ Winv @ J.T)
        assert np.allclose(Jp, ref, atol=1e-9)
        assert np.allclose(J @ Jp, np.eye(6), atol=1e-9)


def test_wln_moves_joints_near_a_limit_less():
    J = np.random.default_rng(2).normal(size=(6, 7))
    lo, hi = -np.ones(7), np.ones(7)
    dx = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    q_mid = np.zeros(7)
    q_near = q_mid.copy()
    q_near[3] = 0.98
    dq_mid = wln_pinv(J, q_mid, lo, hi)[0] @ dx
    dq_near = wln_pinv(J, q_near, lo, hi)[0] @ dx
    assert abs(dq_near[3]) < 0.1 * abs(dq_mid[3])
    # a joint at its limit does not move while it is pushed into it
    q_at = q_mid.copy()
    q_at[3] = 1.0
    assert wln_pinv(J, q_at, lo, hi)[0][3] == pytest.approx(np.zeros(6))


def test_damped_svd_is_plain_pinv_away_from_singularities():
    rng = np.random.default_rng(3)
    for _ in range(50):
        J = rng.normal(size=(6, 7))
        if np.linalg.svd(J, compute_uv=False)[-1] < 0.1:
            continue
        assert np.allclose(damped_svd_pinv(J), np.linalg.pinv(J), atol=1e-12)


def test_damped_svd_stays_bounded_at_singularities():
    rng = np.random.default_rng(4)
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(7, 7)))
    for smallest in (0.0, 1e-8, 1e-4, 0.03):
        S = np.zeros((6, 7))
        S[np.arange(6), np.arange(6)] = [1.5, 1.2, 1.0, 0.7, 0.4, smallest]
        J = U @ S @ V.T
        Jp = damped_svd_pinv(J, eps=0.05, lam_max=0.05)
        # with λ_max = ε the gain σ/(σ² + λ²) = σ/ε² never exceeds 1/ε, however small σ_min gets
        assert np.linalg.norm(Jp, 2) <= 1.0 / 0.05 + 1e-9
        assert np.all(np.isfinite(Jp))
    # continuity at σ_min = ε: no jump when damping switches on
    S = np.zeros((6, 7))
    S[np.arange(6), np.arange(6)] = [1.5, 1.2, 1.0, 0.7, 0.4, 0.05]
    a = damped_svd_pinv(U @ S @ V.T, eps=0.05 + 1e-9)
    b = damped_svd_pinv(U @ S @ V.T, eps=0.05 - 1e-9)
    assert np.allclose(a, b, atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 6), st.integers(0, 2**31 - 1))
def test_batched_inverses_equal_one_at_a_time(N, seed):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(N, 6, 7))
    J[0, :, 0] = J[0, :, 1]                               # one rank-deficient Jacobian in the batch
    q = rng.uniform(-0.99, 0.99, size=(N, 7))
    lo, hi = -np.ones(7), np.ones(7)
    B = damped_svd_pinv(J)
    W, G = wln_pinv(J, q, lo, hi)
    for k in range(N):
        assert np.allclose(B[k], damped_svd_pinv(J[k]), atol=1e-10)
        Wk, Gk = wln_pinv(J[k], q[k], lo, hi)
        assert np.allclose(W[k], Wk, atol=1e-10) and np.allclose(G[k], Gk)


# ----------------------------------------------------------------------------- steer_to_pose
@pytest.fixture(scope="module")
def armar3():
    return RobotModel.preset("armar3")


@pytest.mark.parametrize("inverse", ["wln", "svd"])
@pytest.mark.parametrize("preset,group", [("armar3", "left_arm"), ("armar3", "right_arm_torso"),
                                          ("maru1", "left_arm_torso"), ("dual_arm", "right_arm")])
def test_steer_reaches_reachable_targets(preset, group, inverse):
    robot = RobotModel.preset(preset)
    kin = GroupKinematics(robot, group)
    q0 = kin.q_group(robot.home)
    rng = np.random.default_rng(5)
    reached = 0
    for _ in range(10):
        q_goal = np.clip(q0 + rng.normal(scale=0.4, size=kin.n), kin.lower, kin.upper)
        T_goal = kin.fk(q_goal)
        r = steer_to_pose(kin, q0, T_goal, inverse=inverse, max_joint_step=0.05)
        assert r.steps.shape[1] == kin.n
        assert np.all(r.steps >= kin.lower - 1e-12) and np.all(r.steps <= kin.upper + 1e-12)
        path = np.vstack([q0, r.steps])
        assert np.max(np.abs(np.diff(path, axis=0))) <= 0.05 + 1e-12
        dp, dr = pose_distance(kin.fk(r.last(q0)), T_goal)
        assert dp == pytest.approx(r.pos_error, abs=1e-12) and dr == pytest.approx(r.rot_error, abs=1e-12)
        if r.reached:
            reached += 1
            assert dp <= 1e-3 and dr <= np.radians(0.5)
        else:
            assert r.status in ("joint_limit", "stalled", "max_iters")
    assert reached >= 8, f"{preset}/{group}/{inverse}: only {reached}/10 reached"


def test_step_size_limit_in_task_space(armar3):
    """LimitStepSize: consecutive TCP positions move ~max_step_pos, never much more, toward the goal."""
    kin = GroupKinematics(armar3, "left_arm")
    q0 = kin.q_group(armar3.home)
    T_goal = kin.fk(q0)
    T_goal[:3, 3] += [0.15, 0.05, 0.10]
    r = steer_to_pose(kin, q0, T_goal, max_step_pos=0.01, max_joint_step=1.0)
    assert r.reached
    P = kin.fk(np.vstack([q0, r.steps]))[:, :3, 3]
    steps = np.linalg.norm(np.diff(P, axis=0), axis=1)
    assert np.max(steps) < 0.0105
    assert len(r.steps) >= 18                            # 0.187 m at ≤ 1 cm per step


def test_steer_stops_when_blocked_and_reports_why(armar3):
    kin = GroupKinematics(armar3, "left_arm")
    q0 = kin.q_group(armar3.home)
    far = kin.fk(q0)
    far[:3, 3] += [2.0, 0.0, 0.0]                         # 2 m away: out of reach
    r = steer_to_pose(kin, q0, far, inverse="svd")
    assert not r.reached and r.status in ("joint_limit", "stalled")
    assert r.iterations < 300
    # is_valid (a collision check) rejects a step: the branch stops before it
    seen = []

    def valid(q):
        seen.append(q)
        return len(seen) < 4

    T_goal = kin.fk(q0)
    T_goal[:3, 3] += [0.1, 0.0, 0.0]
    r = steer_to_pose(kin, q0, T_goal, is_valid=valid)
    assert r.status == "invalid" and len(r.steps) == 3
    # already there: no step
    r = steer_to_pose(kin, q0, kin.fk(q0))
    assert r.reached and len(r.steps) == 0 and np.array_equal(r.last(q0), q0)
    with pytest.raises(ValueError):
        steer_to_pose(kin, q0, T_goal, inverse="jt")


def test_result_unpacks_as_steps_and_reached(armar3):
    kin = GroupKinematics(armar3, "left_arm")
    q0 = kin.q_group(armar3.home)
    T_goal = kin.fk(q0)
    T_goal[:3, 3] += [0.05, 0.0, 0.0]
    res = steer_to_pose(kin, q0, T_goal)
    steps, reached = res
    assert isinstance(res, SteerResult) and reached and steps is res.steps


def test_wln_keeps_away_from_limits_better_than_svd(armar3):
    """Eq. 28's purpose: along the same approaches, WLN ends farther from the joint limits."""
    kin = GroupKinematics(armar3, "left_arm_torso")
    q0 = kin.q_group(armar3.home)
    rng = np.random.default_rng(8)
    margins = {"wln": [], "svd": []}
    for _ in range(15):
        q_goal = np.clip(q0 + rng.normal(scale=0.5, size=kin.n), kin.lower, kin.upper)
        for inv in margins:
            r = steer_to_pose(kin, q0, kin.fk(q_goal), inverse=inv)
            q = r.last(q0)
            rng_ = kin.upper - kin.lower
            margins[inv].append(np.min(np.minimum(q - kin.lower, kin.upper - q) / rng_))
    assert np.mean(margins["wln"]) > np.mean(margins["svd"])


# ----------------------------------------------------------------------------- the DAGRRT paper, section 4
# (x, y, z [mm], φ, θ, ψ [rad]) of the TCPs, printed in the paper; frame = Simox ARMAR-III root.
DAGRRT_PAPER_POSES = {
    "left_initial": ("left", [-729.387, 150.811, 1296.943, 1.669, 0.992, -2.542]),
    "right_initial": ("right", [390.833, 138.736, 1320.031, -1.214, 1.048, 0.587]),
    "left_target": ("left", [-204.765, 516.069, 1302.585, -0.150, -0.952, -2.499]),
    "right_target": ("right", [207.720, 416.536, 1146.943, -1.874, 0.587, 0.317]),
}


def dagrrt_paper_pose(p: list[float], convention: str = "rpy") -> np.ndarray:
    """Paper pose → 4x4 (m). 'rpy' (chosen, see config/robots/README.md): R = Rz(ψ) Ry(θ) Rx(φ), i.e.
    (φ, θ, ψ) = Simox's (roll, pitch, yaw); 'zyz' (as the paper's eq. 4 states): R = Rz(φ) Ry(θ) Rz(ψ)."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(p[:3]) / 1000.0
    phi, theta, psi = p[3:]
    if convention == "rpy":
        T[:3, :3] = Rotation.from_euler("ZYX", [psi, theta, phi]).as_matrix()
    else:
        T[:3, :3] = Rotation.from_euler("ZYZ", [phi, theta, psi]).as_matrix()
    return T


@pytest.mark.parametrize("inverse", ["svd", "wln"])
@pytest.mark.parametrize("pose", list(DAGRRT_PAPER_POSES))
def test_dagrrt_paper_example_poses_reached_from_home(pose, inverse):
    robot = RobotModel.preset("dual_arm")
    side, p = DAGRRT_PAPER_POSES[pose]
    kin = GroupKinematics(robot, f"{side}_arm")
    q0 = kin.q_group(robot.home)
    T = dagrrt_paper_pose(p, "rpy")
    r = steer_to_pose(kin, q0, T, inverse=inverse, tol_pos=2e-4, tol_rot=np.radians(0.05))
    assert r.reached, (r.status, r.pos_error, np.degrees(r.rot_error))
    q = r.last(q0)
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    dp, dr = pose_distance(kin.fk(q), T)
    assert dp < 1e-3 and np.degrees(dr) < 0.5


def test_dagrrt_paper_poses_zyz_reading_also_reachable_with_wln():
    """The paper's stated ZYZ reading is reachable too (WLN), so reachability cannot pick the convention."""
    robot = RobotModel.preset("dual_arm")
    for side, p in DAGRRT_PAPER_POSES.values():
        kin = GroupKinematics(robot, f"{side}_arm")
        r = steer_to_pose(kin, kin.q_group(robot.home), dagrrt_paper_pose(p, "zyz"), inverse="wln")
        assert r.reached, (side, p, r.status)


def test_module_constants_documented():
    assert geninv.DEFAULT_EPS > 0 and geninv.DEFAULT_LAM_MAX > 0


def test_nullspace_joint_limit_term_keeps_the_task_and_helps_svd():
    """The GIRRT paper's eq. 24 as an option: with it the SVD loop also reaches the ZYZ reading of R-initial."""
    robot = RobotModel.preset("dual_arm")
    kin = GroupKinematics(robot, "right_arm")
    q0 = kin.q_group(robot.home)
    T = dagrrt_paper_pose(DAGRRT_PAPER_POSES["right_initial"][1], "zyz")
    assert steer_to_pose(kin, q0, T, inverse="svd", nullspace_gain=0.01).reached
    # the projected term alone does not move the TCP (first order): (I - J⁺J) z is in the null space
    _, J = kin.fk_jacobian(q0)
    Jp = damped_svd_pinv(J)
    z = np.random.default_rng(9).normal(size=kin.n)
    assert np.allclose(J @ (z - Jp @ (J @ z)), 0.0, atol=1e-10)


# ----------------------------------------------------------------------------- fast paths vs plain formulas
# The single-configuration code (scalar damping, LAPACK called directly, precomputed limit constants,
# Python-float bookkeeping in steer_to_pose) must give what the formulas give when written plainly.
def _ref_gradient(q, lo, hi):
    ok = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    lo_, hi_ = np.where(ok, lo, -1.0), np.where(ok, hi, 1.0)
    qq = np.where(ok, q, 0.0)
    inside = (qq > lo_) & (qq < hi_)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = np.where(inside, 4.0 * (hi_ - qq) ** 2 * (qq - lo_) ** 2, 1.0)
        g = np.where(inside, (hi_ - lo_) ** 2 * (2.0 * qq - hi_ - lo_) / den, np.where(qq >= hi_, np.inf, -np.inf))
    return np.where(ok, g, 0.0)


def _ref_weights(q, lo, hi, prev):
    g = _ref_gradient(q, lo, hi)
    mag = np.abs(g)
    if prev is None:
        return 1.0 + mag, g
    with np.errstate(invalid="ignore"):
        return np.where((mag - np.abs(prev)) >= 0, 1.0 + mag, 1.0), g


def _ref_pinv(J, eps=geninv.DEFAULT_EPS, lam_max=geninv.DEFAULT_LAM_MAX):
    """Σ σ_i / (σ_i² + λ²) v_i u_iᵀ, term by term."""
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    lam2 = (1.0 - (S[-1] / eps) ** 2) * lam_max ** 2 if S[-1] < eps else 0.0
    out = np.zeros(J.shape[::-1])
    for s, u, v in zip(S, U.T, Vt):
        if s * s + lam2 > 0:
            out += s / (s * s + lam2) * np.outer(v, u)
    return out


def _ref_wln_pinv(J, q, lo, hi, prev):
    w, g = _ref_weights(q, lo, hi, prev)
    s = np.where(np.isfinite(w), 1.0 / np.sqrt(w), 0.0)
    return s[:, None] * _ref_pinv(J * s), g


def _ref_blocked(q, lo, hi):
    return "joint_limit" if np.any((q <= lo + 1e-9) | (q >= hi - 1e-9)) else "stalled"


def _ref_steer(kin, q0, T_target, inverse, nullspace_gain, max_iters, max_step_pos=0.02, max_step_rot=0.1,
               max_joint_step=0.1, tol_pos=1e-3, tol_rot=np.radians(0.5), stall_iters=15, lo=None, hi=None):
    """steer_to_pose's loop written plainly, on the batched FK and pose-error paths: (steps, status,
    iterations, position error, rotation error) and each iteration's errors."""
    lo = kin.lower if lo is None else lo
    hi = kin.upper if hi is None else hi
    q = np.clip(q0, lo, hi)
    steps, prev, history, errs = [], None, [], []
    for it in range(max_iters + 1):
        T, J = (a[0] for a in kin.fk_jacobian(np.stack([q, q])))
        e = pose_error(T[None], T_target[None])[0]
        ep, er = np.linalg.norm(e[:3]), np.linalg.norm(e[3:])
        errs.append((ep, er))
        if ep <= tol_pos and er <= tol_rot:
            return steps, "reached", it, ep, er, errs
        if it == max_iters:
            return steps, "max_iters", it, ep, er, errs
        history.append(ep / max_step_pos + er / max_step_rot)
        if len(history) > stall_iters and history[-1] >= history[-1 - stall_iters] * (1.0 - 1e-3):
            return steps, _ref_blocked(q, lo, hi), it, ep, er, errs
        scale = min(1.0, max_step_pos / ep if ep > 0 else np.inf, max_step_rot / er if er > 0 else np.inf)
        if inverse == "wln":
            Jp, prev = _ref_wln_pinv(J, q, lo, hi, prev)
        else:
            Jp = _ref_pinv(J)
        dq = Jp @ (e * scale)
        if nullspace_gain > 0.0:
            z = -nullspace_gain * np.clip(_ref_gradient(q, lo, hi), -1e6, 1e6)
            if np.max(np.abs(z)) > 0.5 * max_joint_step:
                z *= 0.5 * max_joint_step / np.max(np.abs(z))
            dq += z - Jp @ (J @ z)
        if np.max(np.abs(dq)) > max_joint_step:
            dq *= max_joint_step / np.max(np.abs(dq))
        q_new = np.clip(q + dq, lo, hi)
        if np.max(np.abs(q_new - q)) < 1e-12:
            return steps, _ref_blocked(q, lo, hi), it, ep, er, errs
        steps.append(q_new)
        q = q_new


def test_limit_terms_equal_the_plain_formulas():
    rng = np.random.default_rng(11)
    lo = np.array([-1.0, -2.0, 0.0, -0.5, -np.inf, 1.0, 0.3])
    hi = np.array([1.0, 0.5, 2.5, 3.0, np.inf, 1.0, 0.3 + 1e-9])     # unbounded, empty and tiny ranges
    Q = rng.uniform(lo.clip(-3, 3) - 0.2, hi.clip(-3, 3) + 0.2, size=(400, 7))
    Q[::3] = np.clip(Q[::3], lo, hi)                                    # many exactly at a limit
    fin = np.isfinite(lo) & np.isfinite(hi)
    Q[1::7, fin] = lo[fin] + rng.uniform(0.01, 0.99, size=(len(Q[1::7]), fin.sum())) * (hi - lo)[fin]  # all inside
    batched = joint_limit_gradient(Q, lo, hi)
    prev = None
    for k, q in enumerate(Q):
        ref = _ref_gradient(q, lo, hi)
        for g in (joint_limit_gradient(q, lo, hi), batched[k]):
            assert np.array_equal(np.isinf(g), np.isinf(ref)) and np.array_equal(np.sign(g), np.sign(ref))
            fin = np.isfinite(ref)
            assert np.allclose(g[fin], ref[fin], rtol=1e-12, atol=1e-12)
        for p in (prev, joint_limit_gradient(q, lo, hi)):               # Δ|∂H/∂θ| = 0 counts as "toward"
            w, g = wln_weights(q, lo, hi, p)
            w_ref, _ = _ref_weights(q, lo, hi, p if p is prev else _ref_gradient(q, lo, hi))
            assert np.array_equal(np.isinf(w), np.isinf(w_ref))
            assert np.allclose(w[np.isfinite(w)], w_ref[np.isfinite(w)], rtol=1e-12)
        prev = g


@pytest.mark.parametrize("shape", [(6, 7), (6, 10), (6, 5), (3, 7)])
def test_single_matrix_inverses_equal_the_plain_formulas(shape):
    """σ_min at 0, deep inside the damping band, at and around ε, and clear of it; λ_max = 0 too."""
    rng = np.random.default_rng(12)
    m, n = shape
    k = min(m, n)
    lo, hi = -np.ones(n), np.ones(n)
    for smin in (0.0, 1e-12, 1e-6, 0.02, 0.049999, 0.05, 0.050001, 0.3):
        U, _ = np.linalg.qr(rng.normal(size=(m, m)))
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        S = np.zeros((m, n))
        S[np.arange(k), np.arange(k)] = np.append(np.sort(rng.uniform(0.4, 2.0, k - 1))[::-1], smin)
        J = U @ S @ V.T
        for eps, lam_max in ((0.05, 0.05), (0.05, 0.01), (0.1, 0.0)):
            Jp = damped_svd_pinv(J, eps, lam_max)
            if lam_max > 0:
                assert np.allclose(Jp, _ref_pinv(J, eps, lam_max), rtol=0, atol=1e-10)
            assert np.allclose(Jp, damped_svd_pinv(J[None], eps, lam_max)[0], rtol=0, atol=1e-10 * max(1.0, np.abs(Jp).max()))
        q = rng.uniform(-1, 1, n)
        q[0] = 1.0                                                        # one joint at its limit (w = ∞)
        g_prev = joint_limit_gradient(q * 0.99, lo, hi)
        for prev in (None, g_prev):
            W, G = wln_pinv(J, q, lo, hi, prev)
            W_ref, G_ref = _ref_wln_pinv(J, q, lo, hi, prev)
            assert np.allclose(W, W_ref, rtol=0, atol=1e-10)
            Wb, _ = wln_pinv(J[None], q[None], lo, hi, None if prev is None else prev[None])
            assert np.allclose(W, Wb[0], rtol=0, atol=1e-10)


def _toy():
    return RobotModel.from_urdf_srdf(TOY_URDF, TOY_SRDF), "shuffled"


@pytest.mark.parametrize("arm", [("armar3", "left_arm_torso"), ("dual_arm", "left_arm"), ("dual_arm", "right_arm"),
                                 "toy"])
def test_steer_equals_the_plain_loop(arm):
    """Regression set: random, at-limit, near-singular and far starts/targets, rotation errors at and
    near π, with and without the null-space term, both inverses; steps agree to 1e-10, statuses exactly.
    The toy arm: a prismatic joint, oblique axes, an unbounded joint, 3 DoF (a 6×3 Jacobian)."""
    rng = np.random.default_rng(13)
    robot, group = _toy() if arm == "toy" else (RobotModel.preset(arm[0]), arm[1])
    kin = GroupKinematics(robot, group)
    lo, hi = kin.lower, kin.upper
    box_lo, box_hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)  # where to draw an unbounded joint's values
    Q = rng.uniform(box_lo, box_hi, size=(500, kin.n))
    near_singular = Q[np.argsort(np.linalg.svd(kin.jacobian(Q), compute_uv=False)[:, -1])[:8]]
    checked = {"reached": 0, "joint_limit": 0, "stalled": 0, "max_iters": 0}
    for kind in range(10):
        q0 = rng.uniform(box_lo, box_hi)
        if kind in (1, 8):                                # several joints at a limit
            q0 = np.where(rng.random(kin.n) < 0.4, np.where(rng.random(kin.n) < 0.5, box_lo, box_hi), q0)
        elif kind == 2:
            q0 = near_singular[0]
        T = kin.fk(np.clip(q0 + rng.normal(scale=0.6, size=kin.n), lo, hi))
        if kind == 3:                                     # out of reach
            T[:3, 3] += rng.normal(size=3)
        elif kind in (4, 5):                              # rotation error at / just below π
            axis = rng.normal(size=3)
            angle = np.pi if kind == 4 else np.pi - 1e-7
            T = kin.fk(q0)
            T[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix() @ T[:3, :3]
        elif kind == 6:
            T = kin.fk(near_singular[1 + int(rng.integers(7))])
        elif kind == 7:                                   # almost there
            T = kin.fk(q0)
            T[:3, 3] += 3e-4
        elif kind in (8, 9):                              # pushed against the limits: a target beyond them
            T = kin.fk(np.where(np.isfinite(lo), np.where(rng.random(kin.n) < 0.5, lo - 0.5, hi + 0.5), q0))
        for inverse in ("wln", "svd"):
            for gain in (0.0, 0.01):
                r = steer_to_pose(kin, q0, T, inverse=inverse, nullspace_gain=gain, max_iters=80)
                steps, status, it, ep, er, _ = _ref_steer(kin, q0, T, inverse, gain, max_iters=80)
                where = (arm, kind, inverse, gain)
                assert r.status == status, where
                assert r.iterations == it and len(r.steps) == len(steps), where
                if steps:
                    assert np.max(np.abs(r.steps - np.array(steps))) < 1e-10, where
                assert abs(r.pos_error - ep) < 1e-10 and abs(r.rot_error - er) < 1e-10, where
                checked[status] += 1
    assert checked["reached"] > 0 and checked["joint_limit"] + checked["stalled"] > 0, checked


def test_is_valid_cuts_the_plain_loop_at_its_first_rejection(armar3):
    """is_valid sees the steps in order; the branch ends before the first it rejects, with that
    iteration's errors, as if the loop had stopped there."""
    kin = GroupKinematics(armar3, "left_arm")
    q0 = kin.q_group(armar3.home)
    T = kin.fk(q0)
    T[:3, 3] += [0.12, -0.05, 0.08]
    steps, status, it, _, _, errs = _ref_steer(kin, q0, T, "wln", 0.0, max_iters=300)
    assert status == "reached" and len(steps) > 6
    seen = []
    r = steer_to_pose(kin, q0, T, is_valid=lambda q: seen.append(q.copy()) or len(seen) < 6)
    assert r.status == "invalid" and len(r.steps) == 5 and r.iterations == 5 and len(seen) == 6
    np.testing.assert_allclose(np.array(seen), np.array(steps[:6]), rtol=0, atol=1e-10)
    assert abs(r.pos_error - errs[5][0]) < 1e-10 and abs(r.rot_error - errs[5][1]) < 1e-10
    assert r.fk_end is None and not r.reached
