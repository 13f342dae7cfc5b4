#!/usr/bin/env python3
"""Planner benchmark: fixed, seeded problems; our planners against the OMPL peer, same run.

    make bench                                    # the default matrix (below), 50 problems per case, 5 s budget
    make bench-quick                              # CI smoke: 2 problems per case, 2 s budget, 5 service calls
    .venv/bin/python benchmarks/bench_planners.py --robots armar3 --families boxes6 --planners girrt,ompl
    .venv/bin/python benchmarks/bench_planners.py --matrix full --problems 50   # every applicable combination

Problems: problem k of (robot, family) is `make_scenario(robot, family, seed=k, hand=...)` (single-arm
planners: hand="left", the object in front of the left shoulder; DAGRRT: hand="both"), start = the
robot's home pose, request seed k, timeout = --budget. Every planner of a robot sees the same problems.
A seed whose scenario cannot be built (ValueError: a fixture colliding with the robot at home; in the
pick families also a problem the reference RRT-Connect does not solve in 30,000 cycles) is skipped and reported;
a family where the first 5 seeds all fail is skipped whole.

Families: empty, boxes6, table_shelf, narrow (the default), and the one-hand pick families of the
standard manipulation benchmarks (scenarios.PICK_FAMILIES: bookshelf_tall, bookshelf_small,
bookshelf_thin, cage, box, table_pick, table_under_pick), run only when --families names them:
    .venv/bin/python benchmarks/bench_planners.py --robots armar3,panda --families bookshelf_tall,cage,box \
        --planners girrt,ompl --budget 10 --problems 10

Default matrix (of the chosen families):
  armar3 (left_arm_torso, 10 DoF): girrt + ompl on all families; rrt, goal_biased_rrt, rrt_connect,
      rc_rrt on boxes6 only; girrt_pick on boxes6 (GIRRT with a 10 cm straight approach along the
      hand axis and a 10 cm lift with the object in hand, each at least 5 cm; verified with verify_retreat too);
  dual_arm (left_arm + right_arm): dagrrt on all families, and dagrrt with workers=1 on boxes6 (the
      parallel speed-up: same problems, median wall time 1 worker / 2 workers);
  real humanoids with meshes (scenarios.HUMANOIDS, from example-robot-data; start = their reference
      pose): girrt + ompl (left arm) and dagrrt (both arms) on all families;
  armar3 and the humanoids: girrt + ompl on the pick families;
  single arms (scenarios.ARMS: panda, ur5, tiago; group "arm"): girrt + ompl on every family;
  <robot>_torso (g1_torso, tiago_torso: the same robot, its arm group with the torso joints, scenarios'
      Humanoid.torso): girrt + ompl on the pick families;
  plus the plan_grasp service round trip (benchmarks/bench_service.py, armar3, boxes6).
`--matrix full` adds every single-arm planner on every family for armar3 and the humanoids, and
dagrrt with workers=1 for every two-armed robot. `--robots/--families/--planners` filter the chosen matrix.

Statistics per case (success = PlanStatus.SUCCESS):
  time: plan.planning_time (GraspPlanner's own perf_counter around the whole request: problem set-up,
      IK, search, shortcutting, time parameterization); median and p95 over ALL attempts, failures
      counted at the time they returned (a timeout ≈ the budget); also the median over successes;
  path length: joint-space Euclidean length of plan.path (after shortcutting/simplification), successes;
  checks/s: configurations checked by every CollisionChecker the request built (their counters) /
      planning time, summed over the case; exact % = share of those that needed python-fcl;
  ours/peer: median time of GIRRT / median time of the OMPL peer, per (robot, family), same problems;
      the paired ratio is the median of per-problem ratios over problems both solved.
  verified: core.verification.verify_plan (independent exact check) on the first --verify successes;
  CPU: process CPU time of the attempt (all threads) — compare with the wall time on a shared machine;
  over budget: attempts that returned more than 5 % + 50 ms after their budget.
A case whose first --abandon-after (10) attempts all failed is stopped there and marked abandoned, so a
broken planner costs 10 budgets, not 50 (its success rate is then over those attempts).
Outputs: a table on stdout (and out/bench/table.md), out/bench/results.json, out/bench/bench.png.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import gc
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from humanoid_planner.core import compiled  # noqa: E402
from humanoid_planner.core.collision import pair_tables  # noqa: E402
from humanoid_planner.core.pipeline.plans import Finisher  # noqa: E402
from humanoid_planner.core.pipeline.problem import ProblemBuilder  # noqa: E402
from humanoid_planner.core.pipeline.planner import (DualGraspPlanRequest, GraspPlanner,  # noqa: E402
                                                  GraspPlanRequest)
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.scenarios import (ALL_FAMILIES, ARMS, FAMILIES, HUMANOIDS, OBJECT_ID,  # noqa: E402
                                        PICK_FAMILIES, load_humanoid, make_scenario)
from humanoid_planner.core.postprocess.smoothing import path_length  # noqa: E402
from humanoid_planner.core.verification import verify_plan, verify_retreat  # noqa: E402
from humanoid_planner.core.grasp.approach import approach_axis  # noqa: E402
from humanoid_planner.core.planners.cartesian import GripperTranslation  # noqa: E402
from humanoid_planner.child_env import child_environment  # noqa: E402

BASELINES = ("rrt", "goal_biased_rrt", "rrt_connect", "rc_rrt")
SINGLE = ("girrt",) + BASELINES + ("ompl", "girrt_pick")
PICK_DISTANCE, PICK_MIN = 0.10, 0.05  # girrt_pick: approach along the hand axis and lift +z, each 10 cm (at least 5)
LIFT = (0.0, 0.0, 1.0)
PLANNERS = SINGLE + ("dagrrt",)
WARMUP_SEED = 1_000_000
TARGETS_DOC = {
    "girrt_armar3_boxes6": "GIRRT, armar3 left_arm_torso, boxes6: success >= 99 %, median <= 50 ms, p95 <= 250 ms, "
                           "median <= 0.5x the OMPL peer's median",
    "dagrrt_dual_arm_boxes6": "DAGRRT, dual_arm, boxes6: success >= 97 %, median <= 150 ms, speed-up (1 worker / "
                              "2 workers) >= 1.5x",
    "service": "plan_grasp service round trip adds <= 5 ms (median of round trip - planning_time)",
    "girrt_pick_armar3_boxes6": "GIRRT with a 10 cm straight approach along the hand axis and a 10 cm lift (min 5 cm "
                                "each), armar3 left_arm_torso, boxes6: success >= 97 %, median <= 100 ms",
}
# per-plan seconds assumed before anything is measured (only for the first ETA)
PRIOR_SECONDS = {"girrt": 0.5, "girrt_pick": 0.6, "ompl": 0.8, "dagrrt": 1.5, "rrt": 2.0, "goal_biased_rrt": 1.5, "rrt_connect": 0.8,
                 "rc_rrt": 2.0}


# ------------------------------------------------------------------------------------------ robots
@dataclass(frozen=True)
class RobotSpec:
    name: str
    group: str  # single-arm planning group
    left: str
    right: str
    note: str
    model: str = ""  # the robot loaded (load_robot); "": the spec's name


# <name>_torso: the same robot, its arm groups with the torso joints (single-arm planners, one-hand scenes)
TORSO = {f"{h.name}_torso": RobotSpec(f"{h.name}_torso", h.torso[0], *h.torso, h.note + "; arm + torso", h.name)
         for h in (*HUMANOIDS.values(), *ARMS.values()) if h.torso}
SPECS = {
    "armar3": RobotSpec("armar3", "left_arm_torso", "left_arm", "right_arm", "preset armar3 (GIRRT paper's D-H), home pose"),
    "dual_arm": RobotSpec("dual_arm", "left_arm", "left_arm", "right_arm", "preset dual_arm (DAGRRT paper), home pose"),
    **{h.name: RobotSpec(h.name, h.left, h.left, h.right, h.note) for h in HUMANOIDS.values()},
    **{h.name: RobotSpec(h.name, h.left, h.left, h.right, h.note) for h in ARMS.values()},  # one arm: left = right
    **TORSO,
}
ROBOTS = ("armar3", "dual_arm", *HUMANOIDS, *ARMS, *TORSO)


def load_robot(name: str) -> RobotModel:
    name = (SPECS[name].model or name) if name in SPECS else name
    return load_humanoid(name) if name in HUMANOIDS or name in ARMS else RobotModel.preset(name)


# ------------------------------------------------------------------------------------------ matrix
@dataclass(frozen=True)
class Case:
    robot: str
    family: str
    planner: str
    workers: int = 2

    @property
    def dual(self) -> bool:
        return self.planner == "dagrrt"

    @property
    def key(self) -> str:
        return f"{self.robot}/{self.family}/{self.planner}" + ("" if self.workers == 2 else f"/w{self.workers}")


def build_matrix(kind: str, robots, families, planners) -> list[Case]:
    cases: list[Case] = []
    if kind == "default":
        for fam in FAMILIES:
            cases += [Case("armar3", fam, "girrt"), Case("armar3", fam, "ompl")]
        cases += [Case("armar3", "boxes6", p) for p in BASELINES]
        cases += [Case("armar3", "boxes6", "girrt_pick")]
        cases += [Case("dual_arm", fam, "dagrrt") for fam in FAMILIES]
        cases += [Case("dual_arm", "boxes6", "dagrrt", workers=1)]
        for robot in HUMANOIDS:
            for fam in FAMILIES:
                cases += [Case(robot, fam, "girrt"), Case(robot, fam, "ompl"), Case(robot, fam, "dagrrt")]
        for robot in ("armar3", *HUMANOIDS, *TORSO):  # one-hand scenes: no dagrrt
            cases += [Case(robot, fam, p) for fam in PICK_FAMILIES for p in ("girrt", "ompl")]
        for robot in ARMS:
            cases += [Case(robot, fam, p) for fam in ALL_FAMILIES for p in ("girrt", "ompl")]
    else:
        for robot in ("armar3", *HUMANOIDS, *ARMS, *TORSO):
            cases += [Case(robot, fam, p) for fam in ALL_FAMILIES for p in SINGLE]
        for robot in ROBOTS:
            if robot in ARMS or robot in TORSO:
                continue
            cases += [Case(robot, fam, "dagrrt") for fam in FAMILIES]
            cases += [Case(robot, "boxes6", "dagrrt", workers=1)]
    return [c for c in cases if c.robot in robots and c.family in families and c.planner in planners]


# ------------------------------------------------------------------------------------------ running
class InstrumentedProblems(ProblemBuilder):
    """ProblemBuilder that records the checkers a request builds and times its IK."""

    def __init__(self, owner: "InstrumentedPlanner", base: ProblemBuilder):
        super().__init__(base.robot, base.options)
        self.owner = owner

    def motion(self, *a, **k):  # every checker a request builds is a MotionValidator's
        m = super().motion(*a, **k)
        self.owner.checkers.append(m.checker)
        return m

    def reachable(self, *a, **k):
        return self.owner.clocked("t_ik", super().reachable, *a, **k)


class InstrumentedFinisher(Finisher):
    """Finisher that times the post-processing (shortcut and timing)."""

    def __init__(self, owner: "InstrumentedPlanner", base: Finisher):
        super().__init__(base.robot, base.options)
        self.owner = owner

    def finish(self, *a, **k):
        return self.owner.clocked("t_finish", super().finish, *a, **k)


class InstrumentedPlanner(GraspPlanner):
    """GraspPlanner that records the checkers a request builds and times IK and post-processing
    (through its public hooks: the problem builder and the finisher, `assemble`)."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self.assemble(InstrumentedProblems(self, self.problems), InstrumentedFinisher(self, self.finisher))
        self.reset()

    def reset(self):
        self.checkers = []
        self.t_ik = 0.0
        self.t_finish = 0.0

    def clocked(self, counter: str, fn, *a, **k):
        """fn(*a, **k), its wall time added to the attribute `counter` (also when it raises)."""
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            setattr(self, counter, getattr(self, counter) + time.perf_counter() - t)


