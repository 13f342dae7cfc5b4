"""planner_setup's SRDF (core/model/srdf_setup.py) on real humanoids from example-robot-data: G1 (no
SRDF), TALOS and Romeo (SRDFs with disabled pairs and a reference pose). The G1 output loads and plans
single- and dual-arm grasps, each verified by core.verification against the exact meshes."""
from __future__ import annotations

import dataclasses

import fcl
import numpy as np
import pytest
import yaml
from lxml import etree

from humanoid_planner.core.collision.geometry import fcl_from_link_geometry, fcl_transform
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.model.srdf_setup import (SetupError, _left_by_name, adjacent_pairs, detect_arms,
                                                     generate_srdf, sampled_pairs)
from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.planner_setup import main as planner_setup
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

ROBOTS = "share/example-robot-data/robots"
SAMPLES = 300  # Setup Assistant samples 10000; enough here to exercise every step quickly


@pytest.fixture(scope="module")
def g1_urdf(example_robot_data):
    return example_robot_data / ROBOTS / "g1_description/urdf/g1_29dof_rev_1_0.urdf"


@pytest.fixture(scope="module")
def g1(g1_urdf):
    res = generate_srdf(g1_urdf, samples=SAMPLES)
    return res, RobotModel.from_urdf_srdf(g1_urdf, res.srdf)


def test_g1_groups_end_effectors_and_home(g1):
    res, robot = g1
    assert {a.side: (a.base_link, a.tcp_link) for a in res.arms} == {
        "left": ("torso_link", "left_rubber_hand"), "right": ("torso_link", "right_rubber_hand")}
    assert res.waist_base == "pelvis"
    assert robot.group("torso").joint_names == ("waist_yaw_joint", "waist_roll_joint", "waist_pitch_joint")
    for side in ("left", "right"):
        arm = robot.group(f"{side}_arm")
        assert len(arm.joint_names) == 7 and arm.tip_link == f"{side}_rubber_hand"
        assert robot.group(f"{side}_arm_torso").joint_names == robot.group("torso").joint_names + arm.joint_names
        ee = robot.end_effectors[f"{side}_hand"]
        assert (ee.group, ee.parent_group, ee.parent_link) == (f"{side}_hand", f"{side}_arm", f"{side}_rubber_hand")
        # MoveIt's naming (end effector = its link group's name): grasps for the hand are usable by its arm
        assert robot.hand_usable_by(f"{side}_hand", f"{side}_arm_torso")
    assert not robot.hand_usable_by("left_hand", "right_arm")
    np.testing.assert_array_equal(robot.home, np.clip(0.0, robot.lower, robot.upper))
    assert robot.adjacent_link_pairs <= robot.disabled_collision_pairs | {
        p for p in robot.adjacent_link_pairs if not p <= set(robot.collision_geometry)}


def test_sampled_pairs_match_brute_force_fcl(g1):
    """The sphere test and the early stops change no verdict: every pair checked exactly at every sample."""
    _, robot = g1
    n, seed = 10, 3
    adjacent = adjacent_pairs(robot)
    default, always, never = sampled_pairs(robot, robot.home, n, seed, skip=adjacent)
    links = sorted(robot.collision_geometry)
    objs = {l: [(fcl_from_link_geometry(g), g.origin) for g in robot.collision_geometry[l]] for l in links}
    Q = np.random.default_rng(seed).uniform(robot.lower, robot.upper, size=(n, robot.dof))

    def collide(a, b, Ta, Tb):
        return any(fcl.collide(fcl.CollisionObject(ga, fcl_transform(Ta @ Oa)),
                               fcl.CollisionObject(gb, fcl_transform(Tb @ Ob)), fcl.CollisionRequest(),
                               fcl.CollisionResult()) for ga, Oa in objs[a] for gb, Ob in objs[b])

    H = robot.link_poses(robot.home, links)
    T = robot.link_poses(Q, links)
    want_default, want_always, want_never = set(), set(), set()
    for i, a in enumerate(links):
        for j in range(i + 1, len(links)):
            b, p = links[j], frozenset((links[i], links[j]))
            if p in adjacent:
                continue
            if collide(a, b, H[i], H[j]):
                want_default.add(p)
                continue
            hits = sum(collide(a, b, T[k, i], T[k, j]) for k in range(n))
            if hits == 0:
                want_never.add(p)
            elif hits >= 0.95 * n:
                want_always.add(p)
    assert (default, always, never) == (want_default, want_always, want_never)
    assert len(never) > 50 and len(never) < len(links) * (len(links) - 1) // 2  # some pairs do collide


def _start(robot: RobotModel) -> np.ndarray:
    """G1's zero pose has the hands 1-2 mm from the thighs; shoulders pitched forward a little."""
    q = robot.home.copy()
    for side in ("left", "right"):
        q[robot.joint_names.index(f"{side}_shoulder_pitch_joint")] = -0.3
    return q


