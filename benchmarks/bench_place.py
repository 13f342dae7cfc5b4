#!/usr/bin/env python3
"""plan_place benchmark: an object held after a pick carried to one of 5 candidate placements on a shelf
beside boxes6 clutter, lowered the last 5 cm straight down, the hand backed away; GraspPlanner's
plan_place (GIRRT) beside the OMPL peer (benchmarks/ompl_peer.plan_ompl_place) on the same problems,
same run.

    make bench                                            # runs this after bench_planners.py
    .venv/bin/python benchmarks/bench_place.py --problems 20

Problems: problem k is the boxes6 scene of `make_scenario(armar3, "boxes6", seed=k, hand="left")`; its
object is picked by plan_grasp (10 cm approach along the hand axis, 10 cm lift; a failed pick skips
the seed) and attached to the hand where the grasp holds it; the start is the end of the lift. Beside
the clutter stands a shelf (SHELF: a board and a second board above it); 5 placements are drawn on the
board (position uniform on it, the object upright, turned about the vertical by up to ±YAW) among those
clear of everything but the board. Each problem is proven solvable first: a placement counts when one
of the collision-free IK solutions of its TCP goal (scenarios.grasp_solutions) can set the object down
and leave it — the descent run backwards, straight up by the approach's distance (at least its
min_distance) with the object attached and allowed to touch the board, and the retreat of the hand
alone after the release, both checked as plan_place checks them (place.PlaceLines.pre_place: the same
straight lines and validators, with the planner's padding); then the plain reference RRT-Connect
(scenarios.reference_plan: no margins, 1 cm edge sampling, --proof seconds) must join the start to one
of those solutions' pre-place configurations (the top of the descent), the object attached. Problems
that fail either are skipped and counted, with the reason.
Both planners get --budget seconds and the same request: pre_place_approach 5 cm down (at least 5 cm),
post_place_retreat 10 cm back along the hand's axis (at least 5 cm). Time = planning_time (set-up, search,
descent, shortcut or simplification, timing, retreat). Every success is verified by
core.verification.verify_place (exact meshes at 1 cm: the arm and the object clear of everything, the
object touching only the board and only during the descent, the placement reached within 2 mm / 1°,
the descent and the retreat straight, the retreat free with the object released, ending clear of it).
Outputs: a table on stdout and out/bench/place.md, out/bench/place.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_planners import SPECS, load_robot  # noqa: E402
from bench_to_state import ms, paired, summarize  # noqa: E402
from ompl_peer import plan_ompl_place  # noqa: E402

from humanoid_planner.core.collision.checker import CollisionChecker  # noqa: E402
from humanoid_planner.core.grasp.approach import approach_axis  # noqa: E402
from humanoid_planner.core.pipeline.place import (PlaceLines, PlaceRequest, object_in_tcp, plan_place, setup,  # noqa: E402
                                                 supports)
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest  # noqa: E402
from humanoid_planner.core.planners.cartesian import GripperTranslation  # noqa: E402
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot, attach  # noqa: E402
from humanoid_planner.core.verification import verify_place  # noqa: E402
from humanoid_planner.scenarios import (MAX_REFERENCE_GOALS, OBJECT_ID, grasp_solutions, make_scenario,  # noqa: E402
                                        reference_plan, shelf)

ROBOT = "armar3"
PLACES = 5
YAW = np.radians(30.0)
DOWN = np.array([0.0, 0.0, -1.0])
APPROACH = GripperTranslation((0.0, 0.0, 0.0), 0.05, 0.05)  # zero direction: the default, the planning frame's -z
RETREAT = 0.10, 0.05  # the retreat back along the hand's axis (TCP frame): desired, least (m)
PICK = 0.10, 0.05  # the pick's approach and lift: desired, least (m)
LIFT = (0.0, 0.0, 1.0)


def picked(gp: GraspPlanner, robot, group: str, sc, seed: int):
    """(start at the end of the lift, the object attached where the grasp holds it), or None when the pick fails."""
    plan = gp.plan_grasp(sc.scene, GraspPlanRequest(
        group, robot.home.copy(), sc.object_pose, sc.grasps, object_id=OBJECT_ID, seed=seed, timeout=10.0,
        approach=GripperTranslation(tuple(approach_axis(robot, group)), *PICK),
        retreat=GripperTranslation(LIFT, *PICK, robot.root_link)))
    if not plan.ok:
        return None
    idx, tip = robot.group_joint_indices(group), robot.group(group).tip_link
    q_grasp, q_up = robot.home.copy(), robot.home.copy()
    q_grasp[idx], q_up[idx] = plan.trajectory.positions[-1], plan.retreat_trajectory.positions[-1]
    return q_up, attach(sc.scene.get(OBJECT_ID), tip, robot.link_poses(q_grasp, [tip])[0], robot.hand_links(group))


def draw_placements(scene: SceneSnapshot, att, R: np.ndarray, board, rng: np.random.Generator) -> list[np.ndarray]:
    """PLACES placements on the board's top, clear of everything else (at most 200 draws)."""
    half_h = att.shapes[0].dims[2] / 2
    size = np.array(board.shapes[0].dims)
    c = board.pose[:3, 3]
    out: list[np.ndarray] = []
    for _ in range(200):
        P = np.eye(4)
        yaw = rng.uniform(-YAW, YAW)
        Rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        P[:3, :3] = Rz @ R
        xy = c[:2] + rng.uniform(-1, 1, 2) * (size[:2] / 2 - 0.05)
        P[:3, 3] = (*xy, c[2] + size[2] / 2 + half_h)
        held, hits = supports(scene, att, P)
        if held == {board.id} and not hits:
            out.append(P)
            if len(out) == PLACES:
                break
    return out


