"""The built-in presets: generated URDF/SRDF equal the papers' D-H tables, load, and are usable."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from preset_generation import dh_tables as dh
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.presets import PRESET_NAMES, UnknownPreset, preset_paths
from humanoid_planner.core.model.robot import DEFAULT_ACCELERATION, RobotModel
from humanoid_planner.core.transforms import invert

REPO = Path(__file__).resolve().parents[4]

EXPECTED_GROUPS = {
    "armar3": {"left_arm": 7, "right_arm": 7, "left_arm_torso": 10, "right_arm_torso": 10, "torso": 3},
    "dual_arm": {"left_arm": 7, "right_arm": 7},
    "maru1": {"left_arm": 6, "right_arm": 6, "left_arm_torso": 7, "right_arm_torso": 7},
}


@pytest.fixture(scope="module", params=PRESET_NAMES)
def preset(request):
    return request.param, RobotModel.preset(request.param)


def test_preset_paths_exist_and_unknown_names_fail():
    for name in PRESET_NAMES:
        urdf, srdf = preset_paths(name)
        assert urdf.is_file() and srdf.is_file()
        assert urdf.parent == REPO / "config" / "robots"
    with pytest.raises(UnknownPreset):
        preset_paths("nao")
    with pytest.raises(KeyError):  # UnknownPreset is a KeyError, like RobotModel.group
        preset_paths("")


def test_committed_files_are_what_the_generator_makes():
    """URDFs byte-identical; SRDFs identical given their (sampled) disable_collisions lists."""
    res = subprocess.run([sys.executable, str(REPO / "scripts" / "gen_presets.py"), "--check"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr


def test_groups_tips_end_effectors_and_home(preset):
    name, robot = preset
    for group, n in EXPECTED_GROUPS[name].items():
        g = robot.group(group)
        assert len(g.joint_names) == n, group
        side = group.split("_")[0]
        if side in ("left", "right"):
            assert g.tip_link == f"{side}_tcp"
            assert robot.hand_usable_by(f"{side}_hand", f"{side}_arm")
            assert not robot.hand_usable_by(f"{side}_hand", "right_arm" if side == "left" else "left_arm")
    if "left_arm_torso" in EXPECTED_GROUPS[name]:  # torso joints first, then the arm
        g = robot.group("left_arm_torso")
        torso = robot.group("torso").joint_names
        assert g.joint_names[: len(torso)] == torso
        assert g.joint_names[len(torso):] == robot.group("left_arm").joint_names
    assert set(robot.end_effectors) == {"left_hand", "right_hand"}
    # home: inside the limits with a margin, and every joint's home comes from the SRDF
    margin = np.minimum(robot.home - robot.lower, robot.upper - robot.home)
    assert np.all(margin >= 0.1), dict(zip(robot.joint_names, margin.round(3)))


def test_limits_velocity_and_acceleration(preset):
    name, robot = preset
    assert np.all(np.isfinite(robot.lower)) and np.all(robot.upper > robot.lower)
    assert np.all((robot.max_velocity >= 1.0) & (robot.max_velocity <= 2.0))
    left, right = dh.PRESET_ARMS[name]
    for arm in (left, right):
        for j in arm.joints:
            i = robot.joint_names.index(f"{arm.side}_{j.name}_joint")
            assert (robot.lower[i], robot.upper[i]) == pytest.approx((j.lower, j.upper), abs=1e-12)
            assert robot.max_velocity[i] == pytest.approx(j.velocity)
            # the URDF's <limit acceleration> extension is read, not the loader's default
            assert robot.max_acceleration[i] == pytest.approx(j.acceleration)
            assert robot.max_acceleration[i] != DEFAULT_ACCELERATION


def test_every_link_has_collision_geometry(preset):
    _, robot = preset
    missing = [lk for lk in robot.link_names if lk not in robot.collision_geometry]
    assert missing == []


def test_srdf_disables_all_adjacent_pairs(preset):
    _, robot = preset
    assert robot.adjacent_link_pairs <= robot.disabled_collision_pairs


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_urdf_fk_equals_dh_product(name):
    """Sigma_0 (first joint frame) → TCP from the URDF equals prod A_i · tool, 1000 configs, 1e-9."""
    robot = RobotModel.preset(name)
    rng = np.random.default_rng(7)
    Q = rng.uniform(robot.lower, robot.upper, size=(1000, robot.dof))
    for arm in dh.PRESET_ARMS[name]:
        first = robot.joints[f"{arm.side}_{arm.joints[0].name}_joint"]
        assert np.allclose(first.origin, arm.base, atol=1e-12), "arm placement differs from the table's base"
        P = robot.link_poses(Q, [first.parent, f"{arm.side}_tcp"])
        sigma0 = P[:, 0] @ first.origin
        rel = invert(sigma0) @ P[:, 1]
        idx = [robot.joint_names.index(n) for n in arm.names()]
        ref = dh.dh_chain(arm, Q[:, idx])
        assert np.max(np.abs(rel - ref)) < 1e-9


def test_armar3_waist_is_the_girrt_papers_eq18():
    """torso_link = Tz(hip) · Rz(yaw) Ry(pitch) Rx(roll) (the GIRRT paper eq. 15–19, rotation at the hip)."""
    robot = RobotModel.preset("armar3")
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = robot.home.copy()
        t = rng.uniform(-np.pi / 4, np.pi / 4, 3)
        q[:3] = t
        T = robot.link_poses(q, ["torso_link"])[0]
        ref = dh.trans(0, 0, dh.ARMAR3_HIP_HEIGHT) @ dh.rot_z(t[0]) @ dh.rot_y(t[1]) @ dh.rot_x(t[2])
        assert np.allclose(T, ref, atol=1e-12)


def test_dual_arm_shoulders_at_simox_placement():
    robot = RobotModel.preset("dual_arm")
    for side, x in (("left", -0.232), ("right", 0.232)):
        first = robot.joints[f"{side}_shoulder_1_joint"]
        T = robot.link_poses(robot.home, [first.parent])[0] @ first.origin
        assert np.allclose(T[:3, 3], [x, 0.123, 1.375], atol=1e-12)
        assert np.allclose(T[:3, :3], (dh.rot_z(-np.pi / 2) @ dh.rot_x(np.pi / 2))[:3, :3], atol=1e-12)


def test_maru1_arm_base_is_row_BU():
    """Both arms hang off the waist row B-U: Rz(theta0) Tz(l0) Tx(d0) Rx(pi/2); shoulders 0.2225 m out."""
    robot = RobotModel.preset("maru1")
    q = robot.home.copy()
    q[robot.joint_names.index("waist_yaw_joint")] = 0.4
    torso = robot.link_poses(q, ["torso_link"])[0]
    assert np.allclose(torso @ dh.MARU1_BASE, dh.dh_matrix(0.4, dh.MARU1_L0, dh.MARU1_D0, np.pi / 2), atol=1e-12)
    q0 = np.zeros(robot.dof)
    P = robot.link_poses(q0, ["left_shoulder_roll_link", "right_shoulder_roll_link"])
    assert np.allclose(P[0, :3, 3], [0.04, 0.2225, 0.284]) and np.allclose(P[1, :3, 3], [0.04, -0.2225, 0.284])


@pytest.mark.parametrize("name", ["armar3", "maru1"])
def test_mirrored_arm_is_mirror_image(name):
    """Same q on both arms gives poses mirrored in the sagittal (x-z) plane."""
    robot = RobotModel.preset(name)
    rng = np.random.default_rng(11)
    left = robot.group_joint_indices("left_arm")
    right = robot.group_joint_indices("right_arm")
    M = dh.MIRROR_Y
    for _ in range(100):
        q = robot.home.copy()
        qa = rng.uniform(robot.lower[left], robot.upper[left])
        q[left], q[right] = qa, qa
        P = robot.link_poses(q, ["left_tcp", "right_tcp"])
        assert np.allclose(P[0][:3, 3], (M @ P[1])[:3, 3], atol=1e-12)
        # x and z axes of the TCP mirror; y completes the right-handed frame
        assert np.allclose(P[0][:3, 0], M[:3, :3] @ P[1][:3, 0], atol=1e-12)
        assert np.allclose(P[0][:3, 2], M[:3, :3] @ P[1][:3, 2], atol=1e-12)


def test_home_is_collision_free_and_not_singular(preset):
    """No enabled link pair touches at home (python-fcl on the URDF's shapes); arms well-conditioned."""
    fcl = pytest.importorskip("fcl")
    name, robot = preset
    links = list(robot.collision_geometry)
    poses = dict(zip(links, robot.link_poses(robot.home, links)))
    objs = {}
    for lk in links:
        objs[lk] = []
        for g in robot.collision_geometry[lk]:
            if g.kind == "box":
                geom = fcl.Box(*g.dims)
            elif g.kind == "sphere":
                geom = fcl.Sphere(g.dims[0])
            elif g.kind == "cylinder":
                geom = fcl.Cylinder(*g.dims)
            else:
                pytest.fail(f"unexpected {g.kind} in a preset")
            W = poses[lk] @ g.origin
            objs[lk].append(fcl.CollisionObject(geom, fcl.Transform(W[:3, :3], W[:3, 3])))
    off = robot.disabled_collision_pairs | robot.adjacent_link_pairs
    hits = []
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            if frozenset((a, b)) in off:
                continue
            if any(fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult())
                   for oa in objs[a] for ob in objs[b]):
                hits.append((a, b))
    assert hits == []
    for group in ("left_arm", "right_arm"):
        kin = GroupKinematics(robot, group)
        J = kin.jacobian(kin.q_group(robot.home))
        sv = np.linalg.svd(J, compute_uv=False)
        assert sv[-1] > 0.05, (group, sv)
