"""`make soak`: the long reliability run against planner_node in its own process.

    .venv/bin/python test/soak.py [--duration 600] [--max-slope 0.05] [--messages 5000] [--skip fuzz,endurance,load]
    .venv/bin/python test/soak.py --skip fuzz,load --duration 3600        # the hour
    .venv/bin/python test/soak.py --skip fuzz,load --duration 86400       # a day
    .venv/bin/python test/soak.py --skip fuzz,load --trace 25 --duration 300   # where the memory goes
    .venv/bin/python test/soak.py --arm-replay 300 [--trace 15]          # the arm process's loop alone

1. endurance (`--duration` s, default 10 minutes): a dual_arm node under a busy robot's load, sent by
   a client process of its own: 6 plan clients back to back (plan_grasp and plan_dual_grasp in turn,
   2 s timeouts), a 200 Hz collision_object stream of MOVE/ADD/REMOVE (boxes behind the robot; some
   refused: MOVE or REMOVE of a box not there), get_planning_scene at 20 Hz, a point cloud at 10 Hz
   and a parameter set every 5 s. Every 10 s the RSS of the node and of its arm process(es);
   least-squares slopes after 2 and after 5 minutes. Every answer is checked: none missing, none
   later than its timeout + 1 s (get_planning_scene and parameter sets: 1 s + 1 s), no parameter set
   refused. Every successful plan is verified (core.verification, exact FCL at 1 cm, limits, the
   grasp reached) in the scene of the version it reports, rebuilt by the client: the stream's
   states, tied to the node's versions by the get_planning_scene answers (which must each match a
   state the stream made), and the point-cloud layer (whose size the answers must report). Writes
   out/soak/endurance.json and endurance.png. Fails when a slope after 5 minutes passes
   `--max-slope`, or an answer or plan fails a check.
2. fuzz: >= 5000 seeded hostile collision_object messages (scene_model.MessageFuzzer) through the
   topic, in batches of 50; after each batch get_planning_scene must equal the reference model's
   scene (scene_model.SceneModel). Reports mismatches (must be 0).
3. load: a fourth client's ordinary plans (armar3, table_shelf) and get_planning_scene calls,
   unloaded and then while a 10^6-triangle mesh arrives and three clients (own processes) send
   10^5-grasp plan requests in a loop. Target: plans p95 <= 2 x unloaded p95 + 0.25 s, scene calls
   p95 <= 100 ms, every request answered.

Prints one JSON summary line per phase and exits 1 if a target is missed.
"""
from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import queue
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
from collections import Counter, deque
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE / "integration")]

import rclpy  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402

from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, DROPPED_QOS, POINTCLOUD_QOS, SERVICE_QOS  # noqa: E402
from humanoid_planner.ros.executors import wait_for_server  # noqa: E402
from humanoid_planner.scenarios import OBJECT_ID  # noqa: E402
from humanoid_planner_interfaces.msg import CollisionObject, Grasp  # noqa: E402
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp  # noqa: E402

from conftest import REPO_ROOT, PlannerProcess  # noqa: E402
from plan_helpers import scenario  # noqa: E402
from scene_model import MessageFuzzer, SceneModel, same_state, state_of  # noqa: E402

EXE = Path(sys.executable).parent / "planner_node"


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def mesh_bytes(n_tri: int, n_vert: int, oid: str = "big_mesh") -> bytes:
    """A serialized CollisionObject (ADD, one mesh) built with numpy, as plain CDR (little endian)."""
    out = bytearray(b"\x00\x01\x00\x00")

    def align(n):
        out.extend(b"\x00" * ((-(len(out) - 4)) % n))

    def u32(v):
        align(4)
        out.extend(struct.pack("<I", v))

    def string(s):
        b = s.encode() + b"\x00"
        u32(len(b))
        out.extend(b)

    def pose():
        align(8)
        out.extend(np.array([0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0], "<f8").tobytes())

    u32(0), u32(0), string(""), string(oid), pose()
    u32(0), u32(0)  # primitives, primitive_poses
    u32(1)  # meshes
    rng = np.random.default_rng(0)
    u32(n_tri)
    out.extend(rng.integers(0, n_vert, size=(n_tri, 3)).astype("<u4").tobytes())
    u32(n_vert)
    align(8)
    out.extend(rng.uniform(-0.05, 0.05, size=(n_vert, 3)).astype("<f8").tobytes())
    u32(1)
    pose()
    u32(0)  # grasps
    out.extend(b"\x00")  # operation ADD
    return bytes(out)


class Client:
    """A client node spun in the background."""

    def __init__(self, context, name: str):
        self.node = rclpy.create_node(name, context=context)
        self.plan = self.node.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
        self.scene = self.node.create_client(GetPlanningScene, "get_planning_scene", qos_profile=SERVICE_QOS)
        self.pub = self.node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)

    def call(self, cli, req, timeout: float = 120.0):
        return call(cli, req, timeout)


def call(cli, req, timeout: float):
    """The answer of one service call, or None after `timeout` seconds."""
    done = threading.Event()
    f = cli.call_async(req)
    f.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout):
        return None
    return f.result()


def start_node(tmp: Path, params: dict) -> PlannerProcess:
    import yaml

    f = tmp / "soak_params.yaml"
    f.write_text(yaml.safe_dump({"humanoid_planner": {"ros__parameters": params}}))
    log = tmp / "node"
    log.mkdir(exist_ok=True)
    return PlannerProcess(EXE, [REPO_ROOT / "config" / "planner.yaml", f], log)


def wait_subscribed(c: Client, timeout: float = 60.0) -> None:
    """Until the node's collision_object subscription has matched c.pub: a service being found says nothing
    of the topic, and what a reliable volatile publisher sends before the match never arrives."""
    deadline = time.monotonic() + timeout
    while c.pub.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            raise TimeoutError("the node's collision_object subscription did not match")
        time.sleep(0.05)


