"""Worker processes that run an arm's grasp search, so DAGRRT's two arms really run in parallel.

Python threads share one interpreter lock, and the planners are many small numpy calls, so two
arm threads run no faster than one (measured in the benchmark). The DAGRRT paper runs the arms with
OpenMP; here DAGRRT's planning thread searches one arm itself and a long-lived worker process the
other (one process per arm plus the planning thread's set-up, pairing and timing made three busy
processes on two cores: measured, each arm's first cycles took half again as long). A worker loads
the robot once and then takes jobs: it shortcuts every grasp solution and streams it back at once,
and stops when told to (or at its deadline). Processes are started with 'forkserver' — never
forked from a process whose other threads (an rclpy executor) might hold locks.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Callable

import numpy as np

from humanoid_planner.core.planners.arm_messages import ArmMessage, Done, Found, Ready, Reachable, Solution, Stop

# Below the parent: when they compete for a core (e.g. with the node's executor threads), the
# node's answers and the plan's own thread come first; the worker's search is one of two.
WORKER_NICENESS = 5
WORKER_DIED = "the arm worker process died; it is restarted for the next request"
START_TIMEOUT = 60.0  # s for a worker to import and load the robot (a few seconds; far more on a loaded machine)
CHECK_EVERY = 1  # cycles between looks at the control pipe (a poll costs microseconds, a late stop milliseconds)


@dataclass
class ArmJob:
    """Everything one arm's search needs; pickled to the worker."""

    job_id: int
    scene: object  # SceneSnapshot
    group: str
    start: np.ndarray  # full robot configuration
    targets: list  # list[GraspTarget]
    object_id: str
    options: object  # PlannerOptions
    seed: object  # int | list | None
    timeout: float
    inverse: str
    approach: object = None  # GripperTranslation | None: targets are pre-grasps; grasps whose approach fails are dropped
    grasp_targets: list | None = None  # with an approach: the grasp targets behind `targets` (same indices)


WORKER_PRELOAD = ["humanoid_planner.core.pipeline.worker_signals", "__main__",
                  "humanoid_planner.core.pipeline.plan_process"]
"""Modules the forkserver imports once, before it forks any worker: worker_signals first (every worker
then starts with SIGINT ignored), then plan_process (which imports the arm process's module too), so
that a forked worker imports nothing before its main runs. Without them, a Ctrl-C that reached a
worker still importing (about a second), or not yet in its main, printed a KeyboardInterrupt traceback
at the node's shutdown."""


def worker_context():
    """The multiprocessing context of the planner's worker processes (plan workers, DAGRRT's arm
    process): forkserver, with WORKER_PRELOAD. A worker gets its arguments (the robot's source: URDF and
    SRDF, hundreds of kB) by its pipe once started, not as Process args: those are pickled into the
    forkserver's pipe, which its child reads only after importing the main module, so Process.start
    blocked on them for seconds, and a node stopped meanwhile left the child a truncated pickle and a
    traceback in the log (Baxter, shut down while its workers started)."""
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(WORKER_PRELOAD)
    return ctx


def start_worker(target: Callable[[Connection], None], args: tuple, **process_kw):
    """Start target(conn) in a worker process (worker_context) and send it `args` by the pipe; (the process,
    the parent's end of the pipe). The worker reads them with worker_args."""
    ctx = worker_context()
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=target, args=(child,), **process_kw)
    proc.start()
    child.close()
    parent.send(args)
    return proc, parent


def worker_args(conn: Connection) -> tuple | None:
    """A worker's arguments as start_worker sent them; None when the parent went away (or stopped it) before
    they were all sent: the worker then has nothing to do."""
    try:
        return conn.recv()
    except Exception:  # noqa: BLE001 - any way the pipe ends early (EOF, a truncated pickle)
        return None


def _worker_main(conn: Connection) -> None:
    """Worker loop: take the arguments (robot source, options) from the pipe (start_worker), load the robot
    once, then run jobs until told to exit (None) or the parent goes away."""
    import signal

    # Ctrl-C reaches the whole process group; the parent decides when workers stop (no tracebacks here)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.nice(WORKER_NICENESS)
    except OSError:
        pass
    args = worker_args(conn)
    if args is None:
        return
    try:
        _serve(conn, *args)
    except (EOFError, BrokenPipeError, OSError):
        pass  # the parent closed the pipe or exited


