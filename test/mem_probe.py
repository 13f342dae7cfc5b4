"""Where does the node's memory go under load? A few-minute probe, not a test (issue 23).

    .venv/bin/python test/mem_probe.py [--minutes 4] [--robot dual_arm] [--trace 25] [--joint-noise 0.01]
    .venv/bin/python test/mem_probe.py --arm-replay 400 [--trace 15]

The planner node runs in this process (as planner_node runs it: EventsExecutor, frozen start-up
objects, warm arm process) so that tracemalloc and the garbage collector can look inside it; the
load comes from a child process of its own, as a robot's clients would send it: `--clients` plan
clients back to back (plan_grasp and plan_dual_grasp in turn, 2 s timeouts), a `--stream-hz`
collision_object stream of MOVE/ADD/REMOVE (boxes behind the robot, some updates refused: MOVE or
REMOVE of a box not there), get_planning_scene at `--scene-hz` and, with `--joint-noise`, joint_states
at 50 Hz with that much noise (rad) on every joint, as a live robot's encoders.

Every 10 s: RSS of this process and of the arm process; every 60 s: object counts per type. After
`--warmup` seconds a tracemalloc snapshot (`--trace N`: N frames per traceback; 0 = off, for RSS
figures without tracing overhead) and another at the end. Prints one JSON line: RSS slopes (least
squares after the warm-up, MB/min), the largest growths by traceback and by type, the sizes of the
node's caches, and the load's answers (sent, answered, late = past timeout + 1 s).

`--arm-replay N` looks at the arm process's side alone: the jobs a few dual plans send it, served N
times by its own loop on a thread of this process (RSS after malloc_trim, tracemalloc with --trace).
"""
from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import signal
import subprocess
import sys
import threading
import time
import tracemalloc
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE)]

PLAN_TIMEOUT = 2.0  # s, every plan request's timeout
BOX_IDS = ("m0", "m1", "m2", "m3", "m4")


def rss_mb(pid: int | str = "self") -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def slope_mb_per_min(samples: list[tuple[float, float]], after: float) -> float:
    """Least-squares slope of (seconds, MB) samples taken after `after` seconds, in MB per minute."""
    pts = np.array([(t, r) for t, r in samples if t >= after and np.isfinite(r)])
    if len(pts) < 3:
        return float("nan")
    return float(np.polyfit(pts[:, 0] / 60.0, pts[:, 1], 1)[0])


