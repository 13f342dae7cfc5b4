"""Batched multi-start IK (ik.solver) on ARMAR-III's right arm: reachable poses are reached within
tolerance and inside the limits, unreachable ones are reported with their error."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.ik.solver import solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_distance

TOL_POS, TOL_ROT = 0.002, 0.0174
SEEDS = 8


@pytest.fixture(scope="module")
def kin() -> GroupKinematics:
    return GroupKinematics(RobotModel.preset("armar3"), "right_arm")


def multistart(kin: GroupKinematics, targets: np.ndarray, rng: np.random.Generator):
    """SEEDS random starts per target, solved in one batch; (q, ok, err) shaped (targets, SEEDS, ...)."""
    k, n = len(targets), kin.n
    seeds = rng.uniform(kin.lower, kin.upper, (k * SEEDS, n))
    T = np.repeat(targets, SEEDS, axis=0)
    q, ok, err = solve_ik_batch(kin, T, seeds, kin.lower, kin.upper, tol_pos=TOL_POS, tol_rot=TOL_ROT)
    return q.reshape(k, SEEDS, n), ok.reshape(k, SEEDS), err.reshape(k, SEEDS, 2)


def test_reachable_poses_are_reached_within_tolerance_and_limits(kin):
    rng = np.random.default_rng(0)
    targets = kin.fk(rng.uniform(kin.lower, kin.upper, (12, kin.n)))  # reachable by construction
    q, ok, err = multistart(kin, targets, rng)
    assert ok.any(axis=1).all()  # every pose reached from at least one start
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)
    for i, j in zip(*np.nonzero(ok)):
        dp, dr = pose_distance(kin.fk(q[i, j]), targets[i])  # independent of the reported error
        assert dp <= TOL_POS + 1e-12 and dr <= TOL_ROT + 1e-12
        assert err[i, j, 0] == pytest.approx(dp, abs=1e-9)
    assert np.all(err[~ok].max(axis=1) > 0)  # a failure is a failure for a reason


def test_unreachable_poses_are_reported(kin):
    rng = np.random.default_rng(1)
    far = kin.fk(rng.uniform(kin.lower, kin.upper, (3, kin.n)))
    far[:, :3, 3] += [3.0, 0.0, 0.0]  # 3 m beyond any reach
    q, ok, err = multistart(kin, far, rng)
    assert not ok.any()
    assert np.all(err[..., 0] > 1.0)  # the arm is under 1 m long
    assert np.all(q >= kin.lower) and np.all(q <= kin.upper)


def test_a_converged_seed_is_returned_unchanged_and_batch_order_is_kept(kin):
    rng = np.random.default_rng(2)
    q0 = rng.uniform(kin.lower, kin.upper, (4, kin.n))
    T = kin.fk(q0)
    q, ok, err = solve_ik_batch(kin, T, q0, kin.lower, kin.upper)
    assert ok.all()
    np.testing.assert_array_equal(q, q0)  # already there: no step taken
    np.testing.assert_allclose(err, 0.0, atol=1e-9)
    # targets swapped: each problem keeps its own seed and target
    q2, ok2, _ = solve_ik_batch(kin, T[::-1], q0, kin.lower, kin.upper)
    for i in range(4):
        if ok2[i]:
            dp, dr = pose_distance(kin.fk(q2[i]), T[::-1][i])
            assert dp <= TOL_POS and dr <= TOL_ROT


def test_seeds_outside_the_limits_are_clipped_first(kin):
    rng = np.random.default_rng(3)
    target = kin.fk(rng.uniform(kin.lower, kin.upper, (1, kin.n)))
    seed = (kin.upper + 1.0)[None]
    q, _, _ = solve_ik_batch(kin, target, seed, kin.lower, kin.upper, iterations=0)
    np.testing.assert_array_equal(q[0], kin.upper)


def test_stall_gives_up_a_start_that_stopped_converging_and_keeps_those_that_converge(kin):
    from humanoid_planner.core.ik.solver import STALL_ITERATIONS

    rng = np.random.default_rng(4)
    far = kin.fk(rng.uniform(kin.lower, kin.upper, (1, kin.n)))
    far[:, :3, 3] += [3.0, 0.0, 0.0]
    seed = rng.uniform(kin.lower, kin.upper, (1, kin.n))
    q, ok, _ = solve_ik_batch(kin, far, seed, kin.lower, kin.upper, stall=STALL_ITERATIONS)
    assert not ok[0]
    ran = [j for j in range(121) if np.array_equal(solve_ik_batch(kin, far, seed, kin.lower, kin.upper,
                                                                  iterations=j)[0], q)]
    assert ran and ran[0] < 120  # the same configuration as after fewer iterations: it stopped there
    # starts near a solution converge steadily: the same answers with and without the rule
    q0 = rng.uniform(kin.lower, kin.upper, (20, kin.n))
    T = kin.fk(q0)
    seeds = np.clip(q0 + rng.normal(0.0, 0.3, q0.shape), kin.lower, kin.upper)
    a = solve_ik_batch(kin, T, seeds, kin.lower, kin.upper, stall=STALL_ITERATIONS)
    b = solve_ik_batch(kin, T, seeds, kin.lower, kin.upper)
    assert b[1].sum() >= 18 and np.array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[0][a[1]], b[0][b[1]])
