"""MotionValidator: edge sampling whose free verdict holds for the whole continuous motion."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

GROUP = "left_arm_torso"


@pytest.fixture(scope="module")
def setup():
    robot = RobotModel.preset("armar3")
    sc = make_scenario(robot, "boxes6", 2, hand="left")
    motion = GraspPlanner(robot).problems.motion(sc.scene, GROUP, robot.home, OBJECT_ID, robot.hand_links(GROUP))
    exact = CollisionChecker(robot, sc.scene, GROUP, robot.home,
                             CheckerSettings(padding=0.0, grasp_object_id=OBJECT_ID, hand_links=robot.hand_links(GROUP)))
    return robot, motion, exact


def _polylines(robot, k, rng):
    idx = robot.group_joint_indices(GROUP)
    lo, hi, q0 = robot.lower[idx], robot.upper[idx], robot.home[idx]
    for _ in range(k):
        pts = np.clip(q0 + np.cumsum(rng.normal(0, 0.25, (4, len(idx))), axis=0), lo, hi)
        yield q0, pts


@pytest.mark.parametrize("tight_ends", [True, False])  # refinement next to the ends (given configurations) or not
def test_free_prefix_verdicts_hold_between_samples(setup, tight_ends):
    """Whatever free_prefix accepts is free of the unpadded geometry at 20x its sampling density."""
    robot, motion, exact = setup
    rng = np.random.default_rng(0)
    accepted = blocked = 0
    for q0, pts in _polylines(robot, 60, rng):
        k = motion.free_prefix(q0, pts, tight_from=tight_ends, tight_to=tight_ends)
        blocked += k < len(pts)
        if k == 0:
            continue
        accepted += 1
        poly = np.vstack([q0[None], pts[:k]])
        for a, b in zip(poly[:-1], poly[1:]):
            n = 20 * int(motion.steps((b - a)[None])[0])
            assert np.all(exact.check_configs(a + np.linspace(0, 1, n + 1)[:, None] * (b - a)))
    assert accepted > 10 and blocked > 10  # both outcomes were exercised


def test_polylines_free_agrees_with_free_prefix(setup):
    robot, motion, _ = setup
    rng = np.random.default_rng(1)
    lines = [np.vstack([q0[None], pts]) for q0, pts in _polylines(robot, 40, rng)]
    for p in lines:
        assert motion.polylines_free([p]) == (motion.free_prefix(p[0], p[1:]) == len(p) - 1)
    free = [p for p in lines if motion.polylines_free([p])]
    assert free and len(free) < len(lines)
    assert motion.polylines_free(free)
    assert not motion.polylines_free(free + [next(p for p in lines if not motion.polylines_free([p]))])
    assert motion.polylines_free([])


@pytest.mark.parametrize("first", [None, 4])
def test_check_edge_agrees_with_a_full_screen(setup, first):
    """check_edge decides tight motions from its own coarse-to-fine batches, whatever its first batch:
    the verdicts of polylines_free (every sample screened at once, then refined), and free ones hold at
    20x the sampling density."""
    robot, motion, exact = setup
    rng = np.random.default_rng(2)
    verdicts = []
    for q0, pts in _polylines(robot, 40, rng):
        for b in pts:
            free = motion.check_edge(q0, b, first=first)
            assert free == motion.polylines_free([np.vstack([q0, b])])
            verdicts.append(free)
            if free:
                n = 20 * int(motion.steps((b - q0)[None])[0])
                assert np.all(exact.check_configs(q0 + np.linspace(0, 1, n + 1)[:, None] * (b - q0)))
    assert 10 < sum(verdicts) < len(verdicts) - 10



@pytest.mark.parametrize("costly", [True, False])
def test_lazy_extension_stops_after_a_small_first_batch(setup, monkeypatch, costly):
    """While most checks are costly (exact or colliding), a lazy extension checks LAZY_FIRST_CHUNK
    samples first, then doubling (else whole chunks), to the checker's first_collision, which stops
    after the first batch with a collision; the free prefix is the waypoints before the blocked
    one's segment either way."""
    from humanoid_planner.core.planners.motion import LAZY_FIRST_CHUNK, LazyMotion

    robot, motion, _ = setup
    q0 = robot.home[robot.group_joint_indices(GROUP)]
    W = q0 + np.outer(np.arange(1, 11) / 10, np.full(len(q0), 0.8))  # ten waypoints, many samples
    pts, seg = motion.samples(q0, W)
    sizes = []

    def fake(q, bounds):
        sizes.extend(hi - lo for lo, hi in bounds)
        return int(np.flatnonzero(np.all(np.isclose(q, pts[3]), axis=1))[0])

    monkeypatch.setattr(motion.checker, "first_collision", fake)
    monkeypatch.setattr(motion.checker.stats, "configs_checked", 10)
    monkeypatch.setattr(motion.checker.stats, "exact_checks", 10 if costly else 0)
    monkeypatch.setattr(motion.checker.stats, "level2_colliding", 0)
    k, tight = LazyMotion(motion).free_prefix_tight(q0, W)
    assert k == seg[3] and not tight.any()
    assert sizes[0] == (LAZY_FIRST_CHUNK if costly else min(motion.chunk, len(pts) - 1))
    assert sum(sizes) == len(pts) - 1 and all(b == min(2 * a, motion.chunk) for a, b in zip(sizes, sizes[1:-1]))