def make_problems(robot, group: str, spec, n: int, proof: float, gp: GraspPlanner) -> tuple[list[dict], dict]:
    """(problems, skipped seed -> reason): n proven-solvable place problems."""
    problems: list[dict] = []
    skipped: dict[int, str] = {}
    seed = 0
    while len(problems) < n and seed < 3 * n + 5:
        why = _problem(robot, group, spec, seed, proof, gp, problems)
        if why:
            skipped[seed] = why
        seed += 1
    return problems, skipped


def _problem(robot, group, spec, seed, proof, gp, problems) -> str | None:
    try:
        sc = make_scenario(robot, "boxes6", seed, left_group=spec.left, right_group=spec.right, hand="left",
                           proof_budget=None)
    except ValueError as e:
        return str(e)
    held = picked(gp, robot, group, sc, seed)
    if held is None:
        return "the pick failed"
    q_up, att = held
    fixtures = shelf(robot)
    scene = SceneSnapshot(1, robot.root_link, tuple(o for o in sc.scene.objects if o.id != OBJECT_ID) + fixtures,
                          attached=(att,))
    T_tcp_obj = object_in_tcp(robot, att, group, q_up)
    R = (robot.link_poses(q_up, [robot.group(group).tip_link])[0] @ T_tcp_obj)[:3, :3]
    board = fixtures[0]
    places = draw_placements(scene, att, R, board, np.random.default_rng([seed, 11]))
    if len(places) < PLACES:
        return f"only {len(places)} placements on the board are clear of the clutter"
    # the proof: IK solutions of the placements' TCP goals whose descent and retreat are free, then the
    # reference RRT-Connect to the tops of their descents, the object attached
    goal_tcp = [GraspSpec(f"p{i}", "", P @ np.linalg.inv(T_tcp_obj)) for i, P in enumerate(places)]
    q, which = grasp_solutions(robot, group, np.eye(4), goal_tcp)
    proof_scene = replace(scene, attached=(replace(att, touch_links=att.touch_links | {board.id}),))
    if len(q):
        free = CollisionChecker(robot, proof_scene, group, q_up).check_configs(q)
        q, which = q[free], which[free]
    if len(q) == 0:
        return "no placement has a collision-free IK solution"
    lines = PlaceLines(gp, setup(robot, scene, request(robot, group, q_up, places, seed, 0.0)), group)
    tops, why = [], {}
    for qi, w in zip(q, which):
        top, why_not = lines.pre_place(qi, int(w))
        if top is None:
            why.setdefault(int(w), why_not)
        else:
            tops.append(top)
    if not tops:
        return "no IK solution of a placement can set the object down and leave it: " + "; ".join(
            f"place_poses[{w}]: {r}" for w, r in sorted(why.items())[:2])
    q = np.array(tops)
    goals = q[np.random.default_rng(seed).permutation(len(q))[:MAX_REFERENCE_GOALS]]
    if not reference_plan(robot, proof_scene, (group,), q_up, goals, proof, seed).ok:
        return f"the reference RRT-Connect did not solve it in {proof:g} s"
    problems.append({"seed": seed, "scene": scene, "start": q_up, "placements": places, "support": (board.id,)})
    return None


