"""The GIRRT paper's closed-form ARMAR-III arm IK (eq. 3–14, misprints fixed): round trips against FK."""
from __future__ import annotations

import numpy as np
import pytest

from preset_generation import armar_ik
from preset_generation.dh_tables import ARMAR3_RIGHT, PI, dh_matrix
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel

LOWER = np.array([j.lower for j in ARMAR3_RIGHT.joints])
UPPER = np.array([j.upper for j in ARMAR3_RIGHT.joints])


@pytest.mark.parametrize("side", ["right", "left"])
def test_round_trip_recovers_the_configuration(side):
    """FK → (pose, swivel) → IK returns the original q among its solutions; 1000 random in-limit q."""
    rng = np.random.default_rng(0)
    Q = rng.uniform(LOWER, UPPER, size=(1000, 7))
    recovered = 0
    for q in Q:
        T = armar_ik.arm_fk(q, side)
        sols = armar_ik.solve(T, armar_ik.swivel_angle(q, side), side)
        assert len(sols) >= 1
        for s in sols:                                  # every returned solution is valid
            assert np.max(np.abs(armar_ik.arm_fk(s, side) - T)) < 1e-7
            assert np.all(s >= LOWER) and np.all(s <= UPPER)
        recovered += bool(np.min(np.max(np.abs(sols - q), axis=1)) < 1e-6)
    assert recovered == len(Q)


def test_all_eight_branches_without_limits():
    """eq. 6 (±), the elbow-frame sign of eq. 3 (±) and eq. 12's two wrist branches: 8 FK-exact solutions."""
    rng = np.random.default_rng(1)
    for q in rng.uniform(LOWER, UPPER, size=(50, 7)):
        T = armar_ik.arm_fk(q)
        sols = armar_ik.solve(T, armar_ik.swivel_angle(q), within_limits=False)
        assert len(sols) == 8
        assert max(np.max(np.abs(armar_ik.arm_fk(s) - T)) for s in sols) < 1e-7


def test_sweep_and_unreachable():
    rng = np.random.default_rng(2)
    q = rng.uniform(LOWER, UPPER)
    T = armar_ik.arm_fk(q)
    sols = armar_ik.solve_sweep(T, n_swivel=36)
    assert len(sols) > 0
    assert all(np.max(np.abs(armar_ik.arm_fk(s) - T)) < 1e-7 for s in sols)
    far = T.copy()
    far[:3, 3] = [2.0, 0.0, 0.0]
    assert armar_ik.solve(far, 0.0).shape == (0, 7)
    assert armar_ik.solve_sweep(far, n_swivel=8).shape == (0, 7)
    with pytest.raises(ValueError):
        armar_ik.solve(T, 0.0, side="middle")


def test_matches_the_preset_urdf_in_the_root_frame():
    """IK of a root-frame TCP pose via Sigma_0 = torso_link · joint-1 origin, checked with GroupKinematics."""
    robot = RobotModel.preset("armar3")
    rng = np.random.default_rng(3)
    for side in ("left", "right"):
        kin = GroupKinematics(robot, f"{side}_arm")
        first = robot.joints[f"{side}_shoulder_1_joint"]
        for _ in range(50):
            q_full = robot.home.copy()
            q_full[:3] = rng.uniform(-0.5, 0.5, 3)              # torso anywhere
            q = rng.uniform(kin.lower, kin.upper)
            T_root = kin.with_reference(q_full).fk(q)
            sigma0 = robot.link_poses(q_full, [first.parent])[0] @ first.origin
            T_local = np.linalg.solve(sigma0, T_root)
            sols = armar_ik.solve(T_local, armar_ik.swivel_angle(q, side), side)
            assert np.min(np.max(np.abs(sols - q), axis=1)) < 1e-6


def test_printed_eq1_is_not_a_rotation_but_the_fixed_one_is():
    """The misprint of eq. 1, element (2,3): '+s_α c_θ' breaks orthogonality; '−s_α c_θ' is a rotation."""
    th, al = 0.7, -PI / 2 + 0.3
    A = dh_matrix(th, 0.1, 0.2, al)
    assert np.allclose(A[:3, :3] @ A[:3, :3].T, np.eye(3), atol=1e-15)
    printed = A.copy()
    printed[1, 2] = np.sin(al) * np.cos(th)
    assert not np.allclose(printed[:3, :3] @ printed[:3, :3].T, np.eye(3), atol=1e-3)


def test_swivel_zero_is_the_lowest_elbow():
    """Swivel 0 puts the elbow toward Sigma_0's +x (down when the torso is upright)."""
    rng = np.random.default_rng(4)
    for q in rng.uniform(LOWER, UPPER, size=(30, 7)):
        T = armar_ik.arm_fk(q)
        heights = []
        for phi in (0.0, 1.0, -1.0, 2.5):
            sols = armar_ik.solve(T, phi, within_limits=False)
            if len(sols) == 0:
                break
            s = sols[0]
            E = np.eye(4)
            for i, j in enumerate(ARMAR3_RIGHT.joints[:4]):
                E = E @ dh_matrix(j.offset + s[i], j.d, j.a, j.alpha)
            heights.append(E[0, 3])                        # elbow's Sigma_0 x = "down"
        if len(heights) == 4:
            assert heights[0] >= max(heights[1:]) - 1e-12
