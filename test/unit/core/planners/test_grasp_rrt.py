"""GIRRT / GRRT (planners.grasp_rrt) on ARMAR-III's left arm in clutter: the path starts at the start,
ends on a grasp within tolerance, every motion of it is collision-free, and a seed fixes the plan."""
from __future__ import annotations

import gc
import threading
import weakref
from dataclasses import replace

import numpy as np
import pytest

from humanoid_planner.core.planners.common import PlanStatus, Termination
from humanoid_planner.core.planners.grasp_rrt import GraspRRT
from humanoid_planner.core.transforms import pose_distance


def girrt(p, seed: int, inverse: str = "wln") -> GraspRRT:
    return GraspRRT(p.seeded(np.random.default_rng(seed)), inverse=inverse)


def _fallback_only(p, planner, monkeypatch) -> GraspRRT:
    """GraspRRT on problem p whose fast path never makes progress (approach, connect and the direct hint
    motions stubbed out), so that only its fallback can reach a grasp."""
    arm = GraspRRT(p.seeded(np.random.default_rng(2)), ik=planner.problems.ik_hints(p.kin, p.q0, p.lower, p.upper, 2))
    monkeypatch.setattr(arm, "_approach", lambda t: None)
    monkeypatch.setattr(arm, "_connect", lambda targets: None)
    monkeypatch.setattr(arm, "_direct", lambda targets: None)
    return arm


@pytest.mark.parametrize("inverse", ["wln", "svd"])
def test_reaches_a_grasp_on_a_free_path(left_problem, inverse):
    p = left_problem
    res = girrt(p, 3, inverse).plan(p.q0, Termination(30.0, max_cycles=p.options.max_cycles))
    assert res.ok, res.message
    np.testing.assert_array_equal(res.path[0], p.q0)
    dp, dr = pose_distance(p.kin.fk(res.path[-1]), res.target.T_target)
    assert dp <= p.options.goal_tolerance_pos and dr <= p.options.goal_tolerance_rot
    assert res.target in p.targets
    assert p.motion.polylines_free([res.path])
    assert np.all(res.path >= p.lower - 1e-12) and np.all(res.path <= p.upper + 1e-12)
    assert 0 < res.iterations and len(res.path) <= res.tree_size


def test_a_finished_search_and_its_fallback_go_with_their_last_reference(left_problem, armar3_planner):
    """No reference cycle holds a search: once its last reference goes, so do its fallback and what they
    hold (a request's checker, whose pooled fcl objects then return to the pool). A cycle between the two
    kept them until the garbage collector ran, so the next plans' checkers made their fcl objects anew
    (TALOS's: 27 ms to build that way, 15 ms from the pool)."""
    p = left_problem
    arm = GraspRRT(p.seeded(np.random.default_rng(4)), ik=armar3_planner.problems.ik_hints(p.kin, p.q0, p.lower, p.upper, 2),
                   fallback_from=0)
    assert arm.plan(p.q0, Termination(30.0, max_cycles=p.options.max_cycles)).ok
    assert arm.fallback is not None and arm.fallback.cycles > 0
    refs = [weakref.ref(arm), weakref.ref(arm.fallback), weakref.ref(arm.fallback.search)]
    gc.disable()
    try:
        del arm
        assert [r() for r in refs] == [None, None, None]
    finally:
        gc.enable()


def test_same_seed_same_path(left_problem):
    p = left_problem
    a = girrt(p, 11).plan(p.q0, Termination(30.0, max_cycles=p.options.max_cycles))
    b = girrt(p, 11).plan(p.q0, Termination(30.0, max_cycles=p.options.max_cycles))
    assert a.ok and b.ok and a.iterations == b.iterations
    np.testing.assert_array_equal(a.path, b.path)


def test_bad_start_budget_and_cancel(left_problem):
    p = left_problem
    outside = p.q0.copy()
    outside[0] = p.upper[0] + 0.1
    assert girrt(p, 0).plan(outside, Termination(5.0)).status is PlanStatus.INVALID_START
    res = girrt(p, 0).plan(p.q0, Termination(30.0, max_cycles=3))
    assert res.status is PlanStatus.PLANNING_FAILED and res.iterations == 3 and "3 cycles" in res.message
    cancel = threading.Event()
    cancel.set()
    res = girrt(p, 0).plan(p.q0, Termination(30.0, cancel))
    assert res.status is PlanStatus.CANCELLED and res.path is None
    with pytest.raises(ValueError):
        GraspRRT(replace(p, targets=()))


