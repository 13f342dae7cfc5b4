"""Problem set-up shared by every planning path (after validation.py has checked the request): collision
checking with guaranteed edge sampling, and the batched IK behind reachability tests and GraspRRT's hints.

`GraspPlanner` (the planning thread) and DAGRRT's arm process both build their arm problems here, so
the two sides of a dual plan are set up the same way and neither reaches into the other.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.ik.solver import DEFAULT_ITERATIONS as IK_ITERATIONS, solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.common import GraspTarget, PlannerOptions
from humanoid_planner.core.planners.motion import MotionValidator
from humanoid_planner.core.scene.types import SceneSnapshot

HINT_IK_ITERATIONS = 30  # damped least-squares iterations of the IK behind GraspRRT's hints


class ProblemBuilder:
    """Builds the pieces of one robot's planning problems. Stateless per request, so thread-safe."""

    def __init__(self, robot: RobotModel, options: PlannerOptions):
        self.robot = robot
        self.options = options

    def warm_up(self) -> None:
        """Build the robot's collision model now (seconds on a mesh robot: TALOS 2-3 s); every later
        checker of this robot shares it, so the first request does not pay for it."""
        r = self.robot
        group = next((g for g, grp in r.groups.items() if grp.joint_names), None)
        if group is not None:
            motion = self.motion(SceneSnapshot(0, r.root_link, ()), group, r.home, "", r.hand_links(group))
            motion.check_configs(r.home[r.group_joint_indices(group)][None])

    def motion(self, scene: SceneSnapshot, groups: str | tuple[str, ...], q_ref: np.ndarray, object_id: str,
                hands: Sequence[str], cross_only: bool = False) -> MotionValidator:
        """Collision checker + guaranteed edge sampling: configurations collide by the user's padding;
        samples between them keep the edge margins (planners/motion.py).

        cross_only (several groups): check only links of different groups against each other — for
        pairing arm paths that were each checked already; ignored unless the groups move disjoint
        link sets (a shared torso would move the other arm's links too)."""
        step = self.options.max_point_motion
        disjoint = False
        if not isinstance(groups, str):
            moved = [set(self.robot.moving_links(g)) for g in groups]
            disjoint = all(not (moved[i] & moved[j]) for i in range(len(moved)) for j in range(i + 1, len(moved)))
        checker = CollisionChecker(self.robot, scene, groups, q_ref, padding=self.options.collision_padding, margin=step / 2,
                                   grasp_object_id=object_id or None, hand_links=tuple(hands),
                                   edge_resolution=self.options.edge_resolution, cross_groups_only=cross_only and disjoint)
        return MotionValidator(checker, step)

    def reachable(self, kin: GroupKinematics, targets: Sequence[GraspTarget], q0: np.ndarray, lower, upper,
                   rng: np.random.Generator, seeds: int | None = None,
                   iterations: int = IK_ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
        """Batched multi-start IK of every target (collisions ignored): (solutions, target index)."""
        o = self.options
        s = seeds or o.ik_seeds
        Q = np.vstack([q0[None], rng.uniform(lower, upper, size=(s - 1, len(q0)))])
        seeds_all = np.repeat(Q[None], len(targets), axis=0).reshape(-1, len(q0))
        T = np.repeat(np.stack([t.T_target for t in targets])[:, None], s, axis=1).reshape(-1, 4, 4)
        q, ok, _ = solve_ik_batch(kin, T, seeds_all, lower, upper, tol_pos=o.goal_tolerance_pos,
                                  tol_rot=o.goal_tolerance_rot, iterations=iterations)
        tidx = np.repeat(np.arange(len(targets)), s)
        return q[ok], tidx[ok]

    def ik_hints(self, kin: GroupKinematics, q0: np.ndarray, lower, upper, seed) -> Callable:
        """GraspRRT's `ik`: the same batched IK as reachable, with the few starts and iterations hints
        need (most solutions converge within 30 iterations; the rest cost 3× as much). When those find
        nothing usable — no solution, or none that `keep` (GraspRRT: collision-free) keeps — the full
        multi-start IK once: where few grasps are reachable at all (Romeo's arm on boxes6: 2 of 16),
        8 starts × 30 iterations found none in 2 of 3 problems, 32 × 120 found ~35 solutions (~40 ms),
        and without hints such a search crawls by Jacobian approaches alone; where the arm is cramped
        (iCub's right_arm_torso, ~10 % of its joint space free) 8 starts found 7 solutions that all
        collided, 32 found a free one.
        With rng: one batch of the full multi-start IK from that generator's starts (GraspRRT's
        fallback, which keeps asking for goal configurations where few solutions are free)."""
        def solve(targets: Sequence[GraspTarget], keep: Callable[[np.ndarray], np.ndarray] | None = None,
                  rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
            if rng is not None:
                return self.reachable(kin, targets, q0, lower, upper, rng)
            q, which = self.reachable(kin, targets, q0, lower, upper, np.random.default_rng(seed),
                                      seeds=self.options.ik_hint_seeds, iterations=HINT_IK_ITERATIONS)
            if len(q) == 0 or (keep is not None and not keep(q).any()):
                q, which = self.reachable(kin, targets, q0, lower, upper, np.random.default_rng(seed))
            return q, which
        return solve
