"""DAGRRT's arm process (core/pipeline/arm_process.py): the control protocol, message by message."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.pipeline.arm_process import ArmJob, ArmWorkerPool
from humanoid_planner.core.planners.arm_messages import Done, Solution, Stop
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneObject, Shape
from humanoid_planner.scenarios import OBJECT_ID, make_scenario


@pytest.fixture(scope="module")
def pool_and_job():
    robot = RobotModel.preset("dual_arm")
    gp = GraspPlanner(robot)
    sc = make_scenario(robot, "empty", 1)
    targets = gp.targets(sc.object_pose, sc.left_grasps, "left_arm")
    opts = replace(gp.options, ik_hint_after=gp.options.dual_ik_hint_after)

    def job(seed: int) -> ArmJob:
        return ArmJob(0, sc.scene, "left_arm", robot.home.copy(), targets, OBJECT_ID, opts, [seed, 1], 10.0, "svd")

    pool = ArmWorkerPool(robot, gp.options, size=1)
    pool.warm_up()
    yield pool, job
    pool.close()


def _next_for(conn, job_id: int, kind: type, timeout: float = 20.0):
    """The first message of type `kind` for job_id; messages of other jobs are skipped (as the pool does)."""
    while conn.poll(timeout):
        msg = conn.recv()
        if isinstance(msg, kind) and msg.job_id == job_id:
            return msg
    return None


def test_a_job_that_arrives_while_another_runs_is_not_lost(pool_and_job):
    """The next request's job can reach a worker before the stop of the last one is read: the worker
    must end the running job and then run the new one, not swallow it (the pool would then wait
    until the deadline for an answer that never comes)."""
    pool, job = pool_and_job
    pool.warm_up()  # after a restart in the background (a worker killed by an earlier test), under its lock
    conn = pool._conns[0]
    a, b = job(1), job(2)
    a.job_id, b.job_id = 1001, 1002
    conn.send(a)
    conn.send(b)  # queued behind a, before a's stop: read by a's control loop
    conn.send(Stop(a.job_id))
    assert _next_for(conn, a.job_id, Done) is not None
    sol = _next_for(conn, b.job_id, Solution)
    assert sol is not None, "the second job was never run"
    conn.send(Stop(b.job_id))
    assert _next_for(conn, b.job_id, Done) is not None


def test_exit_during_a_job_ends_the_worker_at_once(pool_and_job):
    """close() sends None; a worker in the middle of a job must exit, not drop the message and wait
    to be terminated."""
    pool, job = pool_and_job
    conn, proc = pool._conns[0], pool._procs[0]
    long = job(4)
    long.job_id = 2001
    long.targets = long.targets[:1]
    long.targets[0] = replace(long.targets[0], T_target=np.eye(4))  # unreachable: the job runs to its deadline
    conn.send(long)
    conn.send(None)
    proc.join(timeout=5.0)
    assert not proc.is_alive(), "the worker ignored the exit request"
    pool._conns, pool._procs = [], []  # the pool starts fresh workers on its next use


def test_a_dead_worker_fails_its_job_and_is_replaced(pool_and_job):
    """A worker killed mid-job (out of memory, a signal) ends that job with an error instead of
    raising into the planner, and the next run gets a fresh worker."""
    pool, job = pool_and_job
    long = job(5)
    long.targets = [replace(long.targets[0], T_target=np.eye(4))]  # unreachable: runs to its deadline
    with pool.start([long]) as run:
        pool._procs[0].kill()
        events = []
        for _ in range(100):
            events += run.events(0.1)
            if run.finished:
                break
        assert run.finished
        assert any(isinstance(m, Done) and "died" in m.error for _, m in events)
    with pool.start([job(6)]) as run:
        got = []
        for _ in range(200):
            got += [m for _, m in run.events(0.1)]
            if any(isinstance(m, Solution) for m in got):
                break
        assert any(isinstance(m, Solution) for m in got)


def test_jobs_stopped_before_they_start_are_not_run(pool_and_job):
    """A worker slower than the plans (niced, on a loaded machine) reads the next jobs and their stops
    while it still runs an earlier one. A stopped or superseded job must end unrun: the worker holds at
    most the newest job, so it neither falls behind nor grows by a job's scene and targets for each
    job it has not reached (each stale job used to run to its deadline, its stop read and dropped
    while another job ran, and the queue of jobs grew without bound). Every job gets its Done."""
    pool, job = pool_and_job
    pool.warm_up()  # after a restart in the background (a worker killed by an earlier test), under its lock
    conn = pool._conns[0]
    stale = []
    for k in range(12):  # changing scenes, as a live scene gives each plan: a new version, a new object
        j = job(100 + k)
        j.job_id = 3000 + k
        T = np.eye(4)
        T[:3, 3] = (-1.5, 0.1 * k, 0.5)  # behind the robot
        box = SceneObject(f"box_{k}", T, (Shape("box", np.eye(4), (0.1, 0.1, 0.1)),))
        j.scene = replace(j.scene, version=j.scene.version + 1 + k, objects=(*j.scene.objects, box))
        j.targets = [replace(j.targets[0], T_target=np.eye(4))]  # unreachable: it would run to its deadline (10 s)
        stale.append(j)
    last = job(7)
    last.job_id = 3100
    t0 = time.monotonic()
    for j in stale:
        conn.send(j)
        conn.send(Stop(j.job_id))
    conn.send(last)
    done: dict[int, Done] = {}
    solved = False
    try:
        while time.monotonic() - t0 < 8.0 and not (solved and len(done) == len(stale)):
            if conn.poll(0.1):
                msg = conn.recv()
                if isinstance(msg, Done) and msg.job_id in {j.job_id for j in stale}:
                    done[msg.job_id] = msg
                solved |= isinstance(msg, Solution) and msg.job_id == last.job_id
        assert len(done) == len(stale), f"stopped jobs without an answer after 8 s: {len(stale) - len(done)}"
        assert solved, "the newest job was not run"
        ran = [d.job_id for d in done.values() if d.cycles > 0]
        assert len(ran) <= 2, f"stopped jobs that were searched anyway: {ran}"
    finally:
        conn.send(Stop(last.job_id))
        if _next_for(conn, last.job_id, Done, timeout=5.0) is None:
            pool._stop_workers()  # a worker stuck in stale jobs: the next test gets a fresh one
