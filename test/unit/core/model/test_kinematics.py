"""GroupKinematics: FK equals the URDF tree walk, the Jacobian equals finite differences, batching."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.presets import PRESET_NAMES
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_error

ROBOTS = {name: RobotModel.preset(name) for name in PRESET_NAMES}
CHAIN_GROUPS = [(name, g) for name, r in ROBOTS.items() for g, pg in r.groups.items() if pg.joint_names]


def fd_jacobian(kin: GroupKinematics, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of the pose (position, rotation vector in the root frame)."""
    J = np.zeros((6, kin.n))
    for i in range(kin.n):
        dq = np.zeros(kin.n)
        dq[i] = h
        J[:, i] = pose_error(kin.fk(q - dq), kin.fk(q + dq)) / (2 * h)
    return J


@pytest.mark.parametrize("name,group", CHAIN_GROUPS)
def test_fk_matches_robot_model_tree_walk(name, group):
    robot = ROBOTS[name]
    rng = np.random.default_rng(1)
    q_ref = rng.uniform(robot.lower, robot.upper)          # held joints away from home too
    kin = GroupKinematics(robot, group, q_ref)
    Q = rng.uniform(kin.lower, kin.upper, size=(300, kin.n))
    T = kin.fk(Q)
    ref = robot.link_poses(robot.expand(group, Q, q_ref), [kin.tip_link])[:, 0]
    assert np.max(np.abs(T - ref)) < 1e-12
    T1, J1 = kin.fk_jacobian(Q[17])
    TN, JN = kin.fk_jacobian(Q)
    assert np.max(np.abs(T1 - TN[17])) < 1e-13 and np.max(np.abs(J1 - JN[17])) < 1e-13
    assert np.max(np.abs(kin.fk(Q[17]) - T1)) < 1e-13


@pytest.mark.parametrize("name,group", CHAIN_GROUPS)
def test_jacobian_equals_finite_differences(name, group):
    robot = ROBOTS[name]
    kin = GroupKinematics(robot, group)
    rng = np.random.default_rng(2)
    for q in rng.uniform(kin.lower, kin.upper, size=(20, kin.n)):
        assert np.max(np.abs(kin.jacobian(q) - fd_jacobian(kin, q))) < 1e-7


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=10, max_size=10), st.sampled_from(["left_arm_torso", "right_arm_torso"]))
def test_jacobian_property_armar3_10dof(u, group):
    kin = GroupKinematics(ROBOTS["armar3"], group)
    q = kin.lower + (np.asarray(u) + 1.0) / 2.0 * (kin.upper - kin.lower)
    T, J = kin.fk_jacobian(q)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.max(np.abs(J - fd_jacobian(kin, q))) < 1e-7


def test_shapes_and_errors():
    kin = GroupKinematics(ROBOTS["armar3"], "left_arm_torso")
    q = kin.q_group(ROBOTS["armar3"].home)
    assert q.shape == (10,)
    T, J = kin.fk_jacobian(q)
    assert T.shape == (4, 4) and J.shape == (6, 10)
    T, J = kin.fk_jacobian(q[None])
    assert T.shape == (1, 4, 4) and J.shape == (1, 6, 10)
    T, J = kin.fk_jacobian(np.repeat(q[None], 5, axis=0))
    assert T.shape == (5, 4, 4) and J.shape == (5, 6, 10)
    assert kin.fk(np.zeros((0, 10))).shape == (0, 4, 4)
    with pytest.raises(ValueError):
        kin.fk(np.zeros(7))
    with pytest.raises(ValueError):
        kin.fk(np.zeros((2, 3, 10)))
    with pytest.raises(ValueError):
        GroupKinematics(ROBOTS["armar3"], "left_arm", q_ref=np.zeros(3))
    with pytest.raises(KeyError):
        GroupKinematics(ROBOTS["armar3"], "no_such_group")
    with pytest.raises(ValueError):  # an end-effector group has no joints
        GroupKinematics(ROBOTS["armar3"], "left_hand_links")


