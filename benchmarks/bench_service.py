#!/usr/bin/env python3
"""plan_grasp service overhead: round trip (request to response) minus the plan's own planning_time.

    .venv/bin/python benchmarks/bench_service.py [--calls 30] [--budget 5] [--robot armar3] [--family boxes6]
                                                 [--client-executor events|single] [--node-executor events|single]
                                                 [--out out/bench/service.json]

Starts `planner_node` (this venv's console script) in its own process on an isolated ROS domain
(ROS_DOMAIN_ID if set, else one reserved with domain_coordinator; ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST),
with its `executor` parameter from config/planner.yaml unless --node-executor is given.
For each problem k (the same seeded scenarios as bench_planners.py: family boxes6, hand="left"), the
scene is replaced over the `collision_object` topic (REMOVE all, then ADD every object, confirmed through
`get_planning_scene`'s version; not timed), then `plan_grasp` is called once (group left_arm_torso,
object_id "target": its own grasp set, planner girrt, seed k+1, start = home) and timed in this process
from `call_async` until the future is done, the client spinning (ros.executors.wait_for_future) an
executor in this thread: rclpy's EventsExecutor (default) or its SingleThreadedExecutor
(--client-executor single, for comparison: a Python executor's wake-up and wait-set work are the
client's share of the overhead, measured in benchmarks/README.md). Overhead = round trip - response.planning_time: request transport and checking in the
node, the worker hand-off, the response (trajectory) conversion, DDS both ways, the client's wake-up and
deserialization. One warm-up call is not counted. For orientation the JSON also has a breakdown: the
round trip of `get_planning_scene` (transport + executors, no planning); of a plan_grasp refused while the
request is checked (unknown planner: no worker involved); the overhead of a plan_grasp that goes through a
planning worker but gives up at once (1 ms timeout: worker hand-off, no trajectory); and, measured in this
process, the node's own per-request work around planning (request checking, response filling, the
response's (de)serialization; the markers, built after the answer has gone out).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from humanoid_planner.child_env import child_environment

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
NODE = "humanoid_planner"


def node_exe() -> str:
    exe = Path(sys.executable).parent / "planner_node"
    return str(exe) if exe.exists() else "planner_node"


def client_executor(kind: str, context):
    """The executor the client waits with: "events" (rclpy's EventsExecutor) or "single"."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


def start_node(robot_name: str, tmp: Path, node_kind: str | None = None,
               parameters: dict | None = None) -> tuple[subprocess.Popen, Path, str]:
    """planner_node for `robot_name` in its own process (config/planner.yaml, then the robot and `parameters`;
    logs to tmp): (process, log path, the executor it spins)."""
    import yaml

    params = tmp / "params.yaml"
    params.write_text(yaml.safe_dump({NODE: {"ros__parameters": {"robot": robot_name, **(parameters or {})}}}))
    log = tmp / "planner_node.log"
    args = [node_exe(), "--ros-args", "--params-file", str(ROOT / "config" / "planner.yaml"), "--params-file",
            str(params), "--log-level", "warn"]
    if node_kind:
        args += ["-p", f"executor:={node_kind}"]
    else:  # what config/planner.yaml sets (the node's default when it sets nothing)
        config = yaml.safe_load((ROOT / "config" / "planner.yaml").read_text()) or {}
        node_kind = config.get(NODE, {}).get("ros__parameters", {}).get("executor", "events")
    env = child_environment()
    with open(log, "wb") as logf:
        proc = subprocess.Popen(args, stdout=logf, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                cwd=str(ROOT))
    return proc, log, node_kind


def wait_for_node(proc: subprocess.Popen, log: Path, clients, publishers=(), timeout: float = 60.0) -> None:
    """Until every client's service is available and every publisher matched; RuntimeError when the node
    exits or the time is up."""
    from humanoid_planner.ros.executors import wait_for_server

    deadline = time.monotonic() + timeout
    for cli in clients:
        while not wait_for_server(cli, 0.2):
            if proc.poll() is not None:
                raise RuntimeError(f"planner_node exited with code {proc.returncode}: "
                                   + log.read_text(errors="replace")[-2000:])
            if time.monotonic() > deadline:
                raise RuntimeError(f"service {cli.srv_name} not available after {timeout:g} s")
    for pub in publishers:
        while pub.get_subscription_count() < 1:
            time.sleep(0.05)
            if time.monotonic() > deadline:
                raise RuntimeError(f"{pub.topic_name}: no subscription matched after {timeout:g} s")


def isolated_domain(stack: contextlib.ExitStack) -> None:
    """This process and the nodes it starts on a ROS domain of their own: ROS_DOMAIN_ID if set, else one
    reserved with domain_coordinator for as long as `stack` is open; discovery on this machine only."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if not os.environ.get("ROS_DOMAIN_ID"):
        import domain_coordinator

        os.environ["ROS_DOMAIN_ID"] = str(stack.enter_context(domain_coordinator.domain_id()))


def stop_node(proc: subprocess.Popen) -> None:
    """SIGTERM, then SIGKILL after 20 s."""
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def measure(calls: int, budget: float, robot_name: str, family: str, group: str, tmp: Path,
            client_kind: str = "events", node_kind: str | None = None) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario
    from humanoid_planner.ros.conversions import scene_object_to_msg
    from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS
    from humanoid_planner.ros.executors import wait_for_future
    from humanoid_planner_interfaces.msg import CollisionObject, ErrorCode
    from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp

    proc, log, node_kind = start_node(robot_name, tmp, node_kind)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    node = Node("bench_service_client", context=ctx)
    executor = client_executor(client_kind, ctx)
    executor.add_node(node)
    load_start = os.getloadavg()[0]

    def call(cli, req, timeout):
        t0 = time.perf_counter()
        fut = cli.call_async(req)
        wait_for_future(executor, fut, timeout)
        t1 = time.perf_counter()
        if not fut.done():
            raise TimeoutError(f"{cli.srv_name}: no answer after {timeout} s")
        return fut.result(), t1 - t0

    try:
        scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
        plan_cli = node.create_client(PlanGrasp, "plan_grasp")
        pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        wait_for_node(proc, log, (scene_cli, plan_cli), (pub,))
        scene_resp, _ = call(scene_cli, GetPlanningScene.Request(), 10)
        frame = scene_resp.planning_frame

        robot = RobotModel.preset(robot_name)

        def load_scene(seed: int):
            sc = make_scenario(robot, family, seed, hand="left")
            version = call(scene_cli, GetPlanningScene.Request(), 10)[0].version
            clear = CollisionObject()
            clear.header.frame_id = frame
            clear.operation = CollisionObject.REMOVE
            msgs = [clear] + [scene_object_to_msg(o, frame) for o in sc.scene.objects]
            for m in msgs:
                pub.publish(m)
            target = version + len(msgs)
            t_end = time.monotonic() + 10
            while call(scene_cli, GetPlanningScene.Request(), 10)[0].version < target:
                if time.monotonic() > t_end:
                    raise RuntimeError(f"scene version {target} not reached")
                time.sleep(0.01)
            return sc

        def plan(seed: int):
            req = PlanGrasp.Request()
            req.group = group
            req.object_id = OBJECT_ID
            req.planner = "girrt"
            req.timeout = float(budget)
            req.seed = seed + 1  # 0 means nondeterministic
            return call(plan_cli, req, budget * 2 + 10)

        load_scene(10_000)
        plan(10_000)  # warm-up
        rows = []
        for k in range(calls):
            load_scene(k)
            resp, rt = plan(k)
            ok = resp.error_code.val == ErrorCode.SUCCESS
            rows.append({"seed": k, "ok": ok, "error_code": int(resp.error_code.val), "round_trip": rt,
                         "planning_time": float(resp.planning_time), "overhead": rt - float(resp.planning_time),
                         "trajectory_points": len(resp.trajectory.points)})
            print(f"   service call {k + 1}/{calls}: {'ok' if ok else resp.error_code.val} round trip "
                  f"{rt * 1000:.1f} ms, planning_time {resp.planning_time * 1000:.1f} ms, "
                  f"overhead {(rt - resp.planning_time) * 1000:.2f} ms",
                  flush=True)
        # transport + executor baseline: a small service of the same node (scene with the problem's objects)
        scene_rt = [call(scene_cli, GetPlanningScene.Request(), 10)[1] for _ in range(20)]
        # plan_grasp refused while checking the request (never reaches a planning worker)
        bad = PlanGrasp.Request()
        bad.group, bad.object_id, bad.planner = group, OBJECT_ID, "no_such_planner"
        refused_rt = [call(plan_cli, bad, 10)[1] for _ in range(20)]
        # plan_grasp through a planning worker that gives up at once (1 ms timeout): hand-off cost, no trajectory
        quick = PlanGrasp.Request()
        quick.group, quick.object_id, quick.planner, quick.timeout = group, OBJECT_ID, "girrt", 0.001
        worker_ov = []
        for _ in range(20):
            resp, rt = call(plan_cli, quick, 10)
            worker_ov.append(rt - resp.planning_time)
        load_end = os.getloadavg()[0]
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
    ov = np.array([r["overhead"] for r in rows])
    breakdown = {"get_planning_scene_round_trip_median": float(np.median(scene_rt)),
                 "refused_plan_grasp_round_trip_median": float(np.median(refused_rt)),
                 "worker_no_trajectory_overhead_median": float(np.median(worker_ov))}
    try:
        breakdown.update(node_side_costs(robot, make_scenario(robot, family, calls - 1, hand="left"), group, budget,
                                         calls))
    except Exception as e:  # noqa: BLE001 - diagnostics only
        breakdown["error"] = f"{type(e).__name__}: {e}"
    return {"robot": robot_name, "family": family, "group": group, "planner": "girrt", "budget": budget,
            "client_executor": client_kind, "node_executor": node_kind,
            "load_average_1min": [load_start, load_end],
            "calls": len(rows), "successes": sum(r["ok"] for r in rows),
            "round_trip_median": float(np.median([r["round_trip"] for r in rows])),
            "planning_time_median": float(np.median([r["planning_time"] for r in rows])),
            "overhead_median": float(np.median(ov)), "overhead_p95": float(np.percentile(ov, 95)),
            "overhead_max": float(ov.max()), "overhead_min": float(ov.min()), "node_exit_code": code,
            "breakdown": breakdown,
            "definition": "client-side perf_counter from call_async to future done (wait_for_future spinning "
                          f"on the client's {client_kind} executor), minus response.planning_time",
            "rows": rows}


def node_side_costs(robot, sc, group: str, budget: float, seed: int) -> dict:
    """In this process, the node's own per-request work around planning, on the last problem's plan:
    request checking (prepare_plan_grasp), response filling (fill_response: trajectory message), rclpy's
    serialization of the response (done once by the node) and deserialization (once by the client), and
    the plan markers and the scene + plan marker array (built on the node's marker thread after the
    answer has gone out). Medians of 20 runs, seconds."""
    from humanoid_planner.core.pipeline.planner import GraspPlanner
    from humanoid_planner.scenarios import OBJECT_ID
    from humanoid_planner.core.scene.types import SceneSnapshot
    from humanoid_planner.ros.frames import Frames
    from humanoid_planner.ros.requests import RequestDefaults, fill_response, prepare_plan_grasp
    from humanoid_planner_interfaces.srv import PlanGrasp

    frame = robot.root_link
    snap = SceneSnapshot(1, frame, sc.scene.objects)
    req = PlanGrasp.Request()
    req.group, req.object_id, req.planner, req.timeout, req.seed = group, OBJECT_ID, "girrt", float(budget), seed + 1
    defaults = RequestDefaults(budget, 0.001)

    def median_time(fn, n=20):
        out = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
        return float(np.median(out))

    prep = prepare_plan_grasp(robot, req, snap, None, defaults, Frames(robot, frame))
    plan = GraspPlanner(robot).plan_grasp(snap, prep.core)
    res = {"prepare_request": median_time(lambda: prepare_plan_grasp(robot, req, snap, None, defaults, Frames(robot, frame)))}
    if plan.ok:
        res["fill_response"] = median_time(lambda: fill_response(PlanGrasp.Response(), plan, frame, False))
        res["trajectory_points"] = len(plan.trajectory.times)
        from rclpy.serialization import deserialize_message, serialize_message

        resp = fill_response(PlanGrasp.Response(), plan, frame, False)
        blob = serialize_message(resp)
        res["response_bytes"] = len(blob)
        res["serialize_response"] = median_time(lambda: serialize_message(resp))
        res["deserialize_response"] = median_time(lambda: deserialize_message(blob, PlanGrasp.Response))
        try:
            from humanoid_planner.ros.markers import plan_markers

            targets = tuple(prep.core.object_pose @ g.tcp_in_object for g in plan.grasps)
            res["plan_markers"] = median_time(lambda: plan_markers(robot, plan, prep.groups, prep.start, targets,
                                                                   frame))
            from humanoid_planner.ros.markers import marker_array, scene_markers

            pm = plan_markers(robot, plan, prep.groups, prep.start, targets, frame)
            # what the node's _publish_markers does after answering: scene + plan markers, serialized once
            res["scene_and_plan_marker_array"] = median_time(
                lambda: serialize_message(marker_array(scene_markers(snap, frame, highlight=OBJECT_ID) + pm)))
        except Exception as e:  # noqa: BLE001 - the markers module is optional here
            res["plan_markers_error"] = repr(e)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=30)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--robot", default="armar3")
    ap.add_argument("--family", default="boxes6")
    ap.add_argument("--group", default="left_arm_torso")
    ap.add_argument("--client-executor", choices=("events", "single"), default="events",
                    help="what the client waits with (default: rclpy's EventsExecutor)")
    ap.add_argument("--node-executor", choices=("events", "single"), default=None,
                    help="planner_node's `executor` parameter (default: config/planner.yaml's)")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench" / "service.json"))
    a = ap.parse_args(argv)
    with contextlib.ExitStack() as stack:
        isolated_domain(stack)
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        try:
            res = measure(a.calls, a.budget, a.robot, a.family, a.group, tmp, a.client_executor, a.node_executor)
        except Exception as e:  # noqa: BLE001 - reported in the JSON, the planner benchmark goes on
            res = {"error": f"{type(e).__name__}: {e}"}
            print(f"   service benchmark failed: {res['error']}", flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))
    if "error" not in res:
        print(f"   plan_grasp overhead over {res['calls']} calls (node: {res['node_executor']} executor, client: "
              f"{res['client_executor']}): median {res['overhead_median'] * 1000:.2f} ms, "
              f"p95 {res['overhead_p95'] * 1000:.2f} ms, max {res['overhead_max'] * 1000:.2f} ms "
              f"(round trip median {res['round_trip_median'] * 1000:.1f} ms)", flush=True)
        print("   breakdown: " + ", ".join(f"{k} {v * 1000:.2f} ms" if isinstance(v, float) else f"{k} {v}"
                                       for k, v in res["breakdown"].items()), flush=True)
    return 0 if "error" not in res else 1


if __name__ == "__main__":
    sys.exit(main())
