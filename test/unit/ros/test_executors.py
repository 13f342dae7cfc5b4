"""ros/executors.py: wait_for_future, the service-call wait for clients that call in a loop; the topic
thread's prompt close."""
from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future

from humanoid_planner.ros import executors
from humanoid_planner.ros.executors import TopicThread, wait_for_future, wait_for_server
from humanoid_planner_interfaces.srv import GetPlanningScene


def test_calls_in_a_loop_leave_no_tasks_behind_and_a_timeout_returns(ros_domain_id):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain_id)
    node = rclpy.create_node("wait_for_future_test", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        served = []
        node.create_service(GetPlanningScene, "wait_for_future_test_scene",
                            lambda req, resp: (served.append(req.components), resp)[1])
        cli = node.create_client(GetPlanningScene, "wait_for_future_test_scene")
        assert wait_for_server(cli, 10.0)
        for k in range(200):
            fut = cli.call_async(GetPlanningScene.Request(components=k))
            assert wait_for_future(ex, fut, 10.0)
            assert fut.result().version == 0
        assert served == list(range(200))
        # spin_until_future_complete leaves 4 tasks per call queued here (801 after this loop): each makes
        # every later wait longer
        assert len(ex._tasks) <= 2
        never = Future()
        t0 = time.monotonic()
        assert not wait_for_future(ex, never, 0.2)
        assert 0.2 <= time.monotonic() - t0 < 2.0
    finally:
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()


def test_wait_for_server_returns_as_soon_as_the_service_is_up_and_times_out_by_the_clock(ros_domain_id):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain_id)
    node = rclpy.create_node("wait_for_server_test", context=ctx)
    try:
        cli = node.create_client(GetPlanningScene, "wait_for_server_test_scene")
        t0 = time.monotonic()
        assert not wait_for_server(cli, 0.1)
        assert 0.1 <= time.monotonic() - t0 < 0.23  # rclpy's own waits in steps of 0.25 s
        node.create_service(GetPlanningScene, "wait_for_server_test_scene", lambda req, resp: resp)
        t0 = time.monotonic()
        assert wait_for_server(cli, 10.0)
        assert time.monotonic() - t0 < 0.2  # same process: the graph knows at once
    finally:
        node.destroy_node()
        ctx.try_shutdown()


@pytest.mark.parametrize("kind", ["events", "single"])
def test_topic_thread_closes_without_waiting_out_its_spin_period(ros_domain_id, monkeypatch, kind):
    """A node's shutdown stops its topic thread at once, whichever executor spins it: with the period
    at 5 s, a close that waited for the thread's spin_once to time out would take seconds."""
    monkeypatch.setattr(executors, "TOPIC_SPIN_PERIOD", 5.0)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain_id)
    owner = rclpy.create_node("topic_thread_test", context=ctx)
    try:
        topics = TopicThread(owner, kind)
        time.sleep(0.2)  # the thread is in its wait for events
        t0 = time.monotonic()
        topics.close()
        assert time.monotonic() - t0 < 2.0  # the thread stopped: else close waits for it 2 periods + 1 s
    finally:
        owner.destroy_node()
        ctx.try_shutdown()
