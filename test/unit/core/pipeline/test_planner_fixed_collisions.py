"""Collisions the plan can neither make nor remove: links that no joint of the planned group moves
(iCub's hips in its own SRDF, a fixed link inside a scene box). The group's checker never counts them
against a configuration, so the plan goes ahead — and says which they are, where MoveIt would have
called the start in collision. A collision of a link the group moves is still the start's (refused)."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, StatePlanRequest
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape

_BOX = '<collision><origin xyz="{x} 0 {z}"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision>'
_LIMIT = '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
# two posts fixed to the base overlap (not disabled in the SRDF); a two-joint arm turns beside them
_URDF = f"""<robot name="posts">
  <link name="base"/>
  <link name="post_a">{_BOX.format(x=-0.5, z=0.0)}</link>
  <link name="post_b">{_BOX.format(x=-0.45, z=0.0)}</link>
  <link name="l1">{_BOX.format(x=0.3, z=0.0)}</link>
  <link name="l2">{_BOX.format(x=0.3, z=0.0)}</link>
  <joint name="fa" type="fixed"><parent link="base"/><child link="post_a"/></joint>
  <joint name="fb" type="fixed"><parent link="base"/><child link="post_b"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>{_LIMIT}</joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 0 1"/>{_LIMIT}</joint>
</robot>"""
_SRDF = """<robot name="posts"><group name="arm"><chain base_link="base" tip_link="l2"/></group>
  <group name="tip"><joint name="j2"/></group></robot>"""


def _robot(tmp_path) -> RobotModel:
    (tmp_path / "posts.urdf").write_text(_URDF)
    (tmp_path / "posts.srdf").write_text(_SRDF)
    return RobotModel.from_urdf_srdf(tmp_path / "posts.urdf", tmp_path / "posts.srdf")


def test_fixed_links_in_collision_plan_and_are_reported(tmp_path):
    robot = _robot(tmp_path)
    planner = GraspPlanner(robot, workers=1)
    scene = SceneSnapshot(1, robot.root_link, ())
    plan = planner.plan_to_state(scene, StatePlanRequest("arm", robot.home.copy(), goal={"j1": 1.0, "j2": -0.5},
                                                         timeout=5.0, seed=0))
    assert plan.ok, plan.message
    assert plan.stats["fixed_collisions"] == ["post_a–post_b"]
    # a box around the fixed posts: the scene's part is reported too, and the arm still plans
    box = SceneObject("crate", np.eye(4), (Shape("box", _at(-0.5, 0.0, 0.0), (0.3, 0.3, 0.3)),))
    plan = planner.plan_to_state(SceneSnapshot(2, robot.root_link, (box,)),
                                 StatePlanRequest("arm", robot.home.copy(), goal={"j1": 1.0, "j2": -0.5}, timeout=5.0))
    assert plan.ok, plan.message
    assert set(plan.stats["fixed_collisions"]) >= {"post_a–post_b", "post_a–crate", "post_b–crate"}


def test_a_collision_of_a_link_the_group_moves_is_still_the_starts(tmp_path):
    """For `tip` (j2 only), l1 is fixed and l2 moves: l2 inside a box is a start in collision (refused,
    the pair named), and the only fixed pair reported is the posts'."""
    robot = _robot(tmp_path)
    planner = GraspPlanner(robot, workers=1)
    start = robot.home.copy()
    T_l2 = robot.link_poses(start, ["l2"])[0]
    box = SceneObject("crate", np.eye(4), (Shape("box", T_l2 @ _at(0.3, 0.0, 0.0), (0.05, 0.05, 0.05)),))
    plan = planner.plan_to_state(SceneSnapshot(1, robot.root_link, (box,)),
                                 StatePlanRequest("tip", start, goal={"j2": 1.0}, timeout=5.0))
    assert plan.status is PlanStatus.START_IN_COLLISION and "l2" in plan.message
    assert plan.stats.get("fixed_collisions") == ["post_a–post_b"]  # the box is l2's: not among them


def _at(x, y, z) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def test_a_grasp_plan_names_a_box_in_the_fixed_torso():
    """GIRRT on ARMAR-III's left arm with a box inside its torso (the arm does not move the torso): the
    arm plans, and the answer names the pair (from the search's own checker)."""
    from humanoid_planner.core.pipeline.planner import GraspPlanRequest
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario

    robot = RobotModel.preset("armar3")
    sc = make_scenario(robot, "empty", 0, hand="left")
    torso = robot.link_poses(robot.home, ["torso_link"])[0]
    box = SceneObject("in_torso", torso @ _at(0.0, 0.0, 0.3), (Shape("box", np.eye(4), (0.05, 0.05, 0.05)),))
    scene = SceneSnapshot(2, sc.scene.frame, (*sc.scene.objects, box))
    req = GraspPlanRequest("left_arm", robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt", 5.0,
                           seed=0)
    plan = GraspPlanner(robot, workers=1).plan_grasp(scene, req)
    assert plan.ok, plan.message
    assert plan.stats["fixed_collisions"] == ["torso_link–in_torso"]
    assert "fixed_collisions" not in GraspPlanner(robot, workers=1).plan_grasp(sc.scene, req).stats
