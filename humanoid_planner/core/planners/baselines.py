"""The Maru-1 thesis's baselines: RRT, goal-biased RRT, RRT-Connect and RC-RRT, to known goal configurations.

This is the "IK first, then plan" pipeline that MoveIt-style stacks use: the caller turns the grasp
set into goal configurations (batched IK, collision-filtered) and any goal reached ends the search.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.planners.arm_problem import ArmProblem
from humanoid_planner.core.planners.common import PlanResult, PlanStatus, Termination, Tree, interpolate_steps

BASELINES = ("rrt", "goal_biased_rrt", "rrt_connect", "rc_rrt")
DOMAIN_DRAWS = 20
"""Samples drawn per cycle at most until one lies in its nearest node's dynamic domain."""
DOMAIN_GROWTH = 0.05
"""A bounded node's domain grows by this share each time an extension from it succeeds."""
GOAL_CONNECT_STEPS = 5  # a new node within this many λ of a goal tries a straight connection to it: near
# enough that the edge often is free, far enough to skip the last few extend steps


class GoalRRT:
    """Single- or bi-directional RRT from a start to any of several goal configurations."""

    def __init__(self, variant: str, problem: ArmProblem, extend_steps: int = 1, lazy: bool = False):
        """problem: its motion validator, limits, options and random stream (no targets: the goals are
        configurations, given to plan); extend_steps: joint_step steps an RRT-Extend takes toward its
        sample (the thesis: one). lazy (rrt_connect only): problem.motion is a motion.LazyMotion and the
        search is a LazyConnectSearch, balanced."""
        if variant not in BASELINES:
            raise ValueError(f"unknown baseline planner {variant!r}; known: {BASELINES}")
        if extend_steps < 1:
            raise ValueError(f"extend_steps must be >= 1, got {extend_steps}")
        if lazy and variant != "rrt_connect":
            raise ValueError(f"a lazy search is an RRT-Connect, not {variant!r}")
        self.extend_steps, self.lazy = int(extend_steps), lazy
        self.variant, self.motion = variant, problem.motion
        self.lower, self.upper = np.asarray(problem.lower, float), np.asarray(problem.upper, float)
        self.opt, self.rng = problem.options, problem.rng
        self.cycles = 0

    def _extend(self, tree: Tree, q_target: np.ndarray, connect: bool, given_target: bool = False,
                i: int | None = None) -> tuple[int, bool]:
        """One RRT step (λ) toward q_target, or all the way (Connect), from node i (default: the
        nearest). Returns (last node, reached).
        Only configurations the problem gave (a tree's roots; q_target when given_target) and nodes
        reached from them through tight samples (Tree.tight) may be tight motion ends
        (MotionValidator.free_prefix): the search's own ones are placed elsewhere instead."""
        step = self.opt.joint_step
        if i is None:
            i = self._rc_nearest(tree, q_target) if self.variant == "rc_rrt" else tree.nearest(q_target)
        full = interpolate_steps(tree.q[i], q_target, step)
        pts = full if connect else full[:self.extend_steps]
        k, tight = self.motion.free_prefix_tight(tree.q[i], pts, tight_from=bool(tree.tight[i]),
                                                 tight_to=given_target and connect)
        if k == 0:
            tree.fails[i] += 1
            return i, False
        last = tree.add(pts[:k], i, tight=tight)
        return last, k == len(full)  # the last point is q_target's (a step cut short lies ≥ step/2 from it)

    def _rc_nearest(self, tree: Tree, q_target: np.ndarray) -> int:
        """RC-RRT (Cheng & LaValle): nodes whose expansions keep failing are picked less often.

        A nearest node with f failed expansions is accepted with probability 1/(1+f); otherwise the
        next candidate by distance is considered (up to 8).
        """
        n = tree.size
        d = tree.sq[:n] - 2.0 * (tree.q[:n] @ q_target)
        order = np.argsort(d)[:8] if n > 8 else np.argsort(d)
        for i in order:
            if self.rng.random() < 1.0 / (1.0 + tree.fails[i]):
                return int(i)
        return int(order[0])

    def plan(self, q_start: np.ndarray, goals: np.ndarray, term: Termination) -> PlanResult:
        """Search until a goal configuration is connected; returns the path start → goal."""
        goals = np.atleast_2d(goals)
        if len(goals) == 0:
            return PlanResult(PlanStatus.NO_IK_SOLUTION, "no collision-free goal configuration")
        start = Tree(np.asarray(q_start, float))
        if self.variant == "rrt_connect":
            return self._plan_connect(start, goals, term)
        self.cycles = 0
        while not term.should_stop(self.cycles):
            self._cycle(term)
            bias = self.opt.goal_bias if self.variant == "goal_biased_rrt" else 0.0
            if self.rng.random() < bias:
                q_rand = goals[int(self.rng.integers(len(goals)))]
            else:
                q_rand = self.rng.uniform(self.lower, self.upper)
            # RRT-Extend (one step), as in the thesis; the new node then tries the nearest goal.
            last, _ = self._extend(start, q_rand, connect=self.variant == "rc_rrt")
            q_new = start.q[last]
            g = goals[int(np.argmin(np.max(np.abs(goals - q_new), axis=1)))]
            if (np.max(np.abs(g - q_new)) <= GOAL_CONNECT_STEPS * self.opt.joint_step
                    and self.motion.free_prefix(q_new, g[None], tight_from=bool(start.tight[last])) == 1):
                idx = start.add(g[None], last)
                return self._done(start.path_to(idx), start.size, term)
        return self._failed(term, start.size)

    def _plan_connect(self, start: Tree, goals: np.ndarray, term: Termination) -> PlanResult:
        """RRT-Connect with every goal configuration as a root of the goal tree."""
        search = LazyConnectSearch(self, start, goals) if self.lazy else ConnectSearch(self, start, goals)
        self.cycles = 0
        while not term.should_stop(self.cycles):
            self._cycle(term)
            path = search.cycle()
            if path is not None:
                return self._done(path, search.size, term)
        return self._failed(term, search.size)

    def _cycle(self, term: Termination) -> None:
        """Count a search cycle, also where the caller watches the plan (Termination.progress)."""
        self.cycles += 1
        if term.progress is not None:
            term.progress.iterations += 1

    def _done(self, path: np.ndarray, size: int, term: Termination) -> PlanResult:
        if term.progress is not None:
            term.progress.solutions += 1
        return PlanResult(PlanStatus.SUCCESS, path=path, iterations=self.cycles, tree_size=size)

    def _failed(self, term: Termination, size: int) -> PlanResult:
        status = term.stop_status()
        msg = "no path to a goal configuration before the timeout" if status is PlanStatus.TIMED_OUT \
            else f"no path to a goal configuration within {self.cycles} cycles"
        return PlanResult(status, msg, iterations=self.cycles, tree_size=size)


