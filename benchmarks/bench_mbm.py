#!/usr/bin/env python3
"""MotionBenchMaker benchmark: public manipulation problems in MoveIt's own YAML, GIRRT beside the OMPL peer and MPlib.

    .venv/bin/python benchmarks/bench_mbm.py --robot-dir MBM/panda --robot-dir MBM/fetch --problems 10 --budget 10
    make bench-mbm MBM_DIR=MBM                  # both robots, the seven families, 10 problems, 10 s

A robot folder holds `<name>.urdf`, `<name>.srdf` (mesh URIs `package://meshes/...`: the folder is given to
RobotModel as a folder of packages, after the ament index) and `problems/<family>_<name>/sceneNNNN.yaml` +
`requestNNNN.yaml` (a moveit_msgs PlanningScene and a MotionPlanRequest with a joint goal), read by
humanoid_planner.moveit_yaml. Problem k of a family is the k-th pair (1-based); every planner gets the same
problems in the same run, request seed k, --budget seconds each:

  girrt  GraspPlanner.plan_grasp with one grasp: the group's TCP pose at the goal configuration (the goal
         as a user of this node states it: where the hand must be, not how the arm gets there); not run for a
         group without a TCP (Baxter's both_arms);
  state  GraspPlanner.plan_to_state given the goal configuration (what the peers are given: the node's
         joint-goal planner beside them on the same input);
  ompl   the peer given the goal configuration itself (benchmarks/ompl_peer.plan_ompl_to_state: the same
         request checks and motion validator, OMPL RRT-Connect, simplification, timing);
  mplib  (with --planners ...,mplib) MPlib 0.2.1 given the goal configuration (Planner.plan_qpos, its defaults),
         run by benchmarks/mplib_peer.py in .venv-mplib (`make mplib-venv`: MPlib needs numpy < 2), one process
         per family; its path (the simplified waypoints) is verified here like the others, the TOPP trajectory
         plan_qpos returns apart, and the paired ratio GIRRT / MPlib counts only MPlib paths that verify.

Every answer is verified by core.verification.verify_plan (exact FCL at 1 cm, limits, the TCP on the goal
pose). The problem files write π where the URDF says 3.14159 (2.7e-6 rad past): the planner clips that itself
(START_LIMIT_SLACK, 1e-4 rad); values further out are counted per family as refused, or with --clip T (default
0) clipped onto the bound first when at most T past it.
Per family and planner: solved / total, median and p95 planning_time over all attempts (failures at the time
they returned), the paired median ratio GIRRT / peer over problems both solved, failures by status, median
tree size. --reference S also runs the plain reference RRT-Connect (scenarios.reference_plan, 1 cm edges, no
padding) to the goal configuration for S seconds, as a proof that a problem is solvable.
Outputs: a table on stdout, out/bench/mbm.md and out/bench/mbm.json (rewritten after each family).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import gc
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_planners import InstrumentedPlanner, git_commit, hms, load_avg, ms, paired_ratio, pct  # noqa: E402
from mplib_peer import Batch, Obstacle, PeerProblem, batch_to_json  # noqa: E402
from ompl_peer import ompl_version, plan_ompl_to_state  # noqa: E402

from humanoid_planner.core import compiled  # noqa: E402
from humanoid_planner.core.collision import pair_tables  # noqa: E402
from humanoid_planner.core.model.robot import MeshResolver, RobotModel  # noqa: E402
from humanoid_planner.core.pipeline.planner import GraspPlanRequest, StatePlanRequest  # noqa: E402
from humanoid_planner.core.pipeline.validation import START_LIMIT_SLACK, RequestRefused, check_start, state_goal  # noqa: E402
from humanoid_planner.core.postprocess.smoothing import path_length  # noqa: E402
from humanoid_planner.core.postprocess.timing import TimedTrajectory, time_parameterize  # noqa: E402
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot  # noqa: E402
from humanoid_planner.core.verification import verify_plan  # noqa: E402
from humanoid_planner.moveit_yaml import motion_plan_request, planning_scene  # noqa: E402
from humanoid_planner.scenarios import reference_plan  # noqa: E402

FAMILIES = ("bookshelf_small", "bookshelf_tall", "bookshelf_thin", "box", "cage", "table_pick", "table_under_pick")
PLANNERS = ("girrt", "state", "ompl", "mplib")
MPLIB_PYTHON = ROOT / ".venv-mplib" / "bin" / "python"
PEER = ("ompl_peer.plan_ompl_to_state: OMPL RRTConnect (default range) to the goal configuration, Python "
        "StateValidityChecker + batched MotionValidator (the planner's), simplifySolution(ptc), same time parameterization")
MPLIB_PEER = ("mplib_peer.py: MPlib 0.2.1 Planner.plan_qpos to the goal configuration, its defaults (OMPL "
              "RRTConnect, range 0.1, simplification, TOPP-RA at 0.1 s within the group's limits), FCL boxes / "
              "cylinders, in .venv-mplib, one process per family")
CLIP = 0.0
"""rad: with --clip, start / goal values at most this far past a bound are clipped onto it first (0: the planner alone decides)."""


@dataclass
class Problem:
    index: int  # k of sceneNNNN / requestNNNN
    scene: SceneSnapshot
    group: str
    start: np.ndarray  # (dof,), clipped
    goal: np.ndarray  # (dof,), clipped
    tcp_goal: np.ndarray | None  # 4x4: the group's TCP at the goal configuration (None: a group without a TCP)
    clipped: tuple[str, ...]  # joints moved onto a bound (start or goal)
    refused_as_given: str  # the planner's refusal of the files' values as written ("" = accepted)
    seed: int = 0  # the request seed: k + --seed-offset


def use_cpu_clock() -> None:
    """--cpu-budget: the planner's clocks (its Termination deadlines and planning_time) and the IK /
    post-processing timers read this process's CPU time. A plan runs in one thread, so a budget then buys
    the same search at any load; OMPL's own termination inside the peer stays on the wall clock."""
    import bench_planners
    import humanoid_planner.core.pipeline.planner as pipeline_planner
    import humanoid_planner.core.planners.common as planners_common
    clock = SimpleNamespace(**{k: getattr(time, k) for k in dir(time) if not k.startswith("_")})
    clock.perf_counter = time.process_time
    for module in (planners_common, pipeline_planner, bench_planners):
        module.time = clock


