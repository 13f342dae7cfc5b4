"""node_main.spin: a signal's shutdown that rclpy reports as RCLError (the context gone between the
executor's check and its wait set) ends the spin like any shutdown; the same error with the context still
up is a fault and propagates."""
from __future__ import annotations

import pytest
import rclpy
from rclpy._rclpy_pybind11 import RCLError

from humanoid_planner.node_main import spin


class _Executor:
    """Raises what rclpy raised once under SIGTERM, after `shutdown` (the signal) if it is set."""

    def __init__(self, context_up: dict, shutdown: bool):
        self.context_up, self.shutdown = context_up, shutdown

    def spin(self, timeout_sec: float | None = None) -> None:
        if self.shutdown:
            self.context_up["ok"] = False
        raise RCLError("failed to initialize wait set: the given context is not valid")

    spin_once = spin


@pytest.mark.parametrize("kind", ["single", "events"])
def test_an_rcl_error_after_shutdown_ends_the_spin(monkeypatch, kind):
    context_up = {"ok": True}
    monkeypatch.setattr(rclpy, "ok", lambda *a, **k: context_up["ok"])
    spin(_Executor(context_up, shutdown=True), kind)


@pytest.mark.parametrize("kind", ["single", "events"])
def test_an_rcl_error_while_the_context_is_up_propagates(monkeypatch, kind):
    context_up = {"ok": True}
    monkeypatch.setattr(rclpy, "ok", lambda *a, **k: context_up["ok"])
    with pytest.raises(RCLError):
        spin(_Executor(context_up, shutdown=False), kind)
