"""The node's planning threads: queued plans run earliest deadline first, and the queue is bounded.

A plain thread pool serves requests first come, first served: a client that queues a burst of slow
requests (long timeouts, many grasps) puts every later request behind the whole burst, and those
later requests — whose timeout counts from arrival — time out in the queue although they would have
needed a thread for a moment. Here a free planning thread takes the queued plan whose deadline comes
first (earliest deadline first): a request that asks for 5 s never waits behind one that asked for
60 s and was queued before it, so a burst of long requests delays a short one by at most the plans
already running. The queue holds at most `max_queued_plans`; beyond that a request is refused at
once (`QueueFull`) rather than left to time out.

Why not a queue per client: rclpy does not tell a service callback who sent the request (the header's
`rmw_request_id_t` exposes only the sequence number in Python, not the writer GUID), so clients cannot
be told apart. The deadline is what a request itself says it can wait, and `max_timeout` bounds how
long any one plan holds a thread.
"""
from __future__ import annotations

import heapq
import itertools
import threading
from typing import Callable


class QueueFull(RuntimeError):
    """`max_queued_plans` plans are already waiting for a planning thread."""


class PlanningThreads:
    """`threads` daemon threads that run submitted callables, earliest deadline first."""

    def __init__(self, threads: int, max_queued_plans: int, name: str = "planner",
                 on_error: Callable[[BaseException], None] | None = None):
        if threads < 1 or max_queued_plans < 1:
            raise ValueError("need at least one planning thread and room for one queued plan")
        self.threads = threads
        self.max_queued_plans = max_queued_plans
        self._on_error = on_error
        self._cv = threading.Condition()
        self._heap: list[tuple[float, int, Callable[[], None]]] = []  # (deadline, arrival order, fn)
        self._order = itertools.count()
        self._running = 0
        self._closed = False
        self._threads = [threading.Thread(target=self._loop, name=f"{name}_{i}", daemon=True) for i in range(threads)]
        for t in self._threads:
            t.start()

    def submit(self, deadline: float, fn: Callable[[], None]) -> None:
        """Queue fn() to run by `deadline` (time.monotonic()); raises QueueFull, or RuntimeError once
        shut down. Of two plans with the same deadline the one submitted first runs first."""
        with self._cv:
            if self._closed:
                raise RuntimeError("the planning threads are shut down")
            if len(self._heap) >= self.max_queued_plans:
                raise QueueFull(f"{len(self._heap)} plans are already waiting for a planning thread "
                                f"(max_queued_plans = {self.max_queued_plans}); try again later")
            heapq.heappush(self._heap, (deadline, next(self._order), fn))
            self._cv.notify()

    @property
    def busy(self) -> int:
        """Planning threads running a plan now."""
        with self._cv:
            return self._running

    @property
    def queued(self) -> int:
        with self._cv:
            return len(self._heap)

    def shutdown(self) -> None:
        """Take no new plans; the threads still run what is queued (plans cancelled beforehand answer
        at once), then end."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    def _take(self) -> Callable[[], None] | None:
        with self._cv:
            while not self._heap:
                if self._closed:
                    return None
                self._cv.wait()
            self._running += 1
            return heapq.heappop(self._heap)[2]

    def _loop(self) -> None:
        while (fn := self._take()) is not None:
            try:
                fn()
            except BaseException as e:  # noqa: BLE001 - a planning thread outlives any plan
                if self._on_error is not None:
                    self._on_error(e)
            finally:
                with self._cv:
                    self._running -= 1
