#!/usr/bin/env python3
"""Same seeds → same plans: a digest of every plan of a fixed, seeded problem set, to compare two commits.

    .venv/bin/python benchmarks/plan_digest.py > before.txt    # on the old commit
    .venv/bin/python benchmarks/plan_digest.py > after.txt     # on the new one
    diff before.txt after.txt                                  # empty: the same plans

A refactor, a cache key or a faster checker must not change what is planned: the planners are seeded and
their verdicts are exact, so a plan depends only on the problem, the seed and the verdicts. The cases:
armar3 GIRRT boxes6 / table_shelf (seeds 0-19), dual_arm DAGRRT with workers=1 (one thread: DAGRRT with
two workers interleaves by wall time and is not reproducible), TALOS GIRRT boxes6 (seeds 0-5). Each line:
case, seed, status, waypoint count and a hash of the path rounded to 1e-9 rad (not the trajectory: the time
parameterization is a solver whose last digits may differ between BLAS kernels).

Time enters a plan in two places only: GIRRT adds pre-grasp targets after REACHABILITY_PROBE (0.25 s) of search,
and shortcutting stops at the deadline. A problem whose search crosses 0.25 s on a loaded machine but not on a
quiet one is planned differently, so compare digests taken on a quiet machine (load < 1).
"""
from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.pipeline.planner import (DualGraspPlanRequest, GraspPlanner,  # noqa: E402
                                                  GraspPlanRequest)
from humanoid_planner.scenarios import HUMANOIDS, OBJECT_ID, load_humanoid, make_scenario  # noqa: E402

BUDGET = 10.0


def digest(path: np.ndarray | None) -> str:
    if path is None:
        return "-"
    return hashlib.sha1((np.round(np.asarray(path, float), 9) + 0.0).tobytes()).hexdigest()[:12]


def cases(which: set[str]):
    """(name, robot loader, planning group or None for DAGRRT, (left, right) groups, family, seeds)."""
    arms = ("left_arm", "right_arm")
    if "armar3" in which:
        for family in ("boxes6", "table_shelf"):
            yield f"armar3/{family}/girrt", lambda: RobotModel.preset("armar3"), "left_arm_torso", arms, family, range(20)
    if "dual_arm" in which:
        yield "dual_arm/boxes6/dagrrt-w1", lambda: RobotModel.preset("dual_arm"), None, arms, "boxes6", range(20)
    if "talos" in which:
        talos = HUMANOIDS["talos"]
        yield ("talos/boxes6/girrt", lambda: load_humanoid("talos"), talos.left, (talos.left, talos.right), "boxes6",
               range(6))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="armar3,dual_arm,talos", help="comma-separated subset of armar3,dual_arm,talos")
    args = ap.parse_args(argv)
    for name, load, group, (left, right), family, seeds in cases(set(args.robots.split(","))):
        robot = load()
        gp = GraspPlanner(robot, workers=1)
        for seed in seeds:
            try:
                if group is None:
                    sc = make_scenario(robot, family, seed, left_group=left, right_group=right, hand="both")
                    plan = gp.plan_dual_grasp(sc.scene, DualGraspPlanRequest(
                        left, right, robot.home.copy(), sc.object_pose, sc.left_grasps, sc.right_grasps,
                        OBJECT_ID, "dagrrt", timeout=BUDGET, seed=seed))
                else:
                    sc = make_scenario(robot, family, seed, left_group=left, right_group=right, hand="left")
                    plan = gp.plan_grasp(sc.scene, GraspPlanRequest(group, robot.home.copy(), sc.object_pose, sc.grasps,
                                                                    OBJECT_ID, "girrt", BUDGET, seed=seed))
            except ValueError as e:  # a fixture that collides with the robot at home: no problem for this seed
                print(f"{name} {seed} skipped {str(e)[:60]}", flush=True)
                continue
            n = 0 if plan.path is None else len(plan.path)
            print(f"{name} {seed} {plan.status.value} {n} {digest(plan.path)}", flush=True)
        gp.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
