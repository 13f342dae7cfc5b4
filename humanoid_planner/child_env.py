"""The environment a Python child process (the node, a client, a benchmark's helper) is started with."""
from __future__ import annotations

import os
from collections.abc import Mapping

BOOTSTRAP_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"
"""Set by the PyPI ROS wheels' bootstrapper once it has re-executed the interpreter with the ROS library
path. A child that inherits it skips that step, so one of another interpreter or venv (an installed copy, a
different checkout) would run with this process's library path, or none."""


def child_environment(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """This process's environment, `extra` on top, without BOOTSTRAP_GUARD: the child sets up its own
    library path (on a ROS install nothing sets the guard, and this is a plain copy)."""
    env = {**os.environ, **(extra or {})}
    env.pop(BOOTSTRAP_GUARD, None)
    return env
