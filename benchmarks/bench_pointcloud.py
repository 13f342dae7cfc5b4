#!/usr/bin/env python3
"""Point-cloud layer benchmark (issue 16): cloud → layer time, and GIRRT with obstacles given as clouds.

    .venv/bin/python benchmarks/bench_pointcloud.py                  # both parts, 30 problems
    .venv/bin/python benchmarks/bench_pointcloud.py --problems 50 --runs 31
    .venv/bin/python benchmarks/bench_pointcloud.py --part layer     # only the cloud → layer time

Part `layer`: a 640 × 480 organized depth image (307 200 points, PointCloud2 as a depth camera
publishes it) of armar3's `table_shelf` scene in a room (floor, back and side wall), seen from above
the torso; timed from the message to the layer: parsing (`ros.pointcloud.cloud_points`), the robot's
solids at home (FK), `cloud_to_layer` (range, transform, cells, self-filter, object filter). Median
and p95 of --runs conversions.

Part `plan`: GIRRT, armar3 left_arm_torso, the `boxes6` problems 1..N (as bench_planners.py: start =
home, request seed k, --budget s). Each problem is planned three ways, alternating the order from
problem to problem: with the six boxes (the reference), with the boxes given as clouds (every face
sampled every 1 cm, like a scanner that saw them all; filtered like a real cloud: robot at home,
the target object), and with those clouds plus a depth image of the room (floor and walls: a layer
of several thousand cells, as a head camera gives). Success, median and p95 of planning_time over all
attempts (failures at the time they returned), the paired median ratio to the boxes, the layer's
cells; the first --verify successes of each cloud row are checked by core.verification against the
six boxes themselves.

Part `stream` (not in `both`): `planner_node` (armar3) in its own process on its own ROS domain; a
client calls `get_planning_scene` back to back for --stream-seconds, in 2 s blocks that alternate
between no clouds and a 640 × 480 depth image (the `layer` part's, in torso_link's frame) published
at 30 Hz by a third process (as a camera driver would; on the same clock, odd blocks); round-trip
medians and p95 per condition, and how many layers the node built (scene versions). The three
processes share the 2 cores: the camera process's own serialization and DDS traffic count too
(the same stream to a topic nobody subscribes to raised the median from 5.7 to 15.4 ms when it ran
in the client's process).

Prints a markdown table and writes out/bench/pointcloud.json.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from humanoid_planner.clouds import box_surface_points, look_at, render_depth, scene_boxes  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest  # noqa: E402
from humanoid_planner.core.scene.types import SceneSnapshot  # noqa: E402
from humanoid_planner.core.scene.voxels import CloudSettings, cloud_to_layer, object_solids, robot_solids  # noqa: E402
from humanoid_planner.core.verification import verify_plan  # noqa: E402
from humanoid_planner.scenarios import OBJECT_ID, make_scenario  # noqa: E402
from humanoid_planner.child_env import child_environment  # noqa: E402

GROUP = "left_arm_torso"
SURFACE_SPACING = 0.01  # m between sampled points on a box face


def box(center, size) -> tuple[np.ndarray, np.ndarray]:
    T = np.eye(4)
    T[:3, 3] = center
    return T, np.asarray(size, dtype=float)


def room(robot: RobotModel) -> list[tuple[np.ndarray, np.ndarray]]:
    """Floor at the robot's base, a wall 1.2 m ahead and one 1.5 m to the left (as boxes to render)."""
    return [box((0.0, 0.0, -0.01), (6.0, 6.0, 0.02)), box((1.2, 0.0, 1.25), (0.02, 6.0, 2.5)),
            box((0.0, 1.5, 1.25), (6.0, 0.02, 2.5))]


def head_camera(robot: RobotModel, target: np.ndarray) -> np.ndarray:
    """A camera 35 cm above the torso link at home, looking at the target (optical frame)."""
    head = robot.link_poses(robot.home, ["torso_link"])[0][:3, 3] + [0.0, 0.0, 0.35]
    return look_at(head, target)


def pct(values, q) -> float:
    return float(np.percentile(values, q))


def part_layer(robot: RobotModel, runs: int) -> dict:
    from humanoid_planner.ros.pointcloud import cloud_points, points_to_cloud

    sc = make_scenario(robot, "table_shelf", 1, hand="left", left_group="left_arm_torso",
                       right_group="right_arm_torso")
    cam = head_camera(robot, sc.object_pose[:3, 3])
    img = render_depth(room(robot) + scene_boxes(sc.scene.objects), cam, 640, 480, fov_x=np.radians(90))
    msg = points_to_cloud(img.reshape(-1, 3), "camera", (480, 640))
    settings = CloudSettings()
    objects = object_solids(sc.scene.objects)
    times, stats = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        pts = cloud_points(msg)
        layer, stats = cloud_to_layer(pts, cam, settings, robot_solids(robot, robot.home), objects)
        times.append(time.perf_counter() - t0)
    return {"points": int(stats.points), "finite_in_range": int(stats.used), "on_robot": int(stats.on_robot),
            "in_objects": int(stats.in_objects), "cells": int(stats.cells), "runs": runs,
            "median_ms": 1e3 * float(np.median(times)), "p95_ms": 1e3 * pct(times, 95),
            "stages_ms_last": {k: 1e3 * v for k, v in stats.stages.items()}}