def request(robot, group: str, start: np.ndarray, places: list[np.ndarray], seed: int, budget: float) -> PlaceRequest:
    """The request both planners get (and the proof checks the lines of)."""
    # back out along the hand's axis: across it (ARMAR-III's TCP -z, the default) the hand would slide
    # along the object it let go of, which the retreat may not end touching
    retreat = GripperTranslation(tuple(-approach_axis(robot, group)), *RETREAT)
    return PlaceRequest(group, start.copy(), OBJECT_ID, places, timeout=budget, seed=seed, approach=APPROACH,
                        retreat=retreat)


def run(plan_fn, robot, group: str, prob: dict, budget: float, gp: GraspPlanner) -> dict:
    req = request(robot, group, prob["start"], prob["placements"], prob["seed"], budget)
    retreat = req.retreat
    plan = plan_fn(gp, prob["scene"], req)
    rec = {"seed": prob["seed"], "status": plan.status.value, "ok": plan.ok, "time": plan.planning_time,
           "message": plan.message[:200], "place_index": int(getattr(plan, "place_index", -1))}
    if plan.ok:
        try:
            rec["verify_problems"] = verify_place(
                robot, prob["scene"], group, prob["start"], plan, OBJECT_ID, prob["placements"][plan.place_index],
                prob["support"], DOWN, approach_min=APPROACH.min_distance - 1e-3,
                retreat_direction=retreat.direction, retreat_min=retreat.min_distance - 2e-3, retreat_in_tcp=True)
        except Exception as e:  # noqa: BLE001 - a crash of the checker is a finding, not a benchmark abort
            rec["verify_problems"] = [f"verify_place raised {e!r}"]
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=50)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--proof", type=float, default=10.0, help="seconds the reference RRT-Connect gets per problem")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    args = ap.parse_args(argv)

    spec = SPECS[ROBOT]
    robot = load_robot(ROBOT)
    gp = GraspPlanner(robot)
    try:
        probs, skipped = make_problems(robot, spec.group, spec, args.problems, args.proof, gp)
        recs = {"ours": [], "ompl": []}
        for prob in probs:
            recs["ours"].append(run(plan_place, robot, spec.group, prob, args.budget, gp))
            recs["ompl"].append(run(plan_ompl_place, robot, spec.group, prob, args.budget, gp))
    finally:
        gp.close()
    rows = [{"robot": ROBOT, "group": spec.group, "planner": who, **summarize(rs, len(skipped)),
             "paired_ratio": paired(recs["ours"], recs["ompl"]) if who == "ours" else None,
             "records": rs, "skipped_seeds": skipped} for who, rs in recs.items()]
    head = ("| robot / group | planner | solved / proven | median | p95 | verified | ours / peer (paired median) |")
    lines = [head, "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = "" if r["paired_ratio"] is None else f"{r['paired_ratio']:.2f}"
        who = "plan_place (GIRRT)" if r["planner"] == "ours" else "OMPL RRT-Connect to IK goals"
        lines.append(f"| {r['robot']} / {r['group']} | {who} | {r['solved']}/{r['problems']} | {ms(r['median'])} | "
                     f"{ms(r['p95'])} | {r['verified']}/{r['solved']} | {ratio} |")
    table = "\n".join(lines)
    print(table)
    print(f"{len(skipped)} seeds skipped (not proven solvable or no pick): "
          + "; ".join(f"{s}: {w[:80]}" for s, w in list(skipped.items())[:5]))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "place.md").write_text(table + "\n")
    meta = {"budget": args.budget, "proof": args.proof, "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    (out / "place.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=str))
    return 1 if any(r["invalid"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