# ----------------------------------------------------------------------------- load (child process)
def run_load(args) -> None:
    """The clients: plans back to back, the collision_object stream, scene polling, joint_states."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from sensor_msgs.msg import JointState

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.ros.conversions import matrix_to_pose_msg, scene_object_to_msg
    from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS, SERVICE_QOS
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario
    from humanoid_planner_interfaces.msg import CollisionObject
    from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp
    from shape_msgs.msg import SolidPrimitive

    robot = RobotModel.preset(args.robot)
    sc = make_scenario(robot, "boxes6", 1, hand="both")
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    ex = MultiThreadedExecutor(num_threads=4, context=ctx)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    base = rclpy.create_node("mem_probe_load", context=ctx)
    ex.add_node(base)
    pub = base.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    scene_cli = base.create_client(GetPlanningScene, "get_planning_scene", qos_profile=SERVICE_QOS)
    js_pub = base.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
    threading.Thread(target=ex.spin, daemon=True).start()
    scene_cli.wait_for_service(timeout_sec=60.0)

    def call(cli, req, timeout):
        done = threading.Event()
        f = cli.call_async(req)
        f.add_done_callback(lambda _f: done.set())
        return f.result() if done.wait(timeout) else None

    def version() -> int:
        r = call(scene_cli, GetPlanningScene.Request(), 10.0)
        return -1 if r is None else r.version

    pub.publish(CollisionObject(operation=CollisionObject.REMOVE))
    for o in sc.scene.objects:
        pub.publish(scene_object_to_msg(o, robot.root_link))
    while version() < len(sc.scene.objects) + 1 and not stop.is_set():
        time.sleep(0.05)

    stats: dict[str, Counter] = {"plan_grasp": Counter(), "plan_dual_grasp": Counter(), "scene": Counter(),
                                 "stream": Counter()}
    lock = threading.Lock()

    def count(kind: str, **kw) -> None:
        with lock:
            stats[kind].update(kw)

    def plan_client(k: int) -> None:
        node = rclpy.create_node(f"mem_probe_client_{k}", context=ctx)
        ex.add_node(node)
        single = node.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
        dual = node.create_client(PlanDualGrasp, "plan_dual_grasp", qos_profile=SERVICE_QOS)
        single.wait_for_service(timeout_sec=30.0)
        i = 0
        while not stop.is_set():
            i += 1
            seed = 1000 * k + i
            if (i + k) % 2:
                kind, cli = "plan_dual_grasp", dual
                req = PlanDualGrasp.Request(left_group="left_arm", right_group="right_arm", object_id=OBJECT_ID,
                                            timeout=PLAN_TIMEOUT, seed=seed)
            else:
                kind, cli = "plan_grasp", single
                req = PlanGrasp.Request(group=("left_arm", "right_arm")[i % 2], object_id=OBJECT_ID,
                                        timeout=PLAN_TIMEOUT, seed=seed)
            t = time.monotonic()
            r = call(cli, req, PLAN_TIMEOUT + 30.0)
            late = time.monotonic() - t > PLAN_TIMEOUT + 1.0
            count(kind, sent=1, answered=r is not None, late=late,
                  **({f"code_{r.error_code.val}": 1} if r is not None else {}))

    def stream() -> None:
        rng = np.random.default_rng(1)
        period, next_t = 1.0 / args.stream_hz, time.monotonic()
        while not stop.is_set():
            oid = BOX_IDS[rng.integers(len(BOX_IDS))]
            op = (CollisionObject.MOVE, CollisionObject.ADD, CollisionObject.REMOVE)[rng.choice(3, p=(0.6, 0.25, 0.15))]
            T = np.eye(4)
            T[:3, 3] = [-1.5 + rng.normal(0, 0.05), rng.normal(0, 0.3), 0.5 + rng.normal(0, 0.05)]
            msg = CollisionObject(id=oid, operation=op)
            msg.header.frame_id = robot.root_link
            msg.pose = matrix_to_pose_msg(T)
            if op == CollisionObject.ADD:
                msg.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.1, 0.1])]
                msg.primitive_poses = [matrix_to_pose_msg(np.eye(4))]
            pub.publish(msg)
            count("stream", sent=1)
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))

    def poll_scene() -> None:
        period, next_t = 1.0 / args.scene_hz, time.monotonic()
        while not stop.is_set():
            t = time.monotonic()
            r = call(scene_cli, GetPlanningScene.Request(), 10.0)
            count("scene", sent=1, answered=r is not None, late=time.monotonic() - t > 1.0)
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))

    def joint_states() -> None:
        rng = np.random.default_rng(2)
        while not stop.is_set():
            q = np.clip(robot.home + rng.normal(0, args.joint_noise, robot.home.shape), robot.lower, robot.upper)
            msg = JointState(name=list(robot.joint_names), position=q.tolist())
            msg.header.stamp = base.get_clock().now().to_msg()
            js_pub.publish(msg)
            time.sleep(0.02)

    threads = [threading.Thread(target=plan_client, args=(k,), daemon=True) for k in range(args.clients)]
    threads += [threading.Thread(target=stream, daemon=True), threading.Thread(target=poll_scene, daemon=True)]
    if args.joint_noise > 0:
        threads.append(threading.Thread(target=joint_states, daemon=True))
    for t in threads:
        t.start()
    stop.wait(args.minutes * 60.0 + 600.0)
    stop.set()
    time.sleep(PLAN_TIMEOUT + 2.0)  # the last answers
    with lock:
        print(json.dumps({k: dict(v) for k, v in stats.items()}), flush=True)
    ex.shutdown(timeout_sec=5.0)
    ctx.try_shutdown()


# ----------------------------------------------------------------------------- node (this process)
def type_counts() -> Counter:
    return Counter(type(o).__name__ for o in gc.get_objects())


def cache_sizes(node) -> dict[str, int]:
    """The node's containers that could grow with plans or scene versions."""
    from humanoid_planner.core.collision.geometry import RobotCollisionModel

    model = RobotCollisionModel._cache.get(node.robot, {})  # noqa: SLF001 - a probe looks inside
    ps = node.plan_server
    return {"pair_tables": sum(len(m.pair_tables) for m in model.values()),
            "scene_object_msgs": len(node.scene_server._object_msgs),  # noqa: SLF001
            "scene_inbox": node.scene_server._inbox.qsize(),  # noqa: SLF001
            "goals": len(ps._goals), "active_plans": ps.active_plans,  # noqa: SLF001
            "watchdog_heap": len(ps._watchdog._heap),  # noqa: SLF001
            "threads": threading.active_count(), "gc_garbage": len(gc.garbage)}


