"""Planning threads (ros/planning_threads.py) and what a request that waited is told, on an in-process
armar3 node with one planning thread.

Earliest deadline first: client A queues a burst of plans with a long timeout, then client B sends
one with a short timeout; B is answered right after A's running plan, not after A's whole burst (first
come, first served would answer it last). A full queue refuses at once. A request whose deadline
passes in the queue says so, with planning_time 0 (it excludes queueing)."""
from __future__ import annotations

import pytest

from humanoid_planner.scenarios import OBJECT_ID
from humanoid_planner_interfaces.msg import ErrorCode
from humanoid_planner_interfaces.srv import PlanGrasp
from humanoid_planner.ros.qos import SERVICE_QOS
from humanoid_planner.ros.executors import wait_for_server

from plan_helpers import SUCCESS, Graph, caged, scenario, single_request, wait_all

pytestmark = pytest.mark.integration


def test_short_requests_do_not_wait_behind_a_burst_and_queueing_is_reported(ros):
    g = Graph(ros, num_workers=1, max_queued_plans=6)
    sc = scenario("table_shelf", 1, "left")
    g.load(sc.scene.objects)
    other = ros.node("client_b")
    b_cli = other.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
    assert wait_for_server(b_cli, 10.0)
    order: list[str] = []
    a = [g.plan.call_async(single_request(object_id=OBJECT_ID, timeout=30.0, seed=i + 1)) for i in range(6)]
    for i, f in enumerate(a):
        f.add_done_callback(lambda _f, i=i: order.append(f"a{i}"))
    # all of A's burst received: running, queued or (fast plans: the burst's last request can arrive
    # after the first ones are answered) already answered
    g.ros.wait_until(lambda: g.planner.plan_server.active_plans + len(order) >= 6, what="A's burst queued")
    done_before_b = len(order)
    assert done_before_b <= 3, order  # B then finds at least 3 of A's plans to jump (FIFO: index 6)
    b = b_cli.call_async(single_request(object_id=OBJECT_ID, timeout=10.0, seed=9))
    b.add_done_callback(lambda _f: order.append("b"))
    answers = wait_all(a + [b], 60.0)
    assert all(r.error_code.val == SUCCESS for r in answers), [r.message for r in answers]
    # after A's running plan (and at most one that started meanwhile), not behind the rest of A's burst
    assert order.index("b") <= done_before_b + 2, order

    # a full queue refuses at once; a deadline that passes in the queue is reported as such
    g.load(caged(sc).objects[-1:])  # the cage: plans now search to their deadline
    burst = [g.plan.call_async(single_request(object_id=OBJECT_ID, timeout=1.0, seed=i + 1)) for i in range(8)]
    answers = wait_all(burst, 30.0)
    full = [r for r in answers if "max_queued_plans = 6" in r.message]
    queued_out = [r for r in answers if "before planning started" in r.message]
    # 8 requests, room for 6 queued: 1 refused, or 2 when the thread had not yet taken the first
    assert 1 <= len(full) <= 2 and all(r.error_code.val == ErrorCode.FAILURE for r in full), \
        [r.message for r in answers]
    assert queued_out, [r.message for r in answers]
    for r in queued_out:
        assert r.error_code.val == ErrorCode.TIMED_OUT and r.planning_time == 0.0
        assert "waiting for a planning thread" in r.message and "checking the request" in r.message