@dataclass
class Problem:
    seed: int
    scenario: object


@dataclass
class ProblemSet:
    problems: list[Problem] = field(default_factory=list)
    skipped: dict[int, str] = field(default_factory=dict)  # seed -> reason


def make_problems(robot: RobotModel, spec: RobotSpec, family: str, hand: str, n: int) -> ProblemSet:
    out = ProblemSet()
    seed = 0
    while len(out.problems) < n and seed < 3 * n + 5:
        try:
            sc = make_scenario(robot, family, seed, left_group=spec.left, right_group=spec.right, hand=hand)
            out.problems.append(Problem(seed, sc))
        except ValueError as e:
            out.skipped[seed] = str(e)
            if seed == 4 and not out.problems:
                break  # the first five seeds all failed: the family does not fit this robot
        seed += 1
    return out


def request_for(case: Case, spec: RobotSpec, robot: RobotModel, sc, seed: int, budget: float):
    if case.dual:
        return DualGraspPlanRequest(spec.left, spec.right, robot.home.copy(), sc.object_pose, sc.left_grasps,
                                    sc.right_grasps, OBJECT_ID, "dagrrt", timeout=budget, seed=seed)
    if case.planner == "girrt_pick":
        return GraspPlanRequest(spec.group, robot.home.copy(), sc.object_pose, sc.grasps, OBJECT_ID, "girrt", budget,
                                seed=seed, approach=GripperTranslation(tuple(approach_axis(robot, spec.group)),
                                                                       PICK_DISTANCE, PICK_MIN),
                                retreat=GripperTranslation(LIFT, PICK_DISTANCE, PICK_MIN))
    return GraspPlanRequest(spec.group, robot.home.copy(), sc.object_pose, sc.grasps, OBJECT_ID,
                            "rrt_connect" if case.planner == "ompl" else case.planner, budget, seed=seed)


