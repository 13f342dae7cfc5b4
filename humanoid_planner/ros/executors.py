"""Executors: the kind the node is spun with, and the topics' own executor thread.

`joint_states` is subscribed by a second node of its own (`<node name>_topics`, same namespace, so the
same topics), spun by its own executor on its own thread (`TopicThread`). An executor serves its events
in arrival order, so with one executor a publisher sending tens of thousands of messages a second queued
every service request behind them. (The scene topics go through no executor at all: the scene thread
takes their messages, ros/scene_intake.py.)
"""
from __future__ import annotations

import threading
import time

from rclpy.context import Context
from rclpy.node import Node

TOPIC_SPIN_PERIOD = 0.2  # s: how long the topic thread waits for an event before it looks at `close`
SERVER_POLL_PERIOD = 0.01  # s: how often wait_for_server looks at the ROS graph


def make_executor(kind: str, logger, context: Context | None = None):
    """(executor, kind actually used). "events": rclpy's EventsExecutor (C++ event queue; the
    Python executors rebuild a wait set in Python for every callback), falling back to "single"
    (rclpy's SingleThreadedExecutor) when this rclpy has none."""
    from rclpy.executors import SingleThreadedExecutor

    if kind == "events":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            logger.warning("this rclpy has no rclpy.experimental.EventsExecutor; using the SingleThreadedExecutor")
        else:
            return EventsExecutor(context=context), "events"
    return SingleThreadedExecutor(context=context), "single"


def wait_for_future(executor, future, timeout_sec: float) -> bool:
    """Spin `executor` in this thread until `future` is done or `timeout_sec` has passed; True if done.

    For a client that calls services in a loop. Not `spin_until_future_complete`: Jazzy's Python executors
    add a wake-up callback to the future on every spin and leave each one queued as a task once the future
    is done, so every call pays for all the calls before it (a SingleThreadedExecutor measured 0.3 ms a
    call at first, 66 ms after 2,500 calls; rclpy's EventsExecutor does not grow).
    """
    end = time.monotonic() + timeout_sec
    while not future.done():
        left = end - time.monotonic()
        if left <= 0.0:
            return False
        executor.spin_once(timeout_sec=left)
    return True


def wait_for_server(endpoint, timeout_sec: float) -> bool:
    """Wait until the server of `endpoint` (a service Client or an ActionClient) is up; True if it is.

    Not rclpy's `wait_for_service` / `wait_for_server`: they sleep in steps of 0.25 s and count the steps,
    not the clock, so a server found 10 ms after the call is noticed 250-500 ms later (every `grasp_client`
    call paid 0.5 s of its 1 s there), and on a loaded machine the timeout stretches. This looks every
    SERVER_POLL_PERIOD against a monotonic deadline (a graph lookup, microseconds).
    """
    ready = getattr(endpoint, "service_is_ready", None) or endpoint.server_is_ready
    end = time.monotonic() + timeout_sec
    while not ready():
        if time.monotonic() >= end:
            return False
        time.sleep(SERVER_POLL_PERIOD)
    return True


class TopicThread:
    """A node for subscriptions that may flood, spun on a thread of its own until `close`."""

    def __init__(self, owner: Node, kind: str):
        self.node = Node(f"{owner.get_name()}_topics", namespace=owner.get_namespace(), context=owner.context,
                         start_parameter_services=False)
        self._log = owner.get_logger()
        self._executor, _ = make_executor(kind, self._log, owner.context)
        self._executor.add_node(self.node)
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scene-topics", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from rclpy.executors import ExternalShutdownException

        while not self._closing.is_set() and self.node.context.ok():
            try:
                self._executor.spin_once(timeout_sec=TOPIC_SPIN_PERIOD)
            except ExternalShutdownException:
                return
            except Exception as e:  # noqa: BLE001 - the callbacks catch their own; this is the executor's
                if self._closing.is_set() or not self.node.context.ok():
                    return
                self._log.error(f"scene topic executor: {e!r}")

    def close(self) -> None:
        """Stop the thread (at once), then the executor and the node."""
        self._closing.set()
        # a task ends the thread's wait for events at once, not after up to TOPIC_SPIN_PERIOD (0.2 s of
        # every node's shutdown); EventsExecutor.wake() does not end a spin_once
        self._executor.create_task(lambda: None)
        self._thread.join(timeout=2 * TOPIC_SPIN_PERIOD + 1.0)
        try:
            self._executor.shutdown(timeout_sec=1.0)
        finally:
            self.node.destroy_node()
