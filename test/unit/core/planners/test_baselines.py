"""The IK-first baselines (planners.baselines: RRT, goal-biased RRT, RRT-Connect, RC-RRT) on the same
ARMAR-III problem as GIRRT: each connects the start to one of the goal configurations on a free path."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from humanoid_planner.core.planners.baselines import BASELINES, ConnectSearch, GoalRRT
from humanoid_planner.core.planners.common import PlanStatus, Termination, Tree


@pytest.fixture(scope="module")
def goals(left_problem, armar3_planner) -> np.ndarray:
    g, failed = armar3_planner.single.goal_configs(left_problem.seeded(np.random.default_rng(0)))
    assert failed is None and len(g) > 1
    return g


def rrt(p, variant: str, seed: int = 1) -> GoalRRT:
    return GoalRRT(variant, p.seeded(np.random.default_rng(seed)))


@pytest.mark.parametrize("variant", BASELINES)
def test_connects_the_start_to_a_goal_on_a_free_path(left_problem, goals, variant):
    p = left_problem
    res = rrt(p, variant).plan(p.q0, goals, Termination(30.0, max_cycles=p.options.max_cycles))
    assert res.ok, res.message
    np.testing.assert_array_equal(res.path[0], p.q0)
    assert np.any(np.all(goals == res.path[-1], axis=1))  # ends exactly on a goal configuration
    assert p.motion.polylines_free([res.path])
    assert res.iterations > 0 and res.tree_size >= len(res.path) - 1


def test_connect_search_names_the_tree_edge_of_every_path_edge(left_problem, goals):
    """ConnectSearch.edges: per edge of the path found, the tree and the node it leads into, whose
    parent holds the other end (a lazy search cuts the edge that fails validation there)."""
    p = left_problem
    rrt_ = rrt(p, "rrt_connect", 3)
    search = ConnectSearch(rrt_, Tree(p.q0), goals)
    for _ in range(p.options.max_cycles):
        if (path := search.cycle()) is not None:
            break
    assert path is not None and len(search.edges) == len(path) - 1
    for (tree, c), a, b in zip(search.edges, path[:-1], path[1:]):
        qp, qc = tree.q[tree.parent[c]], tree.q[c]
        assert tree is search.start or tree is search.goal
        # the node where the trees met holds the other tree's configuration (to rounding)
        assert (np.allclose(qp, a) and np.allclose(qc, b)) or (np.allclose(qp, b) and np.allclose(qc, a))
    assert {id(t) for t, _ in search.edges} == {id(search.start), id(search.goal)} or len(path) == 2


def test_same_seed_same_path(left_problem, goals):
    p = left_problem
    a = rrt(p, "rrt_connect", 7).plan(p.q0, goals, Termination(30.0))
    b = rrt(p, "rrt_connect", 7).plan(p.q0, goals, Termination(30.0))
    np.testing.assert_array_equal(a.path, b.path)


def test_no_goals_unknown_variant_budget_and_cancel(left_problem, goals):
    p = left_problem
    res = rrt(p, "rrt").plan(p.q0, np.empty((0, len(p.q0))), Termination(5.0))
    assert res.status is PlanStatus.NO_IK_SOLUTION
    with pytest.raises(ValueError, match="unknown baseline"):
        rrt(p, "prm")
    res = rrt(p, "rrt").plan(p.q0, goals, Termination(30.0, max_cycles=2))
    assert res.status is PlanStatus.PLANNING_FAILED and res.iterations == 2
    cancel = threading.Event()
    cancel.set()
    assert rrt(p, "rc_rrt").plan(p.q0, goals, Termination(30.0, cancel)).status is PlanStatus.CANCELLED


@pytest.mark.parametrize("balance", [True, False])
def test_balanced_search_extends_the_smaller_tree(left_problem, goals, balance):
    """balance: every cycle extends toward its sample from the tree with fewer nodes (a big start tree,
    one goal: always the goal tree); without it the trees take turns, the start tree first."""
    p = left_problem
    rrt_ = rrt(p, "rrt_connect", 5)
    start = Tree(p.q0)
    start.add(p.q0 + np.linspace(0.0, 0.05, 40)[1:, None], 0)  # 40 nodes near the start
    search = ConnectSearch(rrt_, start, goals[:1], balance=balance)
    extended = []
    grow = rrt_._extend

    def spy(tree, q, connect, *args, **kwargs):
        if not connect:
            extended.append(tree is search.goal)
        return grow(tree, q, connect, *args, **kwargs)

    rrt_._extend = spy
    for _ in range(6):
        if search.cycle() is not None or search.goal.size >= search.start.size:
            break
    assert extended
    assert extended == ([True] * len(extended) if balance else [k % 2 == 1 for k in range(len(extended))])
