#!/usr/bin/env python3
"""Big scenes and update floods through ROS: what scene size and topic traffic cost the node's clients.

    .venv/bin/python benchmarks/bench_scale.py [--objects 1000] [--flood 10] [--only-flood] [--out out/bench/scale.json]

Starts `planner_node` (armar3, config/planner.yaml) in its own process on an isolated ROS domain; this
process is the client (its own executor thread). Phases, in order:
1. apply: `--objects` boxes (ADD, out of the arm's reach) published back to back (the node's own QoS
   profile, reliable keep-all: flow-controlled); time from the first publish until the node's scene
   version (a `get_planning_scene` that asks for no object) has advanced by all of them, and the
   updates/s that makes;
2. MOVE: 5 × `--objects` MOVE updates of those boxes back to back, then ADD of `--objects` new boxes:
   updates applied per second (scene version over time) with that many objects present (MOVEs of one
   object that wait together are applied as the last of them; the version counts every message);
3. names: `get_planning_scene` (OBJECT_NAMES) round trips with 3 × `--objects` objects in the scene, and
   what converting one such answer into Python messages costs this client alone (`client_conversion`:
   rclpy's deserialize_message of the same answer, the floor of any rclpy client's round trip);
4. flood: idle baselines first (names round trip, a plan_grasp of the `target` object), then another
   process publishes MOVE updates as fast as it can for `--flood` seconds while this one keeps calling
   both; reported: their medians / p95 during the flood, unanswered calls, the messages the publisher
   sent (K), the versions the scene advanced by (applied) and the node's `~/dropped_scene_updates`
   count (dropped), and whether applied + dropped = K. `--only-flood` runs phase 1 (the boxes the flood
   moves) and this phase only.
Figures are medians / p95 in seconds; the JSON also holds the load average.
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
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_service import isolated_domain, start_node, stop_node, wait_for_node  # noqa: E402
from humanoid_planner.child_env import child_environment  # noqa: E402

FAR = (3.0, 0.0, 0.5)  # m: a row of boxes starting here is out of armar3's reach


def box_msg(oid: str, k: int, frame: str, op: int):
    from geometry_msgs.msg import Pose
    from shape_msgs.msg import SolidPrimitive

    from humanoid_planner_interfaces.msg import CollisionObject

    m = CollisionObject()
    m.header.frame_id = frame
    m.id, m.operation = oid, op
    m.pose = Pose()
    m.pose.position.x, m.pose.position.y, m.pose.position.z = FAR[0] + 0.2 * (k % 50), 0.2 * (k // 50), FAR[2]
    m.pose.orientation.w = 1.0
    if op == CollisionObject.ADD:
        m.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.1, 0.1])]
        m.primitive_poses = [Pose()]
        m.primitive_poses[0].orientation.w = 1.0
    return m


def flood_publisher(seconds: float, frame: str, n_ids: int) -> None:
    """Child process: MOVE updates of box0..box{n_ids-1} as fast as possible for `seconds` (keep-last 100, no
    flow control); prints the count."""
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message

    from humanoid_planner_interfaces.msg import CollisionObject

    rclpy.init()
    node = rclpy.create_node("flood_publisher")
    # what a client that does not wait for the node publishes with: reliable, keep last 100
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(CollisionObject, "collision_object", qos)
    while pub.get_subscription_count() < 1:
        time.sleep(0.05)
    blobs = [serialize_message(box_msg(f"box{k}", k, frame, CollisionObject.MOVE)) for k in range(n_ids)]
    sent = 0
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        for b in blobs[:100]:
            pub.publish(b)
        sent += min(100, len(blobs))
    # reliable QoS: the samples still in this writer reach the node only while it exists
    pub.wait_for_all_acked(Duration(seconds=60))
    print(json.dumps({"sent": sent, "seconds": seconds}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def stats(xs: list[float]) -> dict:
    if not xs:
        return {"calls": 0}
    a = np.array(xs)
    return {"calls": len(a), "median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "max": float(a.max())}


def client_conversion(resp, repeats: int = 20) -> dict:
    """What any rclpy client pays for an answer before it can read it: rclpy's conversion of the
    serialized response into Python messages (deserialize_message: the C conversion a client's executor
    runs on each answer), median and min over `repeats`, with the answer's size. The names part of
    the round trip that no change in the node can take away."""
    from rclpy.serialization import deserialize_message, serialize_message

    raw = serialize_message(resp)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        deserialize_message(raw, type(resp))
        times.append(time.perf_counter() - t0)
    return {"objects": len(resp.objects), "bytes": len(raw), "median": float(np.median(times)),
            "min": float(min(times)), "per_object_us": float(np.median(times)) / max(1, len(resp.objects)) * 1e6}


def measure(n: int, flood_s: float, tmp: Path, only_flood: bool = False) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from humanoid_planner.ros.executors import wait_for_future
    from rclpy.node import Node
    from std_msgs.msg import UInt64

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.ros.conversions import scene_object_to_msg
    from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, DROPPED_QOS
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario
    from humanoid_planner_interfaces.msg import CollisionObject
    from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp

    domain = int(os.environ["ROS_DOMAIN_ID"])
    proc, log, _ = start_node("armar3", tmp)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = Node("scale_client", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    dropped = [0]
    res: dict = {}
    names = GetPlanningScene.Request(components=GetPlanningScene.Request.OBJECT_NAMES)
    version_only = GetPlanningScene.Request(components=GetPlanningScene.Request.VOXELS)  # no object in the answer

    def call(cli, req, timeout=30.0):
        t0 = time.perf_counter()
        fut = cli.call_async(req)
        wait_for_future(ex, fut, timeout)
        if not fut.done():
            cli.remove_pending_request(fut)
            return None, time.perf_counter() - t0
        return fut.result(), time.perf_counter() - t0

    def scene(timeout=30.0, req=names):
        resp, _ = call(scene_cli, req, timeout)
        if resp is None:
            raise RuntimeError("get_planning_scene unanswered")
        return resp

    def version() -> int:
        return scene(req=version_only).version

    def wait_version(v: int, timeout: float) -> float:
        t_end = time.monotonic() + timeout
        while (cur := version()) < v:
            if time.monotonic() > t_end:
                raise RuntimeError(f"scene version {v} not reached (at {cur})")
            time.sleep(0.005)
        return time.perf_counter()

    try:
        scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
        plan_cli = node.create_client(PlanGrasp, "plan_grasp")
        pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        node.create_subscription(UInt64, "humanoid_planner/dropped_scene_updates",
                                 lambda m: dropped.__setitem__(0, m.data), DROPPED_QOS)
        wait_for_node(proc, log, (scene_cli, plan_cli), (pub,))
        frame = scene().planning_frame

        # 1. apply n boxes
        msgs = [box_msg(f"box{k}", k, frame, CollisionObject.ADD) for k in range(n)]
        v0 = version()
        t0 = time.perf_counter()
        for m in msgs:
            pub.publish(m)
        t1 = wait_version(v0 + n, 60)
        res["apply"] = {"objects": n, "seconds": t1 - t0, "updates_per_s": n / (t1 - t0)}

        extras = 0 if only_flood else 2 * n  # the ADDs of phases 2 and 3
        if not only_flood:
            # 2. MOVE and ADD rates with n objects present
            moves = [box_msg(f"box{k % n}", k, frame, CollisionObject.MOVE) for k in range(5 * n)]
            v0 = version()
            t0 = time.perf_counter()
            for m in moves:
                pub.publish(m)
            t1 = wait_version(v0 + len(moves), 60)
            adds = [box_msg(f"extra{k}", n + k, frame, CollisionObject.ADD) for k in range(2 * n)]
            v0 = version()
            t2 = time.perf_counter()
            for m in adds[:n]:
                pub.publish(m)
            t3 = wait_version(v0 + n, 60)
            res["updates"] = {"objects_present": n, "move_per_s": len(moves) / (t1 - t0), "add_per_s": n / (t3 - t2)}

            # 3. names with 3n objects
            v0 = version()
            for m in adds[n:]:
                pub.publish(m)
            wait_version(v0 + n, 60)
            res["names"] = {"objects": len(scene().objects), **stats([call(scene_cli, names)[1] for _ in range(100)])}
            res["names"]["client_conversion"] = client_conversion(scene())

        # 4. flood: back to n far boxes + the boxes6 scene with its target
        v0 = version()
        for k in range(extras):
            pub.publish(box_msg(f"extra{k}", 0, frame, CollisionObject.REMOVE))
        sc = make_scenario(RobotModel.preset("armar3"), "boxes6", 0, hand="left")
        for o in sc.scene.objects:
            pub.publish(scene_object_to_msg(o, frame))
        wait_version(v0 + extras + len(sc.scene.objects), 60)
        plan_req = PlanGrasp.Request(group="left_arm_torso", object_id=OBJECT_ID, planner="girrt", timeout=5.0, seed=1)

        def probe(seconds: float) -> dict:
            """names and plan_grasp round trips, alternately, for `seconds`."""
            scene_rt, plan_rt, unanswered = [], [], 0
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                for cli, req, out, timeout in ((scene_cli, names, scene_rt, 10.0), (plan_cli, plan_req, plan_rt, 15.0)):
                    resp, rt = call(cli, req, timeout)
                    if resp is None:
                        unanswered += 1
                    else:
                        out.append(rt)
            return {"names": stats(scene_rt), "plan": stats(plan_rt), "unanswered": unanswered}

        # this client's objects out of the collector's sight, as the node does with its own
        # (node_main.freeze_startup_objects): each names answer makes ~10^4 objects, and the full
        # collections they trigger walked this whole process (90 ms idle, 200-380 ms during the flood),
        # which landed in the round trips measured
        gc.collect()
        gc.freeze()
        idle = probe(5.0)
        v0, d0 = version(), dropped[0]
        env = child_environment()
        flood = subprocess.Popen([sys.executable, __file__, "--flood-publisher", str(flood_s), "--frame", frame,
                                  "--ids", str(n)], stdout=subprocess.PIPE, text=True, env=env)
        time.sleep(1.0)  # the publisher's discovery
        during = probe(flood_s)
        out, _ = flood.communicate(timeout=flood_s + 120)
        sent = json.loads(out.strip().splitlines()[-1])["sent"]
        # applied: versions advanced until the backlog is done (stable for 2 s)
        last, stable_since = version(), time.monotonic()
        while time.monotonic() - stable_since < 2.0:
            time.sleep(0.2)
            v = version()
            if v != last:
                last, stable_since = v, time.monotonic()
        time.sleep(1.2)  # the drop count is published at most once a second
        applied, lost = last - v0, dropped[0] - d0
        res["flood"] = {"seconds": flood_s, "sent": sent, "applied": applied, "dropped_reported": lost,
                        "unaccounted": sent - applied - lost, "idle": idle, "during": during,
                        "plan_p95_limit": 2 * idle["plan"].get("p95", 0.0) + 0.1}
    finally:
        stop_node(proc)
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
    res["load_average"] = os.getloadavg()
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=1000)
    ap.add_argument("--flood", type=float, default=10.0, help="seconds of flood")
    ap.add_argument("--only-flood", action="store_true", help="phase 1 (the boxes) and the flood only")
    ap.add_argument("--out", default=str(ROOT / "out" / "bench" / "scale.json"))
    ap.add_argument("--flood-publisher", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--frame", default="", help=argparse.SUPPRESS)
    ap.add_argument("--ids", type=int, default=1000, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.flood_publisher is not None:
        flood_publisher(a.flood_publisher, a.frame, a.ids)
        return 0
    with contextlib.ExitStack() as stack:
        isolated_domain(stack)
        res = measure(a.objects, a.flood, Path(stack.enter_context(tempfile.TemporaryDirectory())), a.only_flood)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))
    print(json.dumps({k: v for k, v in res.items()}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