def test_g1_output_plans_a_single_arm_grasp(g1):
    _, robot = g1
    robot.home = _start(robot)  # the scenario's reference posture (the planner takes the request's start)
    sc = make_scenario(robot, "boxes6", 1, hand="left")
    req = GraspPlanRequest("left_arm", robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt", 20.0,
                           seed=1)
    plan = GraspPlanner(robot).plan_grasp(sc.scene, req)
    assert plan.ok, plan.message
    target = sc.object_pose @ plan.grasps[0].tcp_in_object
    assert verify_plan(robot, sc.scene, ("left_arm",), robot.home, plan, (target,), object_id=OBJECT_ID) == []


def test_g1_output_plans_a_dual_arm_grasp(g1):
    _, robot = g1
    robot.home = _start(robot)
    sc = make_scenario(robot, "empty", 1)
    # the grasps name their hands by end effector, as a MoveIt user's would
    named = [tuple(dataclasses.replace(g, hand=f"{side}_hand") for g in gs)
             for side, gs in (("left", sc.left_grasps), ("right", sc.right_grasps))]
    req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, named[0], named[1],
                               OBJECT_ID, timeout=20.0, seed=1)
    plan = GraspPlanner(robot, workers=1).plan_dual_grasp(sc.scene, req)
    assert plan.ok, plan.message
    targets = tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps)
    assert verify_plan(robot, sc.scene, ("left_arm", "right_arm"), robot.home, plan, targets,
                       object_id=OBJECT_ID) == []


def test_talos_merges_its_srdf(example_robot_data):
    d = example_robot_data / ROBOTS / "talos_data"
    res = generate_srdf(d / "robots/talos_reduced.urdf", d / "srdf/talos.srdf", samples=100)
    robot = RobotModel.from_urdf_srdf(d / "robots/talos_reduced.urdf", res.srdf)
    given = RobotModel.from_urdf_srdf(d / "robots/talos_reduced.urdf", d / "srdf/talos.srdf")
    assert given.disabled_collision_pairs <= robot.disabled_collision_pairs  # merged, none lost
    assert {"l_arm", "r_arm", "left_arm", "right_arm", "left_arm_torso", "torso"} <= set(robot.groups)  # both kept
    assert robot.group("torso").joint_names == ("torso_1_joint", "torso_2_joint")
    np.testing.assert_allclose(robot.home, given.state("half_sitting"))  # its reference pose is home
    assert res.home_source == "the input SRDF's group_state 'half_sitting'"
    assert "half_sitting" in robot.group_states
    assert {a.tcp_link for a in res.arms} == {"gripper_left_base_link", "gripper_right_base_link"}


def test_romeo_detects_its_gripper_frames(example_robot_data):
    d = example_robot_data / ROBOTS / "romeo_description"
    res = generate_srdf(d / "urdf/romeo.urdf", d / "srdf/romeo.srdf", samples=0)
    assert {a.side: (a.shoulder_link, a.tcp_link) for a in res.arms} == {
        "left": ("LShoulderPitchLink", "l_gripper"), "right": ("RShoulderPitchLink", "r_gripper")}
    robot = RobotModel.from_urdf_srdf(d / "urdf/romeo.urdf", res.srdf)
    assert robot.group("torso").joint_names == ("TrunkYaw",) and len(robot.group("left_arm").joint_names) == 7


def test_given_links_and_errors(g1_urdf):
    res = generate_srdf(g1_urdf, samples=0, hands={"left": "left_wrist_yaw_link"},
                        shoulders={"right": "right_shoulder_roll_link"})
    tips = {a.side: (a.base_link, a.tcp_link) for a in res.arms}
    assert tips == {"left": ("torso_link", "left_wrist_yaw_link"),
                    "right": ("right_shoulder_pitch_link", "right_rubber_hand")}
    with pytest.raises(SetupError, match="no link 'nope'"):
        generate_srdf(g1_urdf, samples=0, hands={"left": "nope"})
    with pytest.raises(SetupError, match="not below"):
        generate_srdf(g1_urdf, samples=0, hands={"left": "right_rubber_hand"})


def test_planner_setup_command_writes_srdf_and_node_parameters(g1_urdf, example_robot_data, tmp_path, capsys,
                                                             monkeypatch):
    out, params = tmp_path / "g1.srdf", tmp_path / "g1.yaml"
    assert planner_setup([str(g1_urdf), "-o", str(out), "--params", str(params), "--samples", "20"]) == 0
    printed = capsys.readouterr().out
    assert "left_arm: torso_link -> left_rubber_hand" in printed and f"wrote {out}" in printed
    etree.fromstring(out.read_bytes())
    values = yaml.safe_load(params.read_text())["/**"]["ros__parameters"]
    assert values["robot_description"] == g1_urdf.read_text() and values["robot_description_semantic"] == out.read_text()
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(example_robot_data))  # URDF text: package:// through the index
    robot = RobotModel.from_urdf_srdf(values["robot_description"], values["robot_description_semantic"])
    assert "left_arm_torso" in robot.groups
    assert planner_setup([str(tmp_path / "missing.urdf"), "-o", str(out)]) == 1
    assert "robot description file not found" in capsys.readouterr().err


