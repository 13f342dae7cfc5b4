#!/usr/bin/env python3
"""Plans per second with 1, 2, 4, 8 clients planning back to back, and the worker hand-off per plan.

    .venv/bin/python benchmarks/bench_clients.py [--clients 1,2,4,8] [--duration 10] [--modes processes,threads]
                                                 [--out out/bench/clients.json] [--no-handoff] [--check]

Part 1, through ROS: for each mode (`planning_processes` true / false) starts `planner_node` (armar3,
config/planner.yaml, `num_workers` left at its default: one per core) in its own process on an isolated
ROS domain, loads the boxes6 scene of seed SCENE_SEED (its `target` carries the grasps; plans of 17-40 ms,
so the node's own per-request work weighs as much as it can), then for each client count
N starts N client processes (each its own rclpy context) that, once all are ready, call `plan_grasp`
(left_arm_torso, GIRRT, 2 s timeout, a new seed per call) back to back for `--duration` s. Reports plans/s
(answers of all clients / duration), the success share and the client-side round-trip median / p95.
Acceptance: 2 clients >= 1.7x the plans/s of 1 client with worker processes (with --check: exit code 1
otherwise).

Part 2, no ROS (`--no-handoff` skips it): the cost of handing a plan to a worker process
(PlanWorkerPool), per plan = round trip of `pool.run` minus the plan's own planning_time, for a plan that
gives up at once (1 ms timeout), with the boxes6 scene (7 objects) plus 0 / 1,000 far boxes, unchanged
between plans or with one box moved before each plan.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from humanoid_planner.child_env import child_environment  # noqa: E402

GROUP = "left_arm_torso"
TIMEOUT = 2.0  # s per plan request
SCENE_SEED = 1  # boxes6 seeds 0, 2, 4 need 0.1-0.5 s plans (scaling is then easy); 1, 3, 5, 6 17-40 ms
TARGET_SPEEDUP = 1.7  # 2 clients / 1 client, worker processes, 2 cores


def client_main(index: int, domain: int) -> int:
    """One client process: ready -> waits for "go" on stdin -> plans until "stop" time -> one JSON line."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from humanoid_planner.ros.executors import wait_for_future
    from humanoid_planner.ros.executors import wait_for_server
    from humanoid_planner.scenarios import OBJECT_ID
    from humanoid_planner_interfaces.msg import ErrorCode
    from humanoid_planner_interfaces.srv import PlanGrasp

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = Node(f"bench_client_{index}", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    cli = node.create_client(PlanGrasp, "plan_grasp")
    while not wait_for_server(cli, 1.0):
        pass
    print("ready", flush=True)
    duration = float(sys.stdin.readline().split()[1])  # "go <duration>"
    rows = []
    seed = 1 + 100_000 * index
    end = time.monotonic() + duration
    cpu0 = time.process_time()
    while time.monotonic() < end:
        req = PlanGrasp.Request(group=GROUP, object_id=OBJECT_ID, planner="girrt", timeout=TIMEOUT, seed=seed)
        t0 = time.perf_counter()
        fut = cli.call_async(req)
        wait_for_future(ex, fut, TIMEOUT * 3 + 10)
        rt = time.perf_counter() - t0
        if not fut.done():
            rows.append((rt, -1, 0.0))
            break
        r = fut.result()
        if time.monotonic() <= end:  # answers after the end do not count
            rows.append((rt, int(r.error_code.val == ErrorCode.SUCCESS), float(r.planning_time)))
        seed += 1
    print(json.dumps({"rows": rows, "cpu": time.process_time() - cpu0}), flush=True)
    ex.shutdown()
    node.destroy_node()
    ctx.try_shutdown()
    return 0


def _cpu(pid: int) -> float:
    """CPU seconds (user + system) of one process so far; 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def tree_cpu(pid: int) -> tuple[float, float]:
    """(CPU s of the node process, CPU s of its descendants: the worker processes and their forkserver)."""
    todo, others = [pid], 0.0
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*/children"):
            try:
                kids = [int(c) for c in task.read_text().split()]
            except OSError:
                kids = []
            todo += kids
            others += sum(_cpu(k) for k in kids)
    return _cpu(pid), others


def run_clients(n: int, duration: float, domain: int) -> dict:
    env = child_environment()
    procs = [subprocess.Popen([sys.executable, __file__, "--client", str(k), "--domain", str(domain)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=str(ROOT))
             for k in range(n)]
    try:
        for p in procs:
            line = p.stdout.readline()
            if line.strip() != "ready":
                raise RuntimeError(f"a client did not start: {line!r}")
        for p in procs:
            p.stdin.write(f"go {duration}\n")
            p.stdin.flush()
        rows, client_cpu = [], 0.0
        for p in procs:
            out = json.loads(p.stdout.readline())
            rows += out["rows"]
            client_cpu += out["cpu"]
            p.wait(timeout=30)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    rt = np.array([r[0] for r in rows]) if rows else np.zeros(1)
    return {"clients": n, "plans": len(rows), "plans_per_s": len(rows) / duration,
            "success": sum(r[1] == 1 for r in rows) / max(1, len(rows)), "unanswered": sum(r[1] == -1 for r in rows),
            "round_trip_median": float(np.median(rt)), "round_trip_p95": float(np.percentile(rt, 95)),
            "planning_time_median": float(np.median([r[2] for r in rows])) if rows else 0.0,
            "clients_cpu_per_plan": client_cpu / max(1, len(rows))}


def measure_mode(processes: bool, counts: list[int], duration: float, tmp: Path) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from bench_service import start_node, stop_node, wait_for_node
    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.ros.conversions import scene_object_to_msg
    from humanoid_planner.ros.executors import wait_for_future
    from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS
    from humanoid_planner.scenarios import make_scenario
    from humanoid_planner_interfaces.msg import CollisionObject
    from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp

    domain = int(os.environ["ROS_DOMAIN_ID"])
    proc, log, _ = start_node("armar3", tmp, parameters={"planning_processes": processes})
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = Node("bench_clients_setup", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    def call(cli, req, timeout=30.0):
        fut = cli.call_async(req)
        wait_for_future(ex, fut, timeout)
        if not fut.done():
            raise TimeoutError(f"{cli.srv_name}: no answer after {timeout} s")
        return fut.result()

    rows = []
    try:
        scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
        plan_cli = node.create_client(PlanGrasp, "plan_grasp")
        pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        wait_for_node(proc, log, (scene_cli, plan_cli), (pub,))
        names = GetPlanningScene.Request(components=GetPlanningScene.Request.OBJECT_NAMES)
        frame = call(scene_cli, names).planning_frame
        sc = make_scenario(RobotModel.preset("armar3"), "boxes6", SCENE_SEED, hand="left", left_group=GROUP)
        for o in sc.scene.objects:
            pub.publish(scene_object_to_msg(o, frame))
        deadline = time.monotonic() + 30
        while len(call(scene_cli, names).objects) < len(sc.scene.objects):
            if time.monotonic() > deadline:
                raise RuntimeError("the scene did not arrive")
            time.sleep(0.05)
        time.sleep(3.0 if processes else 0.5)  # the worker processes finish starting (node start-up warm-up)
        for n in counts:
            run_clients(n, 2.0, domain)  # warm-up: every worker has planned and holds the scene
            cpu0 = tree_cpu(proc.pid)
            row = run_clients(n, duration, domain)
            cpu1 = tree_cpu(proc.pid)
            plans = max(1, row["plans"])
            row["node_cpu_per_plan"] = (cpu1[0] - cpu0[0]) / plans  # includes plans after the end: an upper bound
            row["workers_cpu_per_plan"] = (cpu1[1] - cpu0[1]) / plans
            rows.append(row)
            print(f"   {'processes' if processes else 'threads'}: {n} client(s): {row['plans_per_s']:.1f} plans/s, "
                  f"success {row['success']:.0%}, round trip median {row['round_trip_median'] * 1000:.0f} ms, "
                  f"p95 {row['round_trip_p95'] * 1000:.0f} ms; CPU per plan: node {row['node_cpu_per_plan'] * 1000:.1f} ms, "
                  f"workers {row['workers_cpu_per_plan'] * 1000:.1f} ms, clients {row['clients_cpu_per_plan'] * 1000:.1f} ms", flush=True)
    finally:
        stop_node(proc)
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
    return {"planning_processes": processes, "cores": len(os.sched_getaffinity(0)), "rows": rows,
            "load_average": os.getloadavg()}


def measure_handoff(plans: int = 40) -> dict:
    """Per-plan cost of handing a plan to a worker, by scene size, unchanged or with one MOVE per plan."""
    from dataclasses import replace

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.pipeline.plan_process import PlanWorkerPool
    from humanoid_planner.core.pipeline.planner import GraspPlanRequest
    from humanoid_planner.core.planners.common import PlannerOptions
    from humanoid_planner.core.scene.planning_scene import PlanningScene
    from humanoid_planner.core.scene.types import Shape
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario

    robot = RobotModel.preset("armar3")
    sc = make_scenario(robot, "boxes6", SCENE_SEED, hand="left", left_group=GROUP)
    pool = PlanWorkerPool(robot, 1, PlannerOptions(), "thread")
    out = {}
    try:
        if not pool.wait_ready(120):
            raise RuntimeError("the worker did not start")
        for far in (0, 1000):
            scene = PlanningScene(sc.scene.frame)
            for o in sc.scene.objects:
                scene.add(o.id, o.pose, o.shapes, o.grasps)
            box = Shape("box", np.eye(4), (0.05, 0.05, 0.05))
            for k in range(far):
                T = np.eye(4)
                T[:3, 3] = (5.0 + 0.2 * (k % 30), 0.2 * (k // 30), 0.0)
                scene.add(f"far_{k}", T, (box,))
            req = GraspPlanRequest(GROUP, robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, timeout=0.001,
                                   seed=1)
            for moving in (False, True):
                times = []
                for i in range(plans + 1):
                    if moving:
                        o = scene.get(sc.scene.objects[0].id)
                        T = np.array(o.pose)
                        T[2, 3] += 1e-4 * (1 if i % 2 else -1)
                        scene.move(o.id, T)
                    snap = scene.snapshot()
                    t0 = time.perf_counter()
                    plan = pool.run("plan_grasp", snap, replace(req), PlannerOptions(), "thread")
                    dt = time.perf_counter() - t0
                    if i:  # the first carries the whole scene
                        times.append(dt - plan.planning_time)
                key = f"{len(sc.scene.objects) + far}_objects_{'one_moved' if moving else 'unchanged'}"
                out[key] = {"median": float(np.median(times)), "p95": float(np.percentile(times, 95))}
                print(f"   hand-off, {key}: median {out[key]['median'] * 1000:.2f} ms, "
                      f"p95 {out[key]['p95'] * 1000:.2f} ms", flush=True)
    finally:
        pool.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", default="1,2,4,8")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--modes", default="processes,threads")
    ap.add_argument("--no-handoff", action="store_true")
    ap.add_argument("--check", action="store_true", help="exit 1 when 2 clients < 1.7x the plans/s of 1 client")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench" / "clients.json"))
    ap.add_argument("--client", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--domain", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.client is not None:
        return client_main(a.client, a.domain)
    counts = [int(x) for x in a.clients.split(",")]
    res: dict = {"duration": a.duration, "timeout": TIMEOUT, "group": GROUP, "modes": {}}
    with contextlib.ExitStack() as stack:
        from bench_service import isolated_domain

        isolated_domain(stack)
        for mode in a.modes.split(","):
            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory()))
            res["modes"][mode] = measure_mode(mode == "processes", counts, a.duration, tmp)
    if not a.no_handoff:
        res["handoff"] = measure_handoff()
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))
    print("| clients | " + " | ".join(f"plans/s ({m})" for m in res["modes"]) + " |")
    print("|---|" + "---|" * len(res["modes"]))
    for i, n in enumerate(counts):
        print(f"| {n} | " + " | ".join(f"{res['modes'][m]['rows'][i]['plans_per_s']:.1f}" for m in res["modes"]) + " |")
    proc_rows = {r["clients"]: r["plans_per_s"] for r in res.get("modes", {}).get("processes", {}).get("rows", [])}
    if 1 in proc_rows and 2 in proc_rows:
        ratio = proc_rows[2] / proc_rows[1]
        print(f"2 clients / 1 client with worker processes: {ratio:.2f}x (target >= {TARGET_SPEEDUP})")
        return 0 if ratio >= TARGET_SPEEDUP or not a.check else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