def out_of_process(case: Case, gp: GraspPlanner) -> bool:
    """DAGRRT's right arm in GraspPlanner's worker process (parallel='process')?"""
    return case.dual and case.workers >= 2 and getattr(gp, "parallel", "thread") == "process"


def run_one(case: Case, spec: RobotSpec, robot: RobotModel, gp: InstrumentedPlanner, prob: Problem, budget: float,
            verify: bool) -> dict:
    sc = prob.scenario
    req = request_for(case, spec, robot, sc, prob.seed, budget)
    gp.reset()
    gc.collect()
    c0 = time.process_time()
    t0 = time.perf_counter()
    if case.planner == "ompl":
        from ompl_peer import plan_ompl

        plan = plan_ompl(gp, sc.scene, req)
    elif case.dual:
        plan = gp.plan_dual_grasp(sc.scene, req)
    else:
        plan = gp.plan_grasp(sc.scene, req)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    rec = {"seed": prob.seed, "status": plan.status.value, "ok": plan.ok, "time": plan.planning_time, "wall": wall,
           "cpu": cpu,
           "iterations": int(plan.iterations), "message": plan.message[:200]}
    configs = sum(c.stats.configs_checked for c in gp.checkers)
    rec.update(configs_checked=int(configs), exact_checks=int(sum(c.stats.exact_checks for c in gp.checkers)),
               edges_checked=int(sum(c.stats.edges_checked for c in gp.checkers)), checkers=len(gp.checkers))
    phases = {}
    if case.planner == "ompl":
        phases = {k: float(plan.stats[k]) for k in ("ik_time", "setup_time", "solve_time", "simplify_time",
                                                    "timing_time") if k in plan.stats}
    else:
        phases["ik_time"] = gp.t_ik
        phases["finish_time"] = gp.t_finish  # shortcut + time parameterization + re-check
    rec["phases"] = phases
    if out_of_process(case, gp):
        rec["counts_partial"] = True  # the right arm's search ran in a worker process: its checks/CPU are not seen
    if "tree_size" in plan.stats:
        rec["tree_size"] = int(plan.stats["tree_size"])
    if plan.ok and plan.path is not None:
        rec["path_length"] = path_length(plan.path)
        rec["waypoints"] = int(len(plan.path))
        rec["duration"] = float(plan.trajectory.times[-1]) if plan.trajectory is not None else None
        if verify:
            groups = (spec.left, spec.right) if case.dual else (spec.group,)
            targets = tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps)
            try:
                rec["verify_problems"] = verify_plan(robot, sc.scene, groups, robot.home, plan, targets,
                                                     object_id=OBJECT_ID)
                if case.planner == "girrt_pick":
                    rec["verify_problems"] += verify_retreat(robot, sc.scene, groups, robot.home, plan, LIFT,
                                                             object_id=OBJECT_ID, min_distance=PICK_MIN)
            except Exception as e:  # noqa: BLE001 - a crash of the checker is a finding, not a benchmark abort
                rec["verify_problems"] = [f"verify_plan raised {e!r}"]
    return rec


# ------------------------------------------------------------------------------------------ statistics
def pct(values, q) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


