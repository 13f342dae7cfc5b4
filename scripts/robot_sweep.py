#!/usr/bin/env python3
"""Robot sweep: every robot with arms in example-robot-data, loaded as the node loads it, planned on, verified.

For each robot: its own SRDF when that has the arm groups, else `planner_setup`'s (generate_srdf, merged with
the robot's SRDF when it ships one); RobotModel.from_urdf_srdf; a single-arm GIRRT grasp (object in front of
the left arm) and, with two arms, a DAGRRT dual grasp (object between the hands) on the scenarios' `empty`
family; each plan checked by core.verification.verify_plan against the exact meshes. Records load time,
setup time, first-plan time, success and every failure's message. Each robot runs in its own process (a
crash or a hang of one robot is a finding, not the end of the sweep).

    .venv/bin/python scripts/robot_sweep.py [--robots g1,h1,...] [--samples 1000] [--budget 5] [-o out.json]

Not part of `make test` (minutes of mesh loading); the README's "robots tried" table comes from it.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# name: (URDF, SRDF or None, left arm group, right arm group or None); relative to example-robot-data's robots/
ROBOTS: dict[str, tuple[str, str | None, str, str | None]] = {
    # humanoids
    "talos": ("talos_data/robots/talos_reduced.urdf", "talos_data/srdf/talos.srdf", "l_arm", "r_arm"),
    "talos_full": ("talos_data/robots/talos_full_v2.urdf", "talos_data/srdf/talos.srdf", "l_arm", "r_arm"),
    "g1": ("g1_description/urdf/g1_29dof_rev_1_0.urdf", None, "left_arm", "right_arm"),
    "g1_hand": ("g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf", None, "left_arm", "right_arm"),
    "romeo": ("romeo_description/urdf/romeo.urdf", "romeo_description/srdf/romeo.srdf", "left_arm", "right_arm"),
    "icub": ("icub_description/robots/icub.urdf", "icub_description/srdf/icub.srdf", "l_arm", "r_arm"),
    "icub_reduced": ("icub_description/robots/icub_reduced.urdf", "icub_description/srdf/icub.srdf", "l_arm",
                     "r_arm"),
    "alex_nub": ("alex_description/urdf/alex_nub_hands.urdf", "alex_description/srdf/alex_nub_hands.srdf",
                 "left_arm", "right_arm"),
    "simple_humanoid": ("simple_humanoid_description/urdf/simple_humanoid.urdf",
                        "simple_humanoid_description/srdf/simple_humanoid.srdf", "left_arm", "right_arm"),
    "human": ("human_description/robots/human.urdf", None, "left_arm", "right_arm"),
    # bimanual / mobile manipulators
    "baxter": ("baxter_description/urdf/baxter.urdf", "baxter_description/srdf/baxter_manipulation.srdf",
               "left_arm", "right_arm"),
    "pr2": ("pr2_description/urdf/pr2.urdf", "pr2_description/srdf/pr2.srdf", "left_arm", "right_arm"),
    "tiago_dual": ("tiago_description/robots/tiago_dual.urdf", None, "left_arm", "right_arm"),
    "tiago_pro": ("tiago_pro_description/robots/tiago_pro.urdf", None, "left_arm", "right_arm"),
    "centauro": ("centauro_description/urdf/centauro.urdf", "centauro_description/srdf/centauro.srdf", "left_arm",
                 "right_arm"),
    # single arms
    "panda": ("panda_description/urdf/panda.urdf", "panda_description/srdf/panda.srdf", "arm", None),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "ur_description/srdf/ur5.srdf", "arm", None),
    "kinova": ("kinova_description/robots/kinova.urdf", "kinova_description/srdf/kinova.srdf", "arm", None),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "xarm_description/srdf/xarm7.srdf", "arm", None),
    "z1": ("z1_description/urdf/z1.urdf", "z1_description/srdf/z1.srdf", "arm", None),
    "tiago": ("tiago_description/robots/tiago.urdf", None, "arm", None),
}


def _has_arms(robot, groups) -> bool:
    return all(g in robot.groups for g in groups if g)


def sweep_one(name: str, samples: int, budget: float) -> dict:
    """One robot: load, (planner_setup), single and dual grasp, verification. Never raises."""
    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.model.srdf_setup import generate_srdf
    from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
    from humanoid_planner.core.verification import verify_plan
    from humanoid_planner.scenarios import OBJECT_ID, example_robots_dir, make_scenario

    urdf, srdf, left, right = ROBOTS[name]
    d = example_robots_dir()
    rec: dict = {"robot": name, "urdf": urdf, "srdf": srdf}
    stage = "load"
    try:
        t0 = time.perf_counter()
        robot = RobotModel.from_urdf_srdf(d / urdf, d / srdf if srdf else None)
        rec["load_time"] = time.perf_counter() - t0
        rec["dof"] = len(robot.joint_names)
        if not _has_arms(robot, (left, right)):
            stage = "planner_setup"
            t0 = time.perf_counter()
            res = generate_srdf(d / urdf, d / srdf if srdf else None, samples=samples)
            rec["setup_time"] = time.perf_counter() - t0
            rec["srdf_source"] = "planner_setup" + (" + own" if srdf else "")
            left, right = ("left_arm", "right_arm") if len(res.arms) == 2 else ("arm", None)
            t0 = time.perf_counter()
            robot = RobotModel.from_urdf_srdf(d / urdf, res.srdf)
            rec["load_time"] = time.perf_counter() - t0
        else:
            rec["srdf_source"] = "own"
        if "home" not in robot.group_states and "half_sitting" in robot.group_states:
            robot.home = robot.state("half_sitting")  # the reference posture of the humanoids' SRDFs
        rec["groups"] = {g: len(robot.group_joint_indices(g)) for g in (left, right) if g}
        gp = GraspPlanner(robot, workers=1, parallel="thread")
        cases = [("single", left, "left" if right else "both")]
        if right:
            cases.append(("dual", None, "both"))
        for kind, group, hand in cases:
            stage = f"{kind} scenario"
            r: dict = {}
            rec[kind] = r
            if not right:
                r.update(ok=False, stage="scenario", message="not planned: scenarios.make_scenario needs two arms")
                continue
            try:
                sc = make_scenario(robot, "empty", 0, left_group=left, right_group=right or left, hand=hand)
            except ValueError as e:
                r.update(ok=False, stage="scenario", message=str(e)[:300])
                continue
            stage = f"{kind} plan"
            t0 = time.perf_counter()
            if kind == "dual":
                req = DualGraspPlanRequest(left, right, robot.home.copy(), sc.object_pose, sc.left_grasps,
                                           sc.right_grasps, OBJECT_ID, "dagrrt", timeout=budget, seed=0)
                plan = gp.plan_dual_grasp(sc.scene, req)
                groups = (left, right)
            else:
                grasps = sc.left_grasps if hand in ("left", "both") else sc.right_grasps
                req = GraspPlanRequest(group, robot.home.copy(), sc.object_pose, grasps, OBJECT_ID, "girrt", budget,
                                       seed=0)
                plan = gp.plan_grasp(sc.scene, req)
                groups = (group,)
            r.update(wall=time.perf_counter() - t0, status=plan.status.value, ok=bool(plan.ok),
                     message=plan.message[:300])
            if plan.ok:
                stage = f"{kind} verify"
                targets = tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps)
                r["verify_problems"] = verify_plan(robot, sc.scene, groups, robot.home, plan, targets,
                                                   object_id=OBJECT_ID)
    except Exception as e:  # noqa: BLE001 - a crash is the finding being recorded
        rec["error"] = {"stage": stage, "type": type(e).__name__, "message": str(e)[:500],
                        "trace": traceback.format_exc(limit=4)[-1500:]}
    return rec


def _child(name: str, samples: int, budget: float, q) -> None:
    q.put(sweep_one(name, samples, budget))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default=",".join(ROBOTS), help="comma-separated names (default: all)")
    ap.add_argument("--samples", type=int, default=1000, help="planner_setup's sampled configurations")
    ap.add_argument("--budget", type=float, default=5.0, help="planning budget per problem (s)")
    ap.add_argument("--timeout", type=float, default=600.0, help="per robot, whole (s)")
    ap.add_argument("-o", "--output", type=Path, help="JSON lines out")
    a = ap.parse_args(argv)
    ctx = mp.get_context("spawn")
    out = a.output.open("w") if a.output else None
    for name in a.robots.split(","):
        if name not in ROBOTS:
            print(f"unknown robot {name!r}; known: {', '.join(ROBOTS)}", file=sys.stderr)
            return 2
        q = ctx.Queue()
        p = ctx.Process(target=_child, args=(name, a.samples, a.budget, q))
        t0 = time.perf_counter()
        p.start()
        p.join(a.timeout)
        if p.is_alive():
            p.kill()
            rec = {"robot": name, "error": {"stage": "?", "type": "Timeout", "message": f"over {a.timeout} s"}}
        elif not q.empty():
            rec = q.get()
        else:
            rec = {"robot": name, "error": {"stage": "?", "type": "Crash", "message": f"exit code {p.exitcode}"}}
        rec["total_time"] = time.perf_counter() - t0
        line = json.dumps(rec)
        print(line, flush=True)
        if out:
            out.write(line + "\n")
            out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
