"""Real humanoids nobody on the team wrote (example-robot-data): TALOS and Unitree G1, meshes included.

RobotModel loads URDF (+ SRDF) with collision meshes; GroupKinematics on their arm chains is checked
against yourdfpy's own forward kinematics (an independent implementation) and finite differences,
and steer_to_pose reaches poses with them.  Skipped when example-robot-data is not installed.
"""
from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest

from humanoid_planner.core.ik.geninv import steer_to_pose
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel

from .test_kinematics import fd_jacobian


def _robots_dir() -> Path:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    root = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not root.is_dir():
        pytest.skip(f"example-robot-data robots not found at {root}")
    return root


@pytest.fixture(scope="module")
def talos():
    R = _robots_dir()
    urdf = R / "talos_data" / "robots" / "talos_reduced.urdf"   # Apache-2.0, PAL Robotics
    return RobotModel.from_urdf_srdf(urdf, R / "talos_data" / "srdf" / "talos.srdf"), urdf


@pytest.fixture(scope="module")
def g1():
    R = _robots_dir()
    urdf = R / "g1_description" / "urdf" / "g1_29dof_rev_1_0.urdf"  # BSD-3-Clause, Unitree; no SRDF
    return RobotModel.from_urdf_srdf(urdf), urdf


def _yourdfpy(urdf: Path):
    import yourdfpy

    return yourdfpy.URDF.load(str(urdf), load_meshes=False, build_collision_scene_graph=False,
                              load_collision_meshes=False)


def _check_chain(robot: RobotModel, urdf: Path, kin: GroupKinematics, n_configs: int = 40) -> None:
    """FK vs yourdfpy at random full configurations (held joints random too), Jacobian vs FD."""
    u = _yourdfpy(urdf)
    rng = np.random.default_rng(0)
    for _ in range(n_configs):
        q_full = rng.uniform(robot.lower, robot.upper)
        cfg = {n: q_full[i] for i, n in enumerate(robot.joint_names) if n in u.actuated_joint_names}
        u.update_cfg(cfg)
        ref = u.get_transform(kin.tip_link, u.base_link)
        k = kin.with_reference(q_full)
        q = k.q_group(q_full)
        T, J = k.fk_jacobian(q)
        assert np.max(np.abs(T - ref)) < 1e-9
        assert np.max(np.abs(J - fd_jacobian(k, q))) < 1e-6
    Q = rng.uniform(kin.lower, kin.upper, size=(200, kin.n))   # batched path on the same chain
    TN, JN = kin.fk_jacobian(Q)
    for i in (0, 57, 199):
        T1, J1 = kin.fk_jacobian(Q[i])
        assert np.allclose(TN[i], T1, atol=1e-13) and np.allclose(JN[i], J1, atol=1e-13)


def test_talos_loads_with_meshes_and_srdf(talos):
    robot, _ = talos
    assert robot.dof >= 30
    assert {"l_arm", "r_arm", "torso"} <= set(robot.groups)
    kinds = {g.kind for shapes in robot.collision_geometry.values() for g in shapes}
    assert "mesh" in kinds
    meshes = [g for shapes in robot.collision_geometry.values() for g in shapes if g.kind == "mesh"]
    assert all(m.vertices.shape[1] == 3 and len(m.triangles) > 0 for m in meshes)
    assert len(robot.disabled_collision_pairs) > 100


@pytest.mark.parametrize("group", ["l_arm", "r_arm"])
def test_talos_srdf_arm_groups(talos, group):
    """TALOS's own SRDF arm groups (torso_2_link → wrist_*_ft_tool_link) work as they are."""
    robot, urdf = talos
    kin = GroupKinematics(robot, group)
    assert kin.n == 7
    _check_chain(robot, urdf, kin)


@pytest.mark.parametrize("tip", ["gripper_left_base_link", "gripper_right_base_link"])
def test_talos_arm_plus_torso_chain(talos, tip):
    """A 9-DoF chain defined from the URDF (torso yaw/pitch + 7 arm joints), not from the SRDF."""
    robot, urdf = talos
    kin = GroupKinematics.from_chain(robot, "base_link", tip)
    assert kin.joint_names[:2] == ("torso_1_joint", "torso_2_joint") and kin.n == 9
    _check_chain(robot, urdf, kin)


@pytest.mark.parametrize("side", ["left", "right"])
def test_g1_waist_and_arm_chain(g1, side):
    """Unitree G1: 3 waist joints + 7 arm joints from the pelvis, the GIRRT paper's 10-DoF layout."""
    robot, urdf = g1
    assert any(g.kind == "mesh" for shapes in robot.collision_geometry.values() for g in shapes)
    kin = GroupKinematics.from_chain(robot, "pelvis", f"{side}_rubber_hand")
    assert kin.n == 10 and kin.joint_names[0] == "waist_yaw_joint"
    _check_chain(robot, urdf, kin)


@pytest.mark.parametrize("inverse", ["wln", "svd"])
def test_steering_on_a_real_arm(talos, inverse):
    robot, _ = talos
    kin = GroupKinematics(robot, "l_arm")
    q0 = (kin.lower + kin.upper) / 2                       # TALOS's zero pose has the elbow at its limit
    rng = np.random.default_rng(4)
    reached = 0
    for _ in range(8):
        goal = np.clip(q0 + rng.normal(scale=0.4, size=kin.n), kin.lower, kin.upper)
        r = steer_to_pose(kin, q0, kin.fk(goal), inverse=inverse)
        reached += r.reached
        assert np.all(r.steps >= kin.lower - 1e-12) and np.all(r.steps <= kin.upper + 1e-12)
    assert reached == 8
