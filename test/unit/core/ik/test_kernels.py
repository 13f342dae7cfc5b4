"""The compiled IK (ik/kernels.py) against the numpy engine it replaces in the IK loop: the TCP pose and
Jacobian of GroupKinematics (a prismatic joint, oblique axes, a shuffled group), transforms.pose_error
(also near a half turn), and solve_ik_batch against the numpy damped-least-squares iteration."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.ik import kernels
from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.ik.solver import solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_error
from ..model.test_kinematics import TOY_SRDF, TOY_URDF


@pytest.fixture(scope="module", params=["toy", "armar3"])
def kin(request) -> GroupKinematics:
    if request.param == "toy":
        return GroupKinematics(RobotModel.from_urdf_srdf(TOY_URDF, TOY_SRDF), "shuffled")
    return GroupKinematics(RobotModel.preset("armar3"), "left_arm_torso")


def test_pose_and_jacobian_match_group_kinematics(kin):
    rng = np.random.default_rng(0)
    cols, parents, prismatic, basis, Ktip = kin.chain_arrays
    W, T, J = np.empty((len(cols), 3, 4)), np.empty((4, 4)), np.empty((6, kin.n))
    for q in rng.uniform(kin.lower, kin.upper, (20, kin.n)):
        kernels.chain_pose_jacobian(q, cols, parents, prismatic, basis, Ktip, W, T, J)
        T_ref, J_ref = kin.fk_jacobian(q)
        np.testing.assert_allclose(T, T_ref, atol=1e-12)
        np.testing.assert_allclose(J, J_ref, atol=1e-12)


def test_pose_error_matches_numpy_also_near_a_half_turn():
    rng = np.random.default_rng(1)
    e = np.empty(6)
    A = np.eye(4)
    for k in range(200):
        B = np.eye(4)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = np.pi - 10.0 ** -rng.uniform(0, 9) if k % 2 else rng.uniform(0, np.pi)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        B[:3, :3] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
        B[:3, 3] = rng.normal(size=3)
        A[:3, 3] = rng.normal(size=3)
        kernels.pose_error(A, B, e)
        np.testing.assert_allclose(e, pose_error(A, B), atol=1e-9)


def _numpy_dls(kin, T_targets, seeds, lower, upper, tol_pos, tol_rot, iterations, damping=0.05, max_step=0.4):
    """The damped-least-squares iteration in numpy, all seeds a step at a time (the reference)."""
    q = np.clip(np.array(seeds, dtype=float), lower, upper)
    active = np.ones(len(q), dtype=bool)
    for _ in range(iterations):
        idx = np.nonzero(active)[0]
        if len(idx) == 0:
            break
        T, J = kin.fk_jacobian(q[idx])
        e = pose_error(T, T_targets[idx])
        done = (np.linalg.norm(e[:, :3], axis=1) <= tol_pos) & (np.linalg.norm(e[:, 3:], axis=1) <= tol_rot)
        active[idx[done]] = False
        idx, J, e = idx[~done], J[~done], e[~done]
        if not len(idx):
            break
        JJt = J @ np.swapaxes(J, 1, 2) + damping ** 2 * np.eye(6)
        dq = (np.swapaxes(J, 1, 2) @ np.linalg.solve(JJt, e[:, :, None]))[:, :, 0]
        scale = np.minimum(1.0, max_step / np.maximum(np.max(np.abs(dq), axis=1), 1e-12))
        q[idx] = np.clip(q[idx] + dq * scale[:, None], lower, upper)
    e = pose_error(kin.fk(q), T_targets)
    err = np.stack([np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)], axis=1)
    return q, (err[:, 0] <= tol_pos) & (err[:, 1] <= tol_rot), err


def test_solve_ik_batch_follows_the_numpy_iteration(kin):
    """Same starts, same steps: the iterates agree to rounding over a few iterations, and over the full
    run the verdicts (and the solutions of the seeds both call converged) agree."""
    rng = np.random.default_rng(2)
    S = 60
    T = kin.fk(rng.uniform(kin.lower, kin.upper, (S, kin.n)))
    seeds = rng.uniform(kin.lower, kin.upper, (S, kin.n))
    for its in (0, 1, 5):
        q, ok, err = solve_ik_batch(kin, T, seeds, kin.lower, kin.upper, iterations=its)
        q_ref, ok_ref, err_ref = _numpy_dls(kin, T, seeds, kin.lower, kin.upper, 0.002, 0.0174, its)
        np.testing.assert_allclose(q, q_ref, atol=1e-8)
        np.testing.assert_allclose(err, err_ref, atol=1e-8)
    q, ok, err = solve_ik_batch(kin, T, seeds, kin.lower, kin.upper)
    q_ref, ok_ref, _ = _numpy_dls(kin, T, seeds, kin.lower, kin.upper, 0.002, 0.0174, 120)
    assert ok.sum() >= 0.9 * ok_ref.sum() and ok.sum() > S // 3
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    for s in np.nonzero(ok)[0]:
        e = pose_error(kin.fk(q[s]), T[s])
        assert np.linalg.norm(e[:3]) <= 0.002 + 1e-12 and np.linalg.norm(e[3:]) <= 0.0174 + 1e-12


def test_bad_shapes_are_refused(kin):
    with pytest.raises(ValueError, match="targets"):
        solve_ik_batch(kin, np.eye(4)[None].repeat(2, 0), np.zeros((3, kin.n)), kin.lower, kin.upper)


def test_read_only_inputs_take_the_compiled_signature(kin):
    """A read-only array (a broadcast view, a frozen problem's limits) would be another numba type: a
    second compilation, seconds, on a plan's first steer. The wrappers hand the kernels writeable copies."""
    q0 = np.clip(np.zeros(kin.n), kin.lower, kin.upper)
    T = kin.fk(np.clip(q0 + 0.2, kin.lower, kin.upper))
    ref = steer_to_pose(kin, q0, T)
    before = len(kernels.steer.signatures)
    frozen = [a.copy() for a in (q0, T, kin.lower, kin.upper)]
    for a in frozen:
        a.setflags(write=False)
    r = steer_to_pose(kin, frozen[0], frozen[1], lower=frozen[2], upper=frozen[3])
    assert len(kernels.steer.signatures) == before
    assert r.status == ref.status and np.array_equal(r.steps, ref.steps)
