"""Entry point of `planner_node` (`ros2 run humanoid_planner planner_node`).

Exit codes: 0 after a clean shutdown (SIGINT, SIGTERM, or an external rclpy shutdown); 1 when the
robot cannot be loaded or the node cannot start (the reason is logged, without a traceback).
"""
from __future__ import annotations

import gc
import signal
import sys

LOGGER_NAME = "humanoid_planner"
SPIN_PERIOD = 1.0
"""s: the EventsExecutor is spun with spin_once(SPIN_PERIOD) in a loop (see spin())."""
GIL_SWITCH_INTERVAL = 0.001
"""s (CPython's default is 0.005). Planning threads are CPU-bound Python; the executor threads that
apply scene updates and answer services must get the GIL back quickly after each blocking rcl call.
Measured with two plans running: the longest a sleeping thread waited for the GIL fell from 118 ms
to 14 ms (99th percentile 21 -> 9 ms)."""


def freeze_startup_objects() -> None:
    """Collect, then move every object alive now (imported modules, the robot model, the planner's
    tables: ~140k objects for armar3) to the permanent generation, so full collections stop walking
    them. Measured on planner_node serving plan_grasp (armar3, boxes6): a full collection took ~70 ms
    and came once every ~25 plans, wherever it fell - inside a plan or between the plan and its answer;
    with the freeze, 40 plans ran without a full collection (the two partial ones took < 1 ms)."""
    gc.collect()
    gc.freeze()


_spinning = False
"""True while the executor spins: a signal then only ends spin (see _on_signal)."""


def _on_signal(signum, frame):
    """SIGINT / SIGTERM. rclpy's own handler (it chains to this one) has already shut the context down,
    which ends spin; raising KeyboardInterrupt then would land in whatever callback the main thread runs
    (a timer's: rclpy logs it as FATAL with a traceback). Outside spin (startup, teardown) it raises, so
    that a signal there ends the process cleanly too."""
    if not _spinning:
        raise KeyboardInterrupt


def spin(executor, kind: str) -> None:
    """Serve until the context is shut down (raises what the executor raises on shutdown / SIGINT)."""
    import rclpy
    from rclpy._rclpy_pybind11 import RCLError

    try:
        if kind == "events":
            # rclpy 7.1's EventsExecutor.spin() does not return when the context is shut down (nor on
            # SIGINT/SIGTERM) and then keeps a core busy; spin_once does return (measured on 7.1.6).
            while rclpy.ok():
                executor.spin_once(timeout_sec=SPIN_PERIOD)
        else:
            executor.spin()
    except RCLError:
        # a signal's shutdown between the executor's check of the context and its next wait set: rclpy
        # raises "failed to initialize wait set: the given context is not valid" (seen once with the
        # single executor under SIGTERM) instead of ExternalShutdownException; the end all the same
        if rclpy.ok():
            raise


def main(args=None) -> int:
    # Installed before rclpy is imported and initialized, so rclpy's handler chains to it.
    global _spinning
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException

        from humanoid_planner.ros.discovery import apply_node_profile, forget_profile
        from humanoid_planner.ros.node import PlannerNode
        from humanoid_planner.ros.parameters import StartupError
    except KeyboardInterrupt:
        return 0

    node = None
    executor = None
    code = 0
    profile = apply_node_profile()  # found by new clients within ~0.5 s; a flood cannot crowd out requests
    try:
        rclpy.init(args=args)
        try:
            node = PlannerNode()
        except StartupError as e:
            rclpy.logging.get_logger(LOGGER_NAME).error(str(e))
            code = 1
        else:
            forget_profile(profile)  # the participant exists: its workers need no path to the file
            # Plans run in the node's own worker pool and answer from there (deferred responses), so
            # no callback ever blocks: one executor thread serves everything. The EventsExecutor takes
            # requests and messages in C++, where the Python executors rebuild a wait set in Python for
            # every callback: plan_grasp answers sooner (docs/RELIABILITY.md, "Threading"), and with 2 plans running
            # it applied all of 3000 collision_object updates streamed at 1000 Hz from another process,
            # the SingleThreadedExecutor 2665 (both all at 300 Hz; a MultiThreadedExecutor(4) had lost a
            # quarter at 300 Hz). The node works on any executor (the tests spin it on a multi-threaded one).
            from humanoid_planner.ros.executors import make_executor

            executor, kind = make_executor(node.executor_kind, node.get_logger())
            executor.add_node(node)
            freeze_startup_objects()
            node.warm_up_in_background()
            node.get_logger().info(f"ready ({kind} executor)")
            _spinning = True
            try:
                spin(executor, kind)
            finally:
                _spinning = False
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as e:  # anything unexpected: one clear line, non-zero exit
        rclpy.logging.get_logger(LOGGER_NAME).fatal(f"planner_node stopped: {e!r}")
        code = 1
    finally:
        forget_profile(profile)
        # A second signal during teardown must not produce a traceback either.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if executor is not None:
            executor.shutdown(timeout_sec=5.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
