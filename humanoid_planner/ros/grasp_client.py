"""`grasp_client`: call the planner's services with a request written as YAML, print the response as YAML.

The equivalent of `ros2 service call` / `ros2 topic pub --once` for this node (ros2cli is not
installable from wheels):

    grasp_client plan_grasp config/examples/plan_grasp.yaml
    grasp_client plan_dual_grasp config/examples/plan_dual_grasp.yaml
    grasp_client plan_grasp "{group: left_arm_torso, object_id: target, timeout: 2.0}"
    grasp_client plan_to_state "{group: left_arm_torso, named_state: home}"
    grasp_client plan_place "{group: left_arm_torso, object_id: target, place_poses: [{pose: {position: {x: 0.45, y: 0.2, z: 1.1}}}]}"
    grasp_client get_planning_scene
    grasp_client collision_object config/examples/target_left.yaml   # publish one CollisionObject
    grasp_client attached_collision_object config/examples/attach_target.yaml   # attach it to the hand

REQUEST is a YAML file, `-` (stdin) or inline YAML; its keys are the request's fields, nested as in
the .srv/.msg files (e.g. `object_pose: {header: {frame_id: base_link}, pose: {position: {x: 0.4}}}`).
Omitted fields keep their defaults. The response is printed as YAML (`--brief`: trajectory points
summarized). Service names are relative, like the node's: use `--ros-args -r __ns:=/robot1` or
`--service` to reach a node in another namespace.

Exit status: 0 = answered with SUCCESS (or the scene / the publication went through), 2 = answered
with another error code, 1 = no answer (service not available, timeout, invalid YAML).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import yaml

SERVICES = ("plan_grasp", "plan_dual_grasp", "plan_to_state", "plan_place", "plan_dual_place", "get_planning_scene")
TOPICS = ("collision_object", "attached_collision_object")


def load_request(text_or_path: str | None) -> dict:
    """The request dict from a file path, '-' (stdin) or inline YAML; None/empty = {}."""
    if text_or_path is None:
        return {}
    if text_or_path == "-":
        text = sys.stdin.read()
    elif Path(text_or_path).is_file():
        text = Path(text_or_path).read_text()
    else:
        text = text_or_path
    data = yaml.safe_load(text)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"the request must be a YAML mapping of fields, got {type(data).__name__}: {data!r}")
    return data


def _service_type(name: str):
    from humanoid_planner_interfaces.srv import (GetPlanningScene, PlanDualGrasp, PlanDualPlace, PlanGrasp, PlanPlace,
                                                 PlanToState)

    return {"plan_grasp": PlanGrasp, "plan_dual_grasp": PlanDualGrasp, "plan_to_state": PlanToState,
            "plan_place": PlanPlace, "plan_dual_place": PlanDualPlace, "get_planning_scene": GetPlanningScene}[name]


def summarize(response: dict) -> dict:
    """--brief: replace trajectory points by their count, duration, and first and last point."""
    for key in ("trajectory", "retreat_trajectory"):
        traj = response.get(key)
        if isinstance(traj, dict) and traj.get("points"):
            pts = traj["points"]
            last = pts[-1]["time_from_start"]
            traj["points"] = {"count": len(pts), "duration": last["sec"] + last["nanosec"] * 1e-9,
                              "first": pts[0]["positions"], "last": pts[-1]["positions"]}
    return response


def error_name(code: int) -> str:
    from humanoid_planner_interfaces.msg import ErrorCode

    names = {v: k for k, v in vars(ErrorCode).items() if k.isupper() and isinstance(v, int)}
    return names.get(code, "?")


def dump(data: dict) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)


def run(argv: list[str], ros_args: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="grasp_client", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("command", choices=SERVICES + TOPICS)
    ap.add_argument("request", nargs="?", help="YAML file, '-' for stdin, or inline YAML (default: empty request)")
    ap.add_argument("--service", help="service or topic name (default: the command; relative names use the namespace)")
    ap.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the service / a subscriber")
    ap.add_argument("--timeout", type=float, default=None,
                    help="seconds to wait for the answer (default: the request's timeout + 30, or 30)")
    ap.add_argument("--brief", action="store_true", help="summarize trajectory points")
    a = ap.parse_args(argv)

    from humanoid_planner.ros.message_dict import MessageFieldError, dict_to_msg, msg_to_dict

    try:
        data = load_request(a.request)
        if a.command in TOPICS:
            from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject

            msg = dict_to_msg(CollisionObject if a.command == "collision_object" else AttachedCollisionObject, data)
        else:
            msg = dict_to_msg(_service_type(a.command).Request, data)
    except (OSError, yaml.YAMLError, ValueError, MessageFieldError) as e:
        print(f"grasp_client: invalid request: {e}", file=sys.stderr)
        return 1

    import rclpy

    from humanoid_planner.ros.discovery import apply_client_profile, forget_profile
    from humanoid_planner.ros.executors import wait_for_server

    profile = apply_client_profile()  # a published scene update arrives in ~0.1 s, not at the next 3 s heartbeat
    rclpy.init(args=["grasp_client", "--ros-args", *ros_args] if ros_args else None)
    node = rclpy.create_node("grasp_client")
    forget_profile(profile)
    name = a.service or a.command
    try:
        if a.command in TOPICS:
            from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS

            pub = node.create_publisher(type(msg), name, COLLISION_OBJECT_QOS)
            deadline = time.monotonic() + a.wait
            while pub.get_subscription_count() < 1:
                if time.monotonic() > deadline:
                    print(f"grasp_client: nobody subscribes to {pub.topic_name} after {a.wait} s", file=sys.stderr)
                    return 1
                time.sleep(0.05)
            pub.publish(msg)
            # reliable QoS: exit only once every matched subscriber has the sample (a fixed sleep lost
            # it on a loaded machine: the node never heard of the object)
            from rclpy.duration import Duration

            if not pub.wait_for_all_acked(Duration(seconds=max(deadline - time.monotonic(), 1.0))):
                print(f"grasp_client: published on {pub.topic_name}, but not acknowledged by every subscriber "
                      f"within {a.wait} s", file=sys.stderr)
                return 1
            print(f"published on {pub.topic_name}")
            return 0
        cli = node.create_client(_service_type(a.command), name)
        if not wait_for_server(cli, a.wait):
            print(f"grasp_client: service {cli.srv_name} not available after {a.wait} s", file=sys.stderr)
            return 1
        timeout = a.timeout if a.timeout is not None else 30.0 + max(0.0, float(getattr(msg, "timeout", 0.0) or 0.0))
        future = cli.call_async(msg)
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
        if not future.done():
            print(f"grasp_client: no answer from {cli.srv_name} after {timeout} s", file=sys.stderr)
            return 1
        response = msg_to_dict(future.result())
        if a.brief:
            response = summarize(response)
        code = response.get("error_code", {}).get("val")
        if code is not None:
            print(f"# error_code: {error_name(code)} ({code})")
        sys.stdout.write(dump(response))
        return 0 if code in (None, 1) else 2
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        argv, ros_args = argv[:i], argv[i + 1:]
    try:
        return run(argv, ros_args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
