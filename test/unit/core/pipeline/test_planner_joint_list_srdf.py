"""A MoveIt configuration whose arm groups are joint lists (Baxter's, Fetch's, PR2's style: `<joint>`s and
`<link>`s, the gripper an `<end_effector parent_link parent_group>` on fixed joints past the last arm joint),
on Baxter's own URDF and SRDF (example-robot-data): a grasp written for the end effector is reached by the
end effector's parent_link (left_gripper), not by the child link of the last joint (left_wrist, 27 cm
before it); a group of both arms (no TCP) is planned to a joint goal. Skipped when example-robot-data is not
installed."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest, StatePlanRequest
from humanoid_planner.core.planners.common import PlannerOptions
from humanoid_planner.core.transforms import pose_distance
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import OBJECT_ID, example_robots_dir, make_scenario

ARM_JOINTS = ("s0", "s1", "e0", "e1", "w0", "w1", "w2")
ARM_LINKS = ("upper_shoulder", "lower_shoulder", "upper_elbow", "lower_elbow", "upper_forearm", "lower_forearm",
             "wrist")


def _arm_groups(side: str, s: str) -> str:
    joints = "".join(f'<joint name="{side}_{n}"/>' for n in ARM_JOINTS)
    links = "".join(f'<link name="{side}_{n}"/>' for n in ARM_LINKS)
    fingers = "".join(f'<link name="{s}_gripper_{f}"/>' for f in ("l_finger", "l_finger_tip", "r_finger", "r_finger_tip"))
    return (f'<group name="{side}_arm">{joints}{links}</group><group name="{side}_hand">{fingers}</group>'
            f'<end_effector name="{side}_hand" parent_link="{side}_gripper" group="{side}_hand" '
            f'parent_group="{side}_arm"/>')


@pytest.fixture(scope="module")
def baxter() -> RobotModel:
    """Baxter's URDF and its baxter_manipulation.srdf (disabled pairs), with joint-list arm groups added."""
    try:
        d = example_robots_dir() / "baxter_description"
    except FileNotFoundError as e:
        pytest.skip(str(e))
    srdf = (d / "srdf/baxter_manipulation.srdf").read_text()
    srdf = srdf.replace("</robot>", _arm_groups("left", "l") + _arm_groups("right", "r")
                        + '<group name="both_arms"><group name="left_arm"/><group name="right_arm"/></group></robot>')
    return RobotModel.from_urdf_srdf(d / "urdf/baxter.urdf", srdf)


def test_the_tcp_of_a_joint_list_group_is_its_end_effectors_parent_link(baxter):
    for side in ("left", "right"):
        g = baxter.group(f"{side}_arm")
        assert g.joint_names == tuple(f"{side}_{n}" for n in ARM_JOINTS)
        assert g.tip_link == f"{side}_gripper"
        assert baxter.hand_usable_by(f"{side}_hand", f"{side}_arm")
        assert not baxter.hand_usable_by(f"{side}_hand", "right_arm" if side == "left" else "left_arm")
    wrist, gripper = baxter.link_poses(baxter.home, ["left_wrist", "left_gripper"])
    assert np.linalg.norm(gripper[:3, 3] - wrist[:3, 3]) == pytest.approx(0.27, abs=0.005)


def test_a_grasp_for_the_end_effector_is_reached_by_the_gripper(baxter):
    sc = make_scenario(baxter, "empty", 0, hand="left")
    grasps = tuple(replace(g, hand="left_hand") for g in sc.left_grasps)
    req = GraspPlanRequest("left_arm", baxter.home.copy(), sc.object_pose, grasps, OBJECT_ID, "girrt", 60.0, seed=1)
    plan = GraspPlanner(baxter, replace(PlannerOptions(), max_cycles=300)).plan_grasp(sc.scene, req)
    assert plan.ok, plan.message
    target = sc.object_pose @ plan.grasps[0].tcp_in_object
    assert verify_plan(baxter, sc.scene, ("left_arm",), baxter.home, plan, (target,), object_id=OBJECT_ID) == []
    # named here, not through the group: the gripper is on the grasp, the wrist 27 cm short of it
    q_end = baxter.home.copy()
    q_end[baxter.group_joint_indices("left_arm")] = plan.trajectory.positions[-1]
    gripper, wrist = baxter.link_poses(q_end, ["left_gripper", "left_wrist"])
    dp, dr = pose_distance(gripper, target)
    assert dp < 0.002 and dr < np.radians(1.0)
    assert np.linalg.norm(wrist[:3, 3] - target[:3, 3]) > 0.25


def test_both_arms_as_one_group_reach_a_joint_goal_around_the_object(baxter):
    """MotionBenchMaker's Baxter problems plan `both_arms` (14 joints on two branches, no TCP) to a joint
    goal: refused before (a TCP was asked of every group); planned now, with the RViz markers (no TCP path
    to draw) built without an error."""
    from humanoid_planner.ros.markers import plan_markers

    both = baxter.group("both_arms")
    assert both.tip_link == "" and len(both.joint_names) == 14
    sc = make_scenario(baxter, "empty", 0, hand="both")
    idx = baxter.group_joint_indices("both_arms")
    goal = baxter.home.copy()
    for joint, turn in (("left_s0", 0.6), ("right_s0", -0.6), ("left_e1", 0.5), ("right_e1", 0.5)):
        goal[baxter.joint_names.index(joint)] += turn
    req = StatePlanRequest("both_arms", baxter.home.copy(),
                           goal={baxter.joint_names[i]: float(goal[i]) for i in idx}, timeout=30.0, seed=1)
    plan = GraspPlanner(baxter).plan_to_state(sc.scene, req)
    assert plan.ok, plan.message
    assert plan.joint_names == both.joint_names
    np.testing.assert_allclose(plan.trajectory.positions[-1], goal[idx], atol=1e-9)
    assert verify_plan(baxter, sc.scene, ("both_arms",), baxter.home, plan, ()) == []
    assert plan_markers(baxter, plan, ("both_arms",), baxter.home, (), "world") == []
