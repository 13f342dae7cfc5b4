"""Plans in worker processes, so that plans per second grow with the cores.

Python threads share one interpreter lock and a plan is many small numpy calls: planning threads in
one process never use more than one core (1, 2, 4, 8 clients planning back to back: 30, 27, 26, 26
plans/s on two cores), and every plan slows the node's executor down. `PlanRunner` runs each plan
either in the calling thread or — with a `PlanWorkerPool` — in one of `size` persistent worker
processes (started with 'forkserver', as DAGRRT's arm process: never forked from a process whose
other threads might hold locks). The same call either way: `PlanRunner.run(kind, scene, request,
cancel, progress)`.

What travels with a job: the request in core terms, the planner options, and the scene as a delta
against the copy the worker already holds (scene/sync.py: objects added, changed or removed, attached
objects, the point-cloud layer; each Shape once per worker, so a mesh's collision geometry is built
once in each worker). Back come the progress figures (every PROGRESS_PERIOD while they change: the
actions' feedback) and the GraspPlan, pickled. A cancel is forwarded at once; a worker that does not
stop within STOP_GRACE of it is killed. A worker that dies mid-plan answers INTERNAL_ERROR (FAILURE)
saying so and is restarted in the background; a plan that finds no worker ready (starting,
restarting) runs in the calling thread instead of waiting, so a plan never waits for a process start
(where this process's collision model is not built yet, it waits for that or a worker, whichever comes
first, within its deadline: PlanRunner._while_cold).
"""
from __future__ import annotations

import atexit
import itertools
import multiprocessing.connection as mp_connection
import os
import queue
import threading
import time
import weakref
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from typing import Callable

from humanoid_planner.core.collision.geometry import RobotCollisionModel, prepare_scene_meshes
from humanoid_planner.core.pipeline.arm_process import start_worker, worker_args
from humanoid_planner.core.pipeline.planner import GraspPlan, GraspPlanner
from humanoid_planner.core.pipeline.problem import ProblemBuilder
from humanoid_planner.core.planners.common import PlannerOptions, PlanStatus, Progress
from humanoid_planner.core.scene.sync import SceneDelta, SceneFeed, SceneReplica
from humanoid_planner.core.scene.types import SceneSnapshot

PLAN_KINDS = ("plan_grasp", "plan_dual_grasp", "plan_to_state", "plan_place", "plan_dual_place")
SCENE_QUERY = "scene"  # a job that only syncs the scene and answers with the worker's copy (tests, checks)
SCENE_SYNC = "sync"  # a job that only syncs the scene and builds the new meshes' collision geometry
PROGRESS_PERIOD = 0.1  # s: a worker sends its plan's progress this often while it changes (the feedback rate)
POLL_PERIOD = 0.01  # s: the waiting thread looks at its plan's cancel event this often
STOP_GRACE = 30.0  # s a worker may take to stop after a cancel before it is taken for hung, killed and restarted:
# a plan stops within a cycle, but a new big mesh's geometry (10^6 triangles: 10-20 s) is built whole first,
# and a worker killed for it would have to build it again
OVERDUE_AFTER = 10.0
"""s past its request's timeout (a scene job: past START_TIMEOUT) after which a search that has not answered
is cancelled, and STOP_GRACE later killed: a worker stuck by a fault answers INTERNAL_ERROR and is restarted,
instead of holding its planning thread (and the client) for ever."""
COLD_POLL = 0.05  # s: a plan waiting for the workers to start or the collision model to be built looks this often
START_TIMEOUT = 60.0  # s for a worker to import and load the robot (seconds; far more on a loaded machine)
RETRY_AFTER = 5.0  # s before a worker that failed to start is tried again
WATCH_PERIOD = 0.5  # s: the pool looks for workers to restart at least this often
RACE_AFTER = 0.1
"""s: a plan without a seed still searching this long gets a second search of the same request in an idle
worker (its own random stream); the first plan found is the answer and the other search is stopped. A
sampling search's time to a plan varies widely between seeds on hard problems (a cage, a narrow shelf): the
sooner of two is often several times sooner than one, and a plan solved within RACE_AFTER costs no second
process. A helper gives way at once to another client's plan that finds no idle worker (_take)."""
RACE_KINDS = ("plan_grasp", "plan_to_state", "plan_place")  # one arm: DAGRRT's kinds use an arm process already
RACE_MIN_LEFT = 0.05  # s: a helper is started only with at least this much of the request's timeout left
GIVE_WAY_WAIT = 0.5  # s a plan that finds no idle worker waits for a helper to give way (it stops within a cycle)
DECIDED_ANYWAY = (PlanStatus.SUCCESS, PlanStatus.START_IN_COLLISION, PlanStatus.NO_IK_SOLUTION,
                  PlanStatus.GRASP_QUALITY_TOO_LOW, PlanStatus.INVALID_REQUEST, PlanStatus.INVALID_GROUP,
                  PlanStatus.INVALID_START, PlanStatus.INVALID_GOAL, PlanStatus.INVALID_OBJECT, PlanStatus.INVALID_FRAME)
