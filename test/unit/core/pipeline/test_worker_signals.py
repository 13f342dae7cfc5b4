"""worker_signals: the planner's worker processes start with SIGINT ignored."""
from __future__ import annotations

import subprocess
import sys

# In a fresh interpreter (its own forkserver), with Python's SIGINT handler installed first: a shell
# that starts the test run in the background hands it SIGINT ignored, which every child would inherit
# whether or not the preload ignores it, so the check would prove nothing there.
_PROBE = """
import signal
signal.signal(signal.SIGINT, signal.default_int_handler)
from humanoid_planner.core.pipeline.arm_process import worker_context
with worker_context().Pool(1) as pool:
    child = pool.apply(signal.getsignal, (signal.SIGINT,))
print(child == signal.SIG_IGN, signal.getsignal(signal.SIGINT) is signal.default_int_handler)
"""


def test_worker_processes_start_with_sigint_ignored():
    """A Ctrl-C to the node's process group must not reach a worker even before its main sets its own
    handler: the forkserver's children start with SIGINT ignored (arm_process.WORKER_PRELOAD), while
    the process that made the pool keeps its handler."""
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "True"], out.stdout + out.stderr


_HOOK_PROBE = """
import sys
import humanoid_planner.core.pipeline.worker_signals
for exc in (EOFError("Ran out of input"), BrokenPipeError(32, "Broken pipe"), ValueError("a real fault")):
    try:
        raise exc
    except Exception:
        sys.excepthook(*sys.exc_info())
"""


def test_a_worker_whose_node_went_away_while_it_started_says_so_in_one_line():
    """The forkserver reports a child's exception through sys.excepthook: a parent gone mid-start is one
    line, any other exception keeps its traceback."""
    out = subprocess.run([sys.executable, "-c", _HOOK_PROBE], capture_output=True, text=True, timeout=60)
    lines = out.stderr.splitlines()
    assert lines[:2] == ["planner worker not started: the node went away while it started (EOFError)",
                         "planner worker not started: the node went away while it started (BrokenPipeError)"]
    assert lines[2].startswith("Traceback") and lines[-1] == "ValueError: a real fault", out.stderr