def wait_version(c: Client, version: int, timeout: float = 60.0) -> object:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r = c.call(c.scene, GetPlanningScene.Request(), 10.0)
        if r is not None and r.version >= version:
            return r
        time.sleep(0.02)
    raise TimeoutError(f"scene version {version} not reached")


def phase_fuzz(c: Client, n: int) -> dict:
    fuzz, model = MessageFuzzer(20261123), SceneModel()
    mismatches = sent = 0
    t0 = time.monotonic()
    while sent < n:
        for _ in range(50):
            msg = fuzz.message()
            model.apply(msg)
            c.pub.publish(msg)
            sent += 1
        r = wait_version(c, model.version)
        if r.version != model.version or not same_state(state_of(r.objects), model.state()):
            mismatches += 1
            model = SceneModel()  # resynchronize: clear both
            c.pub.publish(CollisionObject(operation=CollisionObject.REMOVE))
            model.apply(CollisionObject(operation=CollisionObject.REMOVE))
            wait_version(c, r.version + 1)
            model.version = r.version + 1
    return {"phase": "fuzz", "messages": sent, "batch_mismatches": mismatches, "ok": mismatches == 0,
            "seconds": round(time.monotonic() - t0, 1)}


def plan_request(seed: int, timeout: float = 5.0) -> PlanGrasp.Request:
    return PlanGrasp.Request(group="left_arm_torso", object_id=OBJECT_ID, timeout=timeout, seed=seed)


def load_scene(c: Client) -> None:
    from humanoid_planner.ros.conversions import scene_object_to_msg

    c.pub.publish(CollisionObject(operation=CollisionObject.REMOVE))
    v = wait_version(c, 0).version + 1
    wait_version(c, v)
    for o in scenario("table_shelf", 1, "left").scene.objects:
        c.pub.publish(scene_object_to_msg(o, "base_link"))
        v += 1
    wait_version(c, v)


def heavy_client(seconds: float) -> None:
    """Own process: send 10^5-grasp plan requests in a loop (each refused: over max_grasps_per_request)."""
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    ex = MultiThreadedExecutor(context=ctx)
    c = Client(ctx, f"heavy_{os.getpid()}")
    ex.add_node(c.node)
    spin = threading.Thread(target=ex.spin, daemon=True)
    spin.start()
    wait_for_server(c.plan, 30.0)
    g = Grasp(id="g")
    g.tcp_in_object.orientation.w = 1.0
    req = PlanGrasp.Request(group="left_arm_torso", object_id="", grasps=[g] * 100_000, timeout=5.0)
    t0, sent, answered = time.monotonic(), 0, 0
    while time.monotonic() - t0 < seconds:
        sent += 1
        answered += c.call(c.plan, req, 120.0) is not None
    print(json.dumps({"heavy_client": os.getpid(), "sent": sent, "answered": answered}), flush=True)
    ex.shutdown(timeout_sec=5.0)
    c.node.destroy_node()
    ctx.try_shutdown()


def measure(c: Client, n: int, seed0: int) -> tuple[list[float], list[float], int]:
    plans, scenes, missing = [], [], 0
    for i in range(n):
        t = time.monotonic()
        r = c.call(c.plan, plan_request(seed0 + i), 60.0)
        plans.append(time.monotonic() - t)
        missing += r is None
        t = time.monotonic()
        r = c.call(c.scene, GetPlanningScene.Request(), 30.0)
        scenes.append(time.monotonic() - t)
        missing += r is None
    return plans, scenes, missing


def p95(xs) -> float:
    return float(np.percentile(xs, 95))


def phase_load(c: Client, n: int, heavy_seconds: float) -> dict:
    load_scene(c)
    plans0, scenes0, miss0 = measure(c, n, 1000)
    big = mesh_bytes(1_000_000, 500_000)
    heavies = [subprocess.Popen([sys.executable, __file__, "--heavy-client", str(heavy_seconds)],
                                stdout=subprocess.PIPE, text=True) for _ in range(3)]
    time.sleep(3.0)  # the heavy clients are sending
    c.pub.publish(big)
    plans1, scenes1, miss1 = measure(c, n, 2000)
    heavy = [json.loads(h.communicate(timeout=heavy_seconds + 300)[0].strip().splitlines()[-1]) for h in heavies]
    target = 2 * p95(plans0) + 0.25
    ok = p95(plans1) <= target and p95(scenes1) <= 0.1 and miss0 + miss1 == 0 and all(
        h["sent"] == h["answered"] for h in heavy)
    return {"phase": "load", "unloaded_plan_p95_s": round(p95(plans0), 3), "loaded_plan_p95_s": round(p95(plans1), 3),
            "plan_target_s": round(target, 3), "unloaded_scene_p95_s": round(p95(scenes0), 3),
            "loaded_scene_p95_s": round(p95(scenes1), 3), "unanswered": miss0 + miss1, "heavy_clients": heavy,
            "load_average": os.getloadavg(), "ok": ok}


# ----------------------------------------------------------------------------- endurance (issue 23)
CLIENTS = 6
PLAN_TIMEOUT = 2.0  # s, every plan request's timeout; late = answered after timeout + LATE_SLACK
LATE_SLACK = 1.0
SCENE_TIMEOUT = 1.0  # s, what get_planning_scene and parameter sets are held to (+ LATE_SLACK)
STREAM_IDS = ("m0", "m1", "m2", "m3", "m4")
HISTORY_S = 60.0  # s of scene states kept to resolve a plan's reported version
CLOUD_BOX = ((-0.6, -0.7, 0.9), (0.2, 0.2, 0.2))  # centre, size: the point cloud's box (beside and behind the robot)


