#!/usr/bin/env python3
"""MPlib as a benchmark peer: plans a batch of joint-goal problems with MPlib 0.2.1 in its own venv.

    make mplib-venv                                         # .venv-mplib: python3.11, mplib==0.2.1, numpy<2
    .venv-mplib/bin/python benchmarks/mplib_peer.py BATCH.json RESULTS.json

MPlib 0.2.1 needs numpy < 2 while the project's venv has numpy 2, so bench_mbm.py (`--planners mplib`) writes a
batch of problems to JSON, runs this script once per batch in `.venv-mplib` (MPlib's import costs ~1.3 s, paid
once), reads the results back and verifies them in its own venv. This file imports only the standard library
and numpy at module level (MPlib inside `plan_batch`), so the batch / result format can be read and tested
without MPlib.

Per problem: the batch's boxes / cylinders / spheres become FCL collision objects of MPlib's PlanningWorld
(the previous problem's are removed), then `Planner.plan_qpos([goal], start, planning_time=budget)` with
MPlib's defaults (OMPL RRTConnect, rrt_range 0.1, simplification on, TOPP-RA at time_step 0.1 within the
group's velocity / acceleration limits), after `set_global_seed(seed)`. Reported: status, the wall time of
plan_qpos (RRTConnect + simplification + TOPP), the time of its OMPL call alone, the simplified waypoints MPlib
planned and the TOPP trajectory it returns (group joints, in the batch's order).
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FORMAT = 1
"""Version of the batch / result JSON (both sides of the pipe must agree)."""
KINDS = ("box", "cylinder", "sphere")


@dataclass(frozen=True)
class Obstacle:
    """One primitive of the scene, in the robot's root frame. dims as shape_msgs/SolidPrimitive: box (x, y, z),
    cylinder (height, radius), sphere (radius,)."""

    name: str
    kind: str
    dims: tuple[float, ...]
    pose: np.ndarray  # 4x4


@dataclass(frozen=True)
class PeerProblem:
    index: int
    seed: int
    start: np.ndarray  # (len(joint_names),) the whole robot, batch order
    goal: np.ndarray  # (len(joint_names),); only the group's joints matter
    budget: float  # s, MPlib's planning_time
    obstacles: tuple[Obstacle, ...]


@dataclass(frozen=True)
class Batch:
    urdf: str  # no package:// URIs left (MPlib would write a rewritten copy beside the file)
    srdf: str
    move_group: str  # the link MPlib plans for; its chain from the root must be exactly group_joints
    joint_names: tuple[str, ...]  # order of start / goal
    group_joints: tuple[str, ...]  # order of the returned paths
    max_velocity: np.ndarray  # (len(group_joints),) for MPlib's TOPP
    max_acceleration: np.ndarray
    problems: tuple[PeerProblem, ...]
    warm_up: bool = True  # plan the first problem once, untimed, before the batch (first-use costs)


def batch_to_json(b: Batch) -> dict:
    return {"format": FORMAT, "urdf": b.urdf, "srdf": b.srdf, "move_group": b.move_group,
            "joint_names": list(b.joint_names), "group_joints": list(b.group_joints),
            "max_velocity": np.asarray(b.max_velocity, float).tolist(),
            "max_acceleration": np.asarray(b.max_acceleration, float).tolist(), "warm_up": b.warm_up,
            "problems": [{"index": p.index, "seed": p.seed, "start": np.asarray(p.start, float).tolist(),
                          "goal": np.asarray(p.goal, float).tolist(), "budget": p.budget,
                          "obstacles": [{"name": o.name, "kind": o.kind, "dims": list(o.dims),
                                         "pose": np.asarray(o.pose, float).tolist()} for o in p.obstacles]}
                         for p in b.problems]}


def batch_from_json(d: dict) -> Batch:
    if d.get("format") != FORMAT:
        raise ValueError(f"batch format {d.get('format')!r}, expected {FORMAT}")
    probs = []
    for p in d["problems"]:
        obs = []
        for o in p["obstacles"]:
            if o["kind"] not in KINDS:
                raise ValueError(f"obstacle {o['name']}: kind {o['kind']!r} not one of {KINDS}")
            obs.append(Obstacle(o["name"], o["kind"], tuple(float(x) for x in o["dims"]), np.array(o["pose"], float)))
        probs.append(PeerProblem(int(p["index"]), int(p["seed"]), np.array(p["start"], float),
                                 np.array(p["goal"], float), float(p["budget"]), tuple(obs)))
    return Batch(d["urdf"], d["srdf"], d["move_group"], tuple(d["joint_names"]), tuple(d["group_joints"]),
                 np.array(d["max_velocity"], float), np.array(d["max_acceleration"], float), tuple(probs),
                 bool(d.get("warm_up", True)))


class _TimedOMPL:
    """Stands in for Planner.planner: times its OMPL call (RRTConnect + simplification) and keeps the
    waypoints, which plan_qpos replaces by their TOPP samples."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.time = 0.0
        self.path: np.ndarray | None = None

    def plan(self, *args, **kwargs):
        t = time.perf_counter()
        status, path = self.inner.plan(*args, **kwargs)
        self.time = time.perf_counter() - t
        self.path = np.asarray(path, float) if status == "Exact solution" else None
        return status, path