def robot_families(robot_dir: Path) -> list[str]:
    """The families of a robot folder: its problems/<family>_<robot> folders, FAMILIES' order first."""
    found = sorted(f.name[:-len(robot_dir.name) - 1] for f in (robot_dir / "problems").iterdir()
                   if f.is_dir() and f.name.endswith("_" + robot_dir.name))
    return [f for f in FAMILIES if f in found] + [f for f in found if f not in FAMILIES]


def load_robot(robot_dir: Path) -> RobotModel:
    name = robot_dir.name
    return RobotModel.from_urdf_srdf(robot_dir / f"{name}.urdf", robot_dir / f"{name}.srdf", package_dirs=[robot_dir])


def clip_near(robot: RobotModel, q: np.ndarray, tol: float) -> tuple[np.ndarray, list[str]]:
    """q with bounded joints at most `tol` past a limit moved onto it, and their names."""
    bounded = ~robot.continuous
    near = bounded & (((q < robot.lower) & (q >= robot.lower - tol)) | ((q > robot.upper) & (q <= robot.upper + tol)))
    out = np.where(near, np.clip(q, robot.lower, robot.upper), q)
    return out, [robot.joint_names[i] for i in np.flatnonzero(near)]


def refusal(robot: RobotModel, group: str, start: np.ndarray, goal: np.ndarray) -> str:
    """The planner's own start / goal checks on these values ("" = accepted)."""
    idx = robot.group_joint_indices(group)
    try:
        check_start(robot, start)
        state_goal(robot, [group], "", {robot.joint_names[i]: float(goal[i]) for i in idx})
    except RequestRefused as e:
        return f"{e.status.value}: {e.message}"
    return ""


