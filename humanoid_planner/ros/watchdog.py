"""The last-resort deadline of every plan: one daemon thread that answers a plan that overran.

The core stops itself at a request's deadline; the watchdog answers TIMED_OUT (and cancels the plan)
if it has not answered `timeout + max(WATCHDOG_GRACE, timeout / 2)` after arrival.
"""
from __future__ import annotations

import heapq
import itertools
import threading
import time
from typing import Callable

WATCHDOG_GRACE = 1.0  # s: at least this long past a request's deadline before the watchdog answers
WATCHDOG_PERIOD = 0.1  # s: how often the watchdog thread looks at the deadlines (it fires up to this late)


class Watchdog:
    """The deadlines of all plans, on one daemon thread that looks at them every `period` seconds.

    A threading.Timer per request started a thread on the request's path: about 0.5 ms, measured in
    the node between taking a request and handing it to a worker. `add` only pushes onto a heap and
    does not wake the thread, so a deadline fires up to `period` late: the watchdog is a last resort,
    `max(1 s, timeout / 2)` after the planner's own deadline.
    """

    def __init__(self, on_error: Callable[[Exception], None], period: float = WATCHDOG_PERIOD):
        self._period = period
        self._on_error = on_error  # called with an exception a deadline's function raised
        self._lock = threading.Lock()
        self._heap: list[list] = []  # [when, sequence number, fn or None once cancelled]
        self._count = itertools.count()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="planner-watchdog", daemon=True)
        self._thread.start()

    def add(self, delay: float, fn: Callable[[], None]) -> list:
        """Call fn() in `delay` seconds (up to `period` later) unless cancelled; returns the entry."""
        entry = [time.monotonic() + delay, next(self._count), fn]
        with self._lock:
            heapq.heappush(self._heap, entry)
        return entry

    @staticmethod
    def cancel(entry: list) -> None:
        entry[2] = None  # dropped when it comes due; its function (and what it holds) is released now

    def close(self, timeout: float = 1.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def _run(self) -> None:
        while not self._stop.wait(self._period):
            now = time.monotonic()
            with self._lock:
                due = []
                while self._heap and self._heap[0][0] <= now:
                    due.append(heapq.heappop(self._heap)[2])
            for fn in due:
                if fn is None:
                    continue
                try:
                    fn()
                except Exception as e:  # noqa: BLE001 - the watchdog must outlive a failing deadline
                    self._on_error(e)
