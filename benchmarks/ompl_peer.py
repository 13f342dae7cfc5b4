"""The peer a user would pick today: IK-sampled goals + OMPL RRT-Connect (PyPI `ompl`), MoveIt-style.

    plan = plan_ompl(grasp_planner, scene_snapshot, GraspPlanRequest(...))   # -> core GraspPlan

What it does, per request (the whole of it is timed as `planning_time`, like GraspPlanner.plan_grasp):

1. the same problem set-up as GraspPlanner, by the same code (SingleArmPipeline.problem): start
   check, grasp targets, the group's kinematics and the same validation our planners use (the
   CollisionChecker with the same padding, grasped object and hand links, and its MotionValidator's
   edge sampling);
2. the same IK goal sampling as the baselines (SingleArmPipeline.goal_configs): batched multi-start IK of
   every grasp (ProblemBuilder.reachable), collision-free solutions only, deduplicated, at most
   PlannerOptions.max_goal_configs of them;
3. OMPL: RealVectorStateSpace with the group's joint limits, `ob.GoalStates` with those goal
   configurations, `og.RRTConnect` with its default (automatic) range, validity from the same code:
   a Python StateValidityChecker (one configuration per call) and a Python MotionValidator whose
   checkMotion is our check_edge (batched, coarse-to-fine chunks with early exit, the same edge sampling
   as our planners — perf_baselines.md's batched-edge variant), solved with
   `ss.solve(ob.timedPlannerTerminationCondition(remaining budget))`;
4. `ss.simplifySolution(ptc)` (OMPL's PathSimplifier: reduceVertices, collapseCloseVertices,
   shortcutPath, B-spline smoothing, checkAndRepair), bounded by the remaining budget — what MoveIt
   runs by default after an OMPL solve;
5. the same time parameterization as our plans (core.timing.time_parameterize; blended corners re-checked,
   exact stops where a blend would touch an obstacle, as GraspPlanner.finish), because a MoveIt user also
   gets a timed trajectory.

Phase times are reported in plan.stats: ik_time, setup_time, solve_time, simplify_time, timing_time.
This module uses GraspPlanner's private helpers on purpose (so the goal sampling is the same code);
if they are renamed, update the calls here.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from humanoid_planner.core.pipeline import place
from humanoid_planner.core.pipeline.completion import Completion
from humanoid_planner.core.pipeline.place import PlacePlan, PlaceRequest
from humanoid_planner.core.pipeline.planner import GraspPlan, GraspPlanner, GraspPlanRequest, StatePlanRequest
from humanoid_planner.core.pipeline.single import closest_target
from humanoid_planner.core.pipeline.validation import RequestRefused
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.postprocess.timing import time_parameterize
from humanoid_planner.core.scene.types import GraspSpec
from humanoid_planner.core.transforms import pose_distance


_OMPL = None


def exit_after_ompl(code: int) -> None:
    """Exit a benchmark that used OMPL without the interpreter's teardown: OMPL's nanobind module
    prints reference-leak warnings at exit (Python subclasses of its validity checkers), harmless
    here, which would bury the benchmark's table."""
    import os
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # noqa: SLF001 - the documented way to exit without the interpreter's teardown


def ompl_modules():
    """(ob, og), imported once with OMPL's console logging reduced to warnings."""
    global _OMPL
    if _OMPL is None:
        from ompl import base as ob, geometric as og, util as ou

        ou.setLogLevel(ou.LogLevel.LOG_WARN)
        _OMPL = (ob, og)
    return _OMPL


def ompl_version() -> str:
    try:
        from importlib.metadata import version

        return version("ompl")
    except Exception:  # noqa: BLE001
        return "unknown"


PEER_DESCRIPTION = ("OMPL RRTConnect (default range) to IK-sampled goal configurations (ob.GoalStates, same IK as "
                    "the baselines), Python StateValidityChecker + batched Python MotionValidator "
                    "(CollisionChecker.check_edge), timedPlannerTerminationCondition, simplifySolution(ptc), "
                    "same time parameterization")


def _to_array(state, n: int) -> np.ndarray:
    return np.fromiter((state[i] for i in range(n)), dtype=float, count=n)


