"""GIRRT, DAGRRT and the baselines through GraspPlanner, verified independently (core/verification.py)."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanner, GraspPlanRequest
from humanoid_planner.core.grasp.quality import dual_grasp_score
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.planners.arm_messages import Reachable
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.scenarios import OBJECT_ID, make_scenario
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.verification import verify_plan


@pytest.fixture(scope="module")
def robots() -> dict[str, RobotModel]:
    return {name: RobotModel.preset(name) for name in ("armar3", "dual_arm", "maru1")}


@pytest.fixture(scope="module", params=["process", "thread"])
def dual_planner(robots, request):
    """DAGRRT with its right arm in a worker process (the default) and with both arms in threads."""
    planner = GraspPlanner(robots["dual_arm"], parallel=request.param)
    planner.warm_up()
    yield planner
    planner.close()


def _single(robot, group, family, seed, planner="girrt", timeout=30.0):  # cycles bound the search; the time only guards a loaded machine
    side = "left" if group.startswith("left") else "right"
    suffix = "_torso" if group.endswith("_torso") else ""
    sc = make_scenario(robot, family, seed, hand=side, left_group="left_arm" + suffix, right_group="right_arm" + suffix)
    grasps = sc.left_grasps if side == "left" else sc.right_grasps
    req = GraspPlanRequest(group, robot.home.copy(), sc.object_pose, grasps, OBJECT_ID, planner, timeout, seed=seed + 1)
    return sc, req, GraspPlanner(robot).plan_grasp(sc.scene, req)


@pytest.mark.parametrize("name,group", [("armar3", "left_arm_torso"), ("armar3", "left_arm"),
                                        ("dual_arm", "left_arm"), ("maru1", "right_arm"),
                                        ("maru1", "right_arm_torso")])
@pytest.mark.parametrize("family", ["empty", "boxes6"])
def test_girrt_reaches_a_grasp_collision_free(robots, name, group, family):
    robot = robots[name]
    for seed in (1, 2):
        sc, req, plan = _single(robot, group, family, seed)
        assert plan.ok, plan.message
        assert plan.scene_version == sc.scene.version
        target = sc.object_pose @ plan.grasps[0].tcp_in_object
        assert verify_plan(robot, sc.scene, (group,), robot.home, plan, (target,), object_id=OBJECT_ID) == []


def test_same_seed_same_plan(robots):
    robot = robots["armar3"]
    _, _, a = _single(robot, "left_arm_torso", "boxes6", 4)
    _, _, b = _single(robot, "left_arm_torso", "boxes6", 4)
    assert a.ok and b.ok
    np.testing.assert_array_equal(a.path, b.path)
    assert a.grasps[0].id == b.grasps[0].id


@pytest.mark.parametrize("planner", ["rrt", "goal_biased_rrt", "rrt_connect", "rc_rrt"])
def test_baselines_reach_a_grasp(robots, planner):
    robot = robots["armar3"]
    sc, req, plan = _single(robot, "left_arm", "empty", 1, planner)
    assert plan.ok, plan.message
    target = sc.object_pose @ plan.grasps[0].tcp_in_object
    assert verify_plan(robot, sc.scene, ("left_arm",), robot.home, plan, (target,), object_id=OBJECT_ID) == []


@pytest.mark.parametrize("family", ["empty", "boxes6"])
def test_dagrrt_pairs_score_and_do_not_collide(robots, dual_planner, family):
    robot = robots["dual_arm"]
    for seed in (1, 2):
        sc = make_scenario(robot, family, seed)
        req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, sc.left_grasps,
                                   sc.right_grasps, OBJECT_ID, timeout=10.0, seed=seed)
        plan = dual_planner.plan_dual_grasp(sc.scene, req)
        assert plan.ok, plan.message
        left, right = plan.grasps
        o = dual_planner.options
        score = dual_grasp_score(sc.object_pose, left, right, o.friction, cone_edges=o.cone_edges).epsilon
        assert score > o.min_grasp_score
        assert score == pytest.approx(plan.grasp_score)
        # the planner's pyramid is inscribed in the finer one: its score is never higher
        assert dual_grasp_score(sc.object_pose, left, right, o.friction, cone_edges=8).epsilon >= score - 1e-9
        targets = (sc.object_pose @ left.tcp_in_object, sc.object_pose @ right.tcp_in_object)
        # both arms together: verify_plan checks the concatenated configuration, arm against arm included
        assert verify_plan(robot, sc.scene, ("left_arm", "right_arm"), robot.home, plan, targets,
                           object_id=OBJECT_ID) == []


def test_dagrrt_back_to_back_requests_get_their_own_answers(robots, dual_planner):
    """A run returns as soon as a pair is found, while the arm workers may still finish a cycle:
    their late messages must never answer the next request (object moved 4 cm between requests)."""
    robot = robots["dual_arm"]
    sc = make_scenario(robot, "empty", 3)
    moved = sc.object_pose.copy()
    moved[:3, 3] += 0.04 * sc.object_pose[:3, 2]
    for k in range(4):
        pose = (sc.object_pose, moved)[k % 2]
        req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), pose, sc.left_grasps,
                                   sc.right_grasps, "", timeout=10.0, seed=k)
        plan = dual_planner.plan_dual_grasp(SceneSnapshot(1, robot.root_link, ()), req)
        assert plan.ok, plan.message
        targets = tuple(pose @ g.tcp_in_object for g in plan.grasps)
        assert verify_plan(robot, SceneSnapshot(1, robot.root_link, ()), ("left_arm", "right_arm"), robot.home, plan,
                           targets) == []


def test_dual_grasp_quality_too_low(robots):
    robot = robots["dual_arm"]
    sc = make_scenario(robot, "empty", 1)
    strip = [g.__class__(g.id, g.hand, g.tcp_in_object) for g in sc.left_grasps]  # no contacts: score 0
    req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, strip, sc.right_grasps,
                               OBJECT_ID, timeout=3.0, seed=1)
    plan = GraspPlanner(robot).plan_dual_grasp(sc.scene, req)
    assert plan.status is PlanStatus.GRASP_QUALITY_TOO_LOW, plan.message


def test_unreachable_grasps_reported_fast(robots):
    robot = robots["armar3"]
    sc = make_scenario(robot, "empty", 1)
    far = sc.object_pose.copy()
    far[:3, 3] += [3.0, 0.0, 0.0]
    req = GraspPlanRequest("left_arm_torso", robot.home.copy(), far, sc.left_grasps, "", "girrt", 10.0, seed=1)
    t = time.perf_counter()
    plan = GraspPlanner(robot).plan_grasp(sc.scene, req)
    assert plan.status is PlanStatus.NO_IK_SOLUTION, plan.message
    assert time.perf_counter() - t < 1.0


@pytest.mark.parametrize("mode", ["process", "thread", "interleaved"])
def test_dual_unreachable_hand_reported_fast_in_every_mode(robots, mode):
    """The reachability probe runs after a quarter second in every DAGRRT mode (the one-worker mode
    used to solve IK up front, which also made the measured parallel speed-up unfair)."""
    robot = robots["dual_arm"]
    sc = make_scenario(robot, "empty", 1)
    far = np.eye(4)
    far[2, 3] = 3.0  # 3 m away along the object's z
    far_right = [dataclasses.replace(g, tcp_in_object=far @ g.tcp_in_object) for g in sc.right_grasps]
    req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, sc.left_grasps, far_right,
                               OBJECT_ID, timeout=10.0, seed=1)
    gp = GraspPlanner(robot, workers=1 if mode == "interleaved" else 2,
                      parallel="thread" if mode == "interleaved" else mode)
    try:
        gp.warm_up()  # the arm process's start is not the request's time
        t = time.perf_counter()
        plan = gp.plan_dual_grasp(sc.scene, req)
        assert plan.status is PlanStatus.NO_IK_SOLUTION, plan.message
        assert "right" in plan.message
        assert time.perf_counter() - t < 1.5
    finally:
        gp.close()


def test_start_in_collision_reported(robots):
    robot = robots["armar3"]
    sc = make_scenario(robot, "empty", 1)
    tcp = robot.link_poses(robot.home, [robot.group("left_arm").tip_link])[0]
    block = SceneObject("block", tcp, (Shape("box", np.eye(4), (0.2, 0.2, 0.2)),))
    scene = SceneSnapshot(2, robot.root_link, sc.scene.objects + (block,))
    req = GraspPlanRequest("left_arm", robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt", 5.0, seed=1)
    plan = GraspPlanner(robot).plan_grasp(scene, req)
    assert plan.status is PlanStatus.START_IN_COLLISION, plan.message


@pytest.mark.parametrize("mode", ["process", "thread", "interleaved"])
@pytest.mark.parametrize("side", ["left_arm", "right_arm"])
def test_dual_start_in_collision_reported_in_every_mode(robots, mode, side):
    """Each arm's own checker checks its start (in process mode the right arm's is in the worker,
    which reports the status, not a generic failure)."""
    robot = robots["dual_arm"]
    sc = make_scenario(robot, "empty", 1)
    tcp = robot.link_poses(robot.home, [robot.group(side).tip_link])[0]
    block = SceneObject("block", tcp, (Shape("box", np.eye(4), (0.2, 0.2, 0.2)),))
    scene = SceneSnapshot(2, robot.root_link, sc.scene.objects + (block,))
    req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, sc.left_grasps,
                               sc.right_grasps, OBJECT_ID, timeout=30.0, seed=1)
    gp = GraspPlanner(robot, workers=1 if mode == "interleaved" else 2,
                      parallel="thread" if mode == "interleaved" else mode)
    try:
        t = time.perf_counter()
        plan = gp.plan_dual_grasp(scene, req)
        assert plan.status is PlanStatus.START_IN_COLLISION, plan.message
        assert time.perf_counter() - t < 15.0  # answered at once, not at the 30 s timeout (includes starting the arm process on a loaded machine)
    finally:
        gp.close()


class _HintsOnlyRun:
    """An ArmRun whose worker sends its arm's IK hints and then nothing (a stuck or slow worker)."""

    finished = False

    def __init__(self, hints):
        self._pending = [(0, Reachable(0, *hints))]

    def events(self, timeout):
        out, self._pending = self._pending, []
        time.sleep(min(timeout, 0.001))
        return out

    def stats(self):
        return [(0, 0, None)]

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