def descendants(pid: int) -> dict[int, int]:
    """Every process below pid: {pid: parent pid}."""
    parent = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                parent[int(d.name)] = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                pass
    out, todo = {}, [pid]
    while todo:
        p = todo.pop()
        for c, pp in parent.items():
            if pp == p and c not in out:
                out[c] = p
                todo.append(c)
    return out


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def node_processes(pid: int) -> tuple[int, list[int]]:
    """(the node's own process, its arm processes): the arm processes are the forkserver's children;
    the node is the process that started the forkserver (below a re-executing launcher, if any)."""
    below = descendants(pid)
    servers = [p for p in below if "forkserver" in cmdline(p) and "forkserver" not in cmdline(below[p])]
    arms = sorted(p for p, pp in below.items() if pp in servers)
    node = below[servers[0]] if servers else pid
    return node, arms


def slope_mb_per_min(samples: list[tuple[float, float]], after: float) -> float | None:
    """Least-squares slope of (seconds, MB) samples taken at or after `after` seconds, MB per minute."""
    pts = np.array([(t, r) for t, r in samples if t >= after and np.isfinite(r)])
    if len(pts) < 3:
        return None
    return round(float(np.polyfit(pts[:, 0] / 60.0, pts[:, 1], 1)[0]), 4)


class History:
    """The scene states the stream made (after each accepted message k) and what the node's polls said
    (version V held state k): enough to name the states a plan's reported version can mean. Point-cloud
    layers bump the version too, at places the client cannot see, so a version between two polls maps
    to a short range of states; a plan must verify in every one of them. A state can recur (a box added
    and removed again); a poll whose state recurs within its possible range is not used."""

    def __init__(self):
        self.lock = threading.Lock()
        self.states: dict[int, tuple] = {}  # k -> state (scene_model.state())
        self.order: deque[int] = deque()
        self.by_state: dict[tuple, list[int]] = {}  # state -> the ks it was made at, increasing
        self.polls: list[tuple[int, int]] = [(0, 0)]  # (version, k), increasing
        self.unmatched = self.ambiguous = 0  # polls whose objects match no state / several states the stream made
        self.unmatched_examples: list[dict] = []

    @staticmethod
    def key(state: list[tuple]) -> tuple:
        return tuple((s[0], tuple(s[1])) for s in state)

    def add_state(self, k: int, state: list[tuple], keep: int) -> None:
        """State k (the model's version), keeping the last `keep` states."""
        key = self.key(state)
        with self.lock:
            self.states[k] = key
            self.by_state.setdefault(key, []).append(k)
            self.order.append(k)
            while len(self.order) > keep:
                old = self.order.popleft()
                old_key = self.states.pop(old)
                ks = self.by_state[old_key]
                ks.remove(old)
                if not ks:
                    del self.by_state[old_key]

    def add_poll(self, version: int, state: list[tuple]) -> None:
        with self.lock:
            V0, k0 = self.polls[-1]
            if version <= V0:
                return
            # layers only add versions: k0 <= k <= version - (V0 - k0)
            ks = [k for k in self.by_state.get(self.key(state), ()) if k0 <= k <= version - (V0 - k0)]
            if not ks:
                self.unmatched += 1
                if len(self.unmatched_examples) < 5:  # where it was: the state made at all? when?
                    self.unmatched_examples.append({"version": version, "last_poll": [V0, k0],
                                                    "made_at": self.by_state.get(self.key(state), [])[-3:],
                                                    "latest_state": self.order[-1] if self.order else None})
            elif len(ks) > 1:
                self.ambiguous += 1
            else:
                self.polls.append((version, ks[0]))
                del self.polls[:-2000]

    def candidates(self, v: int) -> tuple[list[tuple], str] | None:
        """(the states version v may be, and how they were found); None: no poll after v yet."""
        with self.lock:
            after = [(V, k) for V, k in self.polls if V >= v]
            before = [(V, k) for V, k in self.polls if V <= v]
            if not after:
                return None
            if not before:
                return [], f"version {v}: no poll before it"
            (V1, k1), (V2, k2) = before[-1], after[0]
            lo, hi = max(k1, v - (V2 - k2)), min(k2, v - (V1 - k1))
            how = f"version {v} between polls ({V1}: state {k1}) and ({V2}: state {k2}): states {lo}..{hi}"
            return [self.states[k] for k in range(lo, hi + 1) if k in self.states], how


class NodeProcess:
    """planner_node in its own process, as on a robot: its own RSS and its arm processes' are sampled."""

    def __init__(self, tmp: Path, robot: str):
        self._proc = start_node(tmp, {"robot": robot})

    def processes(self) -> tuple[int, list[int]]:
        return node_processes(self._proc.pid)

    def alive(self) -> bool:
        return self._proc.proc.poll() is None

    def output(self) -> str:
        return self._proc.output()

    def inside(self) -> dict:
        return {}

    def stop(self) -> None:
        self._proc.stop()