def _make_validators(ob, si, checker, n: int):
    class Validity(ob.StateValidityChecker):
        def __init__(self, si_):
            super().__init__(si_)
            self.calls = 0

        def isValid(self, state):  # noqa: N802 - OMPL's name
            self.calls += 1
            return bool(checker.check_configs(_to_array(state, n)[None])[0])

    class Motion(ob.MotionValidator):
        def __init__(self, si_):
            super().__init__(si_)
            self.calls = 0

        def checkMotion(self, s1, s2, *last_valid):  # noqa: N802 - OMPL's name
            self.calls += 1
            q1, q2 = _to_array(s1, n), _to_array(s2, n)
            ok = checker.check_edge(q1, q2)
            if last_valid and not ok:  # the (s1, s2, lastValid) overload (RRT-Connect never calls it)
                try:
                    lv = last_valid[0]
                    for i in range(n):
                        lv.first[i] = float(q1[i])
                    lv.second = 0.0
                except Exception:  # noqa: BLE001 - binding differences: the boolean answer is what matters
                    pass
            return ok

    return Validity(si), Motion(si)


def plan_ompl(planner: GraspPlanner, scene, req: GraspPlanRequest, *, motion_validator: bool = True,
              simplify: bool = True) -> GraspPlan:
    """One request through the OMPL pipeline; the answer has the same fields as GraspPlanner.plan_grasp's."""
    t0 = time.perf_counter()
    plan = _plan(planner, scene, req, t0, motion_validator, simplify)
    plan.scene_version = scene.version
    plan.planning_time = time.perf_counter() - t0
    return plan


def _plan(gp: GraspPlanner, scene, req: GraspPlanRequest, t0: float, motion_validator: bool,
          simplify: bool) -> GraspPlan:
    deadline = t0 + req.timeout
    prob = gp.single.problem(scene, req)  # the same set-up and checker as our planners
    if isinstance(prob, GraspPlan):
        return prob
    targets, idx, lower, upper = prob.targets, prob.idx, prob.lower, prob.upper
    kin, checker, q0 = prob.kin, prob.motion, prob.q0
    plan = gp.single.new_plan(prob)
    stats = plan.stats
    stats.update(peer="ompl.RRTConnect", motion_validator=motion_validator)

    def finish_stats():
        stats.update(checker.checker.summary())
        stats["validation"] = "MotionValidator (ProblemBuilder.motion)"

    # --- IK goals, the same as the baselines (SingleArmPipeline.goal_configs)
    t = time.perf_counter()
    goals, failed = gp.single.goal_configs(prob)
    stats["ik_time"] = time.perf_counter() - t
    if failed is not None:
        plan.status, plan.message = failed.status, failed.message
        finish_stats()
        return plan
    stats["goal_configs"] = len(goals)

    path, plan.status, plan.message = ompl_path(gp, checker, q0, goals, lower, upper, deadline, stats,
                                                motion_validator=motion_validator, simplify=simplify)
    if path is None:
        finish_stats()
        return plan

    traj = ompl_timing(gp, checker, path, idx, lower, upper, req, stats)
    T_end = kin.fk(path[-1])
    d = [sum(pose_distance(T_end, tg.T_target)) for tg in targets]
    target = targets[int(np.argmin(d))]
    plan.path, plan.trajectory = path, traj
    plan.grasps, plan.tcp_poses = (target.grasp,), (T_end,)
    plan.iterations = stats.get("tree_size", 0)
    finish_stats()
    return plan