def test_reference_configuration_moves_the_arm_base():
    robot = ROBOTS["armar3"]
    arm = GroupKinematics(robot, "left_arm")
    q_ref = robot.home.copy()
    q_ref[:3] = [0.3, -0.2, 0.1]                           # torso yawed, pitched, rolled
    moved = arm.with_reference(q_ref)
    q = arm.q_group(robot.home)
    full = GroupKinematics(robot, "left_arm_torso")
    assert np.allclose(moved.fk(q), full.fk(full.q_group(q_ref)), atol=1e-12)
    assert not np.allclose(arm.fk(q), moved.fk(q))
    assert moved.joint_names == arm.joint_names and np.array_equal(moved.q_ref, q_ref)


def test_from_chain_equals_group():
    robot = ROBOTS["armar3"]
    g = GroupKinematics(robot, "right_arm_torso")
    c = GroupKinematics.from_chain(robot, "base_link", "right_tcp")
    assert c.joint_names == g.joint_names
    q = np.random.default_rng(4).uniform(g.lower, g.upper, size=(50, g.n))
    assert np.allclose(c.fk(q), g.fk(q), atol=1e-14)
    with pytest.raises(ValueError):
        GroupKinematics.from_chain(robot, "left_tcp", "left_tcp")


# A small robot with everything a user's URDF may contain: a prismatic joint, non-z axes (also
# negative and oblique), fixed joints between movers, and a group whose joints are listed out of order.
TOY_URDF = """<?xml version="1.0"?>
<robot name="toy">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="tip"/>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="l1"/>
    <origin xyz="0.1 0 0.5" rpy="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="0" upper="0.4" effort="1" velocity="0.2"/></joint>
  <joint name="j1" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.2 0.1" rpy="0.2 -0.4 0.1"/><axis xyz="0 -1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="fix" type="fixed"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0" rpy="0 0.5 0"/></joint>
  <joint name="j2" type="continuous"><parent link="l3"/><child link="l4"/>
    <origin xyz="0 0 0.25" rpy="0 0 0"/><axis xyz="0.6 0 0.8"/></joint>
  <joint name="tool" type="fixed"><parent link="l4"/><child link="tip"/><origin xyz="0.05 0.02 0.1" rpy="0.1 0.2 0.3"/></joint>
</robot>
"""
TOY_SRDF = """<?xml version="1.0"?>
<robot name="toy">
  <group name="shuffled"><joint name="j2"/><joint name="lift"/><joint name="j1"/><joint name="tool"/></group>
</robot>
"""


def test_prismatic_oblique_axes_and_group_order():
    robot = RobotModel.from_urdf_srdf(TOY_URDF, TOY_SRDF)
    kin = GroupKinematics(robot, "shuffled")
    assert kin.joint_names == ("j2", "lift", "j1") and kin.tip_link == "tip"
    rng = np.random.default_rng(5)
    Q = rng.uniform(kin.lower, kin.upper, size=(100, 3))
    ref = robot.link_poses(robot.expand("shuffled", Q, robot.home), ["tip"])[:, 0]
    assert np.max(np.abs(kin.fk(Q) - ref)) < 1e-13
    T, J = kin.fk_jacobian(Q)
    for k in range(5):
        assert np.allclose(kin.fk(Q[k]), ref[k], atol=1e-13)
        Jfd = fd_jacobian(kin, Q[k])
        assert np.max(np.abs(J[k] - Jfd)) < 1e-7
        assert np.allclose(kin.jacobian(Q[k]), J[k], atol=1e-13)
    # the prismatic column: pure translation along its axis (world frame), no rotation
    lift = kin.joint_names.index("lift")
    assert np.allclose(J[:, 3:, lift], 0.0)
    assert np.allclose(np.linalg.norm(J[:, :3, lift], axis=1), 1.0)


def test_batched_is_faster_per_configuration():
    """The point of batching (figures in benchmarks/bench_kinematics.py); loose bound for shared CI."""
    import time

    kin = GroupKinematics(ROBOTS["armar3"], "left_arm_torso")
    Q = np.random.default_rng(6).uniform(kin.lower, kin.upper, size=(1000, kin.n))
    kin.fk_jacobian(Q)
    t0 = time.perf_counter()
    for _ in range(5):
        kin.fk_jacobian(Q)
    batched = (time.perf_counter() - t0) / 5000
    t0 = time.perf_counter()
    for q in Q[:300]:
        kin.fk_jacobian(q)
    single = (time.perf_counter() - t0) / 300
    assert single / batched > 4.0, (single, batched)