def summarize(case: Case, spec: RobotSpec, probs: ProblemSet, recs: list[dict], budget: float,
              parallel: str | None = None) -> dict:
    times = [r["time"] for r in recs]
    ok = [r for r in recs if r["ok"]]
    total_time = sum(times)
    configs = sum(r["configs_checked"] for r in recs)
    exact = sum(r["exact_checks"] for r in recs)
    statuses: dict[str, int] = {}
    for r in recs:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    phase_keys = sorted({k for r in recs for k in r["phases"]})
    partial = any(r.get("counts_partial") for r in recs)
    verified = [r for r in recs if "verify_problems" in r]
    return {
        "robot": case.robot, "family": case.family, "planner": case.planner, "workers": case.workers,
        "parallel": parallel,
        "group": f"{spec.left}+{spec.right}" if case.dual else spec.group, "key": case.key,
        "n": len(recs), "successes": len(ok), "success_rate": len(ok) / len(recs) if recs else None,
        "time_median": pct(times, 50), "time_p95": pct(times, 95),
        "time_mean": float(np.mean(times)) if times else None,
        "time_median_success": pct([r["time"] for r in ok], 50), "time_p95_success": pct([r["time"] for r in ok], 95),
        "time_max": max(times) if times else None,
        "overruns": sum(t > budget * 1.05 + 0.05 for t in times),  # returned > 5 % + 50 ms after the budget
        "cpu_median": None if partial else pct([r["cpu"] for r in recs], 50),
        "path_length_median": pct([r["path_length"] for r in ok if "path_length" in r], 50),
        "checks_per_s": configs / total_time if total_time > 0 and not partial else None,
        "exact_share": exact / configs if configs and not partial else None,
        "counts_partial": partial,
        "status_counts": statuses,
        "phase_medians": {k: pct([r["phases"][k] for r in recs if k in r["phases"]], 50) for k in phase_keys},
        "phase_medians_success": {k: pct([r["phases"][k] for r in ok if k in r["phases"]], 50) for k in phase_keys},
        "verified": {"checked": len(verified), "valid": sum(not r["verify_problems"] for r in verified),
                     "problems": [{"seed": r["seed"], "problems": r["verify_problems"]} for r in verified
                                  if r["verify_problems"]]},
        "skipped_seeds": {str(k): v for k, v in probs.skipped.items()},
        "abandoned": len(recs) < len(probs.problems),
        "problems_available": len(probs.problems),
        "budget": budget,
        "problems": recs,
    }


def paired_ratio(a: dict, b: dict) -> tuple[float | None, int]:
    """Median over problems both solved of time_a / time_b (same seed)."""
    tb = {r["seed"]: r["time"] for r in b["problems"] if r["ok"]}
    ratios = [r["time"] / tb[r["seed"]] for r in a["problems"] if r["ok"] and r["seed"] in tb and tb[r["seed"]] > 0]
    return (float(np.median(ratios)) if ratios else None), len(ratios)


def peer_core_median(peer: dict) -> float | None:
    """Median over all peer attempts of IK + setup + solve (no simplification, no time parameterization)."""
    vals = []
    for r in peer["problems"]:
        p = r["phases"]
        if r["ok"]:
            vals.append(p.get("ik_time", 0) + p.get("setup_time", 0) + p.get("solve_time", 0))
        else:
            vals.append(r["time"])
    return pct(vals, 50)


def ratios(summaries: list[dict]) -> list[dict]:
    by = {(s["robot"], s["family"], s["planner"], s["workers"]): s for s in summaries}
    out = []
    for (robot, fam, planner, w), s in by.items():
        peer = by.get((robot, fam, "ompl", 2))
        if planner == "ompl" or peer is None or w != 2 or s["time_median"] is None or not peer["time_median"]:
            continue
        pr, n = paired_ratio(s, peer)
        core = peer_core_median(peer)
        out.append({"robot": robot, "family": fam, "planner": planner, "ours_median": s["time_median"],
                    "peer_median": peer["time_median"], "ratio": s["time_median"] / peer["time_median"],
                    "paired_ratio": pr, "paired_n": n, "ours_success": s["success_rate"],
                    "peer_success": peer["success_rate"], "peer_core_median": core,
                    "ratio_vs_peer_core": (s["time_median"] / core) if core else None})
    return out


def speedups(summaries: list[dict]) -> list[dict]:
    by = {(s["robot"], s["family"], s["planner"], s["workers"]): s for s in summaries}
    out = []
    for (robot, fam, planner, w), one in by.items():
        two = by.get((robot, fam, planner, 2))
        if w != 1 or two is None:
            continue
        pr, n = paired_ratio(one, two)
        out.append({"robot": robot, "family": fam, "planner": planner, "median_1_worker": one["time_median"],
                    "median_2_workers": two["time_median"],
                    "speedup": one["time_median"] / two["time_median"] if two["time_median"] else None,
                    "paired_speedup": pr, "paired_n": n, "success_1_worker": one["success_rate"],
                    "success_2_workers": two["success_rate"],
                    "note": "" if n else "no problem solved by both: the ratio is of timeouts, not a speed-up"})
    return out