class NodeInProcess:
    """The node in this process, spun as planner_node spins it (EventsExecutor, frozen start-up objects,
    warm arm process), so that tracemalloc and the garbage collector see inside it (`--trace N`: N frames
    per traceback; a snapshot after `--warmup` s and one at the end; object counts per type)."""

    def __init__(self, robot: str, trace: int, warmup: float):
        from rclpy.executors import ExternalShutdownException
        from rclpy.parameter import Parameter

        from humanoid_planner.node_main import GIL_SWITCH_INTERVAL, freeze_startup_objects
        from humanoid_planner.ros.executors import make_executor
        from humanoid_planner.ros.node import PlannerNode

        sys.setswitchinterval(GIL_SWITCH_INTERVAL)
        rclpy.init()  # the default context: make_executor's EventsExecutor spins that one, as in planner_node
        self.node = PlannerNode(parameter_overrides=[Parameter("robot", value=robot)])
        self.node.get_logger().set_level(rclpy.logging.LoggingSeverity.ERROR)  # 200 Hz of refused MOVEs
        self.executor, _ = make_executor("events", self.node.get_logger())
        self.executor.add_node(self.node)
        freeze_startup_objects()
        self.node.warm_up_in_background()
        self.trace, self.warmup, self.t0 = trace, warmup, time.monotonic()
        self.snap0 = self.types0 = None

        def spin() -> None:
            try:
                while rclpy.ok():
                    self.executor.spin_once(timeout_sec=1.0)
            except ExternalShutdownException:
                pass

        threading.Thread(target=spin, name="soak-executor", daemon=True).start()

    def processes(self) -> tuple[int, list[int]]:
        if self.snap0 is None and time.monotonic() - self.t0 >= self.warmup:
            gc.collect()
            tracemalloc.start(self.trace)
            self.snap0, self.types0 = tracemalloc.take_snapshot(), type_counts()
        pool = self.node.planner._pool  # noqa: SLF001 - a probe looks inside
        return os.getpid(), [p.pid for p in pool._procs] if pool is not None else []  # noqa: SLF001

    def alive(self) -> bool:
        return True

    def output(self) -> str:
        return ""

    def inside(self) -> dict:
        """Growth since the warm-up: by traceback, by type; the node's caches."""
        gc.collect()
        out = {"caches": cache_sizes(self.node), "scene_version": self.node.scene.version}
        if self.snap0 is not None:
            types1 = type_counts()
            out["type_growth"] = sorted(((k, n - self.types0.get(k, 0)) for k, n in types1.items()
                                         if n - self.types0.get(k, 0) > 50), key=lambda kv: -kv[1])[:15]
            snap1 = tracemalloc.take_snapshot()
            out["traced_mb"] = round(tracemalloc.get_traced_memory()[0] / 2**20, 2)
            out["top_growth"] = [{"kib": st.size_diff // 1024, "blocks": st.count_diff,
                                  "where": st.traceback.format(limit=self.trace)[-12:]}
                                 for st in snap1.compare_to(self.snap0, "traceback")[:12]]
            tracemalloc.stop()
        return out

    def stop(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def type_counts() -> Counter:
    return Counter(type(o).__name__ for o in gc.get_objects())


def cache_sizes(node) -> dict[str, int]:
    """The node's containers that could grow with plans or scene versions."""
    from humanoid_planner.core.collision.geometry import RobotCollisionModel

    model = RobotCollisionModel._cache.get(node.robot, {})  # noqa: SLF001 - a probe looks inside
    ps = node.plan_server
    return {"pair_tables": sum(len(m.pair_tables) for m in model.values()),
            "scene_object_msgs": sum(len(m) for m in node.scene_server._object_msgs.values()),  # noqa: SLF001
            "scene_inbox": node.scene_server.intake.backlog(),
            "goals": len(ps._goals), "active_plans": ps.active_plans,  # noqa: SLF001
            "watchdog_heap": len(ps._watchdog._heap),  # noqa: SLF001
            "threads": threading.active_count(), "gc_garbage": len(gc.garbage)}


def phase_endurance(tmp: Path, args) -> dict:
    """A dual_arm node under a busy robot's load for `--duration` s: RSS of the node and of its arm
    processes every 10 s, their least-squares slopes, and every answer and plan checked."""
    node = NodeInProcess(args.robot, args.trace, args.warmup) if args.trace else NodeProcess(tmp, args.robot)
    load = None
    samples: list[tuple[float, float, float]] = []  # (s, node MB, arm processes MB)
    loads: list[float] = []
    try:
        load = subprocess.Popen([sys.executable, __file__, "--load-child", "--robot", args.robot,
                                 "--clients", str(args.clients), "--stream-hz", str(args.stream_hz),
                                 "--scene-hz", str(args.scene_hz), "--cloud-hz", str(args.cloud_hz),
                                 "--param-period", str(args.param_period), "--verify-every", str(args.verify_every),
                                 "--verify-grace", str(args.verify_grace)], stdout=subprocess.PIPE, text=True)
        line = load.stdout.readline()  # "started": the scene and the first cloud are in, the clients run
        if not line:
            raise RuntimeError(f"the load did not start; node output:\n{node.output()[-3000:]}")
        t0 = time.monotonic()
        arms_seen: set[int] = set()
        while (t := time.monotonic() - t0) < args.duration and node.alive():
            pid, arms = node.processes()
            arms_seen.update(arms)
            samples.append((round(t, 1), round(rss_mb(pid), 2),
                            round(sum(rss_mb(a) for a in arms), 2) if arms else float("nan")))
            loads.append(os.getloadavg()[0])
            time.sleep(max(0.0, 10.0 * len(samples) - (time.monotonic() - t0)))
            if len(samples) % 6 == 0:  # the figures so far survive a run that does not finish
                write_partial(samples, args.out)
        alive = node.alive()
        load.send_signal(signal.SIGTERM)
        answers = json.loads(load.communicate(timeout=args.verify_grace + 300)[0].strip().splitlines()[-1])
        inside = node.inside()
    finally:
        if load is not None and load.poll() is None:
            load.kill()
        node.stop()
    node_s = [(t, n) for t, n, _ in samples]
    arm_s = [(t, a) for t, _, a in samples]
    out = {"phase": "endurance", "robot": args.robot, "duration_s": args.duration, "node_alive": alive,
           "arm_processes_seen": len(arms_seen),
           "node_rss_mb": [node_s[0][1], node_s[-1][1]] if node_s else None,
           "arm_rss_mb": [arm_s[0][1], arm_s[-1][1]] if arm_s else None,
           "node_slope_after_2_min": slope_mb_per_min(node_s, 120.0),
           "node_slope_after_5_min": slope_mb_per_min(node_s, 300.0),
           "arm_slope_after_2_min": slope_mb_per_min(arm_s, 120.0),
           "arm_slope_after_5_min": slope_mb_per_min(arm_s, 300.0),
           "max_slope_mb_per_min": args.max_slope, "load_average": [round(min(loads), 2), round(max(loads), 2)]
           if loads else None, "answers": answers, "samples": samples, **({"inside": inside} if inside else {})}
    out["failures"] = endurance_failures(out, args)
    out["ok"] = not out["failures"]
    return out


def write_partial(samples: list, directory: Path) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "endurance.partial.json").write_text(json.dumps({
        "samples": samples, "node_slope_after_5_min": slope_mb_per_min([(t, n) for t, n, _ in samples], 300.0),
        "arm_slope_after_5_min": slope_mb_per_min([(t, a) for t, _, a in samples], 300.0)}))


