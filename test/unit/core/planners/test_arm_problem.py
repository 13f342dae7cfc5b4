"""ArmProblem (planners.arm_problem): the one value an arm's planners read, built by ProblemBuilder.arm."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from humanoid_planner.core.planners.arm_problem import ArmProblem


def test_the_builder_sets_up_the_group_at_its_start(left_problem, armar3):
    p = left_problem
    idx = armar3.group_joint_indices("left_arm")
    np.testing.assert_array_equal(p.idx, idx)
    np.testing.assert_array_equal(p.q0, armar3.home[idx])
    np.testing.assert_array_equal(p.lower, armar3.lower[idx])
    assert p.kin.group == "left_arm" and p.motion.checker.groups == ("left_arm",) and len(p.targets) > 0
    T = p.targets[0].T_target
    held = p.held(T)  # the retreat's validator: the grasped object rides on the hand, out of the world
    assert len(held.checker.scene.attached) == len(p.motion.checker.scene.attached) + 1


def test_is_frozen_and_seeded_shares_all_but_the_stream(left_problem):
    p = left_problem
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.lower = p.upper  # type: ignore[misc]
    rng = np.random.default_rng(9)
    q = p.seeded(rng)
    assert q.rng is rng and q.motion is p.motion and q.targets is p.targets


def test_a_joint_space_problem_has_no_group_indices(left_problem):
    p = ArmProblem(None, left_problem.motion, left_problem.lower, left_problem.upper, left_problem.options,
                   np.random.default_rng(0))
    with pytest.raises(ValueError, match="kinematics"):
        p.idx  # noqa: B018