def targets(summaries: list[dict], ratio_rows: list[dict], speed_rows: list[dict], service: dict | None) -> list[dict]:
    by = {(s["robot"], s["family"], s["planner"], s["workers"]): s for s in summaries}
    rows = []

    def add(what, value, limit, cmp, unit=""):
        ok = None if value is None else (value >= limit if cmp == ">=" else value <= limit)
        rows.append({"target": what, "value": value, "limit": limit, "cmp": cmp, "unit": unit, "met": ok})

    g = by.get(("armar3", "boxes6", "girrt", 2))
    if g:
        add("GIRRT armar3 boxes6 success", g["success_rate"], 0.99, ">=", "ratio")
        add("GIRRT armar3 boxes6 median", g["time_median"], 0.050, "<=", "s")
        add("GIRRT armar3 boxes6 p95", g["time_p95"], 0.250, "<=", "s")
        r = next((r for r in ratio_rows if (r["robot"], r["family"], r["planner"]) == ("armar3", "boxes6", "girrt")),
                 None)
        if r:
            add("GIRRT armar3 boxes6 median / OMPL peer median", r["ratio"], 0.5, "<=", "x")
    p = by.get(("armar3", "boxes6", "girrt_pick", 2))
    if p:
        add("GIRRT + 10 cm approach + 10 cm lift armar3 boxes6 success", p["success_rate"], 0.97, ">=", "ratio")
        add("GIRRT + 10 cm approach + 10 cm lift armar3 boxes6 median", p["time_median"], 0.100, "<=", "s")
    d = by.get(("dual_arm", "boxes6", "dagrrt", 2))
    if d:
        add("DAGRRT dual_arm boxes6 success", d["success_rate"], 0.97, ">=", "ratio")
        add("DAGRRT dual_arm boxes6 median", d["time_median"], 0.150, "<=", "s")
    sp = next((s for s in speed_rows if (s["robot"], s["family"]) == ("dual_arm", "boxes6")), None)
    if sp:
        add("DAGRRT dual_arm boxes6 speed-up 1 worker / 2 workers", sp["speedup"], 1.5, ">=", "x")
    for robot in ("talos", "g1"):  # issue 12: the humanoids as surely and fast as the presets
        for fam, limit in (("boxes6", 0.100), ("table_shelf", 0.250)):
            g = by.get((robot, fam, "girrt", 2))
            if g:
                add(f"GIRRT {robot} {fam} success", g["success_rate"], 0.99, ">=", "ratio")
                add(f"GIRRT {robot} {fam} median", g["time_median"], limit, "<=", "s")
        for fam in ("boxes6", "table_shelf"):
            d = by.get((robot, fam, "dagrrt", 2))
            if d:
                add(f"DAGRRT {robot} {fam} success", d["success_rate"], 0.97, ">=", "ratio")
                add(f"DAGRRT {robot} {fam} median", d["time_median"], 0.400, "<=", "s")
    if service and service.get("overhead_median") is not None:
        add("plan_grasp service overhead (median)", service["overhead_median"], 0.005, "<=", "s")
    return rows


def checks_per_robot(summaries: list[dict]) -> list[dict]:
    """Configurations checked per second of planning, per robot, over every case whose checks this
    process saw (not DAGRRT with its arm process), and the share that needed exact FCL."""
    out = []
    for robot in dict.fromkeys(s["robot"] for s in summaries):
        recs = [r for s in summaries if s["robot"] == robot for r in s["problems"] if not r.get("counts_partial")]
        t = sum(r["time"] for r in recs)
        n = sum(r["configs_checked"] for r in recs)
        if recs and t > 0:
            out.append({"robot": robot, "checks_per_s": n / t, "configs": n,
                        "exact_share": sum(r["exact_checks"] for r in recs) / n if n else None})
    return out


# ------------------------------------------------------------------------------------------ output
def ms(x) -> str:
    return "–" if x is None else f"{x * 1000:.0f}" if x >= 0.1 else f"{x * 1000:.1f}"