def ompl_path(gp: GraspPlanner, checker, q0: np.ndarray, goals: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              deadline: float, stats: dict, *, motion_validator: bool = True,
              simplify: bool = True) -> tuple[np.ndarray | None, PlanStatus, str]:
    """OMPL RRT-Connect from q0 to any of `goals` with our validity and motion checks, then OMPL's
    simplification: (path or None, status, message). Phase times go to `stats`."""
    ob, og = ompl_modules()
    n = len(q0)
    t = time.perf_counter()
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    si = ss.getSpaceInformation()
    validity, motion = _make_validators(ob, si, checker, n)
    ss.setStateValidityChecker(validity)
    if motion_validator:
        si.setMotionValidator(motion)
    else:  # OMPL's DiscreteMotionValidator; resolution as a fraction of the space extent ≈ our edge resolution
        si.setStateValidityCheckingResolution(gp.options.edge_resolution / max(si.getMaximumExtent(), 1e-9))

    def state(q):
        s = space.allocState()
        for i in range(n):
            s[i] = float(q[i])
        return s

    keep_alive = [state(q0)]  # OMPL holds raw pointers to these
    ss.setStartState(keep_alive[0])
    goal = ob.GoalStates(si)
    for q in goals:
        s = state(q)
        keep_alive.append(s)
        goal.addState(s)
    ss.setGoal(goal)
    rrt = og.RRTConnect(si)
    ss.setPlanner(rrt)
    ss.setup()
    stats["range"] = float(rrt.getRange())
    stats["setup_time"] = time.perf_counter() - t

    t = time.perf_counter()
    status = ss.solve(ob.timedPlannerTerminationCondition(max(0.0, deadline - time.perf_counter())))
    stats["solve_time"] = time.perf_counter() - t
    stats["ompl_status"] = str(status)
    try:
        pdata = ob.PlannerData(si)
        rrt.getPlannerData(pdata)
        stats["tree_size"] = int(pdata.numVertices())
    except Exception:  # noqa: BLE001 - informative only
        pass
    stats.update(validity_calls=validity.calls, motion_calls=motion.calls)
    if not ss.haveExactSolutionPath():
        late = time.perf_counter() >= deadline
        return None, PlanStatus.TIMED_OUT if late else PlanStatus.PLANNING_FAILED, f"OMPL: {status}"
    raw = ss.getSolutionPath()
    stats["raw_waypoints"] = raw.getStateCount()
    stats["raw_length"] = float(raw.length())

    # simplify: MoveIt's default after an OMPL solve
    t = time.perf_counter()
    if simplify and deadline - time.perf_counter() > 0:
        ss.simplifySolution(ob.timedPlannerTerminationCondition(max(0.0, deadline - time.perf_counter())))
    stats["simplify_time"] = time.perf_counter() - t
    sol = ss.getSolutionPath()
    path = np.array([_to_array(sol.getState(k), n) for k in range(sol.getStateCount())])
    stats.update(validity_calls=validity.calls, motion_calls=motion.calls)
    del keep_alive
    return path, PlanStatus.SUCCESS, ""


def ompl_timing(gp: GraspPlanner, checker, path: np.ndarray, idx: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                req, stats: dict):
    """The same time parameterization as GraspPlanner.finish: blended corners, kept only where the timed
    samples stay collision-free, else exact stops on the (checked) path."""
    r = gp.robot
    t = time.perf_counter()
    timing = dict(velocity_scaling=req.velocity_scaling, acceleration_scaling=req.acceleration_scaling,
                  position_limits=(lower, upper))
    traj = time_parameterize(path, r.max_velocity[idx], r.max_acceleration[idx], **timing)
    pos = traj.positions
    blended = getattr(traj, "max_deviation", 1.0) > 0
    if blended and len(pos) > 1 and checker.free_prefix(pos[0], pos[1:]) < len(pos) - 1:
        traj = time_parameterize(path, r.max_velocity[idx], r.max_acceleration[idx], path_tolerance=0.0, **timing)
    stats["timing_time"] = time.perf_counter() - t
    return traj


def plan_ompl_to_state(gp: GraspPlanner, scene, req: StatePlanRequest) -> GraspPlan:
    """The peer of GraspPlanner.plan_to_state: the same request checks and motion validator, OMPL RRT-Connect
    to the one goal configuration, simplified and timed the same way."""
    t0 = time.perf_counter()
    r = gp.robot
    prob = gp.state_problem(scene, req)  # the same checks and motion validator
    if isinstance(prob, GraspPlan):
        return prob
    idx, checker, plan = prob.idx, prob.motion, prob.plan
    stats = plan.stats
    stats["peer"] = "ompl.RRTConnect"
    path, plan.status, plan.message = ompl_path(gp, checker, prob.q0, prob.goal[None], r.lower[idx], r.upper[idx],
                                                t0 + req.timeout, stats)
    if path is not None:
        plan.path = path
        plan.trajectory = ompl_timing(gp, checker, path, idx, r.lower[idx], r.upper[idx], req, stats)
    stats.update(checker.checker.summary())
    plan.scene_version = scene.version
    plan.planning_time = time.perf_counter() - t0
    return plan


