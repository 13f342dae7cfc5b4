#!/usr/bin/env python3
"""get_planning_scene by parts while a 10^6-triangle mesh is in the scene and plans run.

    .venv/bin/python benchmarks/bench_scene_reads.py [--calls 200] [--out out/bench/scene_reads.json] [--threads]

Starts `planner_node` (armar3, config/planner.yaml) in its own process on an isolated ROS domain, loads the
boxes6 scene of seed 0 (its `target` object carries the grasps), then measures from this process the round
trip of `get_planning_scene` asking only for the object names (`components = OBJECT_NAMES`), `--calls`
times at about 20 Hz, in phases: idle; while a second client (another process, `--plan-client`) calls
`plan_grasp` back to back; the same with one more object, a mesh of 10^6 triangles / 5·10^5 vertices
(published pre-serialized, test/soak.py's mesh_bytes); and, for comparison, a few calls asking for
everything (`components = 0`, the full mesh in each answer). Reports median / p95 / max per phase and the
plans done meanwhile.
"""
from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "test"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_service import isolated_domain, start_node, stop_node, wait_for_node  # noqa: E402
from humanoid_planner.child_env import child_environment  # noqa: E402

TARGET_P95 = 0.020  # s: names-only reads while planning next to a 10^6-triangle mesh
SETTLE = 10.0  # s after the mesh is visible: the node's scene thread builds its full message meanwhile


