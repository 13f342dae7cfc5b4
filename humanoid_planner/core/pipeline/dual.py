"""The dual-arm grasp pipeline (DAGRRT): a checked request → one ArmProblem per arm (pre-grasp targets when
an approach is asked) → the two searches, in this thread, in threads, or the right arm in the arm process
→ pairs scored, checked together and completed (`PairCompleter`) → the `Finisher`.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from humanoid_planner.core.grasp.quality import DualGraspScorer
from humanoid_planner.core.pipeline.arm_process import ArmJob, ArmWorkerPool
from humanoid_planner.core.pipeline.completion import Completion
from humanoid_planner.core.pipeline.pair_completion import PairCompleter
from humanoid_planner.core.pipeline.plans import DualGraspPlanRequest, Finisher, GraspPlan
from humanoid_planner.core.pipeline.problem import DualProblem, ProblemBuilder
from humanoid_planner.core.pipeline.single import REACHABILITY_PROBE
from humanoid_planner.core.pipeline.validation import RequestRefused, check_dual_request
from humanoid_planner.core.planners.common import GraspTarget, PlanResult, PlanStatus, Termination, substream
from humanoid_planner.core.planners.dagrrt import DAGRRT, PairChecks
from humanoid_planner.core.planners.grasp_rrt import GraspRRT
from humanoid_planner.core.scene.types import SceneSnapshot

HELPER_STREAM = 5  # appended to the right arm's seed for the planning thread's second search of it (DAGRRT);
# a label, not a knob: any value gives an independent generator, another value other seeded dual plans
NO_IK = "none of the {} hand's grasps is reachable (inverse kinematics has no solution within the limits)"


class DualArmPipeline:
    """plan_dual_grasp's way through the core; one `DualSearch` per request."""

    def __init__(self, builder: ProblemBuilder, finisher: Finisher, workers: int, parallel: str,
                 pool: Callable[[], ArmWorkerPool]):
        """workers/parallel: as GraspPlanner's; pool: the arm process pool (started when first asked)."""
        self.builder, self.finisher, self.workers, self.parallel, self.pool = builder, finisher, workers, parallel, pool

    def plan(self, scene: SceneSnapshot, req: DualGraspPlanRequest, term: Termination) -> GraspPlan:
        r, o = self.builder.robot, self.builder.options
        try:
            start = check_dual_request(r, scene.frame, req)
        except RequestRefused as e:
            return GraspPlan(e.status, e.message)
        groups = (req.left_group, req.right_group)
        grasps = tuple(tuple(self.builder.targets(req.object_pose, gs, g))
                       for gs, g in ((req.left_grasps, groups[0]), (req.right_grasps, groups[1])))
        for side, ts in zip(("left", "right"), grasps):
            if all(len(t.grasp.contacts) < o.min_contacts_per_hand for t in ts):
                return GraspPlan(PlanStatus.GRASP_QUALITY_TOO_LOW,
                                 f"no {side} grasp has the {o.min_contacts_per_hand} contact(s) per hand GraspScore "
                                 "needs, so no pair can score above the minimum")
        return DualSearch(self, DualProblem(scene, groups, start, grasps, req.object_id), req, term).run()