def plan_ompl_place(gp: GraspPlanner, scene, req: PlaceRequest) -> PlacePlan:
    """The peer of place.plan_place, MoveIt-style: the same set-up and scenes (place.setup, the object
    attached; the supports obstacles to it until the set-down), IK goals of the placements' pre-place
    TCP poses (the baselines' goal sampling), OMPL RRT-Connect to them with the same motion validator
    (it carries the object), simplified and timed as the other peers, then the same straight descent
    (Completion, place.set_down) and the same retreat (place.retreat). A placement whose descent or
    retreat is blocked is left out and the search runs again while time remains, as plan_place does."""
    t0 = time.perf_counter()
    deadline = t0 + req.timeout
    r = gp.robot
    try:
        s = place.setup(r, scene, req)
    except RequestRefused as e:
        return place.stamp(GraspPlan(e.status, e.message), scene, t0)
    T_obj_tcp = np.linalg.inv(place.object_in_tcp(r, s.att, req.group, s.start))
    touch, approach, searched = place.touch_stretch(s, gp.options.collision_padding)
    left = dict(s.goals)
    blocked: list[str] = []
    stats: dict = {"peer": "ompl.RRTConnect"}
    while left:
        grasps = [GraspSpec(f"place_poses[{i}]", "", place.raised(P, s.approach, touch) @ T_obj_tcp)
                  for i, P in left.items()]
        greq = GraspPlanRequest(req.group, s.start, np.eye(4), grasps, planner="rrt_connect",
                                timeout=max(deadline - time.perf_counter(), 1e-3), seed=req.seed,
                                velocity_scaling=req.velocity_scaling, acceleration_scaling=req.acceleration_scaling,
                                approach=approach)
        prob = gp.single.problem(searched, greq)
        if isinstance(prob, GraspPlan):
            return place.stamp(prob, scene, t0)
        done = Completion(prob, approach, None) if approach is not None else None
        search = replace(prob, targets=tuple(done.pre_targets(list(prob.targets)))) if done else prob
        plan = gp.single.new_plan(prob)
        plan.stats = stats
        goals, failed = gp.single.goal_configs(search)
        if failed is not None:
            plan.status, plan.message = failed.status, failed.message.replace("grasp", "placement")
            return place.stamp(plan, scene, t0)
        path, plan.status, plan.message = ompl_path(gp, prob.motion, prob.q0, goals, prob.lower, prob.upper,
                                                    deadline, stats)
        if path is None:
            return place.stamp(plan, scene, t0)
        target = closest_target(prob.kin.fk(path[-1]), search.targets)
        index = int(target.grasp.id[len("place_poses["):-1])
        left.pop(index)
        if done is not None and not done.accept_here(path[-1], target).ok:
            blocked.append(f"place_poses[{index}] (the descent is blocked)")
        else:
            c = done.lines[target.index] if done is not None else None
            plan.path = np.vstack([path, c.settle]) if c is not None else path
            plan.trajectory = ompl_timing(gp, prob.motion, plan.path, prob.idx, prob.lower, prob.upper, req, stats)
            if c is not None:
                plan = gp.finisher.add_lines(plan, c, prob.motion, lambda: prob.motion, prob.idx, greq)
            why = place.set_down(gp, s, req, plan, touch, prob.motion) if touch > 0 else None
            if why is None:
                plan.grasps, plan.tcp_poses = ((GraspSpec(target.grasp.id, "", s.goals[index] @ T_obj_tcp),),
                                               (prob.kin.fk(plan.path[-1]),))
                why = place.retreat(gp, s, req, plan, index)
            if why is None:
                return place.stamp(plan, scene, t0, index)
            blocked.append(f"place_poses[{index}] ({why})")
        if time.perf_counter() >= deadline:
            break
    return place.stamp(GraspPlan(PlanStatus.PLANNING_FAILED, "blocked at " + "; ".join(blocked)), scene, t0)