"""Outcomes that another random stream would not change (or a plan): the first of a race to come back with
one is the answer. The others (timed out, search failed, worker died) wait for the other search."""


def run_plan(planner: GraspPlanner, kind: str, scene: SceneSnapshot, request, cancel: threading.Event | None,
             progress: Progress | None) -> GraspPlan:
    """One plan of `kind` (a PLAN_KINDS name) on `planner`, wherever it runs."""
    from humanoid_planner.core.pipeline.place import plan_place

    if kind == "plan_dual_grasp":
        return planner.plan_dual_grasp(scene, request, cancel, progress)
    if kind == "plan_to_state":
        return planner.plan_to_state(scene, request, cancel, progress)
    if kind in ("plan_place", "plan_dual_place"):
        return plan_place(planner, scene, request, cancel, progress)
    if kind == "plan_grasp":
        return planner.plan_grasp(scene, request, cancel, progress)
    raise ValueError(f"unknown plan kind {kind!r} (one of {PLAN_KINDS})")


# ------------------------------------------------------------------------------------------ messages
@dataclass(frozen=True)
class PlanJob:
    job_id: int
    kind: str  # a PLAN_KINDS name, or SCENE_QUERY
    request: object  # GraspPlanRequest, DualGraspPlanRequest, StatePlanRequest or PlaceRequest
    options: PlannerOptions
    parallel: str  # GraspPlanner's parallel: how DAGRRT runs its second arm
    scene: SceneDelta


@dataclass(frozen=True)
class CancelJob:
    job_id: int


@dataclass(frozen=True)
class JobProgress:
    job_id: int
    state: tuple  # Progress.state()


@dataclass(frozen=True)
class JobDone:
    job_id: int
    result: object = None  # GraspPlan (SceneSnapshot for SCENE_QUERY)
    error: str | None = None  # the job raised this (type: message)
    scene_lost: bool = False  # the delta could not be applied: the worker's copy is empty again


@dataclass(frozen=True)
class WorkerReady:
    pid: int


class PlanWorkerError(RuntimeError):
    """A plan raised in its worker process (the worker itself lives on)."""