def load_problem(robot: RobotModel, folder: Path, k: int, tol: float, seed_offset: int = 0) -> Problem:
    scene = planning_scene(yaml.safe_load((folder / f"scene{k:04d}.yaml").read_text()), robot).snapshot()
    loaded = motion_plan_request(yaml.safe_load((folder / f"request{k:04d}.yaml").read_text()), robot)
    group = loaded.request.group
    as_given = refusal(robot, group, loaded.request.start, loaded.goal)
    start, moved_s = clip_near(robot, loaded.request.start, tol)
    goal, moved_g = clip_near(robot, loaded.goal, tol)
    tip = robot.group(group).tip_link
    tcp = robot.link_poses(goal, [tip])[0] if tip else None
    return Problem(k, scene, group, start, goal, tcp, tuple(sorted(set(moved_s + moved_g))), as_given, k + seed_offset)


def run(gp: InstrumentedPlanner, planner: str, p: Problem, budget: float, verify: bool) -> dict:
    robot = gp.robot
    idx = robot.group_joint_indices(p.group)
    gp.reset()
    gc.collect()
    c0 = time.process_time()
    if planner == "girrt":
        req = GraspPlanRequest(p.group, p.start, p.tcp_goal, (GraspSpec("goal", "", np.eye(4)),), "", "girrt",
                               budget, seed=p.seed)
        plan = gp.plan_grasp(p.scene, req)
    elif planner in ("ompl", "state"):
        goal = {robot.joint_names[i]: float(p.goal[i]) for i in idx}
        req = StatePlanRequest(p.group, p.start, goal=goal, timeout=budget, seed=p.seed)
        plan = plan_ompl_to_state(gp, p.scene, req) if planner == "ompl" else gp.plan_to_state(p.scene, req)
    else:  # the reference, untimed by the planner: its own clock
        t = time.perf_counter()
        res = reference_plan(robot, p.scene, (p.group,), p.start, p.goal[idx][None], budget, p.seed)
        return {"problem": p.index, "seed": p.seed, "ok": bool(res.ok), "status": "success" if res.ok else "failed",
                "time": time.perf_counter() - t, "cpu": time.process_time() - c0}
    rec = {"problem": p.index, "seed": p.seed, "status": plan.status.value, "ok": plan.ok, "time": plan.planning_time,
           "cpu": time.process_time() - c0, "message": plan.message[:200], "iterations": int(plan.iterations),
           "configs_checked": int(sum(c.stats.configs_checked for c in gp.checkers)),
           "exact_checks": int(sum(c.stats.exact_checks for c in gp.checkers)), "ik_time": gp.t_ik}
    for key in ("tree_size", "goal_configs", "fallback_cycles"):
        if key in plan.stats:
            rec[key] = int(plan.stats[key])
    if plan.ok and plan.path is not None:
        rec["path_length"] = path_length(plan.path)
        # how far the reached configuration lies from the file's goal configuration (GIRRT may reach another
        # posture of the same TCP pose)
        rec["goal_distance"] = float(np.linalg.norm(plan.path[-1] - p.goal[idx]))
        if verify:
            try:
                rec["verify_problems"] = verify_plan(robot, p.scene, (p.group,), p.start, plan, targets(p))
            except Exception as e:  # noqa: BLE001 - a crash of the checker is a finding, not a benchmark abort
                rec["verify_problems"] = [f"verify_plan raised {e!r}"]
    return rec


def targets(p: Problem) -> tuple[np.ndarray, ...]:
    """What a verified plan must reach besides the goal configuration: the TCP pose, when the group has one."""
    return () if p.tcp_goal is None else (p.tcp_goal,)


def scene_obstacles(scene: SceneSnapshot) -> tuple[Obstacle, ...]:
    """The scene's primitives in the planning frame, as a peer that takes FCL primitives is given them."""
    if scene.attached or scene.voxels is not None:
        raise ValueError("attached objects and point clouds are not passed to MPlib")
    out = []
    for o in scene.objects:
        for sh in o.shapes:
            if sh.kind not in ("box", "cylinder", "sphere"):
                raise ValueError(f"object {o.id}: {sh.kind} shapes are not passed to MPlib")
            out.append(Obstacle(o.id, sh.kind, tuple(float(x) for x in sh.dims), o.pose @ sh.pose))
    return tuple(out)