class _HintsOnlyPool:
    """Computes the job's hints the way the worker does, then stays silent."""

    def __init__(self, gp):
        self.gp = gp

    def try_start(self, jobs):
        from humanoid_planner.core.planners.grasp_rrt import GraspRRT

        job, gp = jobs[0], self.gp
        prob = gp.problems.arm(job.scene, job.group, job.start, job.targets, np.random.default_rng(0), job.options,
                               job.object_id)
        arm = GraspRRT(prob, inverse=job.inverse, ik=gp.problems.ik_hints(prob.kin, prob.q0, prob.lower, prob.upper, job.seed))
        arm.start(prob.q0)
        arm._compute_hints()
        return _HintsOnlyRun((arm.hints, arm.hint_targets))


def test_dagrrt_planning_thread_helps_the_workers_arm(robots):
    """Once its own arm has a solution, the planning thread searches the worker's arm too, from the
    worker's IK hints: with a worker that never answers, the plan still succeeds — and verifies."""
    robot = robots["dual_arm"]
    gp = GraspPlanner(robot, parallel="process")
    gp._pool = _HintsOnlyPool(gp)
    for seed in (1, 2):
        sc = make_scenario(robot, "boxes6", seed)
        req = DualGraspPlanRequest("left_arm", "right_arm", robot.home.copy(), sc.object_pose, sc.left_grasps,
                                   sc.right_grasps, OBJECT_ID, timeout=10.0, seed=seed)
        plan = gp.plan_dual_grasp(sc.scene, req)
        assert plan.ok, plan.message
        assert plan.stats["helper_cycles"] > 0
        targets = tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps)
        assert verify_plan(robot, sc.scene, ("left_arm", "right_arm"), robot.home, plan, targets,
                           object_id=OBJECT_ID) == []