# ------------------------------------------------------------------------------------------ worker side
def _worker_main(conn) -> None:
    """A planning worker: take its arguments (robot source, planner options, parallel) from the pipe, load the
    robot once, then plan jobs until the node says stop or goes away.

    At the node's own priority: a plan in a worker must not get less CPU than one in a planning thread
    (the node's executor mostly sleeps and is woken first anyway)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group; the node stops its workers
    args = worker_args(conn)
    if args is None:
        return
    try:
        _PlanWorker(conn, *args).serve()
    except (EOFError, BrokenPipeError, OSError):
        pass  # the node closed the pipe or exited


class _PlanWorker:
    """The worker's two threads: the main one plans; a reader takes jobs and cancels off the pipe at
    any time and sends the running plan's progress."""

    def __init__(self, conn, source: tuple, options: PlannerOptions, parallel: str):
        from humanoid_planner.core.model.robot import RobotModel

        self.conn = conn
        self.robot = RobotModel.from_urdf_srdf(*source)
        self.replica = SceneReplica()
        self.jobs: queue.Queue = queue.Queue()
        self._send_lock = threading.Lock()
        self._lock = threading.Lock()
        self._current: tuple[int, threading.Event, Progress] | None = None
        self._cancelled: set[int] = set()  # cancels that came before their job started
        self._planner: GraspPlanner | None = None
        self._planner_for(options, parallel).problems.warm_up()  # the collision model, before the first job

    def send(self, msg) -> None:
        with self._send_lock:
            self.conn.send(msg)

    def serve(self) -> None:
        self.send(WorkerReady(os.getpid()))
        threading.Thread(target=self._read, name="plan-worker-reader", daemon=True).start()
        try:
            while (job := self.jobs.get()) is not None:
                self._run(job)
        finally:
            if self._planner is not None:
                self._planner.close()  # its DAGRRT arm process, if it started one

    def _planner_for(self, options: PlannerOptions, parallel: str) -> GraspPlanner:
        p = self._planner
        if p is None or p.options != options or p.parallel != parallel:
            if p is not None:
                p.close()
            self._planner = p = GraspPlanner(self.robot, options, parallel=parallel)
        return p

    def _read(self) -> None:
        sent = None
        try:
            while True:
                if not self.conn.poll(PROGRESS_PERIOD):
                    sent = self._report(sent)
                    continue
                msg = self.conn.recv()
                if msg is None:
                    break
                if isinstance(msg, CancelJob):
                    with self._lock:
                        if self._current is not None and self._current[0] == msg.job_id:
                            self._current[1].set()
                        else:
                            self._cancelled.add(msg.job_id)
                else:
                    self.jobs.put(msg)
        except Exception:  # noqa: BLE001 - the node went away (EOF), or a message that does not unpickle: the
            pass  # pipe is out of step; stop the plan running, then exit (the node restarts the worker)
        with self._lock:
            if self._current is not None:
                self._current[1].set()
        self.jobs.put(None)

    def _report(self, sent: tuple | None) -> tuple | None:
        with self._lock:
            current = self._current
        if current is None:
            return None
        state = current[2].state()
        if state != sent:
            self.send(JobProgress(current[0], state))
        return state

    def _run(self, job: PlanJob) -> None:
        cancel, progress = threading.Event(), Progress()
        with self._lock:
            self._current = (job.job_id, cancel, progress)
            if job.job_id in self._cancelled:
                cancel.set()
            self._cancelled = {k for k in self._cancelled if k > job.job_id}
        try:
            try:
                scene = self.replica.apply(job.scene)
                # new meshes' geometry whole, now: a cancelled plan must not leave it to the next one;
                # the new objects' bounding balls too (what a checker culls the scene with)
                prepare_scene_meshes(tuple(job.scene.shapes.values()))
                scene.object_spheres
            except Exception as e:  # noqa: BLE001 - out of step with the node: start afresh next time
                self.replica.clear()
                out = JobDone(job.job_id, error=f"the worker's scene copy could not be updated: {e!r}", scene_lost=True)
            else:
                try:
                    if job.kind == SCENE_SYNC:
                        result = None
                    elif job.kind == SCENE_QUERY:
                        result = scene
                    else:
                        planner = self._planner_for(job.options, job.parallel)
                        result = run_plan(planner, job.kind, scene, job.request, cancel, progress)
                    out = JobDone(job.job_id, result)
                except Exception as e:  # noqa: BLE001 - reported as the plan's failure; the worker lives on
                    out = JobDone(job.job_id, error=f"{type(e).__name__}: {e}")
        finally:
            with self._lock:
                self._current = None
        self.send(out)


# ------------------------------------------------------------------------------------------ node side
class _Slot:
    """One worker process and what the node knows of it."""

    def __init__(self, index: int):
        self.index = index
        self.state = "down"  # down -> starting -> ready <-> busy; down again when it dies
        self.proc = None
        self.conn = None
        self.feed = SceneFeed()
        self.retry_at = 0.0
        self.syncing = False  # busy with a background scene sync, not a plan
        self.helper = False  # running a race's second search: gives way to a plan that finds no idle worker
        self.preempt = False  # asked to give way (the race's waiting thread sends the cancel)
        self.draining = False  # a race's stopped search, whose answer is still to come


_POOLS: "weakref.WeakSet[PlanWorkerPool]" = weakref.WeakSet()


@atexit.register
def _close_pools() -> None:
    """Workers are not daemons (a worker starts DAGRRT's arm process of its own), so multiprocessing
    would wait for them at exit: stop them first (atexit runs this before multiprocessing's own)."""
    for pool in list(_POOLS):
        pool.close()