def endurance_failures(out: dict, args) -> list[str]:
    """What missed its target (empty: the run passed)."""
    bad = []
    if not out["node_alive"]:
        bad.append("the node died")
    for who in ("node", "arm"):
        slope = out[f"{who}_slope_after_5_min"]
        if slope is None:
            bad.append(f"{who}: too short for a slope after 5 minutes")
        elif slope > args.max_slope:
            bad.append(f"{who}: RSS slope {slope} MB/min after 5 minutes > {args.max_slope}")
    a = out["answers"]
    for kind in ("plan_grasp", "plan_dual_grasp", "scene", "parameters"):
        c = a.get(kind, {})
        if c.get("sent", 0) == 0:
            bad.append(f"{kind}: nothing sent")
        if c.get("answered", 0) != c.get("sent", 0):
            bad.append(f"{kind}: {c.get('sent', 0) - c.get('answered', 0)} unanswered")
        if c.get("late", 0):
            bad.append(f"{kind}: {c['late']} late")
        if c.get("refused", 0):
            bad.append(f"{kind}: {c['refused']} refused")
    v = a["verification"]
    if v["verified"] != v["queued"] or v["invalid"]:
        bad.append(f"plans: {v['invalid']} invalid, {v['queued'] - v['verified']} not verified of {v['queued']}")
    if a["stream"].get("dropped_by_node", 0):
        bad.append(f"stream: the node dropped {a['stream']['dropped_by_node']} updates (its queue was full)")
    if a["scene"].get("unmatched_polls", 0):
        bad.append(f"scene: {a['scene']['unmatched_polls']} answers match no state the stream made")
    if a["cloud"].get("layer_mismatch", 0):
        bad.append(f"cloud: {a['cloud']['layer_mismatch']} answers with another layer size")
    return bad


