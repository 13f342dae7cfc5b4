"""Straight TCP lines (approach, retreat): on the line within 2 mm / 1 deg, inside the joint limits,
checked by core.verification's generic FK."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.cartesian import (END_TOL_POS, LINE_STEP, LINE_TOL_POS, LINE_TOL_ROT,
                                                      SEGMENT_SAMPLES, STEER_TOL_POS, STEER_TOL_ROT, WAYPOINT_ITERS,
                                                      WAYPOINT_STEP_ROT, GripperTranslation, line_deviation,
                                                      parallel_lines, straight_line)
from humanoid_planner.core.transforms import rotation_vector
from humanoid_planner.core.verification import verify_straight

from ..ik.test_geninv import _ref_steer
from ..model.test_kinematics import TOY_SRDF, TOY_URDF


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


def test_straight_line_keeps_to_the_line_within_the_limits(armar3):
    r = armar3
    kin = GroupKinematics(r, "left_arm", r.home)
    idx = r.group_joint_indices("left_arm")
    lo, hi = r.lower[idx], r.upper[idx]
    q0 = r.home[idx]
    d = np.array([0.3, 0.2, 1.0])
    line = straight_line(kin, q0, d, 0.10, lo, hi)
    assert line.reason == "complete" and line.distance == pytest.approx(0.10)
    assert np.all(line.waypoints >= lo) and np.all(line.waypoints <= hi)
    assert verify_straight(r, ("left_arm",), r.home, np.vstack([q0, line.waypoints]), d, min_distance=0.10) == []
    # far beyond the arm's reach the line stops where the arm gives out, still on the line
    far = straight_line(kin, q0, d, 2.0, lo, hi)
    assert far.reason in ("ik", "deviation") and 0.05 < far.distance < 2.0
    assert verify_straight(r, ("left_arm",), r.home, np.vstack([q0, far.waypoints]), d) == []


def test_parallel_lines_move_both_tcps_by_the_same_displacement(armar3):
    r = armar3
    groups = ("left_arm", "right_arm")
    kins = [GroupKinematics(r, g, r.home) for g in groups]
    idx = [r.group_joint_indices(g) for g in groups]
    line = parallel_lines(kins, [r.home[i] for i in idx], (0, 0, 1), 0.08, [(r.lower[i], r.upper[i]) for i in idx])
    assert line.reason == "complete" and line.distance == pytest.approx(0.08)
    path = np.vstack([np.concatenate([r.home[i] for i in idx]), line.waypoints])
    assert verify_straight(r, groups, r.home, path, (0, 0, 1), min_distance=0.08) == []


def test_translation_problems_are_named():
    assert GripperTranslation((0, 0, 1), 0.1, 0.05).problem() is None
    assert "direction" in GripperTranslation((0, 0, 0), 0.1).problem()
    assert "finite" in GripperTranslation((0, 0, 1), float("nan")).problem()
    assert "min_distance" in GripperTranslation((0, 0, 1), 0.1, 0.2).problem()


# ----------------------------------------------------------------------------- the compiled line vs numpy
def _ref_deviation(kin, q_path, T0, d, samples=SEGMENT_SAMPLES):
    """line_deviation in numpy: the batched FK and rotation vectors of R0ᵀ R."""
    f = np.arange(1, samples + 1) / samples
    a, b = q_path[:-1], q_path[1:]
    T = kin.fk((a[:, None, :] + f[None, :, None] * (b - a)[:, None, :]).reshape(-1, q_path.shape[1]))
    rel = T[:, :3, 3] - T0[:3, 3]
    along = rel @ d
    off = np.linalg.norm(rel - along[:, None] * d, axis=1)
    ang = np.linalg.norm(rotation_vector(np.einsum("ji,njk->nik", T0[:3, :3], T[:, :3, :3])), axis=1)
    return tuple(x.reshape(len(a), samples).max(1) for x in (off, ang, along))


def _ref_line(kin, q0, d, distance, lo, hi, inverse, step=LINE_STEP, tol_pos=LINE_TOL_POS, tol_rot=LINE_TOL_ROT):
    """straight_line without validate, each waypoint steered by the plain loop (FK recomputed at every start)."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    T0 = kin.fk(q0)
    k = max(1, int(np.ceil(distance / step - 1e-9)))
    out, q, reason = [], q0, "complete"
    for j, si in enumerate(distance * np.arange(1, k + 1) / k):
        T = T0.copy()
        T[:3, 3] += si * d
        steps, status, *_ = _ref_steer(kin, q, T, inverse, 0.0, max_iters=WAYPOINT_ITERS, max_step_pos=step,
                                       max_step_rot=WAYPOINT_STEP_ROT, tol_pos=END_TOL_POS if j == k - 1 else STEER_TOL_POS,
                                       tol_rot=STEER_TOL_ROT, lo=lo, hi=hi)
        if status != "reached":
            reason = "ik"
            break
        q = steps[-1] if steps else q
        out.append(q)
    W = np.array(out).reshape(-1, len(q0))
    if len(W):
        off, ang, _ = _ref_deviation(kin, np.vstack([q0, W]), T0, d)
        bad = np.nonzero((off > tol_pos) | (ang > tol_rot))[0]
        if len(bad):
            W, reason = W[:bad[0]], "deviation"
    return W, reason