class PlanWorkerPool:
    """`size` persistent planning processes for one robot. Thread-safe: each call of `run` takes a free
    ready worker for its plan (give it at most `size` callers at once, e.g. the planning threads)."""

    def __init__(self, robot, size: int, options: PlannerOptions | None = None, parallel: str = "process",
                 scene: Callable[[], SceneSnapshot] | None = None):
        """scene: the node's current scene; idle workers are brought up to it in the background (at most
        every WATCH_PERIOD), so that a plan hands over only what changed since, and a new mesh's
        collision geometry is built while the worker waits, not in a plan's time."""
        if size < 1:
            raise ValueError("a worker pool needs at least one worker")
        self._args = (robot.source, options or PlannerOptions(), parallel)
        self._slots = [_Slot(k) for k in range(size)]
        self._scene = scene
        self._lock = threading.Condition()  # slot states; notified when a slot becomes free
        self._starter: threading.Thread | None = None
        self._watcher: threading.Thread | None = None
        self._closing = threading.Event()
        self._ids = itertools.count(1)
        self.restarts = 0  # workers started again after one died
        _POOLS.add(self)

    @property
    def size(self) -> int:
        return len(self._slots)

    def pids(self) -> list[int | None]:
        """Each worker's process id (None: not running)."""
        with self._lock:
            return [s.proc.pid if s.proc is not None and s.state != "down" else None for s in self._slots]

    @property
    def ready(self) -> int:
        """Workers started and alive (free or busy)."""
        with self._lock:
            return sum(s.state in ("ready", "busy") for s in self._slots)

    def start_in_background(self) -> None:
        """Start the workers that are not running, on a thread of its own (a second or two each)."""
        with self._lock:
            if self._closing.is_set() or (self._starter is not None and self._starter.is_alive()):
                return
            now = time.monotonic()
            down = [s for s in self._slots if s.state == "down" and now >= s.retry_at]
            if not down:
                return
            for s in down:
                s.state = "starting"
            self._starter = threading.Thread(target=self._start, args=(down,), name="plan-workers-start", daemon=True)
            self._starter.start()
            if self._watcher is None:
                self._watcher = threading.Thread(target=self._watch, name="plan-workers-watch", daemon=True)
                self._watcher.start()

    def _watch(self) -> None:
        """Restart a worker as soon as it dies while idle (one that dies mid-plan is restarted by the
        thread waiting for its answer), and retry the start of one that failed to start."""
        while not self._closing.is_set():
            with self._lock:
                sentinels = [s.proc.sentinel for s in self._slots if s.state == "ready" and s.proc is not None]
            try:
                if sentinels:
                    mp_connection.wait(sentinels, timeout=WATCH_PERIOD)
                else:
                    self._closing.wait(WATCH_PERIOD)
                if not self._closing.is_set():
                    self._reap()
                    self._sync_idle()
            except Exception:  # noqa: BLE001 - e.g. a worker stopped meanwhile (its sentinel closed): look again
                self._closing.wait(0.05)

    def _sync_idle(self) -> None:
        """Bring each idle worker's scene up to the node's, one at a time (a plan that wants the worker
        meanwhile waits for the sync: it would hand the same changes over itself)."""
        if self._scene is None:
            return
        snap = self._scene()
        for s in self._slots:
            with self._lock:
                if s.state != "ready" or s.feed.holds(snap):
                    continue
                s.state, s.syncing = "busy", True
            try:  # the slot is released once the worker has answered (or died)
                self._hand_over(s, SCENE_SYNC, snap, None, self._args[1], self._args[2], None, None)
            except PlanWorkerError:
                pass  # its copy is reset; the next plan sends the whole scene

    def wait_ready(self, timeout: float) -> bool:
        """Start the workers (if not yet) and wait until all are ready (tests, tools); False at timeout."""
        deadline = time.monotonic() + timeout
        while self.ready < self.size:
            self.start_in_background()
            if time.monotonic() > deadline or self._closing.is_set():
                return False
            time.sleep(0.02)
        return True

    def _start(self, slots: list[_Slot]) -> None:
        """Start `slots`, then any that went down meanwhile, until none is left to start."""
        while slots:
            self._start_batch(slots)
            with self._lock:
                now = time.monotonic()
                slots = [s for s in self._slots if s.state == "down" and now >= s.retry_at
                         and not self._closing.is_set()]
                for s in slots:
                    s.state = "starting"

    def _start_batch(self, slots: list[_Slot]) -> None:
        started = []
        for s in slots:
            if self._closing.is_set():
                self._give_up(s)
                continue
            try:
                proc, parent = start_worker(_worker_main, self._args, name=f"plan-worker-{s.index}", daemon=False)
                s.proc, s.conn = proc, parent
                started.append((s, parent, proc))
            except Exception:  # noqa: BLE001 - plans run in their threads meanwhile; tried again later
                self._give_up(s)
        deadline = time.monotonic() + START_TIMEOUT
        for s, conn, proc in started:  # its own references: close() may stop the slot (s.conn = None) meanwhile
            ok = False
            try:
                while not conn.poll(0.05):  # in slices: close() never waits for a worker loading the robot
                    if self._closing.is_set() or time.monotonic() > deadline or not proc.is_alive():
                        break
                else:
                    ok = isinstance(conn.recv(), WorkerReady)
            except (EOFError, OSError, ValueError):  # ValueError: the connection was closed by close()
                ok = False
            with self._lock:
                mine = s.conn is conn  # else close() stopped it already
                if ok and mine and not self._closing.is_set():
                    s.feed.reset()
                    s.state = "ready"
                    continue
            if mine:
                self._give_up(s)

    def _give_up(self, s: _Slot) -> None:
        self._stop(s, 0.0)
        s.retry_at = time.monotonic() + RETRY_AFTER

    def _stop(self, s: _Slot, wait: float) -> None:
        """Stop a worker (asked, then terminated) and mark it down."""
        proc, conn = s.proc, s.conn
        with self._lock:
            s.state, s.proc, s.conn = "down", None, None
            s.feed.reset()
        if conn is not None:
            try:  # without blocking: a hung worker that reads nothing may have let its pipe fill
                os.set_blocking(conn.fileno(), False)
                conn.send(None)
            except (OSError, ValueError):
                pass
        if proc is not None:
            proc.join(timeout=wait)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=1.0)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=1.0)
        if conn is not None:
            conn.close()

    def _reap(self) -> None:
        """Idle workers that died (killed, out of memory) are marked down and restarted."""
        with self._lock:
            dead = [s for s in self._slots if s.state == "ready" and not s.proc.is_alive()]
        for s in dead:
            self._stop(s, 0.0)
            self.restarts += 1
        now = time.monotonic()
        if dead or any(s.state == "down" and now >= s.retry_at for s in self._slots):
            self.start_in_background()

    def _take(self, scene: SceneSnapshot) -> _Slot | None:
        """A ready worker, now marked busy — one that holds `scene` already if there is one; None when
        none is ready (then the missing ones are started). A worker busy with a background scene sync
        is waited for."""
        self._reap()
        give_way_until = time.monotonic() + GIVE_WAY_WAIT
        with self._lock:
            while not self._closing.is_set():
                ready = [s for s in self._slots if s.state == "ready"]
                if ready:
                    s = next((s for s in ready if s.feed.holds(scene)), ready[0])
                    s.state = "busy"
                    return s
                helpers = [s for s in self._slots if s.helper]
                for s in helpers:
                    s.preempt = True
                if not any(s.syncing for s in self._slots) and not (
                        (helpers or any(s.draining for s in self._slots)) and time.monotonic() < give_way_until):
                    return None
                self._lock.wait(0.01)
        return None

    def _take_spare(self, scene: SceneSnapshot) -> _Slot | None:
        """A ready worker for a race's helper, now marked busy, without waiting; None when none is idle."""
        with self._lock:
            ready = [s for s in self._slots if s.state == "ready"]
            if not ready:
                return None
            s = next((s for s in ready if s.feed.holds(scene)), ready[0])
            s.state, s.helper, s.preempt = "busy", True, False
            return s

    def _release(self, s: _Slot) -> None:
        with self._lock:
            s.syncing = s.helper = s.preempt = s.draining = False
            if s.state == "busy":
                s.state = "ready"
            self._lock.notify_all()

    def run(self, kind: str, scene: SceneSnapshot, request, options: PlannerOptions, parallel: str,
            cancel: threading.Event | None = None, progress: Progress | None = None) -> GraspPlan | SceneSnapshot | None:
        """Plan in a free worker: the GraspPlan (for SCENE_QUERY the worker's scene), or None when no
        worker was ready or the job could not be handed over (the caller plans without a worker). A plan
        of RACE_KINDS without a seed races a second search after RACE_AFTER when a worker is idle."""
        slot = self._take(scene)
        if slot is None:
            return None
        race = (self.size > 1 and kind in RACE_KINDS and getattr(request, "seed", 0) is None
                and getattr(request, "timeout", 0.0) > RACE_AFTER + RACE_MIN_LEFT)
        return self._hand_over(slot, kind, scene, request, options, parallel, cancel, progress, race)

    def _send(self, slot: _Slot, kind: str, scene: SceneSnapshot, request, options: PlannerOptions,
              parallel: str) -> int | None:
        """Hand a job to a worker taken for it: its id, or None when the worker turned out dead (stopped,
        restarted in the background, the slot released)."""
        job_id = next(self._ids)
        try:
            slot.conn.send(PlanJob(job_id, kind, request, options, parallel, slot.feed.delta(scene)))
        except (OSError, ValueError):  # the worker died since it was last seen alive: nothing started
            self._stop(slot, 0.0)
            self._release(slot)
            self.restarts += 1
            self.start_in_background()
            return None
        except BaseException:  # e.g. a request that does not pickle: the worker never got the delta
            slot.feed.reset()
            self._release(slot)
            raise
        return job_id

    def _hand_over(self, slot: _Slot, kind: str, scene: SceneSnapshot, request, options: PlannerOptions,
                   parallel: str, cancel: threading.Event | None, progress: Progress | None, race: bool = False):
        """Send the job to `slot` (taken for it) and wait for its answer (_Race); every slot taken is
        released once its worker has answered."""
        job_id = self._send(slot, kind, scene, request, options, parallel)
        if job_id is None:
            return None
        helper = (lambda: self._take_spare(scene)) if race else None
        return _Race(self, _Job(kind, scene, request, options, parallel), cancel, progress, helper).wait(slot, job_id)

    def _died(self, slot: _Slot, scene: SceneSnapshot, why: str | None) -> GraspPlan:
        proc = slot.proc
        if why is None and proc is not None:
            proc.join(timeout=1.0)
            code = proc.exitcode
            why = ("it was killed by signal " + str(-code) if code is not None and code < 0
                   else f"exit code {code}" if code is not None else "its pipe closed")
        self._stop(slot, 0.0)
        self.restarts += 1
        self._reap()  # whatever killed it may have killed the others too
        return GraspPlan(PlanStatus.INTERNAL_ERROR, f"the planning worker process died during the plan ({why}); "
                         "it is restarted for the next request", scene_version=scene.version)

    def close(self) -> None:
        """Stop every worker for good; a start in progress gives up."""
        self._closing.set()
        for s in self._slots:
            if s.state != "down" or s.proc is not None:
                self._stop(s, 1.0)