def test_search_continues_on_the_targets_it_is_given(left_problem):
    """DAGRRT's arms drop a reached grasp and search on: search() reaches only the targets passed."""
    p = left_problem
    arm = girrt(p, 5)
    assert arm.start(p.q0) is None
    found = arm.search(Termination(30.0, max_cycles=p.options.max_cycles))
    assert found is not None
    rest = [t for t in p.targets if t.index != found[1].index]
    again = arm.search(Termination(30.0, max_cycles=p.options.max_cycles), rest)
    assert again is not None and again[1].index != found[1].index
    dp, _ = pose_distance(p.kin.fk(arm.tree.q[again[0]]), again[1].T_target)
    assert dp <= p.options.goal_tolerance_pos


def test_a_stalled_search_falls_back_to_rrt_connect_within_its_budget(left_problem, armar3_planner, monkeypatch):
    """The safety net: with every approach and Connect of the fast path failing (the tree never grows,
    as Baxter's did at its zero pose), the search does not spin until the timeout: after
    STALL_CYCLES cycles a plain RRT-Connect to the free IK solutions takes three quarters of the
    configuration checks, its path reaches a grasp, and the result says so."""
    from humanoid_planner.core.planners import grasp_rrt

    p = left_problem
    arm = _fallback_only(p, armar3_planner, monkeypatch)
    res = arm.plan(p.q0, Termination(30.0, max_cycles=20000))  # the stubbed fast-path cycles check nothing: many
    assert res.ok, res.message
    assert res.extra["fallback"] == "rrt_connect" and res.extra["fallback_cycles"] > 0
    assert res.iterations > grasp_rrt.STALL_CYCLES
    share = arm.fallback.checks / (arm.fallback.checks + arm._fast_checks)  # of the checks since it joined
    assert share >= grasp_rrt.FALLBACK_SHARE - 0.05
    np.testing.assert_array_equal(res.path[0], p.q0)
    dp, dr = pose_distance(p.kin.fk(res.path[-1]), res.target.T_target)
    assert dp <= p.options.goal_tolerance_pos and dr <= p.options.goal_tolerance_rot
    assert p.motion.polylines_free([res.path])


def test_girrt_runs_its_fallback_from_the_first_cycle_and_searches_before_more_ik(left_problem, armar3_planner,
                                                                                monkeypatch):
    """fallback_from=1 (GIRRT): once the straight motions to the hints failed, the fallback joins in the first
    cycle, fast path healthy or not; with the hints as goals its first IK batch waits for FALLBACK_IK_EVERY cycles."""
    from humanoid_planner.core.planners import grasp_rrt

    p = left_problem
    arm = GraspRRT(p.seeded(np.random.default_rng(2)), ik=armar3_planner.problems.ik_hints(p.kin, p.q0, p.lower, p.upper, 2),
                   fallback_from=1)
    monkeypatch.setattr(arm, "_direct", lambda targets: None)
    asked: list[int] = []
    ik = arm.ik
    arm.ik = lambda *a: (asked.append(arm.fallback.cycles if arm.fallback else -1), ik(*a))[1]
    arm.start(p.q0)
    arm.search(Termination(30.0, max_cycles=1))
    assert arm.fallback is not None and arm.fallback.cycles == 1 and len(arm.fallback.goal_targets) > 0
    assert asked == [-1]  # the hints' IK only: the fallback's first cycle searched
    arm.search(Termination(30.0, max_cycles=grasp_rrt.FALLBACK_IK_EVERY + 1))
    assert asked[1:2] in ([], [grasp_rrt.FALLBACK_IK_EVERY])  # [] when a grasp was reached before


def test_the_fallback_counts_a_lazy_path_only_once_the_validator_proves_its_edges(left_problem, armar3_planner,
                                                                                  monkeypatch):
    """The fallback's RRT-Connect checks its motions as the reference does (LazyMotion: samples only, no
    margins); an edge of a path it finds that the validator refuses is cut from its tree and the search
    goes on. Here the first three edges asked are refused: three cuts, then a path whose every edge passed.
    (Every edge is asked: the batch that passes edges keeping all their margins is told none does.)"""
    from humanoid_planner.core.planners.motion import LazyMotion, MotionValidator

    p = left_problem
    arm = _fallback_only(p, armar3_planner, monkeypatch)
    monkeypatch.setattr(MotionValidator, "edges_keep_margins", lambda self, A, B: np.zeros(len(A), dtype=bool))
    asked: list[tuple[np.ndarray, np.ndarray]] = []
    validate = LazyMotion.validate_edge

    def refuse_three(self, q0, q1):
        asked.append((q0, q1))
        return len(asked) > 3 and validate(self, q0, q1)

    monkeypatch.setattr(LazyMotion, "validate_edge", refuse_three)
    res = arm.plan(p.q0, Termination(30.0, max_cycles=4000))
    assert res.ok, res.message
    assert res.extra["fallback"] == "rrt_connect" and res.extra["fallback_cut_edges"] == 3
    assert len(asked) - 3 == len(res.path) - 1  # each edge of the path was asked (a refusal stops at its edge)
    for (a, b), q0, q1 in zip(asked[3:], res.path[:-1], res.path[1:]):
        assert {tuple(np.round(a, 9)), tuple(np.round(b, 9))} == {tuple(np.round(q0, 9)), tuple(np.round(q1, 9))}
    assert p.motion.polylines_free([res.path])


