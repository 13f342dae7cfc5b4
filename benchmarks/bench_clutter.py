#!/usr/bin/env python3
"""Dense clutter: GIRRT among hundreds to thousands of boxes in the workspace, each problem with a free
straight joint path from start to goal.

    .venv/bin/python benchmarks/bench_clutter.py [--objects 1000,3000] [--problems 20] [--budget 10]

Problem k (robot armar3, group left_arm_torso, start = home): a goal configuration drawn uniformly
within the limits whose TCP lies in front of the robot; the target is a 2 cm sphere at the goal's TCP
pose with one grasp there (tcp_in_object = identity). N boxes (3–8 cm sides, random orientation) are
drawn uniformly in a box in front of the robot (scenarios.robot_frame: from 0.2 reach behind to 1.0
reach ahead of the workspace centre, ±reach sideways, ±0.6 reach up and down) and every box that comes within 2 cm of the robot anywhere along the straight
joint path home → goal is dropped and redrawn; the path is free of self-collision by the planner's own
motion validator in the empty scene. "Within 2 cm" is decided conservatively: by the
bounding spheres of each link's collision shapes at 200 configurations of the path, so the straight
path is free with at least that margin (not checked by the planner's own code). Every success is
verified by core.verification.verify_plan (exact meshes, 1 cm). Reports solved / problems, median
and p95 planning time per N.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from humanoid_planner.core.collision.geometry import link_geometry_box  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest  # noqa: E402
from humanoid_planner.core.scene.types import GraspSpec, SceneObject, SceneSnapshot, Shape  # noqa: E402
from humanoid_planner.core.verification import verify_plan  # noqa: E402
from humanoid_planner.scenarios import robot_frame  # noqa: E402

GROUP = "left_arm_torso"
MARGIN = 0.02  # m the straight path keeps from every box
PATH_SAMPLES = 200


def link_spheres(robot: RobotModel) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(links, centres in the link frame (L, 3), radii (L,)): one sphere containing each link's shapes."""
    names, centres, radii = [], [], []
    for link, shapes in robot.collision_geometry.items():
        for g in shapes:
            b = link_geometry_box(g)
            names.append(link)
            centres.append(b.pose[:3, 3])
            radii.append(float(np.linalg.norm(b.half)) + b.rounding)
    return names, np.array(centres), np.array(radii)


def make_problem(robot: RobotModel, n: int, seed: int, spheres, gp: GraspPlanner
                 ) -> tuple[SceneSnapshot, np.ndarray, np.ndarray]:
    """(scene, goal configuration of the group, target pose)."""
    rng = np.random.default_rng([seed, n])
    idx = robot.group_joint_indices(GROUP)
    fr = robot_frame(robot)
    tip = robot.group(GROUP).tip_link
    empty = gp.problems.motion(SceneSnapshot(0, robot.root_link, ()), GROUP, robot.home, "", ())
    while True:  # a goal whose TCP is in front of the robot, reached without self-collision in a straight line
        q = robot.home.copy()
        q[idx] = rng.uniform(robot.lower[idx], robot.upper[idx])
        T = robot.link_poses(q, [tip])[0]
        d = T[:3, 3] - fr.center
        if (d @ fr.forward > -0.1 * fr.reach and abs(d @ fr.up) < 0.5 * fr.reach
                and empty.free_prefix(robot.home[idx], q[idx][None]) == 1):
            break
    names, c_local, r = spheres
    path = robot.home[None] + np.linspace(0, 1, PATH_SAMPLES)[:, None] * (q - robot.home)[None]
    P = robot.link_poses(path, list(dict.fromkeys(names)))  # (S, L', 4, 4)
    order = {n_: i for i, n_ in enumerate(dict.fromkeys(names))}
    li = np.array([order[n_] for n_ in names])
    Pl = P[:, li]  # (S, shapes, 4, 4)
    centres = np.einsum("slij,lj->sli", Pl[:, :, :3, :3], c_local) + Pl[:, :, :3, 3]
    centres = centres.reshape(-1, 3)
    radii = np.tile(r, PATH_SAMPLES)
    boxes: list[SceneObject] = []
    while len(boxes) < n:
        m = 4 * (n - len(boxes))
        size = rng.uniform(0.03, 0.08, size=(m, 3))
        u = rng.uniform(-1.0, 1.0, size=(m, 3))
        pos = fr.center + fr.reach * (0.4 * fr.forward + u[:, :1] * 0.6 * fr.forward + u[:, 1:2] * fr.left
                                      + u[:, 2:3] * 0.6 * fr.up)
        rad = 0.5 * np.linalg.norm(size, axis=1)
        gap = np.min(np.linalg.norm(pos[:, None, :] - centres[None, ::7], axis=-1) - radii[None, ::7], axis=1) - rad
        ok = np.flatnonzero(gap > MARGIN)
        if len(ok):  # the sparse screen above is only a prefilter; now every path sphere
            full = np.array([np.min(np.linalg.norm(centres - pos[i], axis=1) - radii) - rad[i] for i in ok])
            ok = ok[full > MARGIN]
        for i in ok[: n - len(boxes)]:
            R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            R *= np.sign(np.linalg.det(R))
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, pos[i]
            boxes.append(SceneObject(f"box{len(boxes)}", T, (Shape("box", np.eye(4), tuple(size[i])),)))
    T_goal = robot.link_poses(q, [tip])[0]
    target = SceneObject("target", T_goal, (Shape("sphere", np.eye(4), (0.01,)),),
                         (GraspSpec("g", "", np.eye(4)),))
    return SceneSnapshot(1, robot.root_link, (*boxes, target)), q[idx], T_goal


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="1000,3000")
    ap.add_argument("--problems", type=int, default=20)
    ap.add_argument("--budget", type=float, default=10.0)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench" / "clutter.json"))
    a = ap.parse_args(argv)
    robot = RobotModel.preset("armar3")
    spheres = link_spheres(robot)
    gp = GraspPlanner(robot)
    rows = []
    try:
        for n in (int(x) for x in a.objects.split(",")):
            recs = []
            for k in range(a.problems):
                scene, q_goal, T_goal = make_problem(robot, n, k, spheres, gp)
                target = scene.get("target")
                req = GraspPlanRequest(GROUP, robot.home.copy(), target.pose, target.grasps, "target", "girrt",
                                       a.budget, seed=k + 1)
                plan = gp.plan_grasp(scene, req)
                rec = {"seed": k, "status": plan.status.value, "time": plan.planning_time}
                if plan.ok:
                    rec["problems"] = verify_plan(robot, scene, (GROUP,), robot.home, plan, (T_goal,),
                                                  object_id="target")
                recs.append(rec)
                print(f"  {n} objects, problem {k}: {rec['status']} {rec['time']:.3f} s"
                      + (f" INVALID {rec['problems']}" if rec.get("problems") else ""), flush=True)
            ok = [r for r in recs if r["status"] == "success"]
            t = [r["time"] for r in recs]
            rows.append({"objects": n, "solved": len(ok), "problems": len(recs),
                         "verified": sum(1 for r in ok if not r["problems"]), "median": float(np.median(t)),
                         "p95": float(np.percentile(t, 95)), "records": recs})
            print(f"{n} objects: {len(ok)}/{len(recs)} solved, median {np.median(t):.3f} s, p95 "
                  f"{np.percentile(t, 95):.3f} s", flush=True)
    finally:
        gp.close()
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"rows": rows, "time": time.strftime("%Y-%m-%d %H:%M:%S")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
