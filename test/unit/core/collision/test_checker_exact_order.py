"""Level 3 tries, per configuration, the shape pairs that collided most often so far first: fewer FCL
calls on TALOS once the counts are in, never another verdict."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import talos_arms_out

from .shapes import pose


def test_learned_pair_order_saves_fcl_calls_and_keeps_verdicts(talos):
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),))
    checker = CollisionChecker(talos, scene, "l_arm", talos_arms_out(talos))
    idx = checker.joint_indices
    Q = np.random.default_rng(41).uniform(talos.lower[idx], talos.upper[idx], (1500, len(idx)))
    first = checker.check_configs(Q)  # no counts yet: the level-2 order
    calls_first = checker.stats.exact_pairs
    assert checker._pair_hits.sum() > 0
    checker.stats.reset()
    again = checker.check_configs(Q)
    assert (again == first).all()
    assert checker.stats.exact_pairs < 0.95 * calls_first
    assert (first[:300] == np.array([checker.exact_check(q) for q in Q[:300]])).all()