def test_a_lazy_paths_edges_are_validated_in_one_batch_with_the_per_edge_verdicts(left_problem, monkeypatch):
    """LazyMotion.first_invalid_edge screens a path's edges in one batch (MotionValidator.edges_keep_margins)
    and asks validate_edge only of those that miss a margin there: an edge the batch passes is one
    validate_edge passes, and the first edge refused is the first validate_edge refuses, edge by edge."""
    from humanoid_planner.core.planners.motion import LazyMotion

    p = left_problem
    lazy = LazyMotion(p.motion)
    rng = np.random.default_rng(5)
    Q = rng.uniform(p.lower, p.upper, size=(300, len(p.q0)))
    A = Q[p.motion.check_configs(Q)]
    B = np.clip(A + rng.normal(0.0, 0.8, size=A.shape), p.lower, p.upper)
    keep = p.motion.check_configs(B)  # a lazy search's edges join free configurations
    A, B = A[keep], B[keep]
    each = np.array([lazy.validate_edge(a, b) for a, b in zip(A, B)])
    batch = p.motion.edges_keep_margins(A, B)
    assert batch.sum() > len(A) // 2 and (~each).sum() >= 3 and (each & ~batch).any()  # every kind of edge is there
    assert each[batch].all()
    asked = []
    validate = LazyMotion.validate_edge
    monkeypatch.setattr(LazyMotion, "validate_edge", lambda self, a, b: asked.append(1) or validate(self, a, b))
    for k in range(0, len(A), 7):
        refused = np.flatnonzero(~each[k:])
        assert lazy.first_invalid_edge(A[k:], B[k:]) == (refused[0] if len(refused) else len(A) - k)
    assert lazy.first_invalid_edge(A[batch], B[batch]) == batch.sum()
    assert len(asked) < sum(len(A) - k for k in range(0, len(A), 7)) // 3  # most edges decided by the batch
    assert lazy.first_invalid_edge(A[:0], B[:0]) == 0


def test_a_healthy_search_does_not_fall_back(left_problem, armar3_planner):
    p = left_problem
    res = GraspRRT(p.seeded(np.random.default_rng(3)),
                   ik=armar3_planner.problems.ik_hints(p.kin, p.q0, p.lower, p.upper, 3)).plan(
        p.q0, Termination(30.0, max_cycles=p.options.max_cycles))
    assert res.ok and res.extra == {"fallback_cycles": 0, "fallback_cut_edges": 0}


def test_exit_lines_go_on_past_their_near_part_only_where_it_is_free_all_the_way(left_problem, armar3_planner):
    """The far part of a goal root's exit line continues its near part (straight back along the hand's axis,
    free) and exists only where the near part ran its whole EXIT_DISTANCE."""
    from humanoid_planner.core.planners.cartesian import LINE_STEP
    from humanoid_planner.core.planners.grasp_rrt import EXIT_DISTANCE, EXIT_FAR
    p = left_problem
    arm = GraspRRT(p.seeded(np.random.default_rng(1)), ik=armar3_planner.problems.ik_hints(p.kin, p.q0, p.lower,
                                                                                            p.upper, 1))
    assert arm.start(p.q0) is None
    arm._compute_hints()
    full = int(np.ceil(EXIT_DISTANCE / LINE_STEP - 1e-9))
    went_on = 0
    for q in arm.hints:
        near, _ = arm._exit_line(q)
        far, _ = arm._exit_line(q, far=True)
        assert arm._exit_line(q.copy(), far=True)[0] is far  # kept per grasp configuration
        assert arm._exit_line(q)[0] is near
        if len(near) < full:
            assert len(far) == 0
            continue
        went_on += len(far) > 0
        T = arm.kin.fk(q)
        back = -(T[:3, :3] @ arm._hand_axis)
        back /= np.linalg.norm(back)
        line = np.vstack([q[None], near, far])
        along = (np.array([arm.kin.fk(w)[:3, 3] for w in line]) - T[:3, 3]) @ back
        assert np.all(np.diff(along) > 0) and along[-1] <= EXIT_FAR + 0.01
        assert p.motion.polylines_free([line])
    assert went_on > 0


