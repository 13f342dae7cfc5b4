"""`make demo`: the product end to end, as a user would run it.

    python -m humanoid_planner.demo [--out out] [--params-file config/planner.yaml] [--seed N]

1. starts `planner_node` in its own process (built-in preset `armar3`, its own ROS domain,
   localhost-only discovery; the node's log goes to out/planner_node.log);
2. from this client process publishes a scene on `collision_object` — a table, a shelf and a
   back wall with the object `target` and its grasp set in front of the left shoulder
   (`core.scenarios`, family table_shelf) — and calls `plan_grasp` for `left_arm_torso`, the hand
   approaching the last 10 cm in a straight line along its axis and lifting the object 10 cm.
   Then the same table, shelf and wall are given as a depth camera would see them: the scene is
   replaced by the object alone, a synthetic 640 x 480 depth image of the scene's own boxes
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
5. stops the node with SIGINT. Exit status 0 when both plans succeed and verify, 1 otherwise.
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

NODE_STARTUP_TIMEOUT = 40.0
LIFT = (0.0, 0.0, 1.0)  # the retreat: straight up in the planning frame


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
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
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
        deadline = time.monotonic() + timeout
        for cli in (self.scene_cli, self.plan_cli, self.dual_cli):
            while not cli.wait_for_service(timeout_sec=0.2):
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

    def close(self) -> None:
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


def _depth_cloud(robot, scenario, frame_id: str):
    """A 640 x 480 depth image of the scenario's boxes (the object too: the node removes its points),
    from a camera 35 cm above `frame_id`'s origin at home looking at the object, as a PointCloud2 in
    `frame_id` (the node places it by forward kinematics)."""
    from humanoid_planner.clouds import look_at, render_depth, scene_boxes
    from humanoid_planner.core.transforms import invert
    from humanoid_planner.ros.pointcloud import points_to_cloud

    T_frame = robot.link_poses(robot.home, [frame_id])[0]
    cam = look_at(T_frame[:3, 3] + [0.0, 0.0, 0.35], scenario.object_pose[:3, 3])
    img = render_depth(scene_boxes(scenario.scene.objects), cam, 640, 480, fov_x=np.radians(90)).reshape(-1, 3)
    T = invert(T_frame) @ cam  # camera in frame_id
    return points_to_cloud(img @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32), frame_id, (480, 640))


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
    env = dict(os.environ)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
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
        ok = all(r.error_code.val == 1 for _, _, _, r, _ in results)
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