class ConnectSearch:
    """RRT-Connect (Kuffner & LaValle) one cycle at a time: a start tree and a goal tree rooted at every
    goal configuration; each cycle extends one tree a step toward a uniform sample and Connects the
    other to the new node, then the trees swap roles. Roots and the nodes reached from them through
    tight samples may be tight motion ends (Tree.tight). GoalRRT's rrt_connect, and GraspRRT's fallback, which
    adds goal configurations as it finds them (add_goals).

    balance: each cycle extends the smaller tree (by nodes) instead of alternating, as VAMP's and
    Kuffner's balanced RRT-Connect do. Where the goals sit in a pocket (a shelf, a box, a cage) the
    goal tree's extensions mostly fail and alternation lets the start tree fill the open space while
    the goal tree stays in the pocket; balanced, the effort goes where the trees are stuck."""

    def __init__(self, rrt: GoalRRT, start: Tree, goals: np.ndarray, balance: bool = False):
        self.rrt, self.start, self.balance = rrt, start, balance
        self.goal: Tree | None = None
        self.goal_roots: list[int] = []  # node index of each goal configuration, in the order added
        self.reached = -1  # which of them the last path ends at
        self.edges: list[tuple[Tree, int]] = []  # the last path's edges in order: (tree, the node the edge leads into)
        self.add_goals(goals)

    def add_goals(self, goals: np.ndarray) -> None:
        """More roots of the goal tree."""
        for g in np.atleast_2d(goals) if len(goals) else ():
            if self.goal is None:
                self.goal = Tree(g)
                self.trees = [self.start, self.goal]
                self.goal_roots.append(0)
            else:
                self.goal_roots.append(self.goal.add(g[None], -1))

    @property
    def size(self) -> int:
        return self.start.size + (self.goal.size if self.goal is not None else 0)

    def _sample(self, tree: Tree) -> tuple[np.ndarray, int]:
        """A uniform sample and its nearest node, redrawn (up to DOMAIN_DRAWS times) while the sample
        lies outside that node's dynamic domain."""
        rrt = self.rrt
        if not np.isfinite(tree.domain[:tree.size]).any():  # no bounded node yet: the first draw is taken
            q = rrt.rng.uniform(rrt.lower, rrt.upper)
            return q, tree.nearest(q)
        # all draws at once (one generator call), queried in order until one lies inside its node's
        # domain (one compiled call): most cycles query the first draw only
        Q = rrt.rng.uniform(rrt.lower, rrt.upper, size=(DOMAIN_DRAWS, len(rrt.lower)))
        k, i = tree.nearest_in_domain(Q)
        return Q[k], i

    def cycle(self) -> np.ndarray | None:
        """One extend + Connect; the path start → a goal configuration (goals[reached], in the order
        added) once the trees meet. Nothing without a goal configuration."""
        if self.goal is None:
            return None
        if self.balance:
            self.trees = [self.goal, self.start] if self.goal.size < self.start.size else [self.start, self.goal]
        a, b = self.trees
        rrt = self.rrt
        q_rand, i = self._sample(a)
        last, _ = rrt._extend(a, q_rand, connect=False, i=i)
        if rrt.opt.dynamic_domain > 0:
            if last == i:  # blocked at once: this node takes only nearby samples from now on
                a.domain[i] = rrt.opt.dynamic_domain
            elif np.isfinite(a.domain[i]):
                a.domain[i] *= 1.0 + DOMAIN_GROWTH
        other, reached = rrt._extend(b, a.q[last], connect=True, given_target=bool(a.tight[last]))
        self.trees = [b, a]
        if not reached:
            return None
        ia, ib = a.path_indices(last), b.path_indices(other)
        self.reached = self.goal_roots.index(int(self.goal.root[other if b is self.goal else last]))
        (s, i_s), (g, i_g) = ((a, ia), (b, ib)) if a is self.start else ((b, ib), (a, ia))
        # the start tree's path, then the goal tree's backwards: its last node (where the trees met)
        # holds the start tree's last configuration, so the edge into it joins the two
        self.edges = [(s, int(c)) for c in i_s[1:]] + [(g, int(c)) for c in i_g[::-1][:-1]]
        return np.vstack([s.q[i_s], g.q[i_g[::-1][1:]]])


