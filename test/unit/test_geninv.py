"""Generalized inverses (seed 000 eq. 26–28, seed 001 eq. 9–12) and steer_to_pose."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanoid_planner.core import geninv
from humanoid_planner.core.geninv import (SteerResult, damped_svd_pinv, joint_limit_cost, joint_limit_gradient,
                                          steer_to_pose, wln_pinv, wln_weights)
from humanoid_planner.core.kinematics import GroupKinematics
from humanoid_planner.core.robot_model import RobotModel
from humanoid_planner.core.transforms import pose_distance

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


# ----------------------------------------------------------------------------- seed 001, section 4
# (x, y, z [mm], φ, θ, ψ [rad]) of the TCPs, printed in the paper; frame = Simox ARMAR-III root.
SEED001_POSES = {
    "left_initial": ("left", [-729.387, 150.811, 1296.943, 1.669, 0.992, -2.542]),
    "right_initial": ("right", [390.833, 138.736, 1320.031, -1.214, 1.048, 0.587]),
    "left_target": ("left", [-204.765, 516.069, 1302.585, -0.150, -0.952, -2.499]),
    "right_target": ("right", [207.720, 416.536, 1146.943, -1.874, 0.587, 0.317]),
}


def seed001_pose(p: list[float], convention: str = "rpy") -> np.ndarray:
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
@pytest.mark.parametrize("pose", list(SEED001_POSES))
def test_seed001_example_poses_reached_from_home(pose, inverse):
    robot = RobotModel.preset("dual_arm")
    side, p = SEED001_POSES[pose]
    kin = GroupKinematics(robot, f"{side}_arm")
    q0 = kin.q_group(robot.home)
    T = seed001_pose(p, "rpy")
    r = steer_to_pose(kin, q0, T, inverse=inverse, tol_pos=2e-4, tol_rot=np.radians(0.05))
    assert r.reached, (r.status, r.pos_error, np.degrees(r.rot_error))
    q = r.last(q0)
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    dp, dr = pose_distance(kin.fk(q), T)
    assert dp < 1e-3 and np.degrees(dr) < 0.5


def test_seed001_poses_zyz_reading_also_reachable_with_wln():
    """The paper's stated ZYZ reading is reachable too (WLN), so reachability cannot pick the convention."""
    robot = RobotModel.preset("dual_arm")
    for side, p in SEED001_POSES.values():
        kin = GroupKinematics(robot, f"{side}_arm")
        r = steer_to_pose(kin, kin.q_group(robot.home), seed001_pose(p, "zyz"), inverse="wln")
        assert r.reached, (side, p, r.status)


def test_module_constants_documented():
    assert geninv.DEFAULT_EPS > 0 and geninv.DEFAULT_LAM_MAX > 0


def test_nullspace_joint_limit_term_keeps_the_task_and_helps_svd():
    """Seed 000 eq. 24 as an option: with it the SVD loop also reaches the ZYZ reading of R-initial."""
    robot = RobotModel.preset("dual_arm")
    kin = GroupKinematics(robot, "right_arm")
    q0 = kin.q_group(robot.home)
    T = seed001_pose(SEED001_POSES["right_initial"][1], "zyz")
    assert steer_to_pose(kin, q0, T, inverse="svd", nullspace_gain=0.01).reached
    # the projected term alone does not move the TCP (first order): (I - J⁺J) z is in the null space
    _, J = kin.fk_jacobian(q0)
    Jp = damped_svd_pinv(J)
    z = np.random.default_rng(9).normal(size=kin.n)
    assert np.allclose(J @ (z - Jp @ (J @ z)), 0.0, atol=1e-10)
