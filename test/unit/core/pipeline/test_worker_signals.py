"""worker_signals: the planner's worker processes start with SIGINT ignored."""
from __future__ import annotations


def test_worker_processes_start_with_sigint_ignored():
    """A Ctrl-C to the node's process group must not reach a worker even before its main sets its own
    handler: the forkserver's children start with SIGINT ignored (arm_process.WORKER_PRELOAD), while
    this process keeps Python's default handler."""
    import signal

    from humanoid_planner.core.pipeline.arm_process import worker_context

    assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
    with worker_context().Pool(1) as pool:
        assert pool.apply(signal.getsignal, (signal.SIGINT,)) == signal.SIG_IGN
    assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN
