"""core/pipeline/plan_process.py: plans in a worker process answer as in the calling thread, the
worker's scene follows the node's by deltas, cancel and progress cross the pipe, a killed worker
fails its plan clearly and is replaced. One worker process serves the module."""
from __future__ import annotations

import math
import os
import signal
import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline import plan_process
from humanoid_planner.core.pipeline.plan_process import SCENE_QUERY, PlanRunner, PlanWorkerPool
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest, StatePlanRequest
from humanoid_planner.core.planners.common import PlanStatus, Progress
from humanoid_planner.core.scene.planning_scene import AttachUpdate, Operation, PlanningScene, SceneUpdate
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, VoxelLayer
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

GROUP = "left_arm_torso"
CANCEL_LIMIT = 0.5  # s from the cancel to the answer (the thread mode's bound in the live-node test)


@pytest.fixture(scope="module")
def setup():
    robot = RobotModel.preset("armar3")
    planner = GraspPlanner(robot, parallel="thread")
    followed = PlanningScene(robot.root_link)  # the scene idle workers are kept up to date with
    pool = PlanWorkerPool(robot, 1, planner.options, "thread", scene=followed.snapshot)
    assert pool.wait_ready(120.0), "the worker process did not start"

    @contextmanager
    def use_planner():
        yield planner

    try:
        yield robot, planner, pool, PlanRunner(use_planner, pool), followed
    finally:
        pool.close()


def _request(robot, sc, seed: int, timeout: float = 5.0) -> GraspPlanRequest:
    return GraspPlanRequest(GROUP, robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, timeout=timeout,
                            seed=seed)


def _caged(robot) -> tuple:
    """boxes6 seed 1 with a solid box around the target: GIRRT searches until its deadline."""
    sc = make_scenario(robot, "boxes6", 1, hand="left", left_group=GROUP)
    T = np.eye(4)
    T[:3, 3] = sc.object_pose[:3, 3]
    cage = SceneObject("cage", T, (Shape("box", np.eye(4), (0.14, 0.14, 0.26)),))
    return sc, SceneSnapshot(sc.scene.version + 1, sc.scene.frame, sc.scene.objects + (cage,))


def test_same_seed_same_plan_as_in_the_calling_thread(setup):
    robot, planner, pool, runner, _ = setup
    for seed in (0, 1, 2):
        sc = make_scenario(robot, "boxes6", seed, hand="left", left_group=GROUP)
        req = _request(robot, sc, seed + 1)
        there = runner.run("plan_grasp", sc.scene, req)
        here = planner.plan_grasp(sc.scene, req)
        assert there.status is here.status is PlanStatus.SUCCESS, (there.message, here.message)
        assert np.array_equal(there.path, here.path) and np.array_equal(there.trajectory.positions,
                                                                        here.trajectory.positions)
        assert there.grasps[0].id == here.grasps[0].id and there.scene_version == sc.scene.version
    goal = {robot.joint_names[i]: float(robot.home[i] + 0.3 * np.sin(i)) for i in robot.group_joint_indices(GROUP)}
    req = StatePlanRequest(GROUP, robot.home.copy(), goal=goal, timeout=5.0, seed=1)
    there, here = runner.run("plan_to_state", sc.scene, req), planner.plan_to_state(sc.scene, req)
    assert there.status is here.status is PlanStatus.SUCCESS and np.array_equal(there.path, here.path)


def test_the_workers_scene_follows_adds_moves_removes_attach_and_voxels(setup):
    robot, planner, pool, _, _ = setup
    box = (Shape("box", np.eye(4), (0.1, 0.1, 0.1)),)
    scene = PlanningScene(robot.root_link)

    def T(x):
        m = np.eye(4)
        m[:3, 3] = (x, 0.0, 0.0)
        return m

    def worker_scene() -> SceneSnapshot:
        return pool.run(SCENE_QUERY, scene.snapshot(), None, planner.options, "thread")

    def same(a: SceneSnapshot, b: SceneSnapshot) -> bool:
        return (a.version == b.version and [(o.id, o.pose.tobytes(), len(o.shapes)) for o in a.objects]
                == [(o.id, o.pose.tobytes(), len(o.shapes)) for o in b.objects]
                and [(x.id, x.link, x.pose.tobytes()) for x in a.attached]
                == [(x.id, x.link, x.pose.tobytes()) for x in b.attached]
                and (a.voxels is None) == (b.voxels is None)
                and (a.voxels is None or np.array_equal(a.voxels.cells, b.voxels.cells)))

    link = robot.link_names[-1]
    changes = [lambda: scene.add("a", T(1), box), lambda: scene.add("b", T(2), box), lambda: scene.move("a", T(3)),
               lambda: scene.remove("b"), lambda: scene.add("c", T(4), box),
               lambda: scene.apply_attach(AttachUpdate(link, SceneUpdate(Operation.ADD, "c")),
                                          lambda _: np.eye(4), robot.link_names),
               lambda: scene.set_voxels(VoxelLayer(0.02, np.array([[1, 2, 3]], np.int32))),
               lambda: scene.apply_attach(AttachUpdate("", SceneUpdate(Operation.REMOVE, "c")),
                                          lambda _: np.eye(4), robot.link_names)]
    for k, change in enumerate(changes):
        change()
        assert same(worker_scene(), scene.snapshot()), f"after change {k}"


