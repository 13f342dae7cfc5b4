"""core/pipeline/plan_process.py, two workers: a plan without a seed still searching after RACE_AFTER gets a
second search in the idle worker; the helper gives way at once to another caller's plan; a cancel stops
both; a seeded plan never races (same seed, same plan); every worker is free again after each answer."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline import plan_process
from humanoid_planner.core.pipeline.plan_process import GIVE_WAY_WAIT, RACE_AFTER, PlanWorkerPool
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.planners.common import PlanStatus, Progress
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

GROUP = "left_arm_torso"


@pytest.fixture(scope="module")
def setup():
    robot = RobotModel.preset("armar3")
    planner = GraspPlanner(robot, parallel="thread")
    pool = PlanWorkerPool(robot, 2, planner.options, "thread")
    assert pool.wait_ready(120.0), "the worker processes did not start"
    sc = make_scenario(robot, "boxes6", 1, hand="left", left_group=GROUP)
    T = np.eye(4)
    T[:3, 3] = sc.object_pose[:3, 3]
    cage = SceneObject("cage", T, (Shape("box", np.eye(4), (0.14, 0.14, 0.26)),))  # every approach blocked
    caged = SceneSnapshot(sc.scene.version + 1, sc.scene.frame, sc.scene.objects + (cage,))
    try:
        yield robot, planner, pool, sc, caged
    finally:
        pool.close()


def _request(robot, sc, seed: int | None, timeout: float) -> GraspPlanRequest:
    return GraspPlanRequest(GROUP, robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, timeout=timeout,
                            seed=seed)


def _states(pool) -> list[tuple[str, bool]]:
    return [(s.state, s.helper) for s in pool._slots]


def _all_free(pool, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while _states(pool) != [("ready", False)] * 2:
        assert time.monotonic() < deadline, f"workers not released: {_states(pool)}"
        time.sleep(0.02)


def _run_in_thread(pool, planner, *args, **kwargs):
    out: dict = {}
    th = threading.Thread(target=lambda: out.setdefault("plan", pool.run(*args, planner.options, "thread", **kwargs)))
    th.start()
    return th, out


def test_a_search_past_race_after_gets_a_helper_that_gives_way_to_another_plan(setup):
    robot, planner, pool, sc, caged = setup
    progress = Progress()
    th, out = _run_in_thread(pool, planner, "plan_grasp", caged, _request(robot, sc, None, 3.0), progress=progress)
    time.sleep(RACE_AFTER + 0.4)
    assert sorted(_states(pool)) == [("busy", False), ("busy", True)]  # the helper searches too
    t0 = time.monotonic()
    other = pool.run("plan_grasp", sc.scene, _request(robot, sc, 2, 5.0), planner.options, "thread")
    assert other is not None, "no worker for the second caller: the helper did not give way"
    assert other.status is PlanStatus.SUCCESS, other.message
    assert time.monotonic() - t0 < GIVE_WAY_WAIT + other.planning_time + 0.5
    th.join(10.0)
    plan = out["plan"]
    assert plan.status is PlanStatus.TIMED_OUT and 2.9 < plan.planning_time < 3.6, (plan.status, plan.planning_time)
    assert progress.phase == "searching" and progress.iterations > 0
    _all_free(pool)


def test_a_cancel_stops_both_searches(setup):
    robot, planner, pool, sc, caged = setup
    cancel = threading.Event()
    timer = threading.Timer(0.6, cancel.set)
    timer.start()
    t0 = time.monotonic()
    plan = pool.run("plan_grasp", caged, _request(robot, sc, None, 20.0), planner.options, "thread", cancel)
    assert plan.status is PlanStatus.CANCELLED, plan.message
    assert time.monotonic() - t0 < 0.6 + 0.5
    _all_free(pool)


def test_a_seeded_plan_never_races_and_a_found_plan_ends_the_race(setup, monkeypatch):
    robot, planner, pool, sc, caged = setup
    th, out = _run_in_thread(pool, planner, "plan_grasp", caged, _request(robot, sc, 1, 1.5))
    time.sleep(RACE_AFTER + 0.4)
    assert sorted(_states(pool)) == [("busy", False), ("ready", False)]
    th.join(10.0)
    assert out["plan"].status is PlanStatus.TIMED_OUT
    _all_free(pool)
    # a helper from the first moment: whichever search finds the plan answers, timed from the request
    monkeypatch.setattr(plan_process, "RACE_AFTER", 0.0)
    for _ in range(3):
        t0 = time.monotonic()
        plan = pool.run("plan_grasp", sc.scene, _request(robot, sc, None, 5.0), planner.options, "thread")
        assert plan.status is PlanStatus.SUCCESS, plan.message
        assert plan.planning_time <= time.monotonic() - t0
        _all_free(pool)
