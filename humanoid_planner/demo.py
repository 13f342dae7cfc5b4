"""`make demo`: the product end to end, as a user would run it.

    python -m humanoid_planner.demo [--out out] [--params-file config/planner.yaml] [--seed N]

1. starts `planner_node` in its own process (built-in preset `armar3`, its own ROS domain,
   localhost-only discovery; the node's log goes to out/planner_node.log);
2. from this client process publishes a scene on `collision_object` — a table, a shelf and a
   back wall with the object `target` and its grasp set in front of the left shoulder
   (`core.scenarios`, family table_shelf) — and calls `plan_grasp` for `left_arm_torso`, the hand
   approaching the last 10 cm in a straight line along its axis and lifting the object 10 cm.
   Then the same table, shelf and wall are given as a depth camera would see them: the scene is
   replaced by the object alone, a synthetic 160 x 120 depth image of the scene's own boxes
   (rendered from above the torso, `clouds.render_depth`) is published on `pointcloud` in the
   `torso_link` frame, and `plan_grasp` is called again — the plan is verified against the boxes
   it never saw as boxes;
3. replaces the scene (REMOVE all, then six random boxes around an object centred between the
   shoulders, family boxes6) and calls `plan_dual_grasp` for `left_arm` + `right_arm`, both hands
   approaching 5 cm straight and lifting the box 10 cm together;
4. prints a result table, checks that `planned_trajectory` carried each trajectory, verifies each
   plan independently (core.verification: start, limits, grasp reached, exact collision check at
   1 cm / 0.01 rad, monotonic time; the retreat straight, collision-free with the object in hand,
   both hands keeping their relative pose), and writes
   out/plan_grasp_scene.png, out/plan_grasp_joints.png, out/plan_dual_grasp_scene.png,
   out/plan_dual_grasp_joints.png;
5. the rest of the cycle (run_cycles): one hand picks, places on a shelf (plan_place), releases and
   goes home (plan_to_state); two hands carry a box across the robot's middle along a table
   (plan_dual_place), release it and go home; every plan verified, out/cycle_*_scene.png;
6. stops the node with SIGINT. Exit status 0 when every plan succeeds and verifies, 1 otherwise.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
from humanoid_planner.child_env import child_environment

NODE_STARTUP_TIMEOUT = 40.0
LIFT = (0.0, 0.0, 1.0)  # the retreat: straight up in the planning frame
CARRY_FROM = 0.10  # m: the two-handed box starts this far left of where the scenario centres it
CARRY_TO = (-0.23, -0.22, -0.21)
"""m: its placements, to the right of where it was picked: across the robot's middle onto the table's right
half. Farther it does not go: from -0.24 on the box stands where the right arm hangs at home, at -0.28
the hands' last 5 cm down have no IK, at -0.30 the move across stops after 27.5 cm (no IK)."""
HANDS_UP = 0.20
"""m: after the release both hands rise straight up, out of the box's ends and clear of the table; from
there the way home is a straight joint motion (backed out 10 cm along their axes they stay beside the
box just over the table, and RRT-Connect for both arms took 0.04-2.5 s CPU by seed, 10 s at load 18)."""


def _node_exe() -> str:
    """planner_node of the same install as this demo: beside the running console script (a colcon
    install keeps both in lib/humanoid_planner, off PATH), else beside the interpreter (a venv's bin/)."""
    for folder in (Path(sys.argv[0]).resolve().parent, Path(sys.executable).parent):
        if (folder / "planner_node").exists():
            return str(folder / "planner_node")
    return "planner_node"


def _wait(future, timeout: float):
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout):
        raise TimeoutError(f"no answer after {timeout} s")
    return future.result()