def resolved_urdf(robot_dir: Path, dest: Path) -> Path:
    """A copy of the robot's URDF in `dest` with every mesh URI replaced by the file RobotModel loads for it:
    MPlib reads `package://` as a plain path prefix, and every mesh path as relative to the URDF's folder.
    An OBJ with line elements is copied without them: MPlib's loader refuses two-vertex faces, and lines bound
    no volume (RobotModel's loader skips them too). Visual elements are left out: only collision geometry is
    planned with, and the MotionBenchMaker folders do not ship every visual mesh."""
    resolve = MeshResolver(robot_dir, [robot_dir])
    copies: dict[Path, Path] = {}

    def mesh(uri: str) -> str:
        path = resolve(uri)
        if path.suffix.lower() == ".obj" and path not in copies:
            lines = path.read_text(errors="replace").splitlines(keepends=True)
            if any(ln.startswith("l ") for ln in lines):
                copies[path] = dest / "meshes" / f"{len(copies)}_{path.name}"
                copies[path].parent.mkdir(exist_ok=True)
                copies[path].write_text("".join(ln for ln in lines if not ln.startswith(("l ", "mtllib ", "usemtl "))))
        return os.path.relpath(copies.get(path, path), dest)

    text = re.sub(r"<visual\b.*?</visual>", "", (robot_dir / f"{robot_dir.name}.urdf").read_text(), flags=re.S)
    text = re.sub(r'filename="([^"]+)"', lambda m: f'filename="{mesh(m.group(1))}"', text)
    out = dest / f"{robot_dir.name}.urdf"
    out.write_text(text)
    return out


def mplib_batch(robot: RobotModel, urdf: Path, srdf: Path, probs: list[Problem], budget: float) -> Batch:
    """The family's problems for mplib_peer: the whole start, the goal configuration, the scene's primitives.
    Values within START_LIMIT_SLACK past a bound are clipped onto it, as GIRRT and the OMPL peer take them (MPlib
    clips the start itself, not the goal)."""
    groups = {p.group for p in probs}
    if len(groups) != 1:
        raise ValueError(f"one planning group per MPlib batch, these problems have {sorted(groups)}")
    group = robot.group(groups.pop())
    idx = robot.group_joint_indices(group.name)
    return Batch(str(urdf), str(srdf), group.tip_link, tuple(robot.joint_names),
                 tuple(robot.joint_names[i] for i in idx), robot.max_velocity[idx], robot.max_acceleration[idx],
                 tuple(PeerProblem(p.index, p.seed, clip_near(robot, p.start, START_LIMIT_SLACK)[0],
                                   clip_near(robot, p.goal, START_LIMIT_SLACK)[0], budget, scene_obstacles(p.scene))
                       for p in probs))