def write_report(out: dict, directory: Path) -> None:
    """out/soak/endurance.json and a plot of RSS over time (matplotlib, as the demo's pictures)."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "endurance.json").write_text(json.dumps(out, indent=1))
    (directory / "endurance.partial.json").unlink(missing_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array([s[0] for s in out["samples"]]) / 60.0
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)  # one scale each: the arm process is smaller
    for ax, k, who, label in ((axes[0], 1, "node", "node"), (axes[1], 2, "arm", "arm process(es)")):
        y = np.array([s[k] for s in out["samples"]])
        ax.plot(t, y, marker=".", label=f"{label}: slope after 5 min {out[f'{who}_slope_after_5_min']} MB/min, "
                f"after 2 min {out[f'{who}_slope_after_2_min']}")
        ax.axvline(5.0, color="grey", lw=0.8, ls="--")
        ax.set_ylabel("RSS (MB)")
        ax.legend(loc="lower right")
        ax.grid(alpha=0.3)
    axes[1].set_xlabel("minutes")
    axes[0].set_title(f"soak: {out['robot']}, {out['duration_s'] / 60:.0f} min, {'ok' if out['ok'] else 'FAILED'}")
    fig.tight_layout()
    fig.savefig(directory / "endurance.png", dpi=100)
    plt.close(fig)


def run_arm_replay(args) -> dict:
    """The arm process's side alone, in this process: record the jobs that dual plans send to the arm
    process, then serve them `--arm-replay` times with the arm process's own loop (`arm_process._serve`,
    on a thread), each in a scene of its own (a new version; the streamed boxes moved, added, removed);
    RSS (after malloc_trim) every fifth of the jobs, growth by traceback with `--trace N`."""
    import multiprocessing as mp
    from dataclasses import replace

    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.pipeline import arm_process
    from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner
    from humanoid_planner.core.planners.arm_messages import Done, Ready
    from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
    from humanoid_planner.scenarios import make_scenario

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
    rng = np.random.default_rng(0)
    box = (Shape("box", np.eye(4), (0.1, 0.1, 0.1)),)

    def in_new_scene(job, job_id: int):
        objects = list(job.scene.objects)
        for oid in STREAM_IDS:
            if rng.random() < 0.7:
                T = np.eye(4)
                T[:3, 3] = [-1.5 + rng.normal(0, 0.05), rng.normal(0, 0.3), 0.5 + rng.normal(0, 0.05)]
                objects.append(SceneObject(oid, T, box))
        scene = SceneSnapshot(job_id, job.scene.frame, tuple(objects), job.scene.voxels, job.scene.attached)
        return replace(job, job_id=job_id, scene=scene)

    parent, child = mp.Pipe()
    threading.Thread(target=arm_process._serve, args=(child, robot.source, planner.options), daemon=True).start()
    assert isinstance(parent.recv(), Ready)
    libc = ctypes.CDLL("libc.so.6")

    def serve(n: int, first: int) -> None:
        for k in range(n):
            parent.send(in_new_scene(jobs[k % len(jobs)], first + k))
            while not isinstance(parent.recv(), Done):
                pass

    serve(len(jobs) * 3, 1)
    gc.collect()
    libc.malloc_trim(0)
    if args.trace:
        tracemalloc.start(args.trace)
        snap0 = tracemalloc.take_snapshot()
    types0 = type_counts()
    samples, step, done = [(0, rss_mb(os.getpid()))], max(1, args.arm_replay // 5), 0
    while done < args.arm_replay:
        serve(step, 10_000 + done)
        done += step
        gc.collect()
        libc.malloc_trim(0)
        samples.append((done, rss_mb(os.getpid())))
    parent.send(None)
    types1 = type_counts()
    out = {"arm_replay_jobs": done, "recorded_jobs": len(jobs), "rss_mb_by_jobs": samples,
           "kb_per_job": round((samples[-1][1] - samples[1][1]) * 1024 / max(1, done - step), 3),
           "type_growth": sorted(((k, n - types0.get(k, 0)) for k, n in types1.items() if n - types0.get(k, 0) > 20),
                                 key=lambda kv: -kv[1])[:15]}
    if args.trace:
        snap1 = tracemalloc.take_snapshot()
        out["top_growth"] = [{"kib": st.size_diff // 1024, "blocks": st.count_diff,
                              "where": st.traceback.format(limit=args.trace)[-12:]}
                             for st in snap1.compare_to(snap0, "traceback")[:12]]
    return out


def verifier(inbox, outbox, robot_name: str) -> None:
    """Own process (niced): verify_plan of each plan in each state its version may mean."""
    os.nice(5)  # as the arm process: the node's answers first
    from humanoid_planner.clouds import box_surface_points
    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.postprocess.timing import TimedTrajectory
    from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
    from humanoid_planner.core.scene.voxels import CloudSettings, cloud_to_layer, object_solids, robot_solids
    from humanoid_planner.core.verification import verify_plan
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario

    robot = RobotModel.preset(robot_name)
    sc = make_scenario(robot, "boxes6", 1, hand="both")
    T = np.eye(4)
    T[:3, 3] = CLOUD_BOX[0]
    layer, _ = cloud_to_layer(box_surface_points(T, CLOUD_BOX[1]), np.eye(4), CloudSettings(),
                              robot_solids(robot, robot.home), object_solids(sc.scene.objects))
    outbox.put(("layer", len(layer)))
    box = (Shape("box", np.eye(4), (0.1, 0.1, 0.1)),)

    class Plan:
        def __init__(self, t, pos, vel, acc):
            self.trajectory, self.path = TimedTrajectory(t, pos, vel, acc), pos

    while (item := inbox.get()) is not None:
        groups, (t, pos, vel, acc), tcps, (states, how) = item
        plan = Plan(t, pos, vel, acc)
        targets = tuple(sc.object_pose @ tcp for tcp in tcps)
        problems = [] if states else [f"its scene version could not be resolved: {how}"]
        for state in states:
            objects = list(sc.scene.objects)
            for oid, p in state:
                if oid in STREAM_IDS:
                    Tb = np.eye(4)
                    Tb[:3, 3] = p
                    objects.append(SceneObject(oid, Tb, box))
            scene = SceneSnapshot(0, robot.root_link, tuple(objects), layer)
            try:
                problems += verify_plan(robot, scene, groups, robot.home, plan, targets, object_id=OBJECT_ID)
            except Exception as e:  # noqa: BLE001 - a plan the check cannot read is a failed plan, not a stuck soak
                problems.append(f"verification raised {e!r}")
        outbox.put(("verified", problems))


def run_load(args) -> None:
    """Own process: the clients of a busy robot. Prints one JSON line of what they saw."""
    import multiprocessing as mp

    from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from humanoid_planner.clouds import box_surface_points
    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.ros.conversions import grasp_from_msg, matrix_to_pose_msg, scene_object_to_msg
    from humanoid_planner.ros.pointcloud import points_to_cloud
    from humanoid_planner.scenarios import make_scenario
    from humanoid_planner_interfaces.srv import PlanDualGrasp
    from sensor_msgs.msg import PointCloud2
    from std_msgs.msg import UInt64
    from shape_msgs.msg import SolidPrimitive

    robot = RobotModel.preset(args.robot)
    sc = make_scenario(robot, "boxes6", 1, hand="both")
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    ex = MultiThreadedExecutor(num_threads=4, context=ctx)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    c = Client(ctx, "soak_load")
    ex.add_node(c.node)
    cloud_pub = c.node.create_publisher(PointCloud2, "pointcloud", POINTCLOUD_QOS)
    dropped = [0]  # the node's count of collision_object messages it had no room for
    c.node.create_subscription(UInt64, "/humanoid_planner/dropped_scene_updates",
                               lambda m: dropped.__setitem__(0, m.data), DROPPED_QOS)
    params = c.node.create_client(SetParameters, "/humanoid_planner/set_parameters", qos_profile=SERVICE_QOS)
    threading.Thread(target=ex.spin, daemon=True).start()
    wait_for_server(c.scene, 60.0)
    wait_subscribed(c)

    spawn = mp.get_context("spawn")
    to_verify, verdicts = spawn.Queue(), spawn.Queue()
    for q in (to_verify, verdicts):
        q.cancel_join_thread()  # at exit, never wait to hand a killed verifier what it will not read
    vproc = spawn.Process(target=verifier, args=(to_verify, verdicts, args.robot), daemon=True)
    vproc.start()

    model, history = SceneModel(), History()
    lock = threading.Lock()
    stats: dict[str, Counter] = {k: Counter() for k in ("plan_grasp", "plan_dual_grasp", "scene", "parameters",
                                                        "stream", "cloud", "verify")}
    worst: Counter = Counter()  # kind -> longest answer time (ms)

    def count(kind: str, seconds: float | None = None, **kw) -> None:
        with lock:
            stats[kind].update(kw)
            if seconds is not None:
                worst[kind] = max(worst[kind], round(seconds * 1000))

    def publish(msg) -> None:
        with lock:  # the model's order is the topic's order
            if model.apply(msg):
                history.add_state(model.version, model.state(), int(HISTORY_S * args.stream_hz))
            c.pub.publish(msg)

    def poll(components: int = 0):
        t = time.monotonic()
        r = c.call(c.scene, GetPlanningScene.Request(components=components), SCENE_TIMEOUT + 30.0)
        dt = time.monotonic() - t
        count("scene", dt, sent=1, answered=r is not None, late=r is not None and dt > SCENE_TIMEOUT + LATE_SLACK)
        if r is not None:
            history.add_poll(r.version, state_of(r.objects))
        return r

    # the start: the scenario's objects, then the first point cloud in the scene
    publish(CollisionObject(operation=CollisionObject.REMOVE))
    for o in sc.scene.objects:
        publish(scene_object_to_msg(o, robot.root_link))
    T = np.eye(4)
    T[:3, 3] = CLOUD_BOX[0]
    cloud = points_to_cloud(box_surface_points(T, CLOUD_BOX[1]), robot.root_link)
    layer_size = verdicts.get(timeout=300.0)[1]
    while not stop.is_set():
        cloud_pub.publish(cloud)
        r = poll()
        if r is not None and r.occupied_voxels > 0 and history.polls:
            break
        time.sleep(0.1)

    pending: list = []  # (version, verification item without states)

    def plan_client(k: int) -> None:
        node = rclpy.create_node(f"soak_client_{k}", context=ctx)
        ex.add_node(node)
        single = node.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
        dual = node.create_client(PlanDualGrasp, "plan_dual_grasp", qos_profile=SERVICE_QOS)
        wait_for_server(single, 30.0)
        wait_for_server(dual, 30.0)
        i = 0
        while not stop.is_set():
            i += 1
            seed = 1000 * k + i
            if (i + k) % 2:
                kind, cli, groups = "plan_dual_grasp", dual, ("left_arm", "right_arm")
                req = PlanDualGrasp.Request(left_group="left_arm", right_group="right_arm", object_id=OBJECT_ID,
                                            timeout=PLAN_TIMEOUT, seed=seed)
            else:
                kind, cli = "plan_grasp", single
                groups = (("left_arm", "right_arm")[i % 2],)
                req = PlanGrasp.Request(group=groups[0], object_id=OBJECT_ID, timeout=PLAN_TIMEOUT, seed=seed)
            t = time.monotonic()
            r = call(cli, req, PLAN_TIMEOUT + 60.0)
            dt = time.monotonic() - t
            ok = r is not None and r.error_code.val == 1
            count(kind, dt, sent=1, answered=r is not None, late=r is not None and dt > PLAN_TIMEOUT + LATE_SLACK,
                  **({f"code_{r.error_code.val}": 1} if r is not None else {}))
            if ok and (seed % args.verify_every == 0):
                tr = r.trajectory
                arrays = tuple(np.array(a, dtype=float) for a in (
                    [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in tr.points],
                    [p.positions for p in tr.points], [p.velocities for p in tr.points],
                    [p.accelerations for p in tr.points]))
                grasps = [r.grasp] if len(groups) == 1 else [r.left_grasp, r.right_grasp]
                tcps = [grasp_from_msg(g, "grasp").tcp_in_object for g in grasps]
                with lock:
                    pending.append((r.scene_version, (groups, arrays, tcps)))

    def stream() -> None:
        rng = np.random.default_rng(1)
        period, next_t = 1.0 / args.stream_hz, time.monotonic()
        while not stop.is_set():
            oid = STREAM_IDS[rng.integers(len(STREAM_IDS))]
            op = (CollisionObject.MOVE, CollisionObject.ADD, CollisionObject.REMOVE)[rng.choice(3, p=(0.6, 0.25, 0.15))]
            Tm = np.eye(4)
            Tm[:3, 3] = [-1.5 + rng.normal(0, 0.05), rng.normal(0, 0.3), 0.5 + rng.normal(0, 0.05)]
            msg = CollisionObject(id=oid, operation=op)
            msg.header.frame_id = robot.root_link
            msg.pose = matrix_to_pose_msg(Tm)
            if op == CollisionObject.ADD:
                msg.primitives = [SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.1, 0.1, 0.1])]
                msg.primitive_poses = [matrix_to_pose_msg(np.eye(4))]
            publish(msg)
            count("stream", sent=1)
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))

    def every(hz: float, work) -> None:
        period, next_t = 1.0 / hz, time.monotonic()
        while not stop.is_set():
            work()
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))

    def scene_poll() -> None:
        r = poll(GetPlanningScene.Request.OBJECT_NAMES | GetPlanningScene.Request.VOXELS)
        if r is not None and r.occupied_voxels != layer_size:
            count("cloud", layer_mismatch=1)

    def cloud_tick() -> None:
        cloud_pub.publish(cloud)
        count("cloud", sent=1)

    flip = [0]

    def parameter_set() -> None:
        flip[0] ^= 1
        req = SetParameters.Request(parameters=[
            ParameterMsg(name="default_timeout", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                                      double_value=5.0 - flip[0])),
            ParameterMsg(name="joint_states_max_age", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                                           double_value=1.0 + flip[0]))])
        t = time.monotonic()
        r = c.call(params, req, SCENE_TIMEOUT + 30.0)
        dt = time.monotonic() - t
        count("parameters", dt, sent=1, answered=r is not None, late=r is not None and dt > SCENE_TIMEOUT + LATE_SLACK,
              refused=r is not None and not all(x.successful for x in r.results))

    def resolve(final: bool = False) -> None:
        with lock:
            todo = list(pending)
            pending.clear()
        keep = []
        for v, item in todo:
            states = history.candidates(v)
            if states is None and not final:
                keep.append((v, item))
                continue
            to_verify.put((*item, states or ([], f"version {v}: no poll after it")))
            count("verify", queued=1)
        with lock:
            pending.extend(keep)

    threads = [threading.Thread(target=plan_client, args=(k,), daemon=True) for k in range(args.clients)]
    threads += [threading.Thread(target=stream, daemon=True),
                threading.Thread(target=every, args=(args.scene_hz, scene_poll), daemon=True),
                threading.Thread(target=every, args=(args.cloud_hz, cloud_tick), daemon=True),
                threading.Thread(target=every, args=(1.0 / args.param_period, parameter_set), daemon=True)]
    for t in threads:
        t.start()
    print(json.dumps({"load": "started"}), flush=True)
    verified = Counter()
    invalid: list = []

    def drain(timeout: float) -> None:
        try:
            while True:
                _, problems = verdicts.get(timeout=timeout)
                verified.update(plans=1, invalid=bool(problems))
                if problems and len(invalid) < 10:
                    invalid.append(problems[:3])
                timeout = 0.0
        except queue.Empty:
            pass

    while not stop.wait(1.0):
        resolve()
        drain(0.0)
    time.sleep(PLAN_TIMEOUT + LATE_SLACK + 1.0)  # the last answers
    poll()  # a poll after every version a plan reported
    resolve(final=True)
    to_verify.put(None)
    queued = stats["verify"]["queued"]
    deadline = time.monotonic() + args.verify_grace
    while verified["plans"] < queued and time.monotonic() < deadline:
        drain(1.0)
    with lock:
        out = {k: dict(v) for k, v in stats.items()}
    out["worst_ms"] = dict(worst)
    out["verification"] = {"queued": queued, "verified": verified["plans"], "invalid": verified["invalid"],
                           "examples": invalid}
    out["scene"]["unmatched_polls"] = history.unmatched
    out["scene"]["ambiguous_polls"] = history.ambiguous
    out["scene"]["unmatched_examples"] = history.unmatched_examples
    out["stream"]["dropped_by_node"] = dropped[0]
    out["layer_cells"] = layer_size
    print(json.dumps(out), flush=True)
    vproc.kill()
    os._exit(0)  # the answers are out; rclpy's shutdown with calls still pending could hang


_DOMAIN = None  # the domain_coordinator context of this run's ROS domain (see main)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=5000)
    ap.add_argument("--duration", type=float, default=600.0, help="s of the endurance phase (3600: the hour, 86400: a day)")
    ap.add_argument("--max-slope", type=float, default=0.05, help="MB/min, largest RSS slope after 5 minutes")
    ap.add_argument("--robot", default="dual_arm", help="the endurance phase's robot")
    ap.add_argument("--clients", type=int, default=CLIENTS)
    ap.add_argument("--stream-hz", type=float, default=200.0)
    ap.add_argument("--scene-hz", type=float, default=20.0)
    ap.add_argument("--cloud-hz", type=float, default=10.0)
    ap.add_argument("--param-period", type=float, default=5.0, help="s between parameter sets")
    ap.add_argument("--verify-every", type=int, default=1, help="verify plans whose seed is a multiple of this")
    ap.add_argument("--verify-grace", type=float, default=600.0, help="s to finish the verifications after the load")
    ap.add_argument("--out", type=Path, default=REPO_ROOT / "out" / "soak")
    ap.add_argument("--plans", type=int, default=20, help="plans per measurement of the load phase")
    ap.add_argument("--skip", default="", help="comma-separated phases to skip: fuzz, endurance, load")
    ap.add_argument("--trace", type=int, default=0, help="endurance with the node in this process and tracemalloc "
                    "snapshots of this many frames per traceback (slows it: for finding a leak, not for figures)")
    ap.add_argument("--warmup", type=float, default=120.0, help="s before --trace's first snapshot")
    ap.add_argument("--arm-replay", type=int, default=0, help="only this: serve this many recorded dual-plan jobs, "
                    "each in a new scene, with the arm process's loop in this process (RSS per job)")
    ap.add_argument("--heavy-client", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--load-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.arm_replay:
        print(json.dumps(run_arm_replay(args)), flush=True)
        return 0
    if args.heavy_client is not None:
        heavy_client(args.heavy_client)
        return 0
    if args.load_child:
        run_load(args)
        return 0
    skip = set(filter(None, args.skip.split(",")))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if not os.environ.get("ROS_DOMAIN_ID"):
        import domain_coordinator

        # held until the process ends (module global): a released domain goes to the next test run on
        # this machine, whose nodes then share this soak's topics
        global _DOMAIN
        _DOMAIN = domain_coordinator.domain_id()
        os.environ["ROS_DOMAIN_ID"] = str(_DOMAIN.__enter__())
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        if "endurance" not in skip:
            result = phase_endurance(Path(tmp), args)
            write_report(result, args.out)
            ok &= result["ok"]
            print(json.dumps({k: v for k, v in result.items() if k != "samples"}), flush=True)
        if skip >= {"fuzz", "load"}:
            return 0 if ok else 1
        ctx = rclpy.context.Context()
        rclpy.init(context=ctx)
        ex = MultiThreadedExecutor(context=ctx)
        c = Client(ctx, "soak_client")
        ex.add_node(c.node)
        spin = threading.Thread(target=ex.spin, daemon=True)
        spin.start()
        node = start_node(Path(tmp), {"robot": "armar3"})
        try:
            if not wait_for_server(c.scene, 60.0):
                print(node.output())
                return 1
            wait_subscribed(c)
            for name, run in (("fuzz", lambda: phase_fuzz(c, args.messages)),
                              ("load", lambda: phase_load(c, args.plans, 60.0))):
                if name in skip:
                    continue
                result = run()
                result["node_alive"] = node.proc.poll() is None
                ok &= result["ok"] and result["node_alive"]
                print(json.dumps(result), flush=True)
        finally:
            node.stop()
        ex.shutdown(timeout_sec=5.0)
        spin.join(5.0)
        c.node.destroy_node()
        ctx.try_shutdown()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