@dataclass(frozen=True)
class _Job:
    """What a race hands to each of its workers."""

    kind: str
    scene: SceneSnapshot
    request: object
    options: PlannerOptions
    parallel: str


@dataclass
class _Search:
    """One of a race's searches: its worker, the job there, when it started and when its cancel was sent."""

    slot: _Slot
    conn: object  # the worker's connection when the job was sent (close() may clear slot.conn meanwhile)
    job_id: int
    started: float  # monotonic
    due: float  # monotonic: cancelled if it has not answered by then (OVERDUE_AFTER)
    told: float | None = None  # when the cancel was sent


class _Race:
    """Waiting for a job's answer in its worker, and (helper given) for a second search of the same
    request started after RACE_AFTER in an idle worker: the first plan found, or the first outcome in
    DECIDED_ANYWAY, is the answer; the other search is cancelled and its worker released once it has
    answered, on a thread of its own. Progress comes from the first search still running. A client's
    cancel goes to both; a helper asked to give way (_take) is cancelled and the first search goes on."""

    def __init__(self, pool: PlanWorkerPool, job: _Job, cancel: threading.Event | None, progress: Progress | None,
                 helper: Callable[[], _Slot | None] | None):
        self.pool, self.job = pool, job
        self.cancel, self.progress, self.helper = cancel, progress, helper
        self.t0 = time.monotonic()
        self.first: _Slot | None = None  # the caller's worker (the others are helpers)
        self.members: list[_Search] = []
        self.failed: list[tuple[GraspPlan | object, str | None]] = []  # (result, error) of searches that ended without an answer

    def wait(self, slot: _Slot, job_id: int):
        self.first = slot
        self.members.append(_Search(slot, slot.conn, job_id, self.t0, self._due(self.t0, self.job.request)))
        helper_at = self.t0 + RACE_AFTER if self.helper is not None else float("inf")
        try:
            while self.members:
                now = time.monotonic()
                if now >= helper_at:
                    helper_at = float("inf")
                    self._start_helper(now)
                answer = self._poll()
                if answer is not None:
                    return answer
                self._stop_if_asked()
            # every search ended without an answer in DECIDED_ANYWAY: the first one's outcome
            result, error = self.failed[0]
            if error is not None:
                raise PlanWorkerError(error)
            return result
        finally:
            for m in self.members:  # the others: stopped, and released once they have answered
                self._drain(m)

    def _start_helper(self, now: float) -> None:
        left = self.job.request.timeout - (now - self.t0)
        if left < RACE_MIN_LEFT or (self.cancel is not None and self.cancel.is_set()):
            return
        slot = self.helper()
        if slot is None:
            return
        job = self.job
        request = replace(job.request, timeout=left)
        job_id = self.pool._send(slot, job.kind, job.scene, request, job.options, job.parallel)
        if job_id is not None:
            self.members.append(_Search(slot, slot.conn, job_id, now, self._due(now, request)))

    @staticmethod
    def _due(started: float, request) -> float:
        """When a search started at `started` is overdue (OVERDUE_AFTER)."""
        timeout = getattr(request, "timeout", None)
        allowed = float(timeout) if isinstance(timeout, (int, float)) and timeout == timeout else START_TIMEOUT
        return started + min(allowed, 1e9) + OVERDUE_AFTER

    def _poll(self):
        """Take what the workers sent; the answer when one came."""
        conns = [m.conn for m in self.members]
        try:
            ready = mp_connection.wait(conns, POLL_PERIOD)
        except (OSError, ValueError):
            ready = conns  # a pipe closed under us (close()): its recv below says which
        for m in list(self.members):
            slot, conn, job_id = m.slot, m.conn, m.job_id
            if conn not in ready:
                continue
            try:
                msg = conn.recv()
            except (EOFError, OSError, ValueError):
                self._ended(m, self.pool._died(slot, self.job.scene, None), None)
                continue
            if getattr(msg, "job_id", None) != job_id:
                continue
            if isinstance(msg, JobProgress):
                if self.progress is not None and m is self.members[0]:
                    self.progress.load(msg.state)
            elif isinstance(msg, JobDone):
                if msg.scene_lost:
                    slot.feed.reset()
                result = msg.result
                if msg.error is None and isinstance(result, GraspPlan) and m.started > self.t0:
                    result = replace(result, planning_time=result.planning_time + (m.started - self.t0))  # from the request
                if msg.error is None and (not isinstance(result, GraspPlan) or result.status in DECIDED_ANYWAY
                                          or (result.status is PlanStatus.CANCELLED and self._cancelled())):
                    self.members.remove(m)
                    self.pool._release(slot)
                    return result
                self._ended(m, result, msg.error)
        return None

    def _cancelled(self) -> bool:
        return self.cancel is not None and self.cancel.is_set()

    def _ended(self, m: _Search, result, error: str | None) -> None:
        """A search ended without the answer (or its worker died): noted; its worker released."""
        self.members.remove(m)
        self.pool._release(m.slot)
        gave_way = (m.slot is not self.first and isinstance(result, GraspPlan) and result.status is PlanStatus.CANCELLED
                    and not self._cancelled())
        if not gave_way:  # the first search's outcome first: the one answered when none found a plan
            self.failed.insert(0 if m.slot is self.first else len(self.failed), (result, error))

    def _stop_if_asked(self) -> None:
        """The client's cancel to every search, a give-way request to its helper, a cancel to an overdue one;
        a worker that does not stop within STOP_GRACE is taken for hung."""
        now = time.monotonic()
        for m in list(self.members):
            if m.told is None and (self._cancelled() or m.slot.preempt or now > m.due):
                try:
                    m.conn.send(CancelJob(m.job_id))
                except (OSError, ValueError):
                    pass  # dead: its recv says so
                m.told = now
            elif m.told is not None and now - m.told > STOP_GRACE:
                self._ended(m, self.pool._died(m.slot, self.job.scene, f"it did not stop within {STOP_GRACE:g} s of the "
                                                                 "cancel and was killed"), None)

    def _drain(self, m: _Search) -> None:
        """Cancel a search whose answer is no longer wanted; its worker is released once it has answered."""
        with self.pool._lock:
            m.slot.draining = True
        if m.told is None:
            try:
                m.conn.send(CancelJob(m.job_id))
            except (OSError, ValueError):
                pass
        threading.Thread(target=self._drained, args=(m.slot, m.conn, m.job_id), name="plan-race-drain",
                         daemon=True).start()

    def _drained(self, slot: _Slot, conn, job_id: int) -> None:
        """Wait (on a thread of its own) for a cancelled search's answer, then free its worker; one that does not
        answer within STOP_GRACE is taken for hung."""
        deadline = time.monotonic() + STOP_GRACE
        try:
            while time.monotonic() < deadline:
                if conn.poll(POLL_PERIOD):
                    msg = conn.recv()
                    if isinstance(msg, JobDone) and msg.job_id == job_id:
                        if msg.scene_lost:
                            slot.feed.reset()
                        self.pool._release(slot)
                        return
            self.pool._died(slot, self.job.scene, "a stopped search did not stop")
        except (EOFError, OSError, ValueError):
            if slot.conn is conn:  # not stopped by close() meanwhile
                self.pool._died(slot, self.job.scene, None)
        self.pool._release(slot)