class _Inbox:
    """What the parent has told a worker: the newest job not yet started or stopped, whether the
    running job must stop, whether to exit.

    The pool runs one job set at a time, so a new job means the parent has closed the run of every
    earlier one: a job still waiting is stale when a newer one arrives, and a Stop may name the running
    job or the waiting one. Keeping only the newest job bounds what a worker holds and runs however
    fast jobs come: a worker slower than the plans (niced, on a loaded machine) would otherwise queue
    every job it has not reached, each with its scene and targets, and run each one to its deadline."""

    def __init__(self, conn: Connection):
        self._conn = conn
        self.job: ArmJob | None = None  # the next job to run
        self.running: int | None = None  # job id of the job being run
        self.stop_running = False
        self.exit = False
        self.dropped: list[int] = []  # jobs ended unrun (stopped or superseded), to be answered

    def read(self, block: bool = False) -> None:
        """Take every waiting message; with block, wait for one first."""
        if block:
            self._take(self._conn.recv())
        while self._conn.poll():
            self._take(self._conn.recv())

    def _take(self, msg: object) -> None:
        if msg is None:
            self.exit = self.stop_running = True
        elif isinstance(msg, ArmJob):
            if self.job is not None:
                self.dropped.append(self.job.job_id)
            self.job = msg
            self.stop_running = True  # a newer job: the running one's run is closed (its Stop may follow)
        elif isinstance(msg, Stop):
            if msg.job_id == self.running:
                self.stop_running = True
            elif self.job is not None and msg.job_id == self.job.job_id:
                self.dropped.append(self.job.job_id)
                self.job = None
            # else: a stop for a job that has already finished

    def start(self) -> ArmJob:
        job, self.job = self.job, None
        self.running, self.stop_running = job.job_id, False
        return job


def release_free_memory() -> None:
    """Give the C heap's free pages back to the system (glibc only; elsewhere nothing). A job's arrays
    and messages vary in size from job to job, so glibc's heap fills with free chunks below chunks still
    in use, which its automatic trim (top of the heap only) never returns: measured under four planning
    threads, the worker's free heap grew 5.6 → 9.5 MB in two minutes (RSS +2.5 MB/min) while the memory
    in use stayed at 28.9 MB. About 1 ms (36 ms when many pages go back)."""
    if _libc is not None:
        _libc.malloc_trim(0)


def _load_libc():
    import ctypes
    import ctypes.util

    try:
        lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        lib.malloc_trim  # noqa: B018 - only glibc has it
        return lib
    except (OSError, AttributeError):
        return None


_libc = _load_libc()


def _run_job(conn: Connection, problems, inbox: _Inbox, job: ArmJob) -> Done:
    """Search one job's arm, streaming what it finds; its Done (locals go when it returns)."""
    from humanoid_planner.core.pipeline.completion import Completion
    from humanoid_planner.core.planners.common import Termination
    from humanoid_planner.core.planners.dagrrt import shortcut_arm_path, shortcut_rng
    from humanoid_planner.core.planners.grasp_rrt import GraspRRT

    cycles = size = 0
    error = status = None
    try:
        problem = problems.arm(job.scene, job.group, job.start, job.targets, np.random.default_rng(job.seed),
                               job.options, job.object_id)
        accept = None
        if job.approach is not None:
            comp = Completion(problem, job.approach, None, retry_shorter=False, repair_postures=False)
            comp.pre_targets(job.grasp_targets)
            accept = comp.accept
        arm = GraspRRT(problem, inverse=job.inverse, accept=accept,
                       ik=problems.ik_hints(problem.kin, problem.q0, problem.lower, problem.upper, job.seed))
        srng = shortcut_rng(job.seed)
        failed = arm.start(problem.q0)
        if failed is not None:
            error, status = failed.message, failed.status.value
        else:
            deadline = time.perf_counter() + job.timeout
            remaining = list(job.targets)
            told_reachable = False
            while (remaining and not inbox.stop_running and time.perf_counter() < deadline
                   and arm.cycles < job.options.max_cycles):
                slice_term = Termination(deadline - time.perf_counter(), max_cycles=arm.cycles + CHECK_EVERY)
                found = arm.search(slice_term, remaining)
                if arm.ik_reachable and not told_reachable:  # spares the parent its own IK probe
                    conn.send(Reachable(job.job_id, arm.hints, arm.hint_targets))
                    told_reachable = True
                if found is not None:
                    goal, target = found
                    conn.send(Found(job.job_id, target.index))  # the parent can score it meanwhile
                    path = shortcut_arm_path(arm, arm.tree.path_to(goal), srng, deadline - time.perf_counter())
                    conn.send(Solution(job.job_id, path, target.index, arm.cycles, arm.tree.size, arm.found_by_fallback))
                    remaining = [t for t in remaining if t.index != target.index]
                inbox.read()  # a stop, the next job (this one is then over: its stop may not have come yet), exit
            cycles, size = arm.cycles, arm.tree.size
    except Exception as e:  # report, never die: the pool stays usable
        error = f"{type(e).__name__}: {e}"
    return Done(job.job_id, cycles, size, error, status)


