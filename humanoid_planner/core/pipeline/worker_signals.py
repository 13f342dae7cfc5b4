"""Imported only by the planner's forkserver (arm_process.WORKER_PRELOAD), never by the node.

It ignores SIGINT in the forkserver while that preloads. The forkserver saves the handlers it finds after
preloading and restores them in every child it forks, so each worker starts with SIGINT ignored — a
Ctrl-C aimed at the node's process group cannot interrupt a worker even before its main runs (it did,
between the fork and the worker's own signal call: a KeyboardInterrupt traceback at shutdown).

It also sets the forkserver's (so its children's) sys.excepthook: a child forked while the node shuts down
finds its parent gone before it has read what to run (EOFError, a broken or reset pipe), and the
forkserver printed that as a traceback in the node's log; it is one line now. Anything else still prints
its traceback."""
import signal
import sys

signal.signal(signal.SIGINT, signal.SIG_IGN)


def _parent_gone_in_one_line(exc_type, exc, tb) -> None:
    if issubclass(exc_type, (EOFError, ConnectionError)):
        sys.stderr.write(f"planner worker not started: the node went away while it started ({exc_type.__name__})\n")
        return
    sys.__excepthook__(exc_type, exc, tb)


sys.excepthook = _parent_gone_in_one_line