class PlanRunner:
    """Runs one plan, the same call whether in the calling thread or in a worker process.

    use_planner: a context manager giving the planner of the moment (its options, and the planner
    itself when the plan runs in the calling thread); pool: the worker processes, None to plan in
    the calling thread always."""

    def __init__(self, use_planner: Callable[[], AbstractContextManager[GraspPlanner]],
                 pool: PlanWorkerPool | None = None):
        self._use_planner = use_planner
        self.pool = pool
        self._warming: threading.Thread | None = None  # this process's collision model, built for a plan

    @property
    def processes(self) -> bool:
        return self.pool is not None

    def run(self, kind: str, scene: SceneSnapshot, request, cancel: threading.Event | None = None,
            progress: Progress | None = None) -> GraspPlan:
        if self.pool is not None:
            with self._use_planner() as planner:
                options, parallel, problems = planner.options, planner.parallel, planner.problems
            plan = self.pool.run(kind, scene, request, options, parallel, cancel, progress)
            if plan is not None:
                return plan
            if not RobotCollisionModel.is_built(problems.robot):
                plan, request = self._while_cold(problems, kind, scene, request, options, parallel, cancel, progress)
                if plan is not None:
                    return plan
        with self._use_planner() as planner:
            return run_plan(planner, kind, scene, request, cancel, progress)

    def _while_cold(self, problems: ProblemBuilder, kind: str, scene: SceneSnapshot, request, options: PlannerOptions, parallel: str,
                    cancel: threading.Event | None, progress: Progress | None) -> tuple[GraspPlan | None, object]:
        """No worker ready and this process's collision model not built: the workers are starting (seconds
        on a mesh robot), and a plan here would build the model first, past its deadline (TALOS: 4.6 s
        for a 3 s timeout). Build it in the background and take whichever comes first, a ready worker or
        the model; at the deadline, TIMED_OUT (never later). Returns (a plan, or None to plan here with)
        the request, its timeout less the wait."""
        if self._warming is None or not self._warming.is_alive():
            self._warming = threading.Thread(target=problems.warm_up, name="planner-model", daemon=True)
            self._warming.start()
        t0 = time.monotonic()
        while not RobotCollisionModel.is_built(problems.robot):
            left = request.timeout - (time.monotonic() - t0)
            if cancel is not None and cancel.is_set():
                return GraspPlan(PlanStatus.CANCELLED, "cancelled while the planner was starting",
                                 scene_version=scene.version, planning_time=time.monotonic() - t0), request
            if left <= 0:
                return GraspPlan(PlanStatus.TIMED_OUT, f"timed out while the planner was starting ({request.timeout:g} s): "
                                 "the planning worker processes were not ready and this process's collision model "
                                 "was still being built; raise the timeout, or plan once the node has logged that its "
                                 "worker processes are ready", scene_version=scene.version,
                                 planning_time=time.monotonic() - t0), request
            time.sleep(min(COLD_POLL, left))
            left = max(request.timeout - (time.monotonic() - t0), 1e-3)
            plan = self.pool.run(kind, scene, replace(request, timeout=left), options, parallel, cancel, progress)
            if plan is not None:
                return plan, request
        return None, replace(request, timeout=max(request.timeout - (time.monotonic() - t0), 1e-3))

    def start_in_background(self) -> None:
        if self.pool is not None:
            self.pool.start_in_background()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()