def _serve(conn: Connection, source: tuple, options) -> None:
    from humanoid_planner.core.collision import pair_tables
    from humanoid_planner.core.pipeline.problem import ProblemBuilder
    from humanoid_planner.core.model.robot import RobotModel

    robot = RobotModel.from_urdf_srdf(*source)
    problems = ProblemBuilder(robot, options)
    problems.warm_up()  # the collision model, before the first job rather than in it
    conn.send(Ready())
    inbox = _Inbox(conn)


    while True:
        inbox.read(block=inbox.job is None and not inbox.exit)
        for job_id in inbox.dropped:
            conn.send(Done(job_id, 0, 0, None, None))
        inbox.dropped.clear()
        if inbox.exit:
            return
        if inbox.job is None:
            continue
        with pair_tables.BUILDER.planning():  # a table built meanwhile in this process takes a quarter of the time
            done = _run_job(conn, problems, inbox, inbox.start())
        conn.send(done)
        inbox.running = None
        if inbox.job is None and not conn.poll():
            release_free_memory()  # idle: milliseconds a plan does not wait for


class ArmWorkerPool:
    """Persistent arm-search processes for one robot. Thread-safe: one job set (ArmRun) at a time."""

    def __init__(self, robot, options, size: int = 1):
        self._args = (robot.source, options)
        self._size = size
        self._conns: list[Connection] = []
        self._procs: list = []
        self._lock = threading.Lock()
        self._restart_lock = threading.Lock()
        self._restarting: threading.Thread | None = None
        self._next_id = 0
        self._closing = threading.Event()  # set by close(): a start in progress gives up at once

    def _ready(self) -> bool:
        return bool(self._procs) and all(p.is_alive() for p in self._procs)

    def _ensure_started(self) -> None:
        if self._ready():
            return
        self._stop_workers()
        if self._closing.is_set():
            raise RuntimeError("the arm worker pool is closed")
        for _ in range(self._size):
            p, parent = start_worker(_worker_main, self._args, daemon=True)
            self._procs.append(p)
            self._conns.append(parent)
        deadline = time.monotonic() + START_TIMEOUT
        for c in self._conns:
            # in slices, so that close() (node shutdown) does not wait for a worker still loading the robot
            while not c.poll(0.05):
                if self._closing.is_set() or time.monotonic() > deadline:
                    for p in self._procs:
                        p.terminate()
                    self._conns, self._procs = [], []
                    raise RuntimeError("arm worker process did not start" if not self._closing.is_set()
                                       else "the arm worker pool is closed")
            if not isinstance(c.recv(), Ready):
                raise RuntimeError("arm worker process did not start")

    def warm_up(self) -> None:
        """Start the processes now (they take about a second to import and load the robot)."""
        with self._lock:
            self._ensure_started()

    def _restart_in_background(self) -> None:
        """Replace dead workers (and a dead forkserver) on a thread of their own: starting one takes
        a second or two, which must not come out of a plan's deadline (killing the forkserver once
        made a plan overrun its deadline by 1.5 s)."""
        with self._restart_lock:
            if self._restarting is not None and self._restarting.is_alive():
                return

            self._restarting = threading.Thread(target=self._warm_up_quietly, name="arm-process-restart", daemon=True)
            self._restarting.start()

    def _warm_up_quietly(self) -> None:
        try:
            self.warm_up()
        except Exception:  # noqa: BLE001 - the next plan falls back to threads and retries
            pass

    def try_start(self, jobs: list[ArmJob]) -> "ArmRun | None":
        """Send one job per worker now, if the workers are ready and free; the returned run owns the
        pool until it is closed (use `with`). None when they are not: busy with another plan's run,
        starting, or dead (then they are restarted in the background) — the caller plans without
        them instead of waiting, so a plan never waits for an arm process."""
        if not self._lock.acquire(blocking=False):
            return None
        try:
            if not self._ready():
                self._lock.release()
                self._restart_in_background()
                return None
            self._send_jobs(jobs)
        except OSError:  # a worker died since the last run (and is not reaped yet)
            self._lock.release()
            self._restart_in_background()
            return None
        except BaseException:
            self._lock.release()
            raise
        return ArmRun(self, jobs)

    def start(self, jobs: list[ArmJob]) -> "ArmRun":
        """Like try_start, but waits for the pool and (re)starts dead workers first (tests, tools)."""
        self._lock.acquire()
        try:
            for attempt in (1, 2):
                self._ensure_started()
                try:
                    self._send_jobs(jobs)
                    break
                except OSError:  # a worker died since the last run (and is not reaped yet): start afresh
                    if attempt == 2:
                        raise
                    self._stop_workers()
        except BaseException:
            self._lock.release()
            raise
        return ArmRun(self, jobs)

    def _send_jobs(self, jobs: list[ArmJob]) -> None:
        """Give each worker its job (lock held), after reading what an earlier run left unread: a stopped
        search may still have sent its last solutions, and a worker blocked sending them to a full pipe
        would never read a big job (a scene) sent to it, both sides waiting for ever. OSError: a worker died."""
        for c in self._conns:
            try:
                while c.poll():
                    c.recv()
            except EOFError as e:
                raise OSError("an arm worker process died") from e
        for k, job in enumerate(jobs):
            job.job_id = self._next_id = self._next_id + 1
            self._conns[k].send(job)

    def close(self) -> None:
        """Stop the workers for good; a start in progress (another thread) terminates its own."""
        self._closing.set()
        if self._lock.acquire(timeout=0.2):  # not while a start or a run holds the workers
            try:
                self._stop_workers()
            finally:
                self._lock.release()

    def _stop_workers(self) -> None:
        for c in self._conns:
            try:
                c.send(None)
            except (BrokenPipeError, OSError):
                pass
        for p in self._procs:
            p.join(timeout=1.0)
            if p.is_alive():
                p.terminate()
        self._conns, self._procs = [], []