def cloud_scenes(robot: RobotModel, sc) -> dict[str, tuple[SceneSnapshot, int]]:
    target = sc.scene.get(OBJECT_ID)
    solids, objects = robot_solids(robot, robot.home), object_solids((target,))
    surfaces = np.concatenate([box_surface_points(p, s, SURFACE_SPACING)
                               for p, s in scene_boxes(sc.scene.objects, (OBJECT_ID,))])
    boxes_layer, _ = cloud_to_layer(surfaces, np.eye(4), CloudSettings(), solids, objects)
    cam = head_camera(robot, sc.object_pose[:3, 3])
    seen = render_depth(room(robot), cam, 640, 480, fov_x=np.radians(90)).reshape(-1, 3)
    seen = seen[np.isfinite(seen).all(1)] @ cam[:3, :3].T + cam[:3, 3]
    room_layer, _ = cloud_to_layer(np.concatenate([surfaces, seen]), np.eye(4), CloudSettings(), solids, objects)
    v = sc.scene.version
    return {"clouds": (SceneSnapshot(v + 1, sc.scene.frame, (target,), boxes_layer), len(boxes_layer)),
            "clouds + room": (SceneSnapshot(v + 2, sc.scene.frame, (target,), room_layer), len(room_layer))}


def part_plan(robot: RobotModel, problems: int, budget: float, verify: int) -> dict:
    planner = GraspPlanner(robot)
    rows = ("boxes", "clouds", "clouds + room")
    recs: dict[str, list[dict]] = {r: [] for r in rows}
    for k in range(1, problems + 1):
        sc = make_scenario(robot, "boxes6", k, hand="left", left_group="left_arm_torso", right_group="right_arm_torso")
        scenes = {"boxes": (sc.scene, 0), **cloud_scenes(robot, sc)}
        order = rows if k % 2 else rows[::-1]
        for row in order:
            snap, cells = scenes[row]
            req = GraspPlanRequest(GROUP, robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt", budget,
                                   seed=k)
            plan = planner.plan_grasp(snap, req)
            rec = {"problem": k, "ok": plan.ok, "time": plan.planning_time, "iterations": plan.iterations,
                   "cells": cells, "status": plan.status.name}
            if plan.ok and row != "boxes" and sum(r.get("verified") is not None for r in recs[row]) < verify:
                target = sc.object_pose @ plan.grasps[0].tcp_in_object
                rec["verified"] = not verify_plan(robot, sc.scene, (GROUP,), robot.home, plan, (target,),
                                                  object_id=OBJECT_ID)
            recs[row].append(rec)
        print(f"  problem {k}: " + ", ".join(f"{r} {1e3 * recs[r][-1]['time']:.0f} ms" for r in rows), flush=True)
    out = {}
    ref = {r["problem"]: r["time"] for r in recs["boxes"]}
    for row in rows:
        t = [r["time"] for r in recs[row]]
        paired = [r["time"] / ref[r["problem"]] for r in recs[row]]
        verified = [r["verified"] for r in recs[row] if "verified" in r]
        out[row] = {"success": float(np.mean([r["ok"] for r in recs[row]])), "median_ms": 1e3 * float(np.median(t)),
                    "p95_ms": 1e3 * pct(t, 95), "paired_ratio_to_boxes": float(np.median(paired)),
                    "cells_median": int(np.median([r["cells"] for r in recs[row]])),
                    "verified": f"{sum(verified)}/{len(verified)}", "attempts": recs[row]}
    return out


def stream_cloud(robot: RobotModel):
    """The `stream` part's PointCloud2: the layer part's depth image, in torso_link's frame."""
    from humanoid_planner.ros.pointcloud import points_to_cloud

    sc = make_scenario(robot, "table_shelf", 1, hand="left", left_group="left_arm_torso",
                       right_group="right_arm_torso")
    cam = head_camera(robot, sc.object_pose[:3, 3])
    img = render_depth(room(robot) + scene_boxes(sc.scene.objects), cam, 640, 480, fov_x=np.radians(90))
    T = np.linalg.inv(robot.link_poses(robot.home, ["torso_link"])[0]) @ cam
    return points_to_cloud((img.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]).astype(np.float32), "torso_link", (480, 640))