def executor_allocated(limit: int = 10) -> list:
    """Live objects that the executor's C++ code allocated while tracing (their traceback ends in
    spin_once), found among the referents of the collector's objects: (type, referrer type, count)."""
    seen: Counter = Counter()
    for holder in gc.get_objects():
        for obj in gc.get_referents(holder):
            tb = tracemalloc.get_object_traceback(obj)
            if tb is not None and "spin_once" in "".join(tb.format(limit=1)):
                seen[(type(obj).__name__, type(holder).__name__)] += 1
    return [[*k, n] for k, n in seen.most_common(limit)]


def arm_pids(node) -> list[int]:
    pool = node.planner._pool  # noqa: SLF001
    return [p.pid for p in pool._procs] if pool is not None else []  # noqa: SLF001


def run_node(args) -> dict:
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.parameter import Parameter

    from humanoid_planner.node_main import GIL_SWITCH_INTERVAL, freeze_startup_objects
    from humanoid_planner.ros.executors import make_executor
    from humanoid_planner.ros.node import PlannerNode

    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    rclpy.init()  # the default context: make_executor's EventsExecutor spins that one, as in planner_node
    node = PlannerNode(parameter_overrides=[Parameter("robot", value=args.robot)])
    node.get_logger().set_level(rclpy.logging.LoggingSeverity.ERROR)  # 200 Hz of refused MOVEs
    executor, kind = make_executor("events", node.get_logger())
    executor.add_node(node)
    freeze_startup_objects()
    node.warm_up_in_background()

    def spin() -> None:
        try:
            while rclpy.ok():
                executor.spin_once(timeout_sec=1.0)
        except ExternalShutdownException:
            pass

    threading.Thread(target=spin, name="probe-executor", daemon=True).start()
    load = subprocess.Popen([sys.executable, __file__, "--load", "--robot", args.robot, "--minutes", str(args.minutes),
                             "--clients", str(args.clients), "--stream-hz", str(args.stream_hz),
                             "--scene-hz", str(args.scene_hz), "--joint-noise", str(args.joint_noise)],
                            stdout=subprocess.PIPE, text=True)
    node_rss, arm_rss, types = [], [], []
    snap0 = types0 = None
    t0 = time.monotonic()
    next_sample = next_types = t0
    while (now := time.monotonic()) - t0 < args.minutes * 60.0:
        t = now - t0
        if now >= next_sample:
            node_rss.append((round(t, 1), rss_mb()))
            arm_rss.append((round(t, 1), sum(rss_mb(p) for p in arm_pids(node)) or float("nan")))
            next_sample += 10.0
        if now >= next_types:
            types.append((round(t), sum(type_counts().values()), node.scene.version, cache_sizes(node)))
            next_types += 60.0
        if args.trace and snap0 is None and t >= args.warmup:
            gc.collect()
            tracemalloc.start(args.trace)
            snap0, types0 = tracemalloc.take_snapshot(), type_counts()
        if snap0 is None and types0 is None and not args.trace and t >= args.warmup:
            types0 = type_counts()
        time.sleep(1.0)
    load.send_signal(signal.SIGTERM)
    answers = json.loads(load.communicate(timeout=120)[0].strip().splitlines()[-1])
    gc.collect()
    types0, types1 = types0 or Counter(), type_counts()
    out = {"robot": args.robot, "minutes": args.minutes, "clients": args.clients, "stream_hz": args.stream_hz,
           "scene_hz": args.scene_hz, "joint_noise": args.joint_noise, "trace": args.trace,
           "scene_version": node.scene.version, "scene_objects": len(node.scene),
           "scene_ids": sorted(o.id for o in node.scene.snapshot().objects)[:20], "load": answers, "caches": cache_sizes(node),
           "node_rss_mb": [node_rss[0][1], node_rss[-1][1]],
           "node_slope_mb_per_min": round(slope_mb_per_min(node_rss, args.warmup), 3),
           "arm_slope_mb_per_min": round(slope_mb_per_min(arm_rss, args.warmup), 3),
           "arm_rss_mb": [arm_rss[0][1], arm_rss[-1][1]], "objects": types,
           "type_growth": sorted(((k, types1[k] - types0.get(k, 0)) for k in types1
                                  if types1[k] - types0.get(k, 0) > 50), key=lambda kv: -kv[1])[:15],
           "node_rss_samples": node_rss[::3], "arm_rss_samples": arm_rss[::3]}
    if snap0 is not None:
        snap1 = tracemalloc.take_snapshot()
        out["traced_mb"] = round(tracemalloc.get_traced_memory()[0] / 2**20, 2)
        out["top_growth"] = [{"kib": st.size_diff // 1024, "blocks": st.count_diff,
                              "where": st.traceback.format(limit=args.trace)[-12:]}
                             for st in snap1.compare_to(snap0, "traceback")[:args.top]]
        out["executor_allocated"] = executor_allocated()
        tracemalloc.stop()
    executor.shutdown(timeout_sec=5.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return out


def run_arm_replay(args) -> dict:
    """The arm process's side alone, in this process: record the jobs that dual plans send to the arm
    process, then serve them again and again with the arm process's own loop (`arm_process._serve`,
    on a thread), with tracemalloc and RSS (after malloc_trim) every `--arm-replay` / 5 jobs."""
    import ctypes
    import multiprocessing as mp
    from dataclasses import replace

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.pipeline import arm_process
    from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner
    from humanoid_planner.core.planners.arm_messages import Done, Ready
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario

    robot = RobotModel.preset(args.robot)
    sc = make_scenario(robot, "boxes6", 1, hand="both")
    planner = GraspPlanner(robot, parallel="process")
    jobs: list = []

    class Recorder:
        """Stands in for the arm process pool: keeps the jobs, runs none (the plan runs in threads)."""

        def try_start(self, sent):
            jobs.extend(replace(j, timeout=0.3) for j in sent)

    planner._pool = Recorder()  # noqa: SLF001
    for seed in range(8):
        planner.plan_dual_grasp(sc.scene, DualGraspPlanRequest("left_arm", "right_arm", robot.home, sc.object_pose,
                                                               sc.left_grasps, sc.right_grasps, OBJECT_ID,
                                                               timeout=PLAN_TIMEOUT, seed=seed))
    parent, child = mp.Pipe()
    threading.Thread(target=arm_process._serve, args=(child, robot.source, planner.options), daemon=True).start()
    assert isinstance(parent.recv(), Ready)
    libc = ctypes.CDLL("libc.so.6")

    def serve(n: int, first: int) -> None:
        for k in range(n):
            parent.send(replace(jobs[k % len(jobs)], job_id=first + k))
            while not isinstance(parent.recv(), Done):
                pass

    serve(len(jobs) * 3, 1)
    gc.collect()
    libc.malloc_trim(0)
    if args.trace:
        tracemalloc.start(args.trace)
        snap0 = tracemalloc.take_snapshot()
    samples, step, done = [(0, rss_mb())], max(1, args.arm_replay // 5), 0
    while done < args.arm_replay:
        serve(step, 10_000 + done)
        done += step
        gc.collect()
        libc.malloc_trim(0)
        samples.append((done, rss_mb()))
    parent.send(None)
    out = {"arm_replay_jobs": done, "recorded_jobs": len(jobs), "rss_mb_by_jobs": samples,
           "kb_per_job": round((samples[-1][1] - samples[1][1]) * 1024 / max(1, done - step), 3)}
    if args.trace:
        snap1 = tracemalloc.take_snapshot()
        out["top_growth"] = [{"kib": st.size_diff // 1024, "blocks": st.count_diff,
                              "where": st.traceback.format(limit=args.trace)[-12:]}
                             for st in snap1.compare_to(snap0, "traceback")[:args.top]]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=4.0)
    ap.add_argument("--warmup", type=float, default=60.0, help="s before the first snapshot and the slope")
    ap.add_argument("--robot", default="dual_arm")
    ap.add_argument("--clients", type=int, default=6)
    ap.add_argument("--stream-hz", type=float, default=200.0)
    ap.add_argument("--scene-hz", type=float, default=20.0)
    ap.add_argument("--joint-noise", type=float, default=0.0, help="rad; > 0: joint_states at 50 Hz")
    ap.add_argument("--trace", type=int, default=0, help="tracemalloc frames per traceback (0: off)")
    ap.add_argument("--top", type=int, default=12)
    ap.add_argument("--arm-replay", type=int, default=0,
                    help="instead of the node: serve this many recorded dual-plan jobs with the arm process's loop")
    ap.add_argument("--out", type=Path, help="also write the JSON here")
    ap.add_argument("--load", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if args.load:
        run_load(args)
        return 0
    if args.arm_replay:
        out = run_arm_replay(args)
        print(json.dumps(out), flush=True)
        return 0
    with contextlib.ExitStack() as stack:
        if not os.environ.get("ROS_DOMAIN_ID"):
            import domain_coordinator

            # held until the end: a released domain is handed to the next test run on this machine
            os.environ["ROS_DOMAIN_ID"] = str(stack.enter_context(domain_coordinator.domain_id()))
        out = run_node(args)
    text = json.dumps(out)
    print(text, flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
