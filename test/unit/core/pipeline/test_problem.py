"""Problem set-up (pipeline.problem): the motion validator's padding and joint blocks,
and the batched IK behind reachability and GraspRRT's hints — on ARMAR-III."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
import humanoid_planner.core.pipeline.problem as problem
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot
from humanoid_planner.core.transforms import pose_distance


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def builder(armar3) -> ProblemBuilder:
    return ProblemBuilder(armar3, PlannerOptions(collision_padding=0.01, edge_resolution=0.05))


def test_motion_keeps_the_user_padding_and_edge_margins_and_splits_disjoint_arms(builder, armar3):
    """Configurations collide by the user's padding; edge samples keep up to half the point motion
    more (planners/motion.py); arms moving disjoint link sets are paired by their cross pairs only."""
    scene = SceneSnapshot(1, armar3.root_link)
    one = builder.motion(scene, "right_arm", armar3.home, "", armar3.hand_links("right_arm"))
    assert one.checker.padding == pytest.approx(0.01)
    assert one.checker.margin == pytest.approx(builder.options.max_point_motion / 2)
    arms = ("left_arm", "right_arm")
    two = builder.motion(scene, arms, armar3.home, "", (), cross_only=True)
    assert two.checker.cross_groups_only
    torso = builder.motion(scene, ("left_arm_torso", "right_arm"), armar3.home, "", (), cross_only=True)
    assert not torso.checker.cross_groups_only  # the torso moves both arms' links


def test_reachable_solutions_reach_their_targets(builder, armar3):
    kin = GroupKinematics(armar3, "right_arm")
    rng = np.random.default_rng(0)
    reachable = kin.fk(rng.uniform(kin.lower, kin.upper, (3, kin.n)))
    far = reachable[0].copy()
    far[:3, 3] += [2.0, 0.0, 0.0]
    targets = [GraspTarget(i, GraspSpec(f"g{i}", "", np.eye(4)), T) for i, T in enumerate([*reachable, far])]
    sols, tidx = builder.reachable(kin, targets, kin.q_ref[kin.joint_indices], kin.lower, kin.upper, rng)
    assert set(tidx.tolist()) == {0, 1, 2}  # every reachable target, never the far one
    o = builder.options
    for q, i in zip(sols, tidx):
        dp, dr = pose_distance(kin.fk(q), targets[i].T_target)
        assert dp <= o.goal_tolerance_pos + 1e-12 and dr <= o.goal_tolerance_rot + 1e-12
    hints = builder.ik_hints(kin, kin.q_ref[kin.joint_indices], kin.lower, kin.upper, seed=5)
    a, b = hints(targets), hints(targets)
    np.testing.assert_array_equal(a[0], b[0])  # seeded: the same hints every time
    starts = max(o.ik_hint_seeds, problem.MIN_HINT_STARTS // len(targets) ** 2)  # few grasps: more starts each
    assert len(a[0]) <= starts * len(targets)


def test_ik_hints_fall_back_to_the_full_ik_when_the_few_starts_find_nothing(armar3, monkeypatch):
    """Where the hint IK (few starts, few iterations) converges nowhere, the full multi-start IK runs
    once, so a search whose grasps are hard to solve still gets hints (Romeo's arm on boxes6)."""
    import humanoid_planner.core.pipeline.problem as problem

    monkeypatch.setattr(problem, "HINT_IK_ITERATIONS", 1)  # the quick pass converges nowhere
    builder = ProblemBuilder(armar3, PlannerOptions())
    kin = GroupKinematics(armar3, "right_arm")
    q0 = kin.q_ref[kin.joint_indices]
    T = kin.fk(np.random.default_rng(3).uniform(kin.lower, kin.upper, (2, kin.n)))
    targets = [GraspTarget(i, GraspSpec(f"g{i}", "", np.eye(4)), t) for i, t in enumerate(T)]
    quick, _ = builder.reachable(kin, targets, q0, kin.lower, kin.upper, np.random.default_rng(5),
                                 seeds=builder.options.ik_hint_seeds, iterations=1)
    assert len(quick) == 0
    q, which = builder.ik_hints(kin, q0, kin.lower, kin.upper, seed=5)(targets)
    assert len(q) > 0
    for qi, i in zip(q, which):
        dp, dr = pose_distance(kin.fk(qi), targets[i].T_target)
        assert dp <= builder.options.goal_tolerance_pos + 1e-12 and dr <= builder.options.goal_tolerance_rot + 1e-12
