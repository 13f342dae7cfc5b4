"""The path of a plan's answer: responses sent from the planning worker (PendingResponse,
`defer_responses`), the watchdog thread, the trajectory message, and planner_node's `executor` parameter.

The executor hands a PendingResponse and the request header to the service's send_response right after
the callback returns; the worker completes it with the response when the plan is done. Whichever comes
second sends, exactly once. The services end to end, on both executors, are in test_plan_services.py.
"""
from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from humanoid_planner.ros import requests
from humanoid_planner.ros.plan_server import PendingResponse, defer_responses
from humanoid_planner.ros.watchdog import Watchdog

pytestmark = pytest.mark.integration


class FakeService:
    """Stands in for rclpy's Service: send_response(response, header) records what was sent."""

    def __init__(self):
        self.sent = []

    def send_response(self, response, header):
        self.sent.append((response, header))


@pytest.mark.parametrize("order", ["header_first", "response_first"])
def test_pending_response_is_sent_once_by_the_second_side(order):
    svc = FakeService()
    send = defer_responses(svc)
    errors = []
    pending = PendingResponse(send, errors.append)
    if order == "header_first":
        svc.send_response(pending, "header")  # what the executor does after the callback returned it
        assert svc.sent == [] and not pending.sent
        pending.complete("response")
    else:
        pending.complete("response")
        assert svc.sent == [] and not pending.sent
        svc.send_response(pending, "header")
    assert svc.sent == [("response", "header")] and pending.sent
    pending.complete("again")  # a second completion (e.g. the watchdog after the worker) sends nothing
    svc.send_response(pending, "header")
    assert svc.sent == [("response", "header")] and errors == []


def test_plain_responses_go_through_unchanged():
    svc = FakeService()
    defer_responses(svc)
    svc.send_response("refused at once", "h1")
    assert svc.sent == [("refused at once", "h1")]


def test_header_and_response_from_two_threads_send_exactly_once():
    for i in range(300):
        svc = FakeService()
        send = defer_responses(svc)
        pending = PendingResponse(send, pytest.fail)
        go = threading.Barrier(2, timeout=10.0)

        def executor_side():
            go.wait()
            svc.send_response(pending, f"header {i}")

        t = threading.Thread(target=executor_side)
        t.start()
        go.wait()
        pending.complete(f"response {i}")
        t.join(10.0)
        assert svc.sent == [(f"response {i}", f"header {i}")]


def test_a_failed_send_is_reported_not_raised():
    def send(response, header):
        raise RuntimeError("context is shut down")

    errors = []
    pending = PendingResponse(send, errors.append)
    pending.attach("header")
    pending.complete("response")  # in a worker thread: must not raise
    assert [str(e) for e in errors] == ["context is shut down"] and pending.sent


def test_unknown_executor_exits_nonzero(start_planner_process):
    proc = start_planner_process(params={"executor": "multi"})
    assert proc.wait(timeout=30.0) == 1
    out = proc.output()
    assert "executor='multi' refused: must be one of events, single" in out and "Traceback" not in out


def test_watchdog_fires_once_in_time_and_not_when_cancelled():
    errors = []
    wd = Watchdog(errors.append, period=0.02)
    try:
        fired = []
        t0 = time.monotonic()
        wd.add(0.1, lambda: fired.append(time.monotonic() - t0))
        cancelled = wd.add(0.05, lambda: fired.append("cancelled one"))
        Watchdog.cancel(cancelled)
        wd.add(0.05, lambda: 1 / 0)  # a failing deadline is reported and does not stop the watchdog
        time.sleep(0.4)
        assert len(fired) == 1 and 0.1 <= fired[0] < 0.3, fired
        assert len(errors) == 1 and isinstance(errors[0], ZeroDivisionError)
    finally:
        wd.close()
    assert not wd._thread.is_alive()


def _plan(times, q):
    q = np.asarray(q, dtype=float)
    traj = SimpleNamespace(times=np.asarray(times, dtype=float), positions=q, velocities=2 * q, accelerations=-q)
    return SimpleNamespace(joint_names=("a", "b", "c"), trajectory=traj)


def test_trajectory_message_matches_the_generated_constructors():
    rng = np.random.default_rng(3)
    times = np.concatenate([[0.0, 0.5, 1.0 - 2e-9, 1.5, 2.25], np.sort(rng.uniform(3.0, 4000.0, 40))])
    plan = _plan(times, rng.uniform(-3.0, 3.0, (len(times), 3)))
    assert requests._make_points is requests._points_direct  # this rosidl: the direct path is the one in use
    msg = requests.trajectory_to_msg(plan, "base_link")
    ns = np.round(times * 1e9).astype(np.int64).tolist()
    rows = [a.tolist() for a in (plan.trajectory.positions, plan.trajectory.velocities, plan.trajectory.accelerations)]
    assert msg.points == requests._points_by_constructor(ns, *rows)
    assert msg.header.frame_id == "base_link" and list(msg.joint_names) == ["a", "b", "c"]
    assert [(p.time_from_start.sec, p.time_from_start.nanosec) for p in msg.points[:5]] == [
        (0, 0), (0, 500_000_000), (0, 999_999_998), (1, 500_000_000), (2, 250_000_000)]
    assert list(msg.points[3].velocities) == list(2 * plan.trajectory.positions[3])
    with pytest.raises(ValueError, match="Duration"):
        requests.trajectory_to_msg(_plan([0.0, float("nan")], np.zeros((2, 3))), "base_link")