def camera(robot: RobotModel, t0: float, block: float, end: float) -> int:
    """The camera process of the `stream` part: 30 Hz during odd blocks since t0 (epoch), until end."""
    import rclpy
    from sensor_msgs.msg import PointCloud2

    from humanoid_planner.ros.qos import POINTCLOUD_QOS

    msg = stream_cloud(robot)
    rclpy.init()
    node = rclpy.create_node("bench_camera")
    pub = node.create_publisher(PointCloud2, "pointcloud", POINTCLOUD_QOS)
    sent = 0
    while time.time() < end:
        if int((time.time() - t0) // block) % 2 == 1:
            pub.publish(msg)
            sent += 1
        time.sleep(1.0 / 30.0)
    print(sent)
    node.destroy_node()
    rclpy.shutdown()
    return 0


def part_stream(robot: RobotModel, seconds: float) -> dict:
    import contextlib
    import signal
    import subprocess

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from humanoid_planner.ros.executors import wait_for_future
    from humanoid_planner.ros.executors import wait_for_server

    from humanoid_planner_interfaces.srv import GetPlanningScene

    block = 2.0
    with contextlib.ExitStack() as stack:
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        if not os.environ.get("ROS_DOMAIN_ID"):
            import domain_coordinator

            os.environ["ROS_DOMAIN_ID"] = str(stack.enter_context(domain_coordinator.domain_id()))
        env = child_environment()
        exe = Path(sys.executable).parent / "planner_node"
        proc = subprocess.Popen([str(exe), "--ros-args", "-p", "robot:=armar3"], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        ctx = Context()
        rclpy.init(context=ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
        node = rclpy.create_node("bench_pointcloud_client", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        cam = None
        try:
            cli = node.create_client(GetPlanningScene, "get_planning_scene")
            if not wait_for_server(cli, 60.0):
                raise RuntimeError("planner_node did not come up")

            def call():
                t = time.perf_counter()
                fut = cli.call_async(GetPlanningScene.Request())
                wait_for_future(ex, fut, 10.0)
                return time.perf_counter() - t, fut.result()

            t0 = time.time() + 8.0  # the camera process starts meanwhile (interpreter, rclpy, the image)
            end = t0 + block * max(2, int(seconds / block))
            cam = subprocess.Popen([sys.executable, __file__, "--camera", f"{t0},{block},{end}"], env=env,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            v0 = call()[1].version
            while time.time() < t0:
                time.sleep(0.05)
            lat = {"quiet": [], "30 Hz clouds": []}
            while time.time() < end - 0.05:
                k = int((time.time() - t0) // block) % 2
                dt = call()[0]
                if int((time.time() - t0) // block) % 2 == k:  # a call that straddles two blocks is dropped
                    lat["30 Hz clouds" if k else "quiet"].append(dt)
            sent = int(cam.communicate(timeout=30)[0].strip() or 0)
            time.sleep(0.5)
            layers = call()[1].version - v0
        finally:
            if cam is not None and cam.poll() is None:
                cam.kill()
            node.destroy_node()
            ctx.try_shutdown()
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=15)
    return {k: {"calls": len(v), "median_ms": 1e3 * float(np.median(v)), "p95_ms": 1e3 * pct(v, 95)}
            for k, v in lat.items()} | {"clouds_sent": sent, "layers_built": layers}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=("layer", "plan", "both", "stream"), default="both")
    ap.add_argument("--stream-seconds", type=float, default=12.0)
    ap.add_argument("--camera", help=argparse.SUPPRESS)  # t0,block,end: run as the stream part's camera process
    ap.add_argument("--problems", type=int, default=30)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--runs", type=int, default=21)
    ap.add_argument("--verify", type=int, default=5)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench")
    args = ap.parse_args(argv)
    robot = RobotModel.preset("armar3")
    if args.camera:
        return camera(robot, *(float(x) for x in args.camera.split(",")))
    res: dict = {"load_before": os.getloadavg()[0]}
    lines = ["| measure | result |", "|---|---|"]
    if args.part in ("layer", "both"):
        lay = res["layer"] = part_layer(robot, args.runs)
        lines.append(f"| cloud → layer, 640×480 organized ({lay['points']} points, {lay['finite_in_range']} finite "
                     f"within range, {lay['cells']} cells) | median {lay['median_ms']:.1f} ms, p95 {lay['p95_ms']:.1f} ms "
                     f"({lay['runs']} runs) |")
    if args.part in ("plan", "both"):
        plan = res["plan"] = part_plan(robot, args.problems, args.budget, args.verify)
        for row, r in plan.items():
            cells = f", {r['cells_median']} cells (median)" if row != "boxes" else ""
            check = f", verified against the boxes {r['verified']}" if row != "boxes" else ""
            lines.append(f"| GIRRT armar3 boxes6, obstacles as {row}{cells} | success {100 * r['success']:.0f} %, "
                         f"median {r['median_ms']:.0f} ms, p95 {r['p95_ms']:.0f} ms, paired ×{r['paired_ratio_to_boxes']:.2f} "
                         f"of boxes{check} |")
    if args.part == "stream":
        st = res["stream"] = part_stream(robot, args.stream_seconds)
        for k in ("quiet", "30 Hz clouds"):
            lines.append(f"| get_planning_scene round trip, {k} ({st[k]['calls']} calls) | median {st[k]['median_ms']:.2f} ms, "
                         f"p95 {st[k]['p95_ms']:.2f} ms |")
        lines.append(f"| layers built / 640×480 clouds sent at 30 Hz (another process) | {st['layers_built']} / "
                     f"{st['clouds_sent']} |")
    res["load_after"] = os.getloadavg()[0]
    lines.append(f"| load average (1 min) before / after | {res['load_before']:.2f} / {res['load_after']:.2f} |")
    print("\n".join(lines))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pointcloud.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