class LazyConnectSearch(ConnectSearch):
    """A balanced ConnectSearch on a lazy check (motion.LazyMotion: the reference's samples, no margins, every
    free configuration a node), as complete as the reference RRT-Connect; a path counts once the validator
    has proven each of its edges (LazyMotion.validate_edge, both ends tight), and the first edge refused is
    cut from its tree with the nodes below it, the search going on without them. What GraspRRT's fallback
    and plan_to_state search with: in a shelf, a box or a cage the validator's margins and refinement cost
    more than the rest of a search, for edges no path uses.

    valid: per tree, the nodes whose edge from their parent passed validation (shared with a later search
    on the same start tree, so its proven edges are not checked again)."""

    def __init__(self, rrt: GoalRRT, start: Tree, goals: np.ndarray, balance: bool = True,
                 valid: dict[Tree, set[int]] | None = None):
        super().__init__(rrt, start, goals, balance)
        self.valid: dict[Tree, set[int]] = {} if valid is None else valid
        self.cut_edges = 0  # edges of found paths the validator refused

    def cycle(self) -> np.ndarray | None:
        path = super().cycle()
        return path if path is not None and self._validated(self.edges) else None

    def _validated(self, edges: list[tuple[Tree, int]]) -> bool:
        """Does every edge of the path found pass the validator (those not proven before, in one batch:
        LazyMotion.first_invalid_edge)? The first that does not is cut; those before it are proven."""
        todo = [(tree, c) for tree, c in edges if c not in self.valid.setdefault(tree, set())]
        if not todo:
            return True
        bad = self.rrt.motion.first_invalid_edge(np.array([tree.q[tree.parent[c]] for tree, c in todo]),
                                                 np.array([tree.q[c] for tree, c in todo]))
        for tree, c in todo[:bad]:
            self.valid[tree].add(c)
        if bad < len(todo):
            tree, c = todo[bad]
            tree.cut(c)
            self.cut_edges += 1
            return False
        return True