@pytest.mark.parametrize("urdf, left, right", [
    ("icub_description/robots/icub.urdf", "l_shoulder_1", "r_shoulder_1"),  # root frame faces backwards
    ("talos_data/robots/talos_reduced.urdf", "arm_left_1_link", "arm_right_1_link"),
    ("g1_description/urdf/g1_29dof_rev_1_0.urdf", "left_shoulder_pitch_link", "right_shoulder_pitch_link"),
    ("romeo_description/urdf/romeo.urdf", "LShoulderPitchLink", "RShoulderPitchLink"),
    ("baxter_description/urdf/baxter.urdf", "left_arm_mount", "right_arm_mount"),
    ("tiago_description/robots/tiago_dual.urdf", "arm_left_1_link", "arm_right_1_link"),
    ("simple_humanoid_description/urdf/simple_humanoid.urdf", "LARM_LINK1", "RARM_LINK1"),
])
def test_detected_arm_sides_follow_the_robots_names(example_robot_data, urdf, left, right):
    robot = RobotModel.from_urdf_srdf(example_robot_data / ROBOTS / urdf)
    assert detect_arms(robot, np.clip(0.0, robot.lower, robot.upper)) == {"left": left, "right": right}


def test_left_by_name_markers():
    assert _left_by_name("l_shoulder_1", "r_shoulder_1") is True
    assert _left_by_name("arm_right_1_link", "arm_left_1_link") is False
    assert _left_by_name("LARM_LINK1", "RARM_LINK1") is True
    assert _left_by_name("RightShoulderPitchLink", "LeftShoulderPitchLink") is False
    assert _left_by_name("arm1_1", "arm2_1") is None
    assert _left_by_name("upper_l", "upper_r") is True
    assert _left_by_name("roll_link", "rorr_link") is None  # an l inside a word is no side marker


def _two_armed_urdf(facing_back: bool, leg_names: tuple[str, str]) -> str:
    """A torso with two 4-joint arms named alike (arm_a / arm_b) above two 4-joint legs named `leg_names`
    (left first); the root frame faces forward (+y = left) or backwards (+y = right, as iCub's)."""
    s = -1.0 if facing_back else 1.0
    links = ['<link name="base"><collision><geometry><box size="0.2 0.3 0.1"/></geometry></collision></link>',
             '<link name="torso"/>']
    joints = ['<joint name="torso_joint" type="fixed"><parent link="base"/><child link="torso"/>'
              '<origin xyz="0 0 0.5"/></joint>']
    limbs = (("arm_a", "torso", 0.2), ("arm_b", "torso", -0.2), (leg_names[0], "base", 0.1),
             (leg_names[1], "base", -0.1))
    for name, parent, y in limbs:
        for i in range(1, 5):
            links.append(f'<link name="{name}_{i}"><collision><geometry><sphere radius="0.02"/></geometry>'
                         '</collision></link>')
            origin = f"0 {s * y} 0" if i == 1 else "0 0 -0.1"
            joints.append(f'<joint name="{name}_j{i}" type="revolute"><parent link="{parent}"/>'
                          f'<child link="{name}_{i}"/><origin xyz="{origin}"/><axis xyz="{i % 2} {1 - i % 2} 0"/>'
                          '<limit lower="-2" upper="2" velocity="1" effort="1"/></joint>')
            parent = f"{name}_{i}"
    return f'<?xml version="1.0"?><robot name="two_arms">{"".join(links)}{"".join(joints)}</robot>'


@pytest.mark.parametrize("facing_back, leg_names, left_arm", [
    (False, ("leg_p", "leg_q"), "arm_a_1"),  # no names say it: the root frame's +y is left (REP 103)
    (True, ("leg_p", "leg_q"), "arm_b_1"),  # ... whichever way the root frame faces
    (True, ("l_leg", "r_leg"), "arm_a_1"),  # the legs' names give the robot's left: the arms follow
    (False, ("l_leg", "r_leg"), "arm_a_1"),
])
def test_unnamed_arms_take_their_side_from_named_limbs(tmp_path, facing_back, leg_names, left_arm):
    urdf = tmp_path / "two_arms.urdf"
    urdf.write_text(_two_armed_urdf(facing_back, leg_names))
    robot = RobotModel.from_urdf_srdf(urdf)
    arms = detect_arms(robot, np.zeros(robot.dof))
    assert arms["left"] == left_arm and {arms["left"], arms["right"]} == {"arm_a_1", "arm_b_1"}


def test_icub_left_arm_is_its_l_arm(example_robot_data):
    """iCub's root frame faces backwards (+y is its right): planner_setup's left_arm is its own l_arm."""
    d = example_robot_data / ROBOTS / "icub_description"
    res = generate_srdf(d / "robots/icub.urdf", d / "srdf/icub.srdf", samples=0)
    robot = RobotModel.from_urdf_srdf(d / "robots/icub.urdf", res.srdf)
    for side, own in (("left", "l_arm"), ("right", "r_arm")):
        assert robot.group(f"{side}_arm").joint_names == robot.group(own).joint_names
        assert robot.end_effectors[f"{side}_hand"].parent_group == f"{side}_arm"