def test_cancel_reaches_the_plan_in_the_worker_and_progress_comes_back(setup):
    robot, _, pool, runner, _ = setup
    sc, caged = _caged(robot)
    cancel, progress = threading.Event(), Progress()
    timer = threading.Timer(1.0, cancel.set)
    timer.start()
    plan = runner.run("plan_grasp", caged, _request(robot, sc, 1, timeout=20.0), cancel, progress)
    assert plan.status is PlanStatus.CANCELLED, plan.message
    assert progress.phase == "searching" and progress.iterations > 0  # reported every 0.1 s while it ran
    # the cage blocks every approach; the tree's Connect nodes still say how near it came
    assert 0.0 < progress.best_tcp_distance < math.inf
    assert plan.planning_time < 1.0 + CANCEL_LIMIT, f"stopped {plan.planning_time - 1.0:.2f} s after the cancel"
    assert runner.run("plan_grasp", sc.scene, _request(robot, sc, 2)).ok


def test_a_worker_killed_mid_plan_fails_that_plan_clearly_and_is_replaced(setup):
    robot, _, pool, runner, _ = setup
    sc, caged = _caged(robot)
    (pid,) = pool.pids()
    killer = threading.Timer(0.5, os.kill, (pid, signal.SIGKILL))
    killer.start()
    t0 = time.monotonic()
    plan = runner.run("plan_grasp", caged, _request(robot, sc, 1, timeout=20.0))
    assert time.monotonic() - t0 < 5.0
    assert plan.status is PlanStatus.INTERNAL_ERROR and "worker process died" in plan.message, plan.message
    assert "signal 9" in plan.message and "restarted" in plan.message
    assert pool.wait_ready(120.0), "no new worker"
    (new,) = pool.pids()
    assert new != pid
    there = pool.run("plan_grasp", sc.scene, _request(robot, sc, 2), setup[1].options, "thread")
    assert there is not None and there.ok, there  # None would mean: not run in a worker


def test_a_worker_that_never_answers_is_cancelled_then_killed_not_waited_for(setup, monkeypatch):
    """A worker stuck by a fault (stopped here: alive, silent) holds its plan only until the request's
    timeout + OVERDUE_AFTER + STOP_GRACE; the plan answers INTERNAL_ERROR and the worker is replaced."""
    robot, planner, pool, runner, _ = setup
    monkeypatch.setattr(plan_process, "OVERDUE_AFTER", 0.5)
    monkeypatch.setattr(plan_process, "STOP_GRACE", 0.5)
    sc, caged = _caged(robot)
    (pid,) = pool.pids()
    stopper = threading.Timer(0.2, os.kill, (pid, signal.SIGSTOP))
    stopper.start()
    t0 = time.monotonic()
    try:
        plan = runner.run("plan_grasp", caged, _request(robot, sc, 1, timeout=1.0))
    finally:
        stopper.join()
        if pool.pids() == [pid]:
            os.kill(pid, signal.SIGCONT)
    assert 1.0 + 0.5 + 0.5 <= time.monotonic() - t0 < 5.0
    assert plan.status is PlanStatus.INTERNAL_ERROR and "did not stop" in plan.message, plan.message
    assert pool.wait_ready(120.0), "no new worker"
    (new,) = pool.pids()
    assert new != pid
    assert runner.run("plan_grasp", sc.scene, _request(robot, sc, 2)).ok


def test_an_idle_worker_gets_scene_changes_in_the_background(setup):
    """A new mesh reaches an idle worker (and has its geometry built there) without any plan; a plan
    afterwards hands over nothing of the scene."""
    robot, planner, pool, _, followed = setup
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.1
    mesh = Shape("mesh", np.eye(4), (), v, np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]))
    T = np.eye(4)
    T[:3, 3] = (3.0, 0.0, 0.0)
    followed.add("far_mesh", T, (mesh,))
    snap = followed.snapshot()
    (slot,) = pool._slots
    deadline = time.monotonic() + 5.0
    while not slot.feed.holds(snap):
        assert time.monotonic() < deadline, "the idle worker was not brought up to the scene"
        time.sleep(0.05)
    assert slot.feed.delta(snap).empty
    there = pool.run(SCENE_QUERY, snap, None, planner.options, "thread")
    assert [o.id for o in there.objects] == ["far_mesh"] and there.version == snap.version


def test_closing_while_workers_start_raises_in_no_thread(setup, monkeypatch):
    """close() stops a slot the moment its worker reports ready, between the start thread's poll and
    its recv: that thread must not trip over the slot's cleared connection (a SIGTERM during start-up)."""
    from multiprocessing.connection import Connection

    robot, planner, _, _, _ = setup
    pool = PlanWorkerPool(robot, 1, planner.options, "thread")
    poll = Connection.poll

    def poll_then_close(conn, timeout=0.0):
        ready = poll(conn, timeout)
        if ready and threading.current_thread().name == "plan-workers-start":
            pool.close()
        return ready

    monkeypatch.setattr(Connection, "poll", poll_then_close)
    errors = []
    monkeypatch.setattr(threading, "excepthook", errors.append)
    pool.start_in_background()
    starter = pool._starter
    starter.join(60.0)
    assert not starter.is_alive() and pool.ready == 0
    assert not errors, [f"{e.thread.name}: {e.exc_type.__name__}: {e.exc_value}" for e in errors]
