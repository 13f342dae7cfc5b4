#!/usr/bin/env python3
"""plan_to_state benchmark: home <-> random free joint states, GraspPlanner.plan_to_state beside the OMPL
peer (benchmarks/ompl_peer.plan_ompl_to_state) on the same problems, same run.

    make bench                                            # runs this after bench_planners.py
    .venv/bin/python benchmarks/bench_to_state.py --robots armar3 --problems 20

Problems: problem k of a robot is the boxes6 scene of `make_scenario(robot, "boxes6", seed=k, hand="left")`
(the grasp object stays in the scene as an obstacle) and a joint goal for the single-arm group drawn
uniformly within its limits (seeded by k) that the planner's own motion validator finds free (padding
included: a goal it refuses would not be a fair problem); even k go home -> goal, odd k goal -> home.
Each problem is proven solvable first by the plain reference RRT-Connect (scenarios.reference_plan,
no margins, 1 cm edge sampling, --proof seconds); unproven ones are skipped and counted.
Per problem both planners get --budget seconds; time = planning_time (set-up, search, shortcut or
simplification, time parameterization). Every success is verified by core.verification.verify_plan
(exact meshes, 1 cm, limits) and its last configuration compared with the goal (1e-6 rad).
Outputs: a table on stdout and out/bench/to_state.md, out/bench/to_state.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_planners import SPECS, load_robot, pct  # noqa: E402
from ompl_peer import plan_ompl_to_state  # noqa: E402

from humanoid_planner.core.pipeline.planner import GraspPlanner, StatePlanRequest  # noqa: E402
from humanoid_planner.core.verification import verify_plan  # noqa: E402
from humanoid_planner.scenarios import make_scenario, reference_plan  # noqa: E402

ROBOTS = ("armar3", "talos")
GOAL_TRIES = 200  # random draws per problem for a free goal


def make_problems(robot, group: str, spec, n: int, proof: float, gp: GraspPlanner) -> tuple[list[dict], dict]:
    """(problems, skipped seed -> reason): n proven-solvable home <-> goal problems."""
    idx = robot.group_joint_indices(group)
    lo, hi = robot.lower[idx], robot.upper[idx]
    problems: list[dict] = []
    skipped: dict[int, str] = {}
    seed = 0
    while len(problems) < n and seed < 3 * n + 5:
        try:
            sc = make_scenario(robot, "boxes6", seed, left_group=spec.left, right_group=spec.right, hand="left",
                               proof_budget=None)
        except ValueError as e:
            skipped[seed] = str(e)
            seed += 1
            continue
        rng = np.random.default_rng([seed, 7])
        motion = gp.problems.motion(sc.scene, group, robot.home, "", ())
        cand = rng.uniform(lo, hi, size=(GOAL_TRIES, len(idx)))
        free = np.flatnonzero(motion.check_configs(cand))
        if len(free) == 0:
            skipped[seed] = "no free goal in the scene"
            seed += 1
            continue
        goal = robot.home.copy()
        goal[idx] = cand[free[0]]
        start, end = (robot.home.copy(), goal) if seed % 2 == 0 else (goal, robot.home.copy())
        if not reference_plan(robot, sc.scene, (group,), start, end[idx][None], proof, seed).ok:
            skipped[seed] = f"the reference RRT-Connect did not solve it in {proof:g} s"
            seed += 1
            continue
        problems.append({"seed": seed, "scene": sc.scene, "start": start, "goal": end})
        seed += 1
    return problems, skipped


def run(plan_fn, robot, group: str, prob: dict, budget: float, gp: GraspPlanner) -> dict:
    idx = robot.group_joint_indices(group)
    goal = {robot.joint_names[i]: float(prob["goal"][i]) for i in idx}
    req = StatePlanRequest(group, prob["start"].copy(), goal=goal, timeout=budget, seed=prob["seed"])
    plan = plan_fn(gp, prob["scene"], req)
    rec = {"seed": prob["seed"], "status": plan.status.value, "ok": plan.ok, "time": plan.planning_time,
           "message": plan.message[:200]}
    if plan.ok:
        problems = verify_plan(robot, prob["scene"], (group,), prob["start"], plan, ())
        if np.max(np.abs(plan.trajectory.positions[-1] - prob["goal"][idx])) > 1e-6:
            problems.append("the trajectory does not end at the goal")
        rec["verify_problems"] = problems
    return rec


def summarize(recs: list[dict], n_skipped: int) -> dict:
    ok = [r for r in recs if r["ok"]]
    times = [r["time"] for r in recs]
    return {"problems": len(recs), "skipped": n_skipped, "solved": len(ok),
            "success": len(ok) / len(recs) if recs else None,
            "median": pct(times, 50), "p95": pct(times, 95),
            "verified": sum(1 for r in ok if not r.get("verify_problems")),
            "invalid": [r["seed"] for r in ok if r.get("verify_problems")]}


def paired(a: list[dict], b: list[dict]) -> float | None:
    """Median over problems both solved of ours / peer."""
    ratios = [x["time"] / y["time"] for x, y in zip(a, b) if x["ok"] and y["ok"] and y["time"] > 0]
    return float(np.median(ratios)) if ratios else None


def ms(x: float | None) -> str:
    return "-" if x is None else f"{1000 * x:.0f} ms" if x >= 0.01 else f"{1000 * x:.1f} ms"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", default=",".join(ROBOTS))
    ap.add_argument("--problems", type=int, default=50)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--proof", type=float, default=10.0, help="seconds the reference RRT-Connect gets per problem")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    args = ap.parse_args(argv)

    def ours(gp, scene, req):
        return gp.plan_to_state(scene, req)

    rows = []
    for name in args.robots.split(","):
        spec = SPECS[name]
        robot = load_robot(name)
        gp = GraspPlanner(robot)
        try:
            probs, skipped = make_problems(robot, spec.group, spec, args.problems, args.proof, gp)
            recs = {"ours": [], "ompl": []}
            for prob in probs:
                recs["ours"].append(run(ours, robot, spec.group, prob, args.budget, gp))
                recs["ompl"].append(run(plan_ompl_to_state, robot, spec.group, prob, args.budget, gp))
        finally:
            gp.close()
        for who, rs in recs.items():
            rows.append({"robot": name, "group": spec.group, "planner": who, **summarize(rs, len(skipped)),
                         "paired_ratio": paired(recs["ours"], recs["ompl"]) if who == "ours" else None,
                         "records": rs, "skipped_seeds": skipped})
    head = "| robot / group | planner | solved / proven | median | p95 | verified | ours / peer (paired median) |"
    lines = [head, "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = "" if r["paired_ratio"] is None else f"{r['paired_ratio']:.2f}"
        lines.append(f"| {r['robot']} / {r['group']} | {'plan_to_state' if r['planner'] == 'ours' else 'OMPL RRT-Connect'}"
                     f" | {r['solved']}/{r['problems']} | {ms(r['median'])} | {ms(r['p95'])} | {r['verified']}/"
                     f"{r['solved']} | {ratio} |")
    table = "\n".join(lines)
    print(table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "to_state.md").write_text(table + "\n")
    meta = {"budget": args.budget, "proof": args.proof, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    (out / "to_state.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=str))
    bad = [r for r in rows if r["invalid"]]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
