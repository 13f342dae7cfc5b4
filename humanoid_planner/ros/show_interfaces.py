"""Start planner_node in its own process, list its services and topics as a client sees them, stop it.

    python -m humanoid_planner.ros.show_interfaces [--params-file FILE ...] [--urdf FILE --srdf FILE]

This is what `make demo` runs until the planning demo exists. It uses its own ROS domain (unless
ROS_DOMAIN_ID is set) and localhost-only discovery, so it never talks to other robots or runs.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

NODE = "humanoid_planner"


def _node_exe() -> str:
    exe = Path(sys.executable).parent / "planner_node"
    return str(exe) if exe.exists() else "planner_node"


def _robot_params_file(urdf: str | None, srdf: str | None, tmp: Path) -> list[str]:
    if not urdf:
        return []
    import yaml

    values = {"robot_description": Path(urdf).read_text()}
    if srdf:
        values["robot_description_semantic"] = Path(srdf).read_text()
    f = tmp / "robot.yaml"
    f.write_text(yaml.safe_dump({NODE: {"ros__parameters": values}}))
    return [str(f)]


def _print_list(title: str, items) -> None:
    print(f"  {title}:")
    for name, types in sorted(items):
        print(f"    {name:45s} {', '.join(types)}")


def show(params_files: list[str], timeout: float) -> int:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from humanoid_planner_interfaces.srv import GetPlanningScene

    args = [_node_exe(), "--ros-args"]
    for f in params_files:
        args += ["--params-file", f]
    print("starting:", " ".join(args[:1] + [a if len(a) < 80 else a[:77] + "..." for a in args[1:]]), flush=True)
    proc = subprocess.Popen(args, stdin=subprocess.DEVNULL)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ["ROS_DOMAIN_ID"]))
    node = Node("humanoid_planner_demo_client", context=ctx)
    try:
        cli = node.create_client(GetPlanningScene, "get_planning_scene")
        deadline = time.monotonic() + timeout
        while not cli.wait_for_service(timeout_sec=0.2):
            if proc.poll() is not None:
                print(f"planner_node exited with code {proc.returncode} before it was ready (see its log above)")
                return proc.returncode or 1
            if time.monotonic() > deadline:
                print(f"planner_node not ready after {timeout} s")
                return 1
        # the node's own endpoints are discovered a little after the service answers
        while time.monotonic() < deadline:
            services = node.get_service_names_and_types_by_node(NODE, "/")
            if any(name.endswith("/get_planning_scene") for name, _ in services):
                break
            time.sleep(0.1)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        future = cli.call_async(GetPlanningScene.Request())
        executor.spin_until_future_complete(future, timeout_sec=5.0)
        executor.remove_node(node)
        executor.shutdown()
        print(f"\nnode /{NODE} (as seen from another process):")
        _print_list("services", node.get_service_names_and_types_by_node(NODE, "/"))
        _print_list("subscriptions", node.get_subscriber_names_and_types_by_node(NODE, "/"))
        _print_list("publishers", node.get_publisher_names_and_types_by_node(NODE, "/"))
        if future.done():
            r = future.result()
            print(f"\nget_planning_scene: version {r.version}, planning frame {r.planning_frame!r}, "
                  f"{len(r.objects)} object(s)")
        print("\nstopping planner_node (SIGINT)", flush=True)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=15)
        print(f"planner_node exited with code {code}")
        return code
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        node.destroy_node()
        ctx.try_shutdown()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params-file", action="append", default=[], help="node parameter YAML (repeatable)")
    ap.add_argument("--urdf", help="robot URDF file (instead of the `robot` preset)")
    ap.add_argument("--srdf", help="robot SRDF file")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the node")
    a = ap.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    with contextlib.ExitStack() as stack:
        if not os.environ.get("ROS_DOMAIN_ID"):
            import domain_coordinator

            os.environ["ROS_DOMAIN_ID"] = str(stack.enter_context(domain_coordinator.domain_id()))
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        try:
            return show(a.params_file + _robot_params_file(a.urdf, a.srdf, tmp), a.timeout)
        except KeyboardInterrupt:
            return 130


if __name__ == "__main__":
    sys.exit(main())