class DemoClient:
    """A client node in its own context, spun in a background thread."""

    def __init__(self):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import MultiThreadedExecutor
        from trajectory_msgs.msg import JointTrajectory

        from sensor_msgs.msg import PointCloud2

        from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, PLANNED_TRAJECTORY_QOS, POINTCLOUD_QOS
        from humanoid_planner_interfaces.msg import CollisionObject
        from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp

        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
        self.node = rclpy.create_node("humanoid_planner_demo", context=self.ctx)
        self.executor = MultiThreadedExecutor(num_threads=2, context=self.ctx)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()
        self.pub = self.node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        self.cloud_pub = self.node.create_publisher(PointCloud2, "pointcloud", POINTCLOUD_QOS)
        self.scene_cli = self.node.create_client(GetPlanningScene, "get_planning_scene")
        self.plan_cli = self.node.create_client(PlanGrasp, "plan_grasp")
        self.dual_cli = self.node.create_client(PlanDualGrasp, "plan_dual_grasp")
        self.published: list = []
        self.node.create_subscription(JointTrajectory, "planned_trajectory", self.published.append,
                                      PLANNED_TRAJECTORY_QOS)

    def wait_ready(self, proc: subprocess.Popen, timeout: float) -> None:
        from humanoid_planner.ros.executors import wait_for_server

        deadline = time.monotonic() + timeout
        for cli in (self.scene_cli, self.plan_cli, self.dual_cli):
            while not wait_for_server(cli, 0.2):
                if proc.poll() is not None:
                    raise RuntimeError(f"planner_node exited with code {proc.returncode} before it was ready")
                if time.monotonic() > deadline:
                    raise TimeoutError(f"planner_node not ready after {timeout} s")
        while self.pub.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                raise TimeoutError("planner_node does not subscribe to collision_object")
            time.sleep(0.05)

    def scene_version(self) -> int:
        from humanoid_planner_interfaces.srv import GetPlanningScene

        return _wait(self.scene_cli.call_async(GetPlanningScene.Request()), 10.0).version

    def publish_scene(self, scene, frame: str) -> int:
        """REMOVE everything, then ADD every object of a core SceneSnapshot; returns the scene version."""
        from humanoid_planner.ros.conversions import scene_object_to_msg
        from humanoid_planner_interfaces.msg import CollisionObject

        expected = self.scene_version() + 1 + len(scene.objects)
        self.pub.publish(CollisionObject(operation=CollisionObject.REMOVE))
        for obj in scene.objects:
            self.pub.publish(scene_object_to_msg(obj, frame))
        deadline = time.monotonic() + 10.0
        while (v := self.scene_version()) < expected:
            if time.monotonic() > deadline:
                raise TimeoutError(f"scene version {v} after 10 s, expected {expected}")
            time.sleep(0.05)
        return v

    def publish_cloud(self, msg, timeout: float = 15.0) -> tuple[int, int]:
        """Publish a PointCloud2 (sensor-data QoS: best effort, so again each second) until the scene
        version moves and the layer has cells (an empty cloud: none); returns (version, occupied_voxels)."""
        from humanoid_planner_interfaces.srv import GetPlanningScene

        before = self.scene_version()
        deadline = time.monotonic() + timeout
        while self.cloud_pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        while time.monotonic() < deadline:
            self.cloud_pub.publish(msg)
            for _ in range(20):
                time.sleep(0.05)
                r = _wait(self.scene_cli.call_async(GetPlanningScene.Request()), 10.0)
                if r.version > before and (r.occupied_voxels > 0) == (msg.width * msg.height > 0):
                    return r.version, r.occupied_voxels
        raise TimeoutError(f"no point-cloud layer after {timeout} s")

    def _spin(self) -> None:
        """Spin until close() asks to stop. Not executor.spin() + executor.shutdown(): Jazzy's shutdown does
        not wait for the callbacks its pool still runs, and the demo once hung for 10 minutes at its end
        (after its last plan, before stopping the node) closing that way."""
        while not self._stop.is_set() and self.ctx.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        """Stop spinning (the thread ends within one spin_once), let handed-out callbacks end, then the
        executor, the node and the context."""
        self._stop.set()
        self.thread.join(timeout=5.0)
        pool = getattr(self.executor, "_executor", None)  # rclpy's thread pool (not public API)
        if pool is not None:
            drain = threading.Thread(target=pool.shutdown, daemon=True)
            drain.start()
            drain.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        self.ctx.try_shutdown()


def _full_configurations(robot, start: np.ndarray, traj) -> np.ndarray:
    idx = [robot.joint_names.index(n) for n in traj.joint_names]
    Q = np.repeat(start[None], len(traj.points), axis=0)
    Q[:, idx] = np.array([p.positions for p in traj.points])
    return Q


def _times(traj) -> np.ndarray:
    return np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in traj.points])


class _ResponsePlan:
    """What core.verification.verify_plan reads from a plan, rebuilt from a response's trajectory."""

    def __init__(self, traj):
        from humanoid_planner.core.postprocess.timing import TimedTrajectory

        pos = np.array([p.positions for p in traj.points])
        self.trajectory = TimedTrajectory(_times(traj), pos, np.array([p.velocities for p in traj.points]),
                                          np.array([p.accelerations for p in traj.points]))
        self.path = pos


class _ResponseRetreat(_ResponsePlan):
    """What core.verification.verify_retreat reads: the trajectory and the retreat trajectory."""

    def __init__(self, resp):
        super().__init__(resp.trajectory)
        self.retreat_trajectory = _ResponsePlan(resp.retreat_trajectory).trajectory


def _translation(v, desired: float, least: float, frame: str = ""):
    from geometry_msgs.msg import Vector3

    from humanoid_planner_interfaces.msg import GripperTranslation

    gt = GripperTranslation(desired_distance=desired, min_distance=least)
    gt.direction.header.frame_id = frame
    gt.direction.vector = Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))
    return gt


def _row(name, groups, resp, grasps, tcp_err, published, verified) -> list[str]:
    from humanoid_planner.ros.requests import ERROR_NAMES

    ok = resp.error_code.val == 1
    t = _times(resp.trajectory) if ok else np.zeros(1)
    return [name, "+".join(groups), ERROR_NAMES.get(resp.error_code.val, str(resp.error_code.val)),
            f"{resp.planning_time:.3f}", str(resp.iterations), f"{t[-1]:.2f}" if ok else "-",
            str(len(resp.trajectory.points)) if ok else "-",
            f"{resp.approach_distance * 100:.0f} / {resp.retreat_distance * 100:.0f}" if ok else "-",
            " + ".join(grasps) if ok else "-",
            f"{tcp_err:.2f}" if ok else "-", str(resp.scene_version), "yes" if published else "no",
            ("yes" if verified else "NO") if ok else "-"]


