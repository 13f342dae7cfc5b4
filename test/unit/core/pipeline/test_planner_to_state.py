"""Plans to a joint-space goal (GraspPlanner.plan_to_state): the goal checks (validation.state_goal),
colliding pairs named, two groups on one timeline, and a search around an obstacle that the held
object (not the bare arm) would hit, verified with the object in the hand. On ARMAR-III."""
from __future__ import annotations

import math

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, StatePlanRequest
from humanoid_planner.core.pipeline.validation import RequestRefused, state_goal, wrap_angle
from humanoid_planner.core.planners.common import PlanStatus, Progress
from humanoid_planner.core.scene.types import AttachedObject, SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.verification import verify_plan

ARM = "left_arm"
EMPTY = SceneSnapshot(0, "base_link")


def box(oid: str, center, size) -> SceneObject:
    T = np.eye(4)
    T[:3, 3] = center
    return SceneObject(oid, T, (Shape("box", np.eye(4), tuple(float(s) for s in size)),))


@pytest.fixture(scope="module")
def planner(armar3) -> GraspPlanner:
    return GraspPlanner(armar3, workers=1)


def goal_of(robot: RobotModel, group: str, q: np.ndarray) -> dict[str, float]:
    idx = robot.group_joint_indices(group)
    return {robot.joint_names[i]: float(q[i]) for i in idx}


def test_goal_checks_name_the_fault(armar3):
    names = list(armar3.group(ARM).joint_names)
    home = goal_of(armar3, ARM, armar3.home)
    np.testing.assert_array_equal(state_goal(armar3, (ARM,), "home", None), armar3.home[armar3.group_joint_indices(ARM)])
    np.testing.assert_array_equal(state_goal(armar3, (ARM,), "", home), state_goal(armar3, (ARM,), "home", None))
    cases = [
        (("home", home), "not both"), (("", None), "neither is given"), (("stow", None), "no group_state 'stow'"),
        (("", {**home, "nope": 0.0}), "unknown joint(s) ['nope']"),
        (("", {**home, "torso_yaw_joint": 0.0}), "['torso_yaw_joint'] are not in 'left_arm'"),
        (("", {n: home[n] for n in names[1:]}), f"no value for joint(s) ['{names[0]}']"),
        (("", {**home, names[2]: math.inf}), f"{names[2]}=inf"),
        (("", {**home, "left_elbow_joint": -0.5}), "left_elbow_joint=-0.5000 not in [0.0000, 2.5307]"),
    ]
    for (named, goal), expected in cases:
        with pytest.raises(RequestRefused) as e:
            state_goal(armar3, (ARM,), named, goal)
        assert e.value.status is PlanStatus.INVALID_GOAL and expected in e.value.message, (expected, e.value.message)
    # a value within the slack of a limit is clipped, as a start state is
    q = state_goal(armar3, (ARM,), "", {**home, "left_elbow_joint": -1e-7})
    assert q[names.index("left_elbow_joint")] == 0.0


def test_a_continuous_joint_goal_wraps(test_robot_description):
    urdf, srdf = test_robot_description
    robot = RobotModel.from_urdf_srdf(urdf.replace('<joint name="wrist" type="revolute">',
                                                   '<joint name="wrist" type="continuous">'), srdf)
    q = state_goal(robot, ("arm",), "", {"shoulder": 0.1, "elbow": 0.2, "wrist": 2 * math.pi + 0.5})
    np.testing.assert_allclose(q, [0.1, 0.2, 0.5])
    assert wrap_angle(-math.pi - 0.25) == pytest.approx(math.pi - 0.25)
    with pytest.raises(RequestRefused, match="wrist"):
        state_goal(robot, ("arm",), "", {"shoulder": 0.1, "elbow": 0.2, "wrist": math.nan})