def run_mplib(robot: RobotModel, robot_dir: Path, probs: list[Problem], budget: float, python: Path,
              verify: bool = True) -> tuple[list[dict], dict]:
    """The problems planned by mplib_peer in its own venv (one process), each answer verified here: MPlib's path
    (its simplified waypoints, timed to follow the straight segments exactly: the path as planned, whatever a
    timing would add) and, apart, the trajectory plan_qpos returns (TOPP-RA samples of a spline through them)."""
    with tempfile.TemporaryDirectory(prefix="mbm-mplib-") as tmp:
        tmpd = Path(tmp)
        batch = mplib_batch(robot, resolved_urdf(robot_dir, tmpd), robot_dir / f"{robot_dir.name}.srdf", probs, budget)
        (tmpd / "batch.json").write_text(json.dumps(batch_to_json(batch)))
        cmd = [str(python), str(Path(__file__).resolve().parent / "mplib_peer.py"), str(tmpd / "batch.json"),
               str(tmpd / "results.json")]
        # generous: MPlib's simplification runs after the budget
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=len(probs) * (3 * budget + 30) + 120)
        if done.returncode != 0:
            raise RuntimeError(f"mplib_peer exited with {done.returncode}: {done.stderr[-2000:]}")
        out = json.loads((tmpd / "results.json").read_text())
    by_index = {p.index: p for p in probs}
    recs = []
    for r in out["results"]:
        p = by_index[r["index"]]
        idx = robot.group_joint_indices(p.group)
        rec = {"problem": p.index, "seed": r["seed"], "status": r["status"], "ok": r["ok"], "time": r["time"],
               "cpu": r["cpu"], "message": r["message"][:200], "ompl_time": r["ompl_time"]}
        if r["ok"]:
            wp = np.array(r["waypoints"], float)
            tr = r["trajectory"]
            rec["path_length"] = path_length(wp)
            rec["goal_distance"] = float(np.linalg.norm(wp[-1] - p.goal[idx]))
            rec["waypoints"] = len(wp)
            if verify:
                returned = TimedTrajectory(np.array(tr["times"], float), np.array(tr["positions"], float),
                                           np.array(tr["velocities"], float), np.array(tr["accelerations"], float),
                                           method="mplib-topp")
                straight = time_parameterize(wp, robot.max_velocity[idx], robot.max_acceleration[idx],
                                             path_tolerance=0.0)
                for key, traj in (("verify_problems", straight), ("verify_trajectory", returned)):
                    try:
                        rec[key] = verify_plan(robot, p.scene, (p.group,), p.start,
                                               SimpleNamespace(path=wp, trajectory=traj), targets(p))
                    except Exception as e:  # noqa: BLE001 - a malformed answer is a finding, not a benchmark abort
                        rec[key] = [f"verify_plan raised {e!r}"]
        recs.append(rec)
    meta = {k: out[k] for k in ("mplib", "numpy", "import_s", "load_s", "warm_up_s")}
    meta["stdout_tail"] = done.stdout[-2000:]  # MPlib prints e.g. "Invalid start state!" there
    return recs, meta


def verified_only(summary: dict) -> dict:
    """The summary's problems with a failed verification counted as unsolved (for the paired ratio)."""
    return {**summary, "problems": [{**r, "ok": r["ok"] and not r.get("verify_problems")} for r in summary["problems"]]}


def summarize(robot: str, family: str, planner: str, recs: list[dict]) -> dict:
    times = [r["time"] for r in recs]
    ok = [r for r in recs if r["ok"]]
    statuses: dict[str, int] = {}
    for r in recs:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    verified = [r for r in recs if "verify_problems" in r]
    trees = [r["tree_size"] for r in recs if "tree_size" in r]
    configs = sum(r.get("configs_checked", 0) for r in recs)
    return {"robot": robot, "family": family, "planner": planner, "n": len(recs), "successes": len(ok),
            "time_median": pct(times, 50), "time_p95": pct(times, 95), "time_median_success": pct([r["time"] for r in ok], 50),
            "cpu_median": pct([r["cpu"] for r in recs], 50), "status_counts": statuses,
            "tree_size_median": pct(trees, 50), "tree_size_median_failed": pct([r["tree_size"] for r in recs
                                                                                if "tree_size" in r and not r["ok"]], 50),
            "checks_per_s": configs / sum(times) if configs and sum(times) > 0 else None,
            "exact_share": sum(r.get("exact_checks", 0) for r in recs) / configs if configs else None,
            "goal_distance_median": pct([r["goal_distance"] for r in ok if "goal_distance" in r], 50),
            "verified": {"checked": len(verified), "valid": sum(not r["verify_problems"] for r in verified),
                         "problems": [{"problem": r["problem"], "problems": r["verify_problems"]} for r in verified
                                      if r["verify_problems"]]},
            "verified_trajectory": {"checked": sum("verify_trajectory" in r for r in recs),
                                   "valid": sum("verify_trajectory" in r and not r["verify_trajectory"] for r in recs)},
            "problems": recs}


def mplib_pairing(girrt: dict, mplib: dict) -> tuple[float | None, int]:
    """Paired median GIRRT / MPlib over problems both solved, counting only MPlib answers that verify."""
    return paired_ratio(girrt, verified_only(mplib))


