"""pair_tables.TableBuilder: the background thread that builds pair tables for later checkers."""
from __future__ import annotations

import threading
import time

from humanoid_planner.core.collision.pair_tables import TableBuilder


def test_newest_job_per_slot_runs_and_a_waiting_key_is_not_queued_twice():
    """Requests whose q_ref keeps moving queue one build per group, not one each: a waiting job is replaced
    by a newer one of its slot; a key already waiting or running is not queued again, nor one that failed."""
    b = TableBuilder()
    started, gate, ran = threading.Event(), threading.Event(), []

    def first() -> None:
        started.set()
        gate.wait(10)
        ran.append(0)

    b.submit(("arm", 0), "arm", first)
    assert started.wait(10)
    b.submit(("arm", 0), "arm", lambda: ran.append(-1))  # running: not again
    b.submit(("arm", 1), "arm", lambda: ran.append(1))
    b.submit(("arm", 2), "arm", lambda: ran.append(2))  # replaces 1
    b.submit(("arm", 2), "arm", lambda: ran.append(-2))  # waiting: not again
    b.submit(("torso", 0), "torso", lambda: ran.append(3))
    gate.set()
    assert b.wait_idle(10)
    assert ran == [0, 2, 3]
    b.submit(("broken", 0), "broken", lambda: 1 / 0)
    assert b.wait_idle(10) and b.failed == 1
    b.submit(("broken", 0), "broken", lambda: ran.append(4))  # a key that failed is not tried again
    assert b.wait_idle(10) and ran == [0, 2, 3]
    b.stop()


def test_it_works_a_quarter_of_the_time_while_a_plan_runs_and_stops_at_exit():
    b = TableBuilder()
    share: dict[str, float] = {}

    def job(name: str) -> None:
        t0, worked = time.perf_counter(), 0.0
        while time.perf_counter() - t0 < 0.4:
            w0 = time.perf_counter()
            while time.perf_counter() - w0 < 0.01:
                pass
            worked += time.perf_counter() - w0
            b.pace()
        share[name] = worked / (time.perf_counter() - t0)

    b.submit(("idle",), "idle", lambda: job("idle"))
    assert b.wait_idle(10)
    with b.planning():
        b.submit(("planning",), "planning", lambda: job("planning"))
        assert b.wait_idle(10)
    assert share["idle"] > 0.9 and share["planning"] < 0.6, share
    b.stop()
    b.submit(("late",), "late", lambda: share.update(late=1.0))
    assert b.wait_idle(1) and "late" not in share


def test_a_forked_child_gets_a_builder_of_its_own():
    """A process forked while this one's builder runs a job has no builder thread and no job of its own:
    its builder starts afresh (no waiting forever on the parent's job)."""
    import os

    from humanoid_planner.core.collision import pair_tables

    started, gate = threading.Event(), threading.Event()
    pair_tables.BUILDER.submit(("fork-test", 0), "fork-test", lambda: (started.set(), gate.wait(10)))
    assert started.wait(10)
    pid = os.fork()
    if pid == 0:  # the child: only the builder, then out
        ran = []
        pair_tables.BUILDER.submit(("fork-test", 1), "fork-test", lambda: ran.append(1))
        os._exit(0 if pair_tables.BUILDER.wait_idle(5) and ran == [1] else 1)
    gate.set()
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert pair_tables.BUILDER.wait_idle(10)