def test_timeout_is_honoured(robots):
    robot = robots["armar3"]
    sc = make_scenario(robot, "empty", 1)
    # a closed box around the object: every grasp is reachable by IK but none can be approached
    cage = SceneObject("cage", sc.object_pose, tuple(
        Shape("box", np.array([[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]]), d)
        for (x, y, z), d in [((0.13, 0, 0), (0.02, 0.28, 0.3)), ((-0.13, 0, 0), (0.02, 0.28, 0.3)),
                             ((0, 0.13, 0), (0.28, 0.02, 0.3)), ((0, -0.13, 0), (0.28, 0.02, 0.3)),
                             ((0, 0, 0.15), (0.28, 0.28, 0.02))]))
    scene = SceneSnapshot(3, robot.root_link, sc.scene.objects + (cage,))
    req = GraspPlanRequest("left_arm_torso", robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt",
                           1.0, seed=1)
    t = time.perf_counter()
    plan = GraspPlanner(robot).plan_grasp(scene, req)
    elapsed = time.perf_counter() - t
    assert plan.status is PlanStatus.TIMED_OUT, plan.message
    assert 1.0 <= elapsed <= 1.1


@pytest.mark.parametrize("bad,status", [
    (dict(group="nope"), PlanStatus.INVALID_GROUP),
    (dict(planner="prm"), PlanStatus.INVALID_REQUEST),
    (dict(start=np.full(17, np.nan)), PlanStatus.INVALID_START),
    (dict(start=np.full(17, 9.0)), PlanStatus.INVALID_START),
    (dict(grasps=()), PlanStatus.INVALID_GOAL),
])
def test_invalid_requests(robots, bad, status):
    robot = robots["armar3"]
    sc = make_scenario(robot, "empty", 1)
    kw = dict(group="left_arm", start=robot.home.copy(), object_pose=sc.object_pose, grasps=sc.left_grasps,
              object_id=OBJECT_ID)
    kw.update(bad)
    plan = GraspPlanner(robot).plan_grasp(sc.scene, GraspPlanRequest(**kw))
    assert plan.status is status
    assert plan.message