def _geometry(fcl, o: Obstacle):
    if o.kind == "box":
        return fcl.Box(np.asarray(o.dims, float))
    if o.kind == "cylinder":
        return fcl.Cylinder(o.dims[1], o.dims[0])  # MPlib: (radius, length); SolidPrimitive: (height, radius)
    return fcl.Sphere(o.dims[0])


def plan_batch(b: Batch) -> dict:
    """Every problem of the batch planned by MPlib; the result JSON (see the module docstring)."""
    t0 = time.perf_counter()
    import mplib
    from mplib.collision_detection import fcl

    t_import = time.perf_counter() - t0
    t0 = time.perf_counter()
    planner = mplib.Planner(urdf=b.urdf, srdf=b.srdf, move_group=b.move_group,
                            joint_vel_limits=b.max_velocity, joint_acc_limits=b.max_acceleration)
    t_load = time.perf_counter() - t0
    names = list(planner.user_joint_names)
    group = [names[i] for i in planner.move_group_joint_indices]
    if group != list(b.group_joints):
        raise ValueError(f"MPlib's joints for move group {b.move_group} are {group}, the batch's group is "
                         f"{list(b.group_joints)}")
    missing = sorted(set(names) - set(b.joint_names))
    if missing:
        raise ValueError(f"the batch gives no value for MPlib's joints {missing}")
    to_mplib = np.array([b.joint_names.index(n) for n in names])
    timed = _TimedOMPL(planner.planner)
    planner.planner = timed
    added: list[str] = []

    def solve(p: PeerProblem) -> dict:
        for name in added:
            planner.remove_object(name)
        added.clear()
        for k, o in enumerate(p.obstacles):
            name = f"{o.name}#{k}"
            planner.planning_world.add_object(name, fcl.CollisionObject(_geometry(fcl, o), mplib.Pose(o.pose)))
            added.append(name)
        mplib.set_global_seed(p.seed)
        timed.time, timed.path = 0.0, None
        c, t = time.process_time(), time.perf_counter()
        try:
            res = planner.plan_qpos([p.goal[to_mplib]], p.start[to_mplib], planning_time=p.budget)
            message = str(res["status"])
        except Exception as e:  # noqa: BLE001 - e.g. TOPP failing: a result of MPlib's, not a benchmark abort
            res, message = {"status": "error"}, f"{type(e).__name__}: {e}"
        elapsed, cpu = time.perf_counter() - t, time.process_time() - c
        ok = res["status"] == "Success"
        rec = {"index": p.index, "seed": p.seed, "ok": ok,
               "status": "success" if ok else "error" if res["status"] == "error" else "failed",
               "message": message, "time": elapsed, "cpu": cpu, "ompl_time": timed.time}
        if timed.path is not None:
            rec["waypoints"] = timed.path.tolist()
        if ok:
            rec["trajectory"] = {"times": np.asarray(res["time"], float).tolist(),
                                 "positions": np.asarray(res["position"], float).tolist(),
                                 "velocities": np.asarray(res["velocity"], float).tolist(),
                                 "accelerations": np.asarray(res["acceleration"], float).tolist()}
        return rec

    warm = None
    if b.warm_up and b.problems:
        p = b.problems[0]
        t = time.perf_counter()
        solve(PeerProblem(p.index, p.seed, p.start, p.goal, min(2.0, p.budget), p.obstacles))
        warm = time.perf_counter() - t
    results = [solve(p) for p in b.problems]
    return {"format": FORMAT, "mplib": mplib.__version__, "numpy": np.__version__, "import_s": t_import,
            "load_s": t_load, "warm_up_s": warm, "results": results}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    batch = batch_from_json(json.loads(Path(argv[0]).read_text()))
    Path(argv[1]).write_text(json.dumps(plan_batch(batch)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