def fmt_rate(x) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def markdown(res: dict) -> str:
    m = res["meta"]
    lines = [f"## Planner benchmark — {m['date']} (commit {m['commit']}, {m['cpus']} CPUs, load "
             f"{m['load_start']}→{m['load_end']}, budget {m['budget']} s, {m['problems']} problems per case)", ""]
    lines += ["| robot | group | family | planner | n | success | median ms | p95 ms | median ok ms | median CPU ms "
              "| path len rad | checks/s | exact % | verified | failures |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in res["cases"]:
        fails = ", ".join(f"{k} {v}" for k, v in s["status_counts"].items() if k != "success") or "–"
        if s["overruns"]:
            fails += f"; {s['overruns']} over budget (max {s['time_max']:.2f} s)"
        if s["abandoned"]:
            fails += f"; abandoned after {s['n']} consecutive failures"
        v = s["verified"]
        name = s["planner"] + ("" if s["workers"] == 2 else f" (workers={s['workers']})")
        if s["planner"] == "dagrrt" and s["workers"] >= 2 and s.get("parallel"):
            name += " (thread + worker process)" if s["parallel"] == "process" else f" ({s['workers']} threads)"
        plen = "–" if s["path_length_median"] is None else f"{s['path_length_median']:.2f}"
        cps = "–" if s["checks_per_s"] is None else f"{s['checks_per_s']:,.0f}"
        exact = "–" if s["exact_share"] is None else f"{100 * s['exact_share']:.0f}"
        lines.append(f"| {s['robot']} | {s['group']} | {s['family']} | {name} | {s['n']} | "
                     f"{fmt_rate(s['success_rate'])} "
                     f"| {ms(s['time_median'])} | {ms(s['time_p95'])} | {ms(s['time_median_success'])} | "
                     f"{ms(s['cpu_median'])} | {plen} | "
                     f"{cps} | {exact} | {v['valid']}/{v['checked']} | {fails} |")
    if res["skipped"]:
        lines += ["", "Skipped: " + "; ".join(f"{k}: {v}" for k, v in res["skipped"].items())]
    per_robot = checks_per_robot(res["cases"])
    if per_robot:
        def share(c: dict) -> str:
            return "–" if c["exact_share"] is None else f"{100 * c['exact_share']:.0f}"
        lines += ["", "Collision checks per robot (every case this process saw): " + "; ".join(
            f"{c['robot']} {c['checks_per_s']:,.0f}/s ({share(c)} % exact)" for c in per_robot)]
    if res["ratios"]:
        lines += ["", "### Ours / OMPL peer (same problems; peer = IK + RRTConnect + simplifySolution + timing)", "",
                  "| robot | family | ours | ours median ms | peer median ms | ratio | paired ratio (n) | "
                  "peer IK+solve median ms | ratio vs IK+solve | success ours / peer |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for r in res["ratios"]:
            pr = "–" if r["paired_ratio"] is None else f"{r['paired_ratio']:.2f} ({r['paired_n']})"
            rc = "–" if r["ratio_vs_peer_core"] is None else f"{r['ratio_vs_peer_core']:.2f}"
            lines.append(f"| {r['robot']} | {r['family']} | {r['planner']} | {ms(r['ours_median'])} | "
                         f"{ms(r['peer_median'])} | {r['ratio']:.2f} | {pr} | {ms(r['peer_core_median'])} | {rc} | "
                         f"{fmt_rate(r['ours_success'])} / {fmt_rate(r['peer_success'])} |")
    if res["speedups"]:
        lines += ["", "### DAGRRT parallel speed-up (same problems, workers=1 vs workers=2)", "",
                  "| robot | family | median 1 worker ms | median 2 workers ms | speed-up | paired (n) | "
                  "success 1 / 2 |"
                  " note |", "|---|---|---|---|---|---|---|---|"]
        for s in res["speedups"]:
            pr = "–" if s["paired_speedup"] is None else f"{s['paired_speedup']:.2f} ({s['paired_n']})"
            sp = "–" if s["speedup"] is None else f"{s['speedup']:.2f}"
            lines.append(f"| {s['robot']} | {s['family']} | {ms(s['median_1_worker'])} | {ms(s['median_2_workers'])} | "
                         f"{sp} | {pr} | {fmt_rate(s['success_1_worker'])} / {fmt_rate(s['success_2_workers'])} | "
                         f"{s['note']} |")
    sv = res.get("service")
    if sv:
        lines += ["", "### plan_grasp service round trip (node in its own process)", ""]
        if sv.get("error"):
            lines.append(f"not measured: {sv['error']}")
        else:
            lines += ["| calls | success | round trip median ms | planning_time median ms | overhead median ms | "
                      "overhead p95 ms | overhead max ms |", "|---|---|---|---|---|---|---|",
                      f"| {sv['calls']} | {sv['successes']}/{sv['calls']} | {ms(sv['round_trip_median'])} | "
                      f"{ms(sv['planning_time_median'])} | {sv['overhead_median'] * 1000:.2f} | "
                      f"{sv['overhead_p95'] * 1000:.2f} | {sv['overhead_max'] * 1000:.2f} |"]
    if res["targets"]:
        lines += ["", f"### Targets (this machine, budget {m['budget']} s; the targets are stated for 5 s)", "",
                  "| target | value | limit | met |", "|---|---|---|---|"]
        for t in res["targets"]:
            u = t["unit"]

            def show(x):
                if x is None:
                    return "–"
                return f"{x * 100:.0f} %" if u == "ratio" else f"{x * 1000:.1f} ms" if u == "s" else f"{x:.2f}x"
            met = "–" if t["met"] is None else ("yes" if t["met"] else "**no**")
            lines.append(f"| {t['target']} | {show(t['value'])} | {t['cmp']} {show(t['limit'])} | {met} |")
    lines += ["", "Times: planning_time of every attempt (failures at the time they returned, timeouts ≈ budget); "
              "'median ok' = successes only. checks/s = configurations checked by the request's collision checkers "
              "/ planning time ('–' where a DAGRRT arm search runs in a worker process, whose checks and CPU "
              "time this process does not see). Peer: " + m["peer"] + "."]
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = [r for r in ROBOTS if any(s["robot"] == r for s in res["cases"])]
    if not robots:
        return
    colors = {p: c for p, c in zip(PLANNERS + ("dagrrt_w1",), plt.get_cmap("tab10").colors)}
    fig, axes = plt.subplots(len(robots), 1, figsize=(11, 3.6 * len(robots)), squeeze=False)
    for ax, robot in zip(axes[:, 0], robots):
        cases = [s for s in res["cases"] if s["robot"] == robot]
        fams = [f for f in ALL_FAMILIES if any(s["family"] == f for s in cases)]
        names = []
        for s in cases:
            nm = s["planner"] + ("" if s["workers"] == 2 else f"_w{s['workers']}")
            if nm not in names:
                names.append(nm)
        width = 0.8 / max(1, len(names))
        for j, nm in enumerate(names):
            for i, fam in enumerate(fams):
                s = next((s for s in cases if s["family"] == fam
                          and s["planner"] + ("" if s["workers"] == 2 else f"_w{s['workers']}") == nm), None)
                if s is None or not s["problems"]:
                    continue
                t = np.maximum([r["time"] for r in s["problems"]], 1e-4)
                x = i - 0.4 + width * (j + 0.5)
                bp = ax.boxplot([t], positions=[x], widths=width * 0.85, patch_artist=True, showfliers=True,
                                flierprops={"markersize": 2}, medianprops={"color": "black"})
                for b in bp["boxes"]:
                    b.set_facecolor(colors.get(nm, "grey"))
                    b.set_alpha(0.75)
                ax.text(x, 0.97, f"{100 * s['success_rate']:.0f}%", transform=ax.get_xaxis_transform(),
                        ha="center", va="top", fontsize=7)
        ax.set_yscale("log")
        lo = min([r["time"] for s in cases for r in s["problems"]] + [0.01])
        ax.set_ylim(max(1e-4, lo * 0.7), res["meta"]["budget"] * 2.5)
        ax.axhline(res["meta"]["budget"], color="grey", ls="--", lw=0.8)
        ax.set_xticks(range(len(fams)))
        ax.set_xticklabels(fams)
        ax.set_xlim(-0.5, len(fams) - 0.5)
        ax.set_ylabel("planning time [s] (log)")
        ax.set_title(f"{robot}: planning time per attempt (failures at their time; dashed = budget; % = success)",
                     fontsize=9)
        ax.legend(handles=[plt.Rectangle((0, 0), 1, 1, color=colors.get(nm, "grey"), alpha=0.75) for nm in names],
                  labels=names, fontsize=7, loc="lower left", ncol=min(7, len(names)))
        ax.grid(axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------------------------------ main
def git_commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except Exception:  # noqa: BLE001
        return "unknown"


def hms(s: float) -> str:
    s = int(max(0, s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def load_avg() -> str:
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except OSError:
        return "?"


def run_service(args, out_dir: Path) -> dict:
    out = out_dir / "service.json"
    cmd = [sys.executable, str(Path(__file__).resolve().parent / "bench_service.py"),
           "--calls", str(args.service_calls), "--budget", str(args.budget), "--out", str(out)]
    env = child_environment()
    print(f"\n== plan_grasp service round trip: {' '.join(cmd[1:])}", flush=True)
    try:
        p = subprocess.run(cmd, env=env, timeout=120 + args.service_calls * (args.budget + 2))
    except subprocess.TimeoutExpired:
        return {"error": "bench_service.py timed out"}
    if p.returncode != 0 or not out.exists():
        return {"error": f"bench_service.py exited with code {p.returncode}"}
    return json.loads(out.read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--robots", default=",".join(ROBOTS))
    ap.add_argument("--families", default=",".join(FAMILIES), help="default: the first four; also "
                    + ", ".join(PICK_FAMILIES))
    ap.add_argument("--planners", default=",".join(PLANNERS), help="girrt, rrt, goal_biased_rrt, rrt_connect, rc_rrt, "
                    "ompl (the peer), dagrrt")
    ap.add_argument("--matrix", choices=("default", "full"), default="default")
    ap.add_argument("--problems", type=int, default=None, help="problems per case (default 50; --quick: 2)")
    ap.add_argument("--budget", type=float, default=None, help="seconds per problem (default 5; --quick: 2)")
    ap.add_argument("--verify", type=int, default=None, help="verify_plan on the first K successes of each case "
                    "(default 5; --quick: 1)")
    ap.add_argument("--quick", action="store_true", help="CI smoke: 2 problems per case, 2 s budget, 5 service calls")
    ap.add_argument("--no-service", action="store_true", help="skip the plan_grasp service round trip")
    ap.add_argument("--service-calls", type=int, default=None, help="default 30; --quick: 5")
    ap.add_argument("--abandon-after", type=int, default=10, help="stop a case whose first K attempts all failed "
                    "(reported as abandoned; 0 = never; default 10)")
    ap.add_argument("--no-plot", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"), help="output directory")
    a = ap.parse_args(argv)
    # steady-state figures: each robot's first check builds its pair tables (as a planning process has them
    # after its first plans; the node builds them in the background instead, pair_tables.BUILDER)
    pair_tables.build_in_background(False)
    compiled.warm_all()  # every compiled kernel loaded before timing, as the node does before its first plan
    a.problems = a.problems or (2 if a.quick else 50)
    a.budget = a.budget or (2.0 if a.quick else 5.0)
    a.verify = a.verify if a.verify is not None else (1 if a.quick else 5)
    a.service_calls = a.service_calls or (5 if a.quick else 30)
    split = lambda s: [x.strip() for x in s.split(",") if x.strip()]  # noqa: E731
    robots, families, planners = split(a.robots), split(a.families), split(a.planners)
    for name, vals, known in (("robot", robots, ROBOTS), ("family", families, ALL_FAMILIES),
                              ("planner", planners, PLANNERS)):
        bad = [v for v in vals if v not in known]
        if bad:
            ap.error(f"unknown {name}(s) {bad}; known: {', '.join(known)}")
    cases = build_matrix(a.matrix, robots, families, planners)
    out_dir = Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not cases and a.no_service:
        print("nothing to run: the filters leave no case of the matrix (try --matrix full)")
        return 2

    from ompl_peer import PEER_DESCRIPTION, ompl_version

    meta = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "commit": git_commit(),
            "cpus": os.cpu_count(), "machine": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__, "ompl": ompl_version(), "load_start": load_avg(), "load_end": None,
            "budget": a.budget, "problems": a.problems, "matrix": a.matrix, "quick": a.quick, "peer": PEER_DESCRIPTION,
            "time_definition": "plan.planning_time of every attempt; failures counted at the time they returned",
            "robots": {r: SPECS[r].note for r in robots}}
    res = {"meta": meta, "cases": [], "skipped": {}, "ratios": [], "speedups": [], "service": None, "targets": []}

    n_plans = len(cases) * a.problems
    prior = sum(PRIOR_SECONDS.get(c.planner, 1.0) * a.problems for c in cases)
    print(f"== planner benchmark: {len(cases)} cases, up to {n_plans} plans, budget {a.budget} s; first estimate "
          f"{hms(prior)} (worst case, every plan at the budget: {hms(n_plans * a.budget)}); load {meta['load_start']}",
          flush=True)
    if prior > 1800:
        print("   note: more than 30 min; narrow it with --robots/--families/--planners or --problems", flush=True)

    robots_cache: dict[str, RobotModel | str] = {}  # the robot, or why it could not be loaded
    problem_cache: dict[tuple[str, str, str], ProblemSet] = {}
    measured: dict[tuple[str, str], list[float]] = {}  # (robot, planner) -> per-plan seconds
    t_start = time.perf_counter()
    tty = sys.stdout.isatty()
    warmed: set[tuple[str, str, int]] = set()
    planners_cache: dict[tuple[str, int], InstrumentedPlanner] = {}

    def eta(remaining_cases, current_left: int, current_est: float) -> float:
        est = current_left * current_est
        for c in remaining_cases:
            m = measured.get((c.robot, c.planner))
            est += (np.mean(m) if m else PRIOR_SECONDS.get(c.planner, 1.0)) * a.problems
        return est

    for ci, case in enumerate(cases):
        spec = SPECS[case.robot]
        if case.robot not in robots_cache:
            t = time.perf_counter()
            try:
                robots_cache[case.robot] = load_robot(case.robot)
                print(f"   loaded {case.robot} in {time.perf_counter() - t:.1f} s (planner_setup's SRDF included "
                      "where it writes one)", flush=True)
            except Exception as e:  # noqa: BLE001 - a robot that cannot be loaded skips its cases, not the run
                robots_cache[case.robot] = f"{type(e).__name__}: {e}"
        robot = robots_cache[case.robot]
        if isinstance(robot, str):
            res["skipped"][case.key] = f"the robot could not be loaded ({robot})"
            print(f"[{ci + 1}/{len(cases)}] {case.key}: SKIPPED — the robot could not be loaded: {robot}", flush=True)
            continue
        hand = "both" if case.dual else "left"
        pkey = (case.robot, case.family, hand)
        if pkey not in problem_cache:
            t = time.perf_counter()
            problem_cache[pkey] = make_problems(robot, spec, case.family, hand, a.problems)
            ps = problem_cache[pkey]
            print(f"   {case.robot}/{case.family} (hand={hand}): {len(ps.problems)} problems built in "
                  f"{time.perf_counter() - t:.1f} s" + (f", {len(ps.skipped)} seed(s) skipped" if ps.skipped else ""),
                  flush=True)
        probs = problem_cache[pkey]
        if not probs.problems:
            reason = next(iter(probs.skipped.values()), "no problem")
            res["skipped"][case.key] = f"no scenario could be built ({reason})"
            print(f"[{ci + 1}/{len(cases)}] {case.key}: SKIPPED — {reason}", flush=True)
            continue
        pkey_gp = (case.robot, case.workers)
        if pkey_gp not in planners_cache:  # one per robot and worker count: DAGRRT's arm process starts once
            planners_cache[pkey_gp] = InstrumentedPlanner(robot, workers=case.workers)
        gp = planners_cache[pkey_gp]
        wkey = (case.robot, case.planner, case.workers)
        if wkey not in warmed:  # first-use costs (caches, imports, the arm process) stay out of the timings
            warmed.add(wkey)
            try:
                if case.dual and hasattr(gp, "warm_up"):
                    gp.warm_up()
                sc = make_scenario(robot, "empty", WARMUP_SEED, left_group=spec.left, right_group=spec.right, hand=hand)
                run_one(case, spec, robot, gp, Problem(WARMUP_SEED, sc), min(1.0, a.budget), False)
            except Exception as e:  # noqa: BLE001
                print(f"   warm-up of {case.key} failed: {e!r}", flush=True)
        recs: list[dict] = []
        head = f"[{ci + 1}/{len(cases)}] {case.key}"
        for k, prob in enumerate(probs.problems):
            verify = sum("verify_problems" in r for r in recs) < a.verify
            rec = run_one(case, spec, robot, gp, prob, a.budget, verify)
            recs.append(rec)
            measured.setdefault((case.robot, case.planner), []).append(rec["wall"])
            done = len(recs)
            hopeless = a.abandon_after and done == a.abandon_after < len(probs.problems) and not any(
                r["ok"] for r in recs)
            if tty or hopeless or done == len(probs.problems) or done % 10 == 0:
                nok = sum(r["ok"] for r in recs)
                med = np.median([r["time"] for r in recs])
                left = eta(cases[ci + 1:], len(probs.problems) - done, float(np.mean([r["wall"] for r in recs])))
                msg = (f"{head}: {done}/{len(probs.problems)} ok {nok} median {med * 1000:.0f} ms | elapsed "
                       f"{hms(time.perf_counter() - t_start)} ETA {hms(left)}")
                if tty and done < len(probs.problems) and not hopeless:
                    print("\r" + msg[:150].ljust(150), end="", flush=True)
                else:
                    print(("\r" if tty else "") + msg, flush=True)
            if hopeless:
                print(f"    abandoned: the first {done} attempts all failed (--abandon-after {a.abandon_after})",
                      flush=True)
                break
        s = summarize(case, spec, probs, recs, a.budget, getattr(gp, "parallel", None) if case.dual else None)
        res["cases"].append(s)
        v = s["verified"]
        print(f"    success {fmt_rate(s['success_rate'])}, median {ms(s['time_median'])} ms, "
              f"p95 {ms(s['time_p95'])} ms, "
              f"path {s['path_length_median'] or 0:.2f} rad, "
              + ("checks/s not seen (arm process), " if s["checks_per_s"] is None else
                 f"{s['checks_per_s']:,.0f} checks/s, ") +
              f"verified {v['valid']}/{v['checked']}" + (f", failures {s['status_counts']}" if s["successes"] < s["n"]
                                                          else ""), flush=True)
        if v["problems"]:
            print(f"    VERIFY PROBLEMS: {v['problems'][:3]}", flush=True)
        res["ratios"], res["speedups"] = ratios(res["cases"]), speedups(res["cases"])
        out_dir.mkdir(parents=True, exist_ok=True)  # (out/ is shared: someone may have removed it meanwhile)
        (out_dir / "results.json").write_text(json.dumps(res, indent=1, default=str))  # partial results survive

    for gp in planners_cache.values():  # stop DAGRRT's arm process before the service part
        if hasattr(gp, "close"):
            gp.close()
    if not a.no_service:
        res["service"] = run_service(a, out_dir)
    meta["load_end"] = load_avg()
    meta["elapsed_s"] = time.perf_counter() - t_start
    res["ratios"], res["speedups"] = ratios(res["cases"]), speedups(res["cases"])
    res["targets"] = targets(res["cases"], res["ratios"], res["speedups"], res["service"])
    res["checks_per_robot"] = checks_per_robot(res["cases"])
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "results.json").write_text(json.dumps(res, indent=1, default=str))
    table = markdown(res)
    (out_dir / "table.md").write_text(table)
    if not a.no_plot and res["cases"]:
        plot(res, out_dir / "bench.png")
    print("\n" + table)
    print(f"wrote {out_dir / 'results.json'}, {out_dir / 'table.md'}"
          + ("" if a.no_plot or not res["cases"] else f", {out_dir / 'bench.png'}")
          + f" in {hms(meta['elapsed_s'])}", flush=True)
    return 0


if __name__ == "__main__":
    from ompl_peer import exit_after_ompl

    exit_after_ompl(main())