def stats(xs: list[float]) -> dict:
    a = np.array(xs)
    return {"calls": len(a), "median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "max": float(a.max())}


def measure(calls: int, tmp: Path, processes: bool = True) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from humanoid_planner.ros.executors import wait_for_future
    from rclpy.node import Node

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.ros.conversions import scene_object_to_msg
    from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS
    from humanoid_planner.scenarios import make_scenario
    from humanoid_planner_interfaces.msg import CollisionObject
    from humanoid_planner_interfaces.srv import GetPlanningScene
    from soak import mesh_bytes

    domain = int(os.environ["ROS_DOMAIN_ID"])
    proc, log, _ = start_node("armar3", tmp, parameters={"max_triangles_per_message": 2_000_000,
                                                         "planning_processes": processes})
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = Node("scene_reader", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    plans: list[int] = []
    env = child_environment()
    # the plan client in a process of its own: in this one, its answers' conversions held the interpreter
    # lock the reads measured here wait for
    plan_proc = subprocess.Popen([sys.executable, __file__, "--plan-client"], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, text=True, env=env)

    def count_plans() -> None:
        for line in plan_proc.stdout:
            if line.strip().lstrip("-").isdigit():
                plans.append(int(line))

    def call(executor, cli, req, timeout=30.0):
        t0 = time.perf_counter()
        fut = cli.call_async(req)
        wait_for_future(executor, fut, timeout)
        if not fut.done():
            raise TimeoutError(f"{cli.srv_name}: no answer after {timeout} s")
        return fut.result(), time.perf_counter() - t0

    names = GetPlanningScene.Request(components=GetPlanningScene.Request.OBJECT_NAMES)

    def reads(n: int, req=names) -> list[float]:
        out = []
        for _ in range(n):
            out.append(call(ex, scene_cli, req)[1])
            time.sleep(0.05)
        return out

    try:
        scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
        pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        wait_for_node(proc, log, (scene_cli,), (pub,))
        frame = call(ex, scene_cli, names)[0].planning_frame
        sc = make_scenario(RobotModel.preset("armar3"), "boxes6", 0, hand="left")
        for o in sc.scene.objects:
            pub.publish(scene_object_to_msg(o, frame))
        want = len(sc.scene.objects)
        deadline = time.monotonic() + 30
        while len(call(ex, scene_cli, names)[0].objects) < want:
            if time.monotonic() > deadline:
                raise RuntimeError("the scene did not arrive")
            time.sleep(0.05)
        # this client's objects out of the collector's sight, as the node does with its own
        # (node_main.freeze_startup_objects): the plan loop's answers trigger full collections that walk
        # this whole process, and those landed in the read round trips measured (bench_scale: 90 ms)
        gc.collect()
        gc.freeze()
        idle = reads(calls)
        plan_proc.stdin.write("go\n")
        plan_proc.stdin.flush()
        worker = threading.Thread(target=count_plans, daemon=True)
        worker.start()
        deadline = time.monotonic() + 60
        while not plans:
            if time.monotonic() > deadline or plan_proc.poll() is not None:
                raise RuntimeError("the plan client answered no plan")
            time.sleep(0.05)
        planning = reads(calls)
        pub.publish(mesh_bytes(1_000_000, 500_000))
        deadline = time.monotonic() + 120
        while len(call(ex, scene_cli, names)[0].objects) < want + 1:
            if time.monotonic() > deadline:
                raise RuntimeError("the mesh was not applied: " + log.read_text(errors="replace")[-1000:])
            time.sleep(0.1)
        time.sleep(SETTLE)
        n0, t0 = len(plans), time.monotonic()
        busy = reads(calls)
        full = reads(5, GetPlanningScene.Request())
        elapsed = time.monotonic() - t0
        done = len(plans) - n0
    finally:
        with contextlib.suppress(OSError, ValueError):
            plan_proc.stdin.close()  # the plan client ends after its current plan
        try:
            plan_proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            plan_proc.kill()
        stop_node(proc)
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
    return {"idle_names": stats(idle), "planning_names": stats(planning), "planning_with_mesh_names": stats(busy),
            "planning_with_mesh_everything": stats(full), "plans_during": done, "plans_per_s": done / elapsed,
            "plan_error_codes": sorted(set(plans)), "target_p95": TARGET_P95, "planning_processes": processes,
            "load_average": os.getloadavg()}


def plan_client() -> int:
    """`--plan-client`: after a line on stdin, plan_grasp back to back (seeds 1, 2, ...), one error code
    per line on stdout, until stdin closes."""
    import rclpy

    from humanoid_planner.scenarios import OBJECT_ID
    from humanoid_planner_interfaces.srv import PlanGrasp

    from rclpy.executors import SingleThreadedExecutor

    from humanoid_planner.ros.executors import wait_for_future, wait_for_server

    rclpy.init()
    node = rclpy.create_node("plan_client")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    cli = node.create_client(PlanGrasp, "plan_grasp")
    stop = threading.Event()
    sys.stdin.readline()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    if not wait_for_server(cli, 30.0):
        return 1
    seed = 1
    while not stop.is_set():
        fut = cli.call_async(PlanGrasp.Request(group="left_arm_torso", object_id=OBJECT_ID, planner="girrt",
                                               timeout=2.0, seed=seed))
        wait_for_future(ex, fut, 30.0)
        if fut.done():
            print(int(fut.result().error_code.val), flush=True)
        seed += 1
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def main(argv=None) -> int:
    if (argv if argv is not None else sys.argv[1:]) == ["--plan-client"]:
        return plan_client()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--threads", action="store_true", help="plans in the node's threads (planning_processes false)")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench" / "scene_reads.json"))
    a = ap.parse_args(argv)
    with contextlib.ExitStack() as stack:
        isolated_domain(stack)
        res = measure(a.calls, Path(stack.enter_context(tempfile.TemporaryDirectory())), not a.threads)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))
    for k in ("idle_names", "planning_names", "planning_with_mesh_names", "planning_with_mesh_everything"):
        s = res[k]
        print(f"get_planning_scene {k}: median {s['median'] * 1000:.1f} ms, p95 {s['p95'] * 1000:.1f} ms, "
              f"max {s['max'] * 1000:.1f} ms ({s['calls']} calls)")
    print(f"plans meanwhile: {res['plans_during']} ({res['plans_per_s']:.1f}/s), error codes {res['plan_error_codes']}")
    return 0 if res["planning_with_mesh_names"]["p95"] <= TARGET_P95 else 1


if __name__ == "__main__":
    sys.exit(main())