def test_colliding_pairs_are_named(armar3, planner):
    q = armar3.home.copy()
    tcp = armar3.link_poses(q, ["left_tcp"])[0, :3, 3]
    scene = SceneSnapshot(1, "base_link", (box("block", tcp, (0.05, 0.05, 0.05)),))
    checker = CollisionChecker(armar3, scene, ARM, q)
    idx = armar3.group_joint_indices(ARM)
    pairs = checker.colliding_pairs(q[idx])
    assert ("left_tcp", "block") in pairs and all(b == "block" for _, b in pairs)
    away = q.copy()
    away[armar3.joint_names.index("left_shoulder_1_joint")] = -0.4
    assert checker.check_configs(away[idx][None])[0] and checker.colliding_pairs(away[idx]) == ()
    # the planner refuses a goal (or a start) in collision with those names
    plan = planner.plan_to_state(scene, StatePlanRequest(ARM, away, named_state="home"))
    assert plan.status is PlanStatus.INVALID_GOAL and "'left_tcp' with 'block'" in plan.message, plan.message
    plan = planner.plan_to_state(scene, StatePlanRequest(ARM, armar3.home.copy(), named_state="home"))
    assert plan.status is PlanStatus.START_IN_COLLISION and "'left_tcp' with 'block'" in plan.message, plan.message


def test_two_groups_move_together_to_home(armar3, planner):
    start = armar3.home.copy()
    for side in ("left", "right"):
        start[armar3.joint_names.index(f"{side}_elbow_joint")] = 0.4
        start[armar3.joint_names.index(f"{side}_shoulder_2_joint")] = -0.6
    plan = planner.plan_to_state(EMPTY, StatePlanRequest(ARM, start, named_state="home", right_group="right_arm", seed=1))
    assert plan.ok, plan.message
    assert plan.joint_names == armar3.group(ARM).joint_names + armar3.group("right_arm").joint_names
    idx = np.concatenate([armar3.group_joint_indices(g) for g in (ARM, "right_arm")])
    np.testing.assert_array_equal(plan.trajectory.positions[-1], armar3.home[idx])
    assert verify_plan(armar3, EMPTY, (ARM, "right_arm"), start, plan, ()) == []


def test_the_held_object_is_carried_around_what_only_it_would_hit(armar3, planner):
    """A 30 cm bar in the left hand; a post that the bar, not the arm, meets on the straight way home."""
    start = armar3.home.copy()
    start[armar3.joint_names.index("left_shoulder_2_joint")] = -0.9
    idx = armar3.group_joint_indices(ARM)
    tip = armar3.group(ARM).tip_link
    bar = AttachedObject("bar", tip, np.eye(4), (Shape("box", np.eye(4), (0.02, 0.02, 0.3)),),
                         frozenset(armar3.hand_links(ARM)))
    mid = start.copy()
    mid[idx] = 0.5 * (start[idx] + armar3.home[idx])
    T_mid = armar3.link_poses(mid, [tip])[0]
    post = box("post", T_mid[:3, :3] @ (0.0, 0.0, 0.12) + T_mid[:3, 3], (0.03, 0.03, 0.03))
    held = SceneSnapshot(2, "base_link", (post,), attached=(bar,))
    bare = SceneSnapshot(2, "base_link", (post,))
    straight = np.vstack([start[idx], armar3.home[idx]])
    assert planner.problems.motion(bare, ARM, start, "", ()).polylines_free([straight])
    assert not planner.problems.motion(held, ARM, start, "", ()).polylines_free([straight])
    progress = Progress()
    plan = planner.plan_to_state(held, StatePlanRequest(ARM, start, named_state="home", seed=2), progress=progress)
    assert plan.ok, plan.message
    assert plan.iterations > 0 and progress.iterations == plan.iterations and progress.solutions == 1
    assert verify_plan(armar3, held, (ARM,), start, plan, ()) == []
    np.testing.assert_array_equal(plan.trajectory.positions[-1], armar3.home[idx])