def _print_table(rows: list[list[str]]) -> None:
    head = ["service", "group(s)", "status", "plan [s]", "iter", "traj [s]", "points", "approach/lift [cm]", "grasp(s)",
            "TCP err [mm]", "scene v", "published", "verified"]
    widths = [max(len(r[i]) for r in rows + [head]) for i in range(len(head))]
    line = "  ".join("-" * w for w in widths)
    print("  ".join(h.ljust(w) for h, w in zip(head, widths)))
    print(line)
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))


def _print_cycle_table(rows: list[list[str]]) -> None:
    head = ["step", "status", "plan [s]", "traj [s]", "reached", "verified"]
    widths = [max(len(r[i]) for r in rows + [head]) for i in range(len(head))]
    print("  ".join(h.ljust(w) for h, w in zip(head, widths)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))


def _depth_cloud(robot, scenario, frame_id: str):
    """A 160 x 120 depth image of the scenario's boxes (the object too: the node removes its points),
    from a camera 35 cm above `frame_id`'s origin at home looking at the object, as a PointCloud2 in
    `frame_id` (the node places it by forward kinematics). Small enough (230 kB) for Fast DDS's default
    shared-memory segment (512 kB): a 640 x 480 cloud (3.7 MB), published once a second best-effort as
    a camera would, did not reach the node within 15 s in about one demo run in four."""
    from humanoid_planner.clouds import look_at, render_depth, scene_boxes
    from humanoid_planner.core.transforms import invert
    from humanoid_planner.ros.pointcloud import points_to_cloud

    T_frame = robot.link_poses(robot.home, [frame_id])[0]
    cam = look_at(T_frame[:3, 3] + [0.0, 0.0, 0.35], scenario.object_pose[:3, 3])
    img = render_depth(scene_boxes(scenario.scene.objects), cam, 160, 120, fov_x=np.radians(90)).reshape(-1, 3)
    T = invert(T_frame) @ cam  # camera in frame_id
    return points_to_cloud(img @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32), frame_id, (120, 160))