def _right_arm_search(robot, seed, hint_after):
    """GRRT-style search of dual_arm's right arm (the DAGRRT paper's table) on a two-handed boxes6 scene."""
    from dataclasses import replace

    from humanoid_planner.core.planners.common import PlannerOptions, Termination
    from humanoid_planner.core.planners.grasp_rrt import GraspRRT

    gp = GraspPlanner(robot, replace(PlannerOptions(), ik_hint_after=hint_after), workers=1)
    sc = make_scenario(robot, "boxes6", seed, hand="both")
    p = gp.problems.arm(sc.scene, "right_arm", robot.home, gp.targets(sc.object_pose, sc.right_grasps, "right_arm"),
                        np.random.default_rng(seed), object_id=OBJECT_ID)
    q0 = p.q0
    arm = GraspRRT(p, inverse="svd", ik=gp.problems.ik_hints(p.kin, q0, p.lower, p.upper, seed))
    assert arm.start(q0) is None
    found = arm.search(Termination(60.0, max_cycles=300))
    return arm, found


def test_ik_hints_are_free_grasp_solutions_and_speed_up_a_hard_arm(robots):
    """The DAGRRT paper's right arm reaches 1 of the 8 dual-grasp poses from home by the Jacobian approach;
    with IK hints its search needs far fewer cycles (counted, not timed)."""
    robot = robots["dual_arm"]
    with_hints, without, hinted = [], [], 0
    for seed in range(6):
        arm, found = _right_arm_search(robot, seed, hint_after=2)
        if arm.failed_approaches < 2:  # reached a grasp before hints were due
            assert arm.hints is None
        else:
            hinted += 1
            assert arm.hints is not None and len(arm.hints) > 0
        assert arm.hints is None or np.all(arm.motion.check_configs(arm.hints))
        by_index = {t.index: t for t in arm.targets}
        for q, ti in zip(arm.hints if arm.hints is not None else (), arm.hint_targets):  # each hint puts the TCP on its grasp
            err = np.linalg.norm(arm.kin.fk(q)[:3, 3] - by_index[int(ti)].T_target[:3, 3])
            assert err <= arm.opt.goal_tolerance_pos + 1e-9
        with_hints.append(arm.cycles if found else 300)
        arm, found = _right_arm_search(robot, seed, hint_after=None)
        assert arm.hints is None
        without.append(arm.cycles if found else 300)
    assert hinted >= 2
    assert sum(with_hints) < 0.6 * sum(without), (with_hints, without)