def fallback_of(p, planner) -> tuple[GraspRRT, object]:
    """GIRRT on p whose straight motions to its IK hints failed, and a fallback for it (not yet attached)."""
    from humanoid_planner.core.planners.grasp_rrt import _Fallback
    arm = GraspRRT(p.seeded(np.random.default_rng(1)), ik=planner.problems.ik_hints(p.kin, p.q0, p.lower, p.upper, 1))
    assert arm.start(p.q0) is None
    arm._compute_hints()
    return arm, _Fallback(arm, np.random.default_rng(1))


def test_the_fallback_draws_no_far_exit_line_below_a_goal_configuration_given_up(left_problem, armar3_planner):
    """A goal configuration cut from the fallback's goal tree (forget_reached) before its far exit line was
    due gets none: the line would bring the posture given up back into the search."""
    arm, fb = fallback_of(left_problem, armar3_planner)
    fb.cycle(list(arm.targets))  # roots the goal tree at the hints, near lines drawn, far ones due
    goal, roots = fb.search.goal, list(fb.search.goal_roots)
    assert fb._far
    cut = {r for r in roots if len(arm._exit_line(goal.q[r], far=True)[0])}
    assert cut  # roots whose far part exists
    for r in cut:
        goal.cut(r)
    before = goal.size
    fb._draw_far()
    alive = np.isfinite(goal.sq[:goal.size])
    assert not any(alive[i] and int(goal.root[i]) in cut for i in range(goal.size))
    assert goal.size == before


def test_the_fallback_checks_its_exit_lines_lazily_and_the_fast_path_then_draws_none(left_problem, armar3_planner):
    """The fallback's goal tree takes its exit lines on its lazy check (validated only once a path runs
    through them), kept apart from the validator's lines; while it runs, the fast path's goal tree draws
    no lines of its own, so no line is refined with the validator's exact checks unless a path uses it."""
    from humanoid_planner.core.planners.grasp_rrt import EXIT_AFTER_CYCLES
    arm, fb = fallback_of(left_problem, armar3_planner)
    arm.fallback = fb
    fb.cycle(list(arm.targets))
    assert fb._far and arm._exits
    assert all(lazy for (_, _, lazy) in arm._exits)  # the validator drew none
    q = arm.hints[0]
    assert arm._exit_line(q, lazy=fb.lazy)[0] is arm._exits[(q.tobytes(), False, True)][0]
    assert not arm._exit_line(q, lazy=fb.lazy)[1].any()  # a lazy line claims no tight waypoint
    arm.cycles = EXIT_AFTER_CYCLES
    arm._goal_tree_for(list(arm.targets))
    assert all(lazy for (_, _, lazy) in arm._exits)
    arm.fallback = None  # without a fallback (DAGRRT's arms before a stall) the fast path draws them itself
    arm.goal_tree = None
    arm._goal_tree_for(list(arm.targets))
    assert any(not lazy for (_, _, lazy) in arm._exits)


def test_ik_hints_are_collision_checked_once_and_only_free_ones_kept(left_problem, armar3_planner, monkeypatch):
    """The hints' IK keeps its solutions if some are free (its keep test checks them all); the search takes
    those verdicts instead of checking every solution again (G1's upper arm beside its torso sent each twice
    to FCL), and a solution that the full IK found instead (none kept) is still checked."""
    p = left_problem
    for full_ik in (False, True):
        arm = GraspRRT(p.seeded(np.random.default_rng(1)), ik=armar3_planner.problems.ik_hints(p.kin, p.q0, p.lower,
                                                                                                p.upper, 1))
        assert arm.start(p.q0) is None
        asked: list[np.ndarray] = []
        check = arm.motion.check_configs

        def counted(q, _check=check, _asked=asked):
            _asked.append(np.array(q, copy=True))
            return _check(q) if not full_ik or len(_asked) > 1 else np.zeros(len(q), dtype=bool)  # none kept: full IK

        monkeypatch.setattr(arm.motion, "check_configs", counted)
        arm._compute_hints()
        assert len(arm.hints) and check(arm.hints).all()
        rows = np.vstack(asked)
        assert len(asked) == (2 if full_ik else 1)  # (full IK: the keep test, then the search checks its own)
        if not full_ik:
            assert len(np.unique(rows, axis=0)) == len(rows)  # each solution once