class ArmRun:
    """One job set in flight on an ArmWorkerPool: yields its messages, skips earlier jobs' late ones.

    Closing stops the workers still at it and frees the pool at once: a stopped worker may still
    finish its current cycle, and the next run skips what it sends then (job ids), so an answer
    never waits for a worker to stop.
    """

    def __init__(self, pool: ArmWorkerPool, jobs: list[ArmJob]):
        self._pool, self._ids = pool, [j.job_id for j in jobs]
        self._conns = pool._conns[:len(jobs)]
        self.done: dict[int, tuple] = {}  # job k -> (cycles, tree size, error) from its "done"
        self.latest = {k: (0, 0, None) for k in range(len(jobs))}  # as of its last solution
        self._closed = False

    @property
    def finished(self) -> bool:
        return len(self.done) == len(self._ids)

    def events(self, timeout: float) -> list[tuple[int, ArmMessage]]:
        """(job k, message) of every message that arrives within timeout (0: only those waiting):
        Found, Solution, Reachable and Done (the last one of a job; a process that died gives a Done
        with error WORKER_DIED)."""
        live = [c for k, c in enumerate(self._conns) if k not in self.done]
        out: list[tuple[int, ArmMessage]] = []
        for c in (wait(live, timeout=max(0.0, timeout)) if live else ()):
            k = self._conns.index(c)
            while c.poll():
                try:
                    msg = c.recv()
                except (EOFError, OSError):  # the process died (killed, out of memory): fail this job only
                    msg = Done(self._ids[k], 0, 0, WORKER_DIED, None)
                if msg.job_id != self._ids[k]:
                    continue  # a late message of an earlier job
                if isinstance(msg, Solution):
                    self.latest[k] = (msg.cycles, msg.tree_size, None)
                out.append((k, msg))
                if isinstance(msg, Done):
                    self.done[k] = (msg.cycles, msg.tree_size, msg.error)
                    break
        return out

    def stats(self) -> list[tuple[int, int, str | None]]:
        """Per job (cycles, tree size, error): final if it finished, else as last reported."""
        return [self.done.get(k, self.latest[k]) for k in range(len(self._ids))]

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            for k, c in enumerate(self._conns):
                if k not in self.done:
                    try:
                        c.send(Stop(self._ids[k]))
                    except OSError:
                        pass  # it died; the pool starts a new one for the next run
        finally:
            self._pool._lock.release()

    def __enter__(self) -> "ArmRun":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
