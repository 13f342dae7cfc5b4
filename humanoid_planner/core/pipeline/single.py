"""The single-arm grasp pipeline: a checked request → the arm's problem → GIRRT (or a baseline to IK goal
configurations), each reached grasp completed by its straight lines (`Completion`) → the `Finisher`.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from humanoid_planner.core.collision.checker import Interrupted
from humanoid_planner.core.pipeline.completion import Completion, Finish
from humanoid_planner.core.pipeline.plans import Finisher, GraspPlan, GraspPlanRequest
from humanoid_planner.core.pipeline.problem import UNREACHABLE_STARTS, IKHints, ProblemBuilder
from humanoid_planner.core.pipeline.validation import RequestRefused, check_grasp_request
from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.baselines import GoalRRT
from humanoid_planner.core.planners.common import GraspTarget, PlanResult, PlanStatus, Termination
from humanoid_planner.core.planners.grasp_rrt import FALLBACK_FROM, GraspRRT
from humanoid_planner.core.scene.types import SceneSnapshot
from humanoid_planner.core.transforms import pose_distance

REACHABILITY_PROBE = 0.25  # s of GIRRT search before the (cheap) reachability test is run


class SingleArmPipeline:
    """plan_grasp's way through the core. Stateless per request, so thread-safe."""

    def __init__(self, builder: ProblemBuilder, finisher: Finisher):
        self.builder, self.finisher = builder, finisher
        self.robot, self.options = builder.robot, builder.options

    def problem(self, scene: SceneSnapshot, req: GraspPlanRequest) -> ArmProblem | GraspPlan:
        """The request checked (validation.check_grasp_request) and set up as the arm's problem (its
        targets the grasps, its stream seeded by the request); or the refusal. The benchmark's OMPL
        peer starts here too, so both plan the same problem with the same checker."""
        try:
            start = check_grasp_request(self.robot, scene.frame, req)
        except RequestRefused as e:
            return GraspPlan(e.status, e.message)
        targets = self.builder.targets(req.object_pose, req.grasps, req.group)
        return self.builder.arm(scene, req.group, start, targets, np.random.default_rng(req.seed),
                                replace(self.options, seed=req.seed), req.object_id)

    def new_plan(self, problem: ArmProblem) -> GraspPlan:
        """A failed plan naming the problem's joints, to be filled in."""
        return GraspPlan(PlanStatus.PLANNING_FAILED, joint_names=tuple(self.robot.joint_names[i] for i in problem.idx))

    def plan(self, scene: SceneSnapshot, req: GraspPlanRequest, term: Termination,
             finish: Finish | None = None) -> GraspPlan:
        """finish: Completion's (what else must work from a reached grasp; plan_place's set-down and retreat)."""
        prob = self.problem(scene, req)
        if isinstance(prob, GraspPlan):
            return prob
        plan = self.new_plan(prob)
        done = None
        if req.approach is not None or req.retreat is not None or finish is not None:
            done = Completion(prob, req.approach, req.retreat, finish=finish)
            search = replace(prob, targets=tuple(done.pre_targets(list(prob.targets))))
        else:
            search = prob
        if req.planner == "girrt":
            res = self.run_girrt(search, term, done)
        else:
            res = self.run_baseline(req.planner, search, term)
        motion, targets = prob.motion, search.targets
        plan.iterations = res.iterations
        plan.search_validator = motion
        plan.stats = {"tree_size": res.tree_size, **res.extra, **motion.checker.summary()}
        if done is not None and not res.ok and done.dropped and len(done.dropped) == len(targets) \
                and res.status is not PlanStatus.TIMED_OUT:
            plan.status, plan.message = PlanStatus.PLANNING_FAILED, done.failure()
            return plan
        if not res.ok:
            plan.status, plan.message = res.status, res.message
            return plan
        T_end = prob.kin.fk(res.path[-1])
        target = res.target if res.target is not None else closest_target(T_end, targets)
        if done is not None and req.planner != "girrt" and not done.accept(res.path[-1], target).ok:
            plan.status, plan.message = PlanStatus.PLANNING_FAILED, done.failure()
            return plan
        plan.status = PlanStatus.SUCCESS
        plan.grasps, plan.tcp_poses = (target.grasp,), (T_end,)
        fin, idx = self.finisher, prob.idx
        if done is None:
            return fin.finish(plan, res.path, motion, idx, req, term, prob.rng)
        c = done.lines[target.index]
        plan = fin.finish(plan, np.vstack([res.path, c.settle]), motion, idx, req, term, prob.rng)
        plan = fin.add_lines(plan, c, motion, lambda: done.held_motion(target.index), idx, req)
        plan.tcp_poses = (prob.kin.fk(plan.path[-1]),)
        return plan

    def run_girrt(self, problem: ArmProblem, term: Termination, completion: Completion | None = None) -> PlanResult:
        """GIRRT on the problem's targets; completion: its `accept` completes each reached grasp, its
        fallback targets (pre-grasps at the approach's min_distance) join after the probe time."""
        p, opts = problem, problem.options
        q0, targets = p.q0, list(p.targets)
        ik = self.builder.ik_hints(p.kin, q0, p.lower, p.upper, opts.seed)
        planner = GraspRRT(p, inverse="wln", ik=ik, accept=completion.accept if completion is not None else None,
                           fallback_from=FALLBACK_FROM)
        planner.progress = term.progress
        failed = planner.start(q0)
        if failed is not None:
            return failed
        live = list(targets)  # searched targets: those whose approach fails leave (or are replaced)
        checker = p.motion.checker
        # the plan's deadline or cancel stops the search within one batch of checks, not at the end of a
        # cycle (a Connect or an approach in dense clutter: many batches); the probe's own deadline does not
        checker.stop = lambda: term.cancel.is_set() or term.expired()
        try:
            probe = Termination(min(REACHABILITY_PROBE, term.remaining()), term.cancel, max_cycles=opts.max_cycles)
            found = planner.search(probe, live)
            if found is None and live and not term.should_stop(planner.cycles):
                # skipped when the IK hints have shown a grasp reachable already; its own generator: how
                # many probe cycles fit in the time must not change the search's draws
                sols = q0[None] if planner.ik_reachable else ik(targets, rng=np.random.default_rng(opts.seed))[0]
                if len(sols) == 0:
                    return PlanResult(PlanStatus.NO_IK_SOLUTION,
                                      f"none of the {len(targets)} grasps is reachable by the group (inverse "
                                      "kinematics has no solution within the joint limits)", iterations=planner.cycles,
                                      tree_size=planner.tree.size)
                if completion is not None:
                    live += completion.fallback_targets(live)
                rest = _WhileReachable(term.remaining(), term.cancel, opts.max_cycles, live, ik)
                found = planner.search(rest, live)
                if found is None and rest.out_of_reach() and not term.should_stop():
                    return self._out_of_reach(live, planner, completion)
        except Interrupted:
            found = None
        finally:
            checker.stop = None
        res = PlanResult(PlanStatus.SUCCESS, iterations=planner.cycles, tree_size=planner.tree.size,
                         extra=planner.fallback_report())
        if found is None:
            res.status = term.stop_status() if term.should_stop() else PlanStatus.PLANNING_FAILED
            res.message = ("no grasp reached before the timeout" if res.status is PlanStatus.TIMED_OUT
                           else f"no grasp reached within {planner.cycles} cycles")
            return res
        goal, res.target = found
        res.path = planner.tree.path_to(goal)
        return res

    @staticmethod
    def _out_of_reach(live: list[GraspTarget], planner: GraspRRT, completion: Completion | None) -> PlanResult:
        """The search ended with only grasps left that IK cannot reach: NO_IK_SOLUTION, or PLANNING_FAILED
        naming why the reachable ones were given up."""
        n = len({t.index for t in live})
        left = (f"the {n} grasp(s) left are out of the group's reach (inverse kinematics solved none from "
                f"{UNREACHABLE_STARTS} starts)")
        res = PlanResult(PlanStatus.NO_IK_SOLUTION, left, iterations=planner.cycles, tree_size=planner.tree.size,
                         extra=planner.fallback_report())
        if completion is not None and completion.dropped:
            res.status, res.message = PlanStatus.PLANNING_FAILED, f"{completion.failure()}; {left}"
        return res

    def goal_configs(self, problem: ArmProblem) -> tuple[np.ndarray, PlanResult | None]:
        """"IK first": distinct collision-free IK solutions of the problem's targets (at most
        max_goal_configs, from its stream), or the failed result that says why there are none.
        Shared by the baselines and the OMPL peer."""
        p, q0 = problem, problem.q0
        if not p.motion.check_configs(q0[None])[0]:
            return np.empty((0, len(q0))), PlanResult(PlanStatus.START_IN_COLLISION, "start configuration is in collision")
        sols, _ = self.builder.reachable(p.kin, p.targets, q0, p.lower, p.upper, p.rng)
        if len(sols) == 0:
            return sols, PlanResult(PlanStatus.NO_IK_SOLUTION,
                                    f"none of the {len(p.targets)} grasps is reachable by the group")
        sols = sols[p.motion.check_configs(sols)]
        if len(sols) == 0:
            return sols, PlanResult(PlanStatus.PLANNING_FAILED, "every inverse-kinematics solution of the grasps collides")
        keep = np.unique(np.round(sols, 3), axis=0, return_index=True)[1][: self.options.max_goal_configs]
        return sols[keep], None

    def run_baseline(self, name: str, problem: ArmProblem, term: Termination) -> PlanResult:
        goals, failed = self.goal_configs(problem)
        if failed is not None:
            return failed
        return GoalRRT(name, problem).plan(problem.q0, goals, term)


class _WhileReachable(Termination):
    """The search's termination, which also ends it once every searched target is out of reach
    (IKHints.out_of_reach: its IK found no solution from UNREACHABLE_STARTS starts)."""

    def __init__(self, timeout: float, cancel, max_cycles: int | None, live: list[GraspTarget], ik: IKHints):
        super().__init__(timeout, cancel, max_cycles)
        self.live, self.ik = live, ik

    def out_of_reach(self) -> bool:
        return bool(self.live) and all(self.ik.out_of_reach(t) for t in self.live)

    def should_stop(self, cycles: int = 0) -> bool:
        return super().should_stop(cycles) or self.out_of_reach()


def closest_target(T: np.ndarray, targets: tuple[GraspTarget, ...] | list[GraspTarget]) -> GraspTarget:
    """The target whose pose is nearest T (a baseline's path ends at an IK solution, not at a target)."""
    d = [sum(pose_distance(T, t.T_target)) for t in targets]
    return targets[int(np.argmin(d))]
