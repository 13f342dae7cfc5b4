"""pipeline.plans: the answer type and the finishing stage shared by every pipeline."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.plans import Finisher, GraspPlan, GraspPlanRequest, colliding_pairs_text
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.planners.common import PlannerOptions, PlanStatus
from humanoid_planner.core.scene.types import SceneSnapshot


def test_colliding_pairs_are_named_a_few_at_a_time():
    assert colliding_pairs_text([]) == "the exact check names no pair"
    pairs = [(f"a{i}", f"b{i}") for i in range(6)]
    assert colliding_pairs_text(pairs[:1]) == "'a0' with 'b0'"
    assert colliding_pairs_text(pairs).endswith("'a3' with 'b3' and 2 more pair(s)")


def test_the_finisher_times_a_path_within_the_limits_and_starts_on_it():
    r = RobotModel.preset("armar3")
    opts = PlannerOptions()
    motion = ProblemBuilder(r, opts).motion(SceneSnapshot(0, r.root_link, ()), "left_arm", r.home, "", ())
    idx = r.group_joint_indices("left_arm")
    path = np.vstack([r.home[idx], r.home[idx] + 0.2, r.home[idx] + np.r_[0.3, np.zeros(len(idx) - 1)]])
    req = GraspPlanRequest("left_arm", r.home, np.eye(4), (), velocity_scaling=0.5)
    traj = Finisher(r, opts).time(path, motion, idx, req)
    np.testing.assert_allclose(traj.positions[0], path[0])
    np.testing.assert_allclose(traj.positions[-1], path[-1], atol=1e-9)
    assert np.all(np.abs(traj.velocities) <= 0.5 * r.max_velocity[idx] + 1e-6)
    assert not GraspPlan(PlanStatus.PLANNING_FAILED).ok and GraspPlan(PlanStatus.SUCCESS).ok