@pytest.mark.parametrize("arm", ["armar3", "toy"])
def test_compiled_line_equals_the_plain_loop(armar3, arm):
    """Free, out-of-reach, near-singular (arm stretched) and joint-limited lines (limits tightened around
    the start), both inverses: the same waypoints to 1e-10 and the same reason; the toy arm has a prismatic
    joint, oblique axes and 3 DoF."""

    if arm == "toy":
        kin = GroupKinematics(RobotModel.from_urdf_srdf(TOY_URDF, TOY_SRDF), "shuffled")
        q_home = np.array([0.3, 0.2, 0.4])
    else:
        kin = GroupKinematics(armar3, "left_arm", armar3.home)
        q_home = kin.q_group(armar3.home)
    rng = np.random.default_rng(21)
    lo_all, hi_all = kin.lower, kin.upper
    reasons = set()
    for case in range(12):
        q0, lo, hi = q_home + rng.normal(scale=0.3, size=kin.n), lo_all, hi_all
        if case % 4 == 1:  # a joint's range ends just past the start
            j = int(rng.integers(kin.n))
            lo, hi = lo_all.copy(), hi_all.copy()
            lo[j], hi[j] = q0[j] - 0.01, q0[j] + 0.01
        elif case % 4 == 2 and arm == "armar3":  # elbow almost straight: near a singularity
            q0[3] = 0.02
        q0 = np.clip(q0, np.maximum(lo, -np.pi), np.minimum(hi, np.pi))
        d = rng.normal(size=3)
        if arm == "toy" and case % 2 == 0:  # along the prismatic joint's axis: the only way its TCP keeps orientation
            d = np.array([0.0, 0.0, rng.choice([-1.0, 1.0])])
        distance = 0.6 if case % 4 == 3 else 0.1  # 0.6 m: beyond what the arm can follow
        for inverse in ("wln", "svd"):
            line = straight_line(kin, q0, d, distance, lo, hi, inverse=inverse)
            W, reason = _ref_line(kin, q0, d, distance, lo, hi, inverse)
            assert line.reason == reason and line.waypoints.shape == W.shape, (case, inverse)
            if len(W):
                assert np.max(np.abs(line.waypoints - W)) < 1e-10, (case, inverse)
            reasons.add(reason)
    assert {"complete", "ik"} <= reasons, reasons


def test_compiled_deviation_equals_numpy(armar3):
    kin = GroupKinematics(armar3, "left_arm_torso", armar3.home)
    rng = np.random.default_rng(22)
    q_path = np.cumsum(rng.normal(scale=0.1, size=(6, kin.n)), axis=0) + kin.q_group(armar3.home)
    T0 = kin.fk(q_path[0])
    d = rng.normal(size=3)
    for got, ref in zip(line_deviation(kin, q_path, T0, d), _ref_deviation(kin, q_path, T0, d / np.linalg.norm(d))):
        assert got.shape == (5,)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert all(len(x) == 0 for x in line_deviation(kin, q_path[:1], T0, d))