def run(out: Path, params_files: list[str], seed: int, timeout: float, robot_name: str) -> int:
    from humanoid_planner.core.grasp.approach import approach_axis
    from humanoid_planner.core.model.robot import RobotModel
    from humanoid_planner.core.scene.types import SceneSnapshot
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario
    from humanoid_planner.core.transforms import pose_distance, pose_to_matrix
    from humanoid_planner.core.verification import verify_plan, verify_retreat
    from humanoid_planner.plots import plot_joints, plot_scene
    from humanoid_planner.ros.pointcloud import points_to_cloud
    from humanoid_planner.ros.conversions import grasp_from_msg
    from humanoid_planner_interfaces.srv import PlanDualGrasp, PlanGrasp

    out.mkdir(parents=True, exist_ok=True)
    log_path = out / "planner_node.log"
    args = [_node_exe(), "--ros-args"]
    for f in params_files:
        args += ["--params-file", f]
    args += ["-p", f"robot:={robot_name}"]
    print(f"starting planner_node (robot {robot_name}, ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}); "
          f"its log: {log_path}", flush=True)
    env = child_environment()
    log = open(log_path, "wb")
    proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=env)
    client = None
    try:
        t0 = time.monotonic()
        robot = RobotModel.preset(robot_name)  # the client's own copy: scenes and pictures
        frame = robot.root_link
        single = make_scenario(robot, "table_shelf", seed, hand="left")
        dual = make_scenario(robot, "boxes6", seed, hand="both")
        client = DemoClient()
        client.wait_ready(proc, NODE_STARTUP_TIMEOUT)
        print(f"planner_node ready after {time.monotonic() - t0:.1f} s\n", flush=True)

        rows, results = [], []
        # --- single arm: left_arm_torso, object in front of the left shoulder on a table under a shelf
        version = client.publish_scene(single.scene, frame)
        print(f"scene 1 (table_shelf, seed {seed}): {len(single.scene.objects)} objects, version {version}")
        group = "left_arm_torso"
        lift = _translation(LIFT, 0.10, 0.05, frame)  # planning frame: straight up
        req = PlanGrasp.Request(group=group, object_id=OBJECT_ID, timeout=timeout, seed=seed,
                                pre_grasp_approach=_translation(approach_axis(robot, group), 0.10, 0.05),
                                post_grasp_retreat=lift)
        n_pub = len(client.published)
        resp = _wait(client.plan_cli.call_async(req), timeout + 30.0)
        results.append(("plan_grasp", (group,), single, resp, [resp.grasp] if resp.error_code.val == 1 else []))
        time.sleep(0.2)
        # --- the same scene seen by a depth camera: only the object is given as an object
        cloud_msg = _depth_cloud(robot, single, "torso_link")
        client.publish_scene(SceneSnapshot(0, frame, (single.scene.get(OBJECT_ID),)), frame)
        version, cells = client.publish_cloud(cloud_msg)
        print(f"scene 1 as a depth image: the object + {cloud_msg.width}x{cloud_msg.height} points in "
              f"{cloud_msg.header.frame_id!r} -> {cells} occupied cells, version {version}")
        n_pub_cloud = len(client.published)
        resp = _wait(client.plan_cli.call_async(req), timeout + 30.0)
        results.append(("plan_grasp_cloud", (group,), single, resp, [resp.grasp] if resp.error_code.val == 1 else []))
        time.sleep(0.2)
        client.publish_cloud(points_to_cloud(np.zeros((0, 3)), frame))  # an empty cloud clears the layer
        # --- dual arm: left_arm + right_arm, object centred between the shoulders among six boxes
        version = client.publish_scene(dual.scene, frame)
        print(f"scene 2 (boxes6, seed {seed}): {len(dual.scene.objects)} objects, version {version}\n")
        groups = ("left_arm", "right_arm")
        dreq = PlanDualGrasp.Request(left_group=groups[0], right_group=groups[1], object_id=OBJECT_ID,
                                     timeout=timeout, seed=seed,
                                     pre_grasp_approach=_translation(approach_axis(robot, groups[0]), 0.05, 0.05),
                                     post_grasp_retreat=lift)
        n_pub_dual = len(client.published)
        dresp = _wait(client.dual_cli.call_async(dreq), timeout + 30.0)
        results.append(("plan_dual_grasp", groups, dual, dresp,
                        [dresp.left_grasp, dresp.right_grasp] if dresp.error_code.val == 1 else []))
        time.sleep(0.3)

        all_problems: list[str] = []
        for (name, grps, sc, r, grasp_msgs), n_before in zip(results, (n_pub, n_pub_cloud, n_pub_dual)):
            ok = r.error_code.val == 1
            published = ok and any(t == r.trajectory for t in client.published[n_before:])
            err = 0.0
            if ok:
                tcp_msgs = [r.tcp_pose] if len(grps) == 1 else [r.left_tcp_pose, r.right_tcp_pose]
                for g, p in zip(grasp_msgs, tcp_msgs):
                    T_target = sc.object_pose @ grasp_from_msg(g, "grasp").tcp_in_object
                    T_tcp = pose_to_matrix([p.position.x, p.position.y, p.position.z],
                                           [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
                    err = max(err, float(pose_distance(T_tcp, T_target)[0]) * 1000)
            problems = []
            if ok:  # independent check: start, limits, grasp reached, exact collisions at 1 cm, time
                targets = tuple(sc.object_pose @ grasp_from_msg(g, "grasp").tcp_in_object for g in grasp_msgs)
                problems = verify_plan(robot, sc.scene, grps, robot.home, _ResponsePlan(r.trajectory), targets,
                                       object_id=OBJECT_ID)
                problems += verify_retreat(robot, sc.scene, grps, robot.home, _ResponseRetreat(r), LIFT,
                                           object_id=OBJECT_ID, min_distance=0.05 - 0.002)
                all_problems += [f"{name}: {p}" for p in problems]
            rows.append(_row(name, grps, r, [g.id for g in grasp_msgs], err, published, not problems))
        _print_table(rows)
        for p in all_problems:
            print(f"verification: {p}")
        for name, grps, sc, r, grasp_msgs in results:
            if r.error_code.val != 1:
                print(f"\n{name} failed: {r.message}")

        print()
        for name, grps, sc, r, grasp_msgs in results:
            if r.error_code.val != 1:
                continue
            Q = _full_configurations(robot, robot.home, r.trajectory)
            Q_back = _full_configurations(robot, robot.home, r.retreat_trajectory)
            tips = [robot.group(g).tip_link for g in grps]
            P = robot.link_poses(Q, tips)  # (K, len(tips), 4, 4)
            P_back = robot.link_poses(Q_back, tips)
            targets = [sc.object_pose @ grasp_from_msg(g, "grasp").tcp_in_object for g in grasp_msgs]
            approach = [T[:3, :3] @ approach_axis(robot, g) for T, g in zip(targets, grps)]
            labels = [f"{g} ({m.id})" for g, m in zip(grps, grasp_msgs)]
            t = _times(r.trajectory)
            what = "single arm (GIRRT)" if len(grps) == 1 else "dual arm (DAGRRT)"
            if name == "plan_grasp_cloud":
                what += ", obstacles seen only as a depth image"
            title = (f"{robot_name} {what}: {sc.family} scene, planned in {r.planning_time:.2f} s, "
                     f"trajectory {t[-1]:.2f} s (last {r.approach_distance * 100:.0f} cm straight), "
                     f"lift {r.retreat_distance * 100:.0f} cm")
            f1 = plot_scene(robot, sc.scene, np.vstack([Q, Q_back]), [P[:, i, :3, 3] for i in range(len(tips))], targets,
                            approach, labels, title, out / f"{name}_scene.png", highlight=OBJECT_ID,
                            retreat_paths=[P_back[:, i, :3, 3] for i in range(len(tips))])
            idx = [robot.joint_names.index(n) for n in r.trajectory.joint_names]
            f2 = plot_joints(t, np.array([p.positions for p in r.trajectory.points]),
                             np.array([p.velocities for p in r.trajectory.points]), list(r.trajectory.joint_names),
                             f"{robot_name} {what}: joint trajectories ({'+'.join(grps)})", out / f"{name}_joints.png",
                             velocity_limits=robot.max_velocity[idx])
            print(f"wrote {f1}\nwrote {f2}")
        print("\nthe rest of the cycle (plan_place, plan_dual_place, plan_to_state):")
        crows, cproblems = run_cycles(client, robot, frame, seed, timeout, out)
        _print_cycle_table(crows)
        for p in cproblems:
            print(f"verification: {p}")
        all_problems += cproblems
        ok = all(r.error_code.val == 1 for _, _, _, r, _ in results) and all(row[1] == "SUCCESS" for row in crows)
        published_ok = all(row[-2] == "yes" for row in rows)
        if ok and not published_ok:
            print("a successful trajectory was not received on planned_trajectory")
        return 0 if ok and published_ok and not all_problems else 1
    finally:
        if client is not None:
            client.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                code = proc.wait(timeout=15)
                print(f"planner_node stopped (exit code {code})")
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                print("planner_node did not stop on SIGINT; killed")
        log.close()


# ------------------------------------------------------------------------------------------ the cycle
class CycleClient:
    """What the cycle needs besides DemoClient: joint_states, attach/detach, plan_place, plan_dual_place,
    plan_to_state (on the same node)."""

    def __init__(self, client: DemoClient, frame: str):
        from sensor_msgs.msg import JointState

        from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, JOINT_STATES_QOS
        from humanoid_planner_interfaces.msg import AttachedCollisionObject
        from humanoid_planner_interfaces.srv import PlanDualPlace, PlanPlace, PlanToState

        n = client.node
        self.client, self.client_frame = client, frame
        self.joints = n.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
        self.attached = n.create_publisher(AttachedCollisionObject, "attached_collision_object", COLLISION_OBJECT_QOS)
        self.place_cli = n.create_client(PlanPlace, "plan_place")
        self.dual_place_cli = n.create_client(PlanDualPlace, "plan_dual_place")
        self.to_state_cli = n.create_client(PlanToState, "plan_to_state")
        from humanoid_planner.ros.executors import wait_for_server

        deadline = time.monotonic() + 10.0
        for cli in (self.place_cli, self.dual_place_cli, self.to_state_cli):
            while not wait_for_server(cli, 0.2):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"planner_node offers no {cli.srv_name}")
        while self.attached.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                raise TimeoutError("planner_node does not subscribe to attached_collision_object")
            time.sleep(0.05)

    def joint_state(self, robot, q: np.ndarray):
        from sensor_msgs.msg import JointState

        return JointState(name=list(robot.joint_names), position=[float(x) for x in q])

    def at(self, robot, q: np.ndarray) -> None:
        """The robot is at q: joint_states (sensor QoS: again until the node has had time to see it)."""
        for _ in range(3):
            self.joints.publish(self.joint_state(robot, q))
            time.sleep(0.1)

    def attach(self, oid: str, link: str, touch, op: int | None = None) -> int:
        """attached_collision_object ADD (op None) or REMOVE; waits for the scene version to move."""
        from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject

        before = self.client.scene_version()
        msg = AttachedCollisionObject(link_name=link, touch_links=list(touch))
        msg.object.id = oid
        msg.object.operation = CollisionObject.ADD if op is None else op
        self.attached.publish(msg)
        deadline = time.monotonic() + 10.0
        while (v := self.client.scene_version()) <= before:
            if time.monotonic() > deadline:
                raise TimeoutError("the attach/detach did not reach the scene")
            time.sleep(0.05)
        return v

    def add(self, obj) -> None:
        """One more scene object (collision_object ADD); waits for the scene version to move."""
        from humanoid_planner.ros.conversions import scene_object_to_msg

        before = self.client.scene_version()
        self.client.pub.publish(scene_object_to_msg(obj, self.client_frame))
        deadline = time.monotonic() + 10.0
        while self.client.scene_version() <= before:
            if time.monotonic() > deadline:
                raise TimeoutError(f"{obj.id!r} did not reach the scene")
            time.sleep(0.05)

    def detach(self, oid: str) -> int:
        from humanoid_planner_interfaces.msg import CollisionObject

        return self.attach(oid, "", (), CollisionObject.REMOVE)


def _last_stop(traj) -> float:
    """When the robot last stands still before the end of a response trajectory: where the reach ends
    and the straight descent starts (the two are timed as separate rest-to-rest motions)."""
    t = _times(traj)
    v = np.array([p.velocities for p in traj.points])
    still = np.flatnonzero(np.all(np.abs(v[:-1]) < 1e-9, axis=1))
    return float(t[still[-1]])


def _translation_matrix(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _relative_pose_kept(robot, groups, start: np.ndarray, positions: np.ndarray, tol_pos: float = 0.002,
                        tol_rot: float = np.radians(1.0)) -> list[str]:
    """Both hands keep their relative pose along the trajectory (the box between them is rigid)."""
    from humanoid_planner.core.transforms import pose_distance

    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    Q = np.repeat(start[None], len(positions), axis=0)
    Q[:, idx] = positions
    P = robot.link_poses(Q, [robot.group(g).tip_link for g in groups])
    rel = np.linalg.inv(P[:, 0]) @ P[:, 1]
    errs = np.array([pose_distance(rel[0], R) for R in rel])
    if errs[:, 0].max() > tol_pos or errs[:, 1].max() > tol_rot:
        return [f"the hands' relative pose drifts by {errs[:, 0].max() * 1000:.2f} mm / "
                f"{np.degrees(errs[:, 1].max()):.2f} deg"]
    return []


def _pose_stamped(T: np.ndarray, frame: str):
    from geometry_msgs.msg import PoseStamped

    from humanoid_planner.ros.conversions import matrix_to_pose_msg

    ps = PoseStamped(pose=matrix_to_pose_msg(T))
    ps.header.frame_id = frame
    return ps


def _at(q_start: np.ndarray, robot, traj) -> np.ndarray:
    """The full configuration at the end of a response trajectory, the other joints as in q_start."""
    return _full_configurations(robot, q_start, traj)[-1]


def _lifted(robot, groups, sc, traj, retreat) -> tuple[np.ndarray, np.ndarray]:
    """(the configuration at the grasp, at the end of the lift) of a pick response."""
    return _at(robot.home, robot, traj), _at(robot.home, robot, retreat)


def _cycle_rows(name: str, resp, extra: str, verified: bool | None) -> list[str]:
    from humanoid_planner.ros.requests import ERROR_NAMES

    ok = resp.error_code.val == 1
    dur = _times(resp.trajectory)[-1] if ok and len(resp.trajectory.points) else 0.0
    return [name, ERROR_NAMES.get(resp.error_code.val, str(resp.error_code.val)), f"{resp.planning_time:.3f}",
            f"{dur:.2f}" if ok else "-", extra if ok else resp.message[:60],
            "-" if verified is None or not ok else "yes" if verified else "NO"]


def run_cycles(client: DemoClient, robot, frame: str, seed: int, timeout: float, out: Path) -> tuple[list, list[str]]:
    """The rest of the manipulation cycle through the node: one hand (pick on the table, lift, place on
    a shelf, detach, home) and two hands (pick the box, lift, carry it across the robot's middle to the table's right half,
    detach, home). Returns (table rows, verification problems); writes one picture per cycle."""
    from dataclasses import replace

    from humanoid_planner.core.grasp.approach import approach_axis
    from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach
    from humanoid_planner.core.verification import verify_place, verify_plan, verify_release
    from humanoid_planner.plots import plot_scene
    from humanoid_planner.scenarios import OBJECT_ID, make_scenario, shelf
    from humanoid_planner_interfaces.srv import PlanDualGrasp, PlanDualPlace, PlanGrasp, PlanPlace, PlanToState

    cyc = CycleClient(client, frame)
    rows, problems = [], []
    down = np.array([0.0, 0.0, -1.0])
    place_down = _translation((0.0, 0.0, 0.0), 0.05, 0.05)  # zero direction: the planning frame's -z
    # after the release, back out along the hand's axis (TCP frame): across it (ARMAR-III's TCP -z, the
    # default) a hand slides along what it let go of, and a retreat may not end touching it
    hand_back = -approach_axis(robot, "left_arm")
    back = _translation(hand_back, 0.10, 0.05)
    lift = _translation(LIFT, 0.10, 0.05, frame)

    def call(cli, req):
        return _wait(cli.call_async(req), timeout + 30.0)

    def home(name, groups, q, world: SceneSnapshot):
        """plan_to_state "home" from q, verified in `world` (the object left where it was placed)."""
        req = PlanToState.Request(group=groups[0], right_group=groups[1] if len(groups) > 1 else "",
                                  start_state=cyc.joint_state(robot, q), named_state="home", timeout=timeout, seed=seed)
        resp = call(cyc.to_state_cli, req)
        ok = resp.error_code.val == 1
        found = []
        if ok:
            idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
            plan = _ResponsePlan(resp.trajectory)
            found = verify_plan(robot, world, groups, q, plan, ())
            if not np.allclose(plan.path[-1], robot.home[idx], atol=1e-6):
                found.append("does not end at home")
            problems.extend(f"{name}: {p}" for p in found)
        rows.append(_cycle_rows(name, resp, "named_state home", not found))
        return resp

    # --- one hand: pick from the table under the shelf, place on the shelf beside it
    sc = make_scenario(robot, "table_shelf", seed, hand="left")
    group = "left_arm_torso"
    tip, hands = robot.group(group).tip_link, robot.hand_links(group)
    fixtures = shelf(robot)
    client.publish_scene(replace(sc.scene, objects=sc.scene.objects + fixtures), frame)
    pick = call(client.plan_cli, PlanGrasp.Request(group=group, object_id=OBJECT_ID, timeout=timeout, seed=seed,
                                                   start_state=cyc.joint_state(robot, robot.home),
                                                   pre_grasp_approach=_translation(approach_axis(robot, group), 0.10, 0.05),
                                                   post_grasp_retreat=lift))
    rows.append(_cycle_rows("pick + lift", pick, f"grasp {pick.grasp.id}", None))
    if pick.error_code.val == 1:
        q_grasp, q_up = _lifted(robot, (group,), sc, pick.trajectory, pick.retreat_trajectory)
        cyc.at(robot, q_grasp)
        cyc.attach(OBJECT_ID, tip, hands)
        obj = sc.scene.get(OBJECT_ID)
        att = attach(obj, tip, robot.link_poses(q_grasp, [tip])[0], hands)
        board = fixtures[0]
        top = board.pose[2, 3] + board.shapes[0].dims[2] / 2
        c = board.pose[:3, 3]
        places = []
        for dy in (-0.10, -0.05, 0.0, 0.05, 0.10):
            P = np.array(sc.object_pose, float)
            P[:3, 3] = (c[0] - 0.05, c[1] + dy, top + obj.shapes[0].dims[2] / 2)
            places.append(P)
        world = SceneSnapshot(1, frame, tuple(o for o in sc.scene.objects if o.id != OBJECT_ID) + fixtures,
                              attached=(att,))
        resp = call(cyc.place_cli, PlanPlace.Request(group=group, start_state=cyc.joint_state(robot, q_up),
                                                     object_id=OBJECT_ID, place_poses=[_pose_stamped(P, frame) for P in places],
                                                     timeout=timeout, seed=seed, pre_place_approach=place_down,
                                                     post_place_retreat=back))
        found = []
        if resp.error_code.val == 1:
            plan = _ResponseRetreat(resp)
            plan.approach_time = _last_stop(resp.trajectory)
            found = verify_place(robot, world, group, q_up, plan, OBJECT_ID, places[resp.place_index], (board.id,),
                                 down, approach_min=0.05 - 1e-3, retreat_direction=hand_back,
                                 retreat_min=0.05 - 2e-3, retreat_in_tcp=True)
            problems.extend(f"plan_place: {p}" for p in found)
        rows.append(_cycle_rows("plan_place (shelf)", resp, f"place_poses[{resp.place_index}], down "
                                f"{resp.approach_distance * 100:.0f} cm, back {resp.retreat_distance * 100:.0f} cm",
                                not found))
        if resp.error_code.val == 1:
            q_placed = _at(q_up, robot, resp.trajectory)
            q_back = _at(q_up, robot, resp.retreat_trajectory)
            cyc.at(robot, q_placed)
            cyc.detach(OBJECT_ID)
            placed = SceneSnapshot(1, frame, world.objects + (SceneObject(OBJECT_ID, places[resp.place_index], obj.shapes),))
            h = home("plan_to_state home", (group,), q_back, placed)
            Q = [_full_configurations(robot, robot.home, pick.trajectory),
                 _full_configurations(robot, robot.home, pick.retreat_trajectory),
                 _full_configurations(robot, q_up, resp.trajectory), _full_configurations(robot, q_up, resp.retreat_trajectory)]
            if h.error_code.val == 1:
                Q.append(_full_configurations(robot, q_back, h.trajectory))
            Q = np.vstack(Q)
            path = robot.link_poses(Q, [tip])[:, 0, :3, 3]
            T_goal = robot.link_poses(q_placed, [tip])[0]
            f = plot_scene(robot, placed, Q, [path], [T_goal], [down], [f"{group} (place_poses[{resp.place_index}])"],
                           f"{robot.name} cycle, one hand: pick, lift, place on the shelf "
                           f"({resp.planning_time * 1000:.0f} ms), release, home", out / "cycle_one_hand_scene.png",
                           highlight=OBJECT_ID)
            print(f"wrote {f}")
        cyc.detach("")  # nothing stays attached for the next cycle

    # --- two hands: the box picked left of the robot's middle, carried to the table's right half
    groups = ("left_arm", "right_arm")
    sc = make_scenario(robot, "empty", 0, hand="both")  # the box alone, where both hands reach it
    obj = sc.scene.get(OBJECT_ID)
    start_pose = sc.object_pose @ _translation_matrix((0.0, CARRY_FROM, 0.0))
    obj = replace(obj, pose=start_pose)
    sc = replace(sc, scene=replace(sc.scene, objects=(obj,)), object_pose=start_pose)
    half_h = obj.shapes[0].dims[2] / 2
    x, y, z = sc.object_pose[:3, 3]
    top = z - half_h - 0.10  # a table 10 cm under the box, in front of the robot (added once the box is lifted)
    table = SceneObject("table", _translation_matrix((x + 0.1, 0.0, top - 0.01)), (Shape("box", np.eye(4), (0.3, 1.0, 0.02)),))
    client.publish_scene(sc.scene, frame)
    tips = [robot.group(g).tip_link for g in groups]
    touch = robot.hand_links(groups[0]) + robot.hand_links(groups[1])
    pick = call(client.dual_cli, PlanDualGrasp.Request(left_group=groups[0], right_group=groups[1], object_id=OBJECT_ID,
                                                       start_state=cyc.joint_state(robot, robot.home),
                                                       timeout=timeout, seed=1, post_grasp_retreat=lift))
    rows.append(_cycle_rows("dual pick + lift", pick, f"grasps {pick.left_grasp.id} + {pick.right_grasp.id}", None))
    if pick.error_code.val == 1:
        q_grasp, q_up = _lifted(robot, groups, sc, pick.trajectory, pick.retreat_trajectory)
        cyc.at(robot, q_grasp)
        cyc.attach(OBJECT_ID, tips[0], touch)
        cyc.add(table)
        places = []
        for dy in CARRY_TO:  # to the right, across the robot's middle
            P = np.array(sc.object_pose, float)
            P[1:3, 3] = (y + dy, top + half_h)
            places.append(P)
        resp = call(cyc.dual_place_cli, PlanDualPlace.Request(
            left_group=groups[0], right_group=groups[1], start_state=cyc.joint_state(robot, q_up), object_id=OBJECT_ID,
            place_poses=[_pose_stamped(P, frame) for P in places], timeout=timeout, seed=seed,
            pre_place_approach=place_down, post_place_retreat=_translation(LIFT, HANDS_UP, 0.05, frame)))
        found = []
        att = attach(obj, tips[0], robot.link_poses(q_grasp, [tips[0]])[0], touch)
        if resp.error_code.val == 1:
            plan = _ResponsePlan(resp.trajectory)
            world = SceneSnapshot(1, frame, (), attached=(att,))  # the table is its support: the robot alone below
            q_end = _at(q_up, robot, resp.trajectory)
            T_end = robot.link_poses(q_end, [tips[0]])[0] @ att.pose
            found = verify_plan(robot, world, groups, q_up, plan, ())
            found += verify_plan(robot, SceneSnapshot(1, frame, (table,)), groups, q_up, plan, ())
            if not np.allclose(T_end, places[resp.place_index], atol=2e-3):
                found.append("the box does not end at the placement")
            found += _relative_pose_kept(robot, groups, q_up, plan.path)
            released = SceneSnapshot(1, frame, (table, SceneObject(OBJECT_ID, places[resp.place_index], obj.shapes)))
            found += verify_release(robot, released, groups, q_up, _ResponsePlan(resp.retreat_trajectory).path)
            problems.extend(f"plan_dual_place: {p}" for p in found)
        carried = abs(CARRY_TO[resp.place_index]) * 100 if resp.error_code.val == 1 else 0.0
        rows.append(_cycle_rows("plan_dual_place (table)", resp, f"place_poses[{resp.place_index}] ({carried:.0f} cm "
                                f"to the right), down {resp.approach_distance * 100:.0f} cm, hands up "
                                f"{resp.retreat_distance * 100:.0f} cm", not found))
        if resp.error_code.val == 1:
            q_placed = _at(q_up, robot, resp.trajectory)
            q_back = _at(q_up, robot, resp.retreat_trajectory)
            cyc.at(robot, q_placed)
            cyc.detach(OBJECT_ID)
            placed = SceneSnapshot(1, frame, (table, SceneObject(OBJECT_ID, places[resp.place_index], obj.shapes)))
            h = home("plan_to_state home (both)", groups, q_back, placed)
            Q = [_full_configurations(robot, robot.home, pick.trajectory),
                 _full_configurations(robot, robot.home, pick.retreat_trajectory),
                 _full_configurations(robot, q_up, resp.trajectory), _full_configurations(robot, q_up, resp.retreat_trajectory)]
            if h.error_code.val == 1:
                Q.append(_full_configurations(robot, q_back, h.trajectory))
            Q = np.vstack(Q)
            P = robot.link_poses(Q, tips)
            goals = list(robot.link_poses(q_placed, tips))
            f = plot_scene(robot, placed, Q, [P[:, i, :3, 3] for i in range(2)], goals, [down, down],
                           [f"{g} (place_poses[{resp.place_index}])" for g in groups],
                           f"{robot.name} cycle, two hands: pick, lift, carry across the table "
                           f"({resp.planning_time * 1000:.0f} ms), release, home", out / "cycle_two_hands_scene.png",
                           highlight=OBJECT_ID)
            print(f"wrote {f}")
        cyc.detach("")
    return rows, problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out", help="folder for the pictures and the node's log (default: out)")
    ap.add_argument("--params-file", action="append", default=[], help="node parameter YAML (repeatable)")
    ap.add_argument("--robot", default="armar3", help="preset (default armar3: left_arm_torso, left_arm, right_arm)")
    ap.add_argument("--seed", type=int, default=3, help="scenario and planner seed (default 3)")
    ap.add_argument("--timeout", type=float, default=10.0, help="planning timeout per request, s (default 10)")
    a = ap.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    with contextlib.ExitStack() as stack:
        if not os.environ.get("ROS_DOMAIN_ID"):
            import domain_coordinator

            os.environ["ROS_DOMAIN_ID"] = str(stack.enter_context(domain_coordinator.domain_id()))
        try:
            return run(Path(a.out), a.params_file, a.seed, a.timeout, a.robot)
        except KeyboardInterrupt:
            return 130
        except (RuntimeError, TimeoutError) as e:
            print(f"demo failed: {e}", file=sys.stderr)
            return 1


if __name__ == "__main__":
    sys.exit(main())
