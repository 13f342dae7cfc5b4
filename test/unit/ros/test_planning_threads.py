"""PlanningThreads: queued plans run earliest deadline first; the queue is bounded."""
from __future__ import annotations

import threading

import pytest

from humanoid_planner.ros.planning_threads import PlanningThreads, QueueFull


def _wait_busy(pool, n=1):
    tick = threading.Event()
    while pool.busy < n and not tick.wait(0.01):
        pass


def test_a_short_deadline_is_not_queued_behind_a_burst_of_long_ones():
    """One thread, blocked; a burst of plans with late deadlines, then one with an early deadline:
    the early one runs first (first come, first served would run it last)."""
    pool = PlanningThreads(1, max_queued_plans=10)
    gate, order, done = threading.Event(), [], threading.Event()
    pool.submit(0.0, lambda: gate.wait(5.0))
    _wait_busy(pool)

    def job(name):
        def run():
            order.append(name)
            if len(order) == 7:
                done.set()
        return run

    for i in range(6):
        pool.submit(100.0, job(f"long{i}"))
    pool.submit(5.0, job("short"))
    gate.set()
    assert done.wait(5.0)
    assert order[0] == "short", order
    assert order[1:] == [f"long{i}" for i in range(6)]  # equal deadlines: in arrival order
    pool.shutdown()


def test_the_queue_is_bounded():
    pool = PlanningThreads(1, max_queued_plans=2)
    gate = threading.Event()
    pool.submit(0.0, lambda: gate.wait(5.0))
    _wait_busy(pool)
    pool.submit(1.0, lambda: None)
    pool.submit(1.0, lambda: None)
    with pytest.raises(QueueFull, match="max_queued_plans = 2"):
        pool.submit(1.0, lambda: None)
    gate.set()
    pool.shutdown()
    with pytest.raises(RuntimeError):
        pool.submit(1.0, lambda: None)


def test_an_exception_is_reported_and_the_thread_lives_on():
    errors, ran = [], threading.Event()
    pool = PlanningThreads(1, 4, on_error=errors.append)
    pool.submit(0.0, lambda: 1 / 0)
    pool.submit(1.0, ran.set)
    assert ran.wait(5.0)
    assert isinstance(errors[0], ZeroDivisionError)
    pool.shutdown()