class DualSearch:
    """One dual request's search: its arms, the pair checks, the reachability probe, and the answer."""

    def __init__(self, pipeline: DualArmPipeline, problem: DualProblem, req: DualGraspPlanRequest, term: Termination):
        b, o = pipeline.builder, pipeline.builder.options
        self.pipeline, self.problem, self.req, self.term = pipeline, problem, req, term
        # with an approach, the arms aim at the pre-grasp poses (GraspTarget.index keys the real grasp)
        self.approach = req.approach if req.approach is not None and req.approach.desired_distance > 0 else None
        self.pairs = PairCompleter(problem, b, self.approach, req.retreat)
        self.options = replace(o, seed=req.seed, ik_hint_after=o.dual_ik_hint_after)
        self.arm_seeds = [substream(req.seed, sub) for sub in (1, 2)]
        self.scorer = DualGraspScorer(o.friction, min_contacts_per_hand=o.min_contacts_per_hand, cone_edges=o.cone_edges)
        self.min_score = req.min_grasp_score if req.min_grasp_score > 0 else o.min_grasp_score
        self.idxs = [b.robot.group_joint_indices(g) for g in problem.groups]

    def make_arm(self, k: int, seed) -> GraspRRT:
        """Arm k's search (its own validator and stream); with an approach, it drops grasps whose
        straight approach fails, as GIRRT does."""
        b, p = self.pipeline.builder, self.problem
        arm = b.arm(p.scene, p.groups[k], p.start, self.pairs.targets[k], np.random.default_rng(seed), self.options,
                    p.object_id)
        accept = None
        if self.approach is not None:
            comp = Completion(arm, self.approach, None, retry_shorter=False, repair_postures=False)
            comp.pre_targets(list(p.grasps[k]))
            accept = comp.accept
        search = GraspRRT(arm, inverse=b.options.dual_inverse, ik=b.ik_hints(arm.kin, arm.q0, arm.lower, arm.upper, seed),
                          accept=accept)
        search.progress = self.term.progress
        return search

    def helper(self) -> GraspRRT:
        """The planning thread's second search of the arm process's arm (its own stream)."""
        return self.make_arm(1, substream(self.arm_seeds[1], HELPER_STREAM))

    def score(self, a: GraspTarget, b: GraspTarget) -> float:
        return self.scorer(a.grasp, b.grasp).epsilon

    def make_planner(self, remote: int | None) -> DAGRRT:
        arms = [None if k == remote else self.make_arm(k, self.arm_seeds[k]) for k in (0, 1)]
        complete = self.pairs.complete if self.req.approach is not None or self.req.retreat is not None else None
        checks = PairChecks(self.pairs.cross_motion, self.score, self.min_score, complete)
        return DAGRRT(arms[0], arms[1], checks, workers=self.pipeline.workers, seeds=tuple(self.arm_seeds))

    def unreachable(self, k: int) -> bool:
        """No grasp of arm k has an inverse-kinematics solution (collisions ignored)."""
        b, p = self.pipeline.builder, self.problem
        kin = self.pairs.sides.kins[k]
        lo, hi = self.pairs.sides.limits[k]
        ik_rng = np.random.default_rng(substream(self.req.seed, 3 + k))
        for seeds in (8, None):
            if len(b.reachable(kin, self.pairs.targets[k], p.start[self.idxs[k]], lo, hi, ik_rng, seeds=seeds)[0]):
                return False
        return True

    def build_pair_motion(self) -> None:
        """Chore for the waiting planning thread: the pair's full validator, needed for the timing."""
        self.pairs.pair_motion  # noqa: B018 (builds it)

    def search(self) -> PlanResult:
        """The two arms' searches and their pairing. The arms start at once; an arm still without a
        solution after the probe time is tested for reachability while the search goes on, so
        unreachable sets still fail fast (every mode alike)."""
        pl, p, term = self.pipeline, self.problem, self.term
        q_start = (p.start[self.idxs[0]], p.start[self.idxs[1]])
        run = None
        if pl.workers >= 2 and pl.parallel == "process":
            # the right arm goes to the worker; this thread searches the left and does the set-up,
            # pairing and timing (with two cores, one worker keeps both busy and neither waits),
            # and once its arm is done it searches the right arm too. A worker that is busy with
            # another plan, starting or dead is not waited for: this plan runs both arms in threads
            job = ArmJob(0, p.scene, p.groups[1], p.start, self.pairs.targets[1], p.object_id, self.options,
                         self.arm_seeds[1], max(0.0, term.remaining()), pl.builder.options.dual_inverse,
                         self.approach, list(p.grasps[1]))
            run = pl.pool().try_start([job])
        if run is not None:
            with run:
                res = self.make_planner(remote=1).plan_with_worker(
                    run, q_start, self.pairs.targets[1], term, self.unreachable, REACHABILITY_PROBE,
                    idle=[self.build_pair_motion], helper=self.helper)
        else:
            res = self.make_planner(remote=None).plan(*q_start, term, self.unreachable, REACHABILITY_PROBE)
        res.extra["arm_process"] = run is not None
        return res

    def run(self) -> GraspPlan:
        r, req, term = self.pipeline.builder.robot, self.req, self.term
        res = self.search()
        if res.extra.get("unreachable") is not None:
            return GraspPlan(PlanStatus.NO_IK_SOLUTION, NO_IK.format(("left", "right")[res.extra["unreachable"]]))
        idx = np.concatenate(self.idxs)
        plan = GraspPlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(r.joint_names[i] for i in idx),
                         iterations=res.iterations, stats={"tree_size": res.tree_size, **res.extra})
        if not res.ok:
            plan.status, plan.message = res.status, res.message
            if self.pairs.incomplete:
                plan.message += "; " + self.pairs.failure()
            return plan
        kins, nl = self.pairs.sides.kins, self.pairs.n_left
        q_end = res.path[-1]
        plan.status = PlanStatus.SUCCESS
        plan.grasps = (res.target.grasp, res.extra["right_target"].grasp)
        plan.tcp_poses = (kins[0].fk(q_end[:nl]), kins[1].fk(q_end[nl:]))
        plan.grasp_score = float(res.extra["grasp_score"])
        fin, pm = self.pipeline.finisher, self.pairs.pair_motion
        if req.approach is None and req.retreat is None:
            return fin.finish(plan, res.path, pm, idx, req, term, None)
        # the pair was completed when it was accepted: settle on the pre-grasps, approach, retreat
        q_pre, lines = self.pairs.completed[(res.target.index, res.extra["right_target"].index)]
        plan = fin.finish(plan, np.vstack([res.path, q_pre[None]]), pm, idx, req, term, None)
        left = res.target.index
        plan = fin.add_lines(plan, lines, pm, lambda: self.pairs.held(left), idx, req)
        plan.tcp_poses = (kins[0].fk(plan.path[-1][:nl]), kins[1].fk(plan.path[-1][nl:]))
        return plan