def markdown(res: dict) -> str:
    m = res["meta"]
    cpu = " of CPU" if m.get("clock") == "cpu" else ""
    seeds = f" (request seeds k + {m['seed_offset']})" if m.get("seed_offset") else ""
    lines = [f"## MotionBenchMaker — {m['date']} (commit {m['commit']}, {m['cpus']} CPUs, load {m['load_start']}→"
             f"{m['load_end']}, budget {m['budget']} s{cpu}, problems 1–{m['problems']}{seeds} of each family, clip {m['clip']:g} rad)",
             "", "| robot | family | GIRRT solved | median ms | p95 ms | OMPL peer solved | median ms | p95 ms | paired "
             "GIRRT / OMPL (n) | MPlib solved | MPlib verified path (trajectory) | median ms | p95 ms | paired GIRRT / MPlib, "
             "verified (n) | verified GIRRT · OMPL | as given: refused | GIRRT failures (median tree) | GIRRT checks/s "
             "(exact %) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    by = {(s["robot"], s["family"], s["planner"]): s for s in res["families"]}
    dash = "–"

    def times(s: dict | None) -> str:
        return " | ".join([dash] * 3) if s is None else f"{s['successes']}/{s['n']} | {ms(s['time_median'])} | {ms(s['time_p95'])}"

    def ratio(pr: tuple[float | None, int]) -> str:
        return dash if pr[0] is None else f"{pr[0]:.2f} ({pr[1]})"

    def valid(s: dict | None) -> str:
        return dash if s is None else f"{s['verified']['valid']}/{s['verified']['checked']}"

    for key, info in res["problem_sets"].items():
        robot, fam = key.split("/")
        g, o, mp = (by.get((robot, fam, p)) for p in ("girrt", "ompl", "mplib"))
        if g is None:
            continue
        fails = ", ".join(f"{k} {v}" for k, v in g["status_counts"].items() if k != "success") or dash
        if g["tree_size_median_failed"] is not None:
            fails += f" ({g['tree_size_median_failed']:.0f})"
        mcells = " | ".join([dash] * 5)
        if mp is not None:
            w = mp["verified_trajectory"]
            mcells = (f"{mp['successes']}/{mp['n']} | {valid(mp)} ({w['valid']}/{w['checked']}) | {ms(mp['time_median'])}"
                      f" | {ms(mp['time_p95'])} | {ratio(mplib_pairing(g, mp))}")
        lines.append(f"| {robot} | {fam} | {times(g)} | {times(o)} | {dash if o is None else ratio(paired_ratio(g, o))} | "
                     f"{mcells} | {valid(g)} · {valid(o)} | {info['refused_as_given']} | {fails} | "
                     + (dash if g.get("checks_per_s") is None else f"{g['checks_per_s']:,.0f} ({100 * g['exact_share']:.0f})")
                     + " |")
    state_rows = [(key, by[(*key.split("/"), "state")]) for key in res["problem_sets"]
                  if (*key.split("/"), "state") in by]
    if state_rows:
        lines += ["", "plan_to_state given the goal configuration, beside the OMPL peer (the same input):", "",
                  "| robot | family | plan_to_state solved | median ms | p95 ms | OMPL peer solved | median ms | p95 ms "
                  "| paired plan_to_state / OMPL (n) | verified plan_to_state · OMPL |", "|---|---|---|---|---|---|---|---|---|---|"]
        for key, st in state_rows:
            robot, fam = key.split("/")
            o = by.get((robot, fam, "ompl"))
            lines.append(f"| {robot} | {fam} | {times(st)} | {times(o)} | {dash if o is None else ratio(paired_ratio(st, o))}"
                         f" | {valid(st)} · {valid(o)} |")
    ref = [s for s in res["families"] if s["planner"] == "reference"]
    if ref:
        lines += ["", "Reference RRT-Connect (1 cm edges, no padding, --reference s): " + "; ".join(
            f"{s['robot']} {s['family']} {s['successes']}/{s['n']}" for s in ref)]
    lines += ["", "Times: planning_time of every attempt (failures at the time they returned). Paired: median over "
              "problems both solved of GIRRT time / peer time. 'As given: refused': problems whose start or goal the "
              "planner refuses as written (past a bound by more than its START_LIMIT_SLACK); they were planned after "
              "clipping. OMPL peer: " + m["peer"] + "."]
    if "mplib_peer" in m:
        lines += ["", "MPlib: " + m["mplib_peer"] + "; time = the wall time of plan_qpos in the peer process. Verified: "
                  "MPlib's path (its simplified waypoints, timed along the straight segments between them) by verify_plan "
                  "(exact FCL at 1 cm, limits, TCP on the goal pose); (trajectory): the TOPP-RA trajectory plan_qpos "
                  "returns (a spline through the waypoints), verified the same way. The MPlib pairing counts an MPlib "
                  "answer only when its path verifies."]
    return "\n".join(lines) + "\n"


def progress(robot: str, fam: str, planner: str, r: dict) -> str:
    return (f"   {robot}/{fam} {planner} #{r['problem']}: {r['status']} {r['time']:.3f} s"
            + (f" tree {r['tree_size']}" if "tree_size" in r else "")
            + (f" fallback {r['fallback_cycles']}" if "fallback_cycles" in r else "")
            + (f" exact {r['exact_checks'] / r['configs_checked']:.0%}" if r.get("configs_checked") else "")
            + (f" VERIFY {r['verify_problems'][:1]}" if r.get("verify_problems") else "")
            + (f" trajectory VERIFY {r['verify_trajectory'][:1]}" if r.get("verify_trajectory") else "")
            + ("" if r["ok"] else f" {r.get('message', '')[:100]}"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--robot-dir", action="append", required=True, help="a robot folder (repeat for several)")
    ap.add_argument("--families", default="", help="comma-separated (default: every problems/<family>_<robot> folder, "
                    f"{', '.join(FAMILIES)} first)")
    ap.add_argument("--planners", default="girrt,ompl", help="girrt, state, ompl, mplib (default girrt,ompl)")
    ap.add_argument("--mplib-python", default=str(MPLIB_PYTHON), help="the Python of the MPlib venv "
                    "(default .venv-mplib/bin/python, made by `make mplib-venv`)")
    ap.add_argument("--problems", type=int, default=10, help="the first N problems of each family (default 10)")
    ap.add_argument("--budget", type=float, default=10.0, help="seconds per plan (default 10)")
    ap.add_argument("--clip", type=float, default=CLIP, help=f"clip start / goal values this far past a bound "
                    f"(rad, default {CLIP:g}; 0 = plan them as given)")
    ap.add_argument("--reference", type=float, default=0.0, help="also run the reference RRT-Connect for S s (0 = no)")
    ap.add_argument("--seed-offset", type=int, default=0, help="request seed k + this for problem k (default 0): "
                    "more runs of the same problems")
    ap.add_argument("--cpu-budget", action="store_true", help="budgets in CPU seconds of this process, not wall "
                    "seconds: on a shared machine the load decides how much search a wall budget buys")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    a = ap.parse_args(argv)
    # steady-state figures: each robot's first check builds its pair tables (as a planning process has them
    # after its first plans; the node builds them in the background instead, pair_tables.BUILDER)
    pair_tables.build_in_background(False)
    compiled.warm_all()  # every compiled kernel loaded before timing, as the node does before its first plan
    split = lambda s: [x.strip() for x in s.split(",") if x.strip()]  # noqa: E731
    families, planners = split(a.families), split(a.planners)
    bad = [p for p in planners if p not in PLANNERS]
    if bad:
        ap.error(f"unknown planner(s) {bad}; known: {', '.join(PLANNERS)}")
    if "mplib" in planners and not Path(a.mplib_python).is_file():
        ap.error(f"--planners mplib: no {a.mplib_python}; MPlib 0.2.1 needs numpy < 2 and runs in a venv of its "
                 f"own: make it with `make mplib-venv` (or give --mplib-python)")
    if a.reference > 0:
        planners.append("reference")
    if a.cpu_budget:
        use_cpu_clock()
    robot_dirs = [Path(d).resolve() for d in a.robot_dir]
    for d in robot_dirs:
        if not (d / f"{d.name}.urdf").is_file() or not (d / "problems").is_dir():
            ap.error(f"{d}: expected {d.name}.urdf, {d.name}.srdf and problems/ in it")
    out_dir = Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    meta = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "commit": git_commit(), "cpus": os.cpu_count(),
            "machine": platform.platform(), "python": platform.python_version(), "ompl": ompl_version(),
            "load_start": load_avg(), "load_end": None, "budget": a.budget, "problems": a.problems,
            "clock": "cpu" if a.cpu_budget else "wall", "seed_offset": a.seed_offset, "clip": a.clip,
            "reference_budget": a.reference, "peer": PEER, "robot_dirs": [str(d) for d in robot_dirs]}
    if "mplib" in planners:
        meta["mplib_peer"] = MPLIB_PEER
        meta["mplib_python"] = a.mplib_python
    res: dict = {"meta": meta, "families": [], "problem_sets": {}, "warm_up": {}}
    t_start = time.perf_counter()
    print(f"== MotionBenchMaker: {', '.join(d.name for d in robot_dirs)}; {len(families) or 'all'} families, {a.problems} "
          f"problems, {', '.join(planners)}, budget {a.budget} s; load {meta['load_start']}", flush=True)
    for d in robot_dirs:
        t = time.perf_counter()
        robot = load_robot(d)
        gp = InstrumentedPlanner(robot)
        print(f"   loaded {d.name} in {time.perf_counter() - t:.1f} s", flush=True)
        warmed = False
        for fam in families or robot_families(d):
            folder = d / "problems" / f"{fam}_{d.name}"
            if not folder.is_dir():
                print(f"   {d.name}/{fam}: no folder {folder}, skipped", flush=True)
                continue
            probs = [load_problem(robot, folder, k, a.clip, a.seed_offset) for k in range(1, a.problems + 1)
                     if (folder / f"scene{k:04d}.yaml").is_file()]
            info = {"n": len(probs), "refused_as_given": sum(bool(p.refused_as_given) for p in probs),
                    "clipped": {str(p.index): list(p.clipped) for p in probs if p.clipped},
                    "refusals": {str(p.index): p.refused_as_given for p in probs if p.refused_as_given}}
            res["problem_sets"][f"{d.name}/{fam}"] = info
            if not warmed and probs:  # first-use costs (pair tables, imports) stay out of the timings
                warmed = True
                for planner in planners:
                    if planner == "mplib":  # mplib_peer warms itself up in each process
                        continue
                    t = time.perf_counter()
                    run(gp, planner, probs[0], min(2.0, a.budget), False)
                    res["warm_up"][f"{d.name}/{planner}"] = time.perf_counter() - t
            for planner in planners:
                if planner == "girrt" and probs and probs[0].tcp_goal is None:
                    print(f"   {d.name}/{fam} girrt: not run, group {probs[0].group!r} has no TCP (no grasp to give; "
                          "--planners state plans its joint goal)", flush=True)
                    continue
                recs = []
                if planner == "mplib" and probs:
                    recs, peer = run_mplib(robot, d, probs, a.budget, Path(a.mplib_python))
                    meta["mplib"] = peer["mplib"]
                    res.setdefault("mplib_processes", {})[f"{d.name}/{fam}"] = peer
                    for r in recs:
                        print(progress(d.name, fam, planner, r), flush=True)
                for p in probs if planner != "mplib" else ():
                    recs.append(run(gp, planner, p, a.reference if planner == "reference" else a.budget,
                                    planner != "reference"))
                    print(progress(d.name, fam, planner, recs[-1]), flush=True)
                s = summarize(d.name, fam, planner, recs)
                res["families"].append(s)
                print(f"{d.name}/{fam} {planner}: {s['successes']}/{s['n']} median {ms(s['time_median'])} ms p95 "
                      f"{ms(s['time_p95'])} ms | elapsed {hms(time.perf_counter() - t_start)}", flush=True)
            (out_dir / "mbm.json").write_text(json.dumps(res, indent=1, default=str))
    meta["load_end"] = load_avg()
    meta["elapsed_s"] = time.perf_counter() - t_start
    table = markdown(res)
    (out_dir / "mbm.json").write_text(json.dumps(res, indent=1, default=str))
    (out_dir / "mbm.md").write_text(table)
    print("\n" + table)
    print(f"wrote {out_dir / 'mbm.json'}, {out_dir / 'mbm.md'} in {hms(meta['elapsed_s'])}", flush=True)
    return 0


if __name__ == "__main__":
    from ompl_peer import exit_after_ompl

    exit_after_ompl(main())
