"""DAGRRT (planners.dagrrt) with both arms in this process: CreatePath puts two arm paths on one
timeline; a plan pairs grasps that score and whose motions do not collide; low scores are reported."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.grasp.quality import DualGraspScorer
from humanoid_planner.core.planners.common import PlanStatus, Termination
from humanoid_planner.core.planners.dagrrt import DAGRRT, PairChecks, create_path, shortcut_rng
from humanoid_planner.core.planners.grasp_rrt import GraspRRT
from humanoid_planner.core.transforms import pose_distance
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

from .conftest import arm_problem


def test_create_path_keeps_both_arms_paths_on_one_timeline():
    rng = np.random.default_rng(0)
    left, right = rng.normal(size=(4, 3)), rng.normal(size=(7, 2))
    merged = create_path(left, right)
    assert merged.shape[1] == 5
    np.testing.assert_allclose(merged[0], np.r_[left[0], right[0]])
    np.testing.assert_allclose(merged[-1], np.r_[left[-1], right[-1]])
    assert len(merged) == len(left) + len(right) - 2  # the shared start and end, every other vertex once
    for cols, path in ((slice(0, 3), left), (slice(3, 5), right)):
        arm = merged[:, cols]
        for v in path:  # each arm passes through all its own vertices, in order ...
            assert np.min(np.linalg.norm(arm - v, axis=1)) < 1e-12
        seg = np.linalg.norm(np.diff(arm, axis=0), axis=1)  # ... at a steady pace along its path
        np.testing.assert_allclose(np.sum(seg), np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    still = create_path(np.zeros((3, 2)), right)  # an arm that does not move stays put
    np.testing.assert_array_equal(still[:, :2], 0.0)


def test_shortcut_generators_are_seeded_per_arm():
    assert shortcut_rng(4).random() == shortcut_rng(4).random() != shortcut_rng(5).random()


@pytest.fixture(scope="module")
def dual(armar3, armar3_planner):
    sc = make_scenario(armar3, "empty", 0, hand="both")
    arms = [arm_problem(armar3_planner, sc, g, grasps) for g, grasps in (("left_arm", sc.left_grasps),
                                                                           ("right_arm", sc.right_grasps))]
    return armar3_planner, sc, arms


def dagrrt(dual, workers: int, score=None, targets=None, seed: int = 3) -> DAGRRT:
    planner, sc, arms = dual
    robot = planner.robot
    opts = replace(arms[0].options, ik_hint_after=arms[0].options.dual_ik_hint_after)
    searches = [GraspRRT(replace(p, targets=tuple(targets[k]) if targets else p.targets, options=opts,
                                 rng=np.random.default_rng([seed, k])), inverse="svd") for k, p in enumerate(arms)]
    pairing = lambda: planner.problems.motion(  # noqa: E731
        sc.scene, ("left_arm", "right_arm"), robot.home, OBJECT_ID,
        robot.hand_links("left_arm") + robot.hand_links("right_arm"), cross_only=True)
    scorer = DualGraspScorer(opts.friction, cone_edges=opts.cone_edges)
    score = score or (lambda a, b: scorer(a.grasp, b.grasp).epsilon)
    return DAGRRT(searches[0], searches[1], PairChecks(pairing, score, opts.min_grasp_score), workers=workers,
                  seeds=(seed, seed + 1))


@pytest.fixture(scope="module")
def planned(dual):
    """Both arms in two threads (workers=2): (the planner, its result)."""
    _, _, arms = dual
    planner = dagrrt(dual, 2)
    return planner, planner.plan(arms[0].q0, arms[1].q0, Termination(60.0))


def test_pairs_a_scoring_collision_free_pair(dual, planned):
    robot, sc, arms = dual
    planner, res = planned
    assert res.ok, res.message
    n = len(arms[0].q0)
    np.testing.assert_array_equal(res.path[0], np.r_[arms[0].q0, arms[1].q0])
    for k, (p, target) in enumerate(((arms[0], res.target), (arms[1], res.extra["right_target"]))):
        dp, dr = pose_distance(p.kin.fk(res.path[-1, k * n:(k + 1) * n]), target.T_target)
        assert dp <= p.options.goal_tolerance_pos and dr <= p.options.goal_tolerance_rot
        assert p.motion.polylines_free([res.path[:, k * n:(k + 1) * n]])  # each arm against the scene
    assert planner.pair_motion.polylines_free([res.path])  # and the arms against each other
    assert res.extra["grasp_score"] > arms[0].options.min_grasp_score
    assert res.extra["pairs_tested"] >= 1


def test_no_pair_scoring_is_reported_as_low_quality(dual, planned):
    """Interleaved (workers=1), each arm searching only the grasp it reached above: one pair, score 0."""
    _, _, arms = dual
    _, found = planned
    planner = dagrrt(dual, 1, score=lambda a, b: 0.0, targets=([found.target], [found.extra["right_target"]]))
    res = planner.plan(arms[0].q0, arms[1].q0, Termination(60.0))
    assert res.status is PlanStatus.GRASP_QUALITY_TOO_LOW, res.message
    assert res.extra["pairs_tested"] == res.extra["pairs_low_score"] == 1


def test_the_reachability_probe_waits_its_time_but_not_past_the_end_of_the_search():
    """The probe tests an arm without a solution only `after` seconds into the request, unless the search
    ended without a pair sooner (both arms gave up): then at once, so the answer names the unreachable arm
    however fast the searches ended."""
    from humanoid_planner.core.planners.dagrrt import _Probe

    asked: list[int] = []
    probe = _Probe(lambda k: asked.append(k) or k == 1, 100.0, Termination(10.0), ([object()], []))
    assert probe() is None and asked == []  # too early
    assert probe(at_end=True) == 1 and asked == [1]  # the left arm has a solution: only the right is tested
    assert probe(at_end=True) == 1 and asked == [1]  # once
