"""Per-pair clearance tables (pair_tables.py) on TALOS: fewer FCL calls, the same verdicts."""
from __future__ import annotations

import re

import fcl
import numpy as np

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.collision import pair_tables
from humanoid_planner.core.collision.geometry import RobotCollisionModel
from humanoid_planner.core.collision.pair_tables import PairTable
from humanoid_planner.core.collision.table_cache import TableCache
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from .shapes import pose, rot
from ..conftest import TALOS
from humanoid_planner.scenarios import talos_arms_out

N = 2000
PANDA = TALOS.parent / "panda_description"


def test_talos_tables_no_false_free_and_fewer_fcl_pairs(talos):
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("box", pose(0.5, -0.35, 1.1, rot([0, 0, 1], 0.5)), (Shape("box", np.eye(4), (0.1, 0.1, 0.3)),))))
    q_ref = talos_arms_out(talos)
    with_tables = CollisionChecker(talos, scene, "r_arm_torso", q_ref, CheckerSettings(margin=0.0075))
    without = CollisionChecker(talos, scene, "r_arm_torso", q_ref, CheckerSettings(margin=0.0075))
    without._tables = {}  # today's path: every pair the covers cannot decide goes to FCL
    for checker in (with_tables, without):  # the numpy levels choose these two pairs (the kernels' hull tests clear one)
        checker.levels.use_compiled = False
    idx = with_tables.joint_indices
    Q = np.random.default_rng(21).uniform(talos.lower[idx], talos.upper[idx], (N, len(idx)))
    ok = with_tables.check_configs(Q)
    pairs = {(with_tables.levels.units[with_tables.levels.self_s[p]], with_tables.levels.units[with_tables.levels.self_o[p]])
             for p in with_tables._tables}
    assert {("torso_2_link", "arm_right_2_link"), ("arm_right_3_link", "arm_right_5_link")} <= pairs
    ref = without.check_configs(Q)
    brute = np.array([without.exact_check(q) for q in Q])
    assert not (ok & ~brute).any()  # 0 false free against brute-force FCL
    assert (ok == ref).all()  # the tables only remove FCL calls, never change a verdict
    s, s0 = with_tables.stats, without.stats
    assert s.table_free > 0
    assert s.exact_pairs < 0.5 * s0.exact_pairs and s.exact_checks < 0.6 * s0.exact_checks
    # motion samples with edge margins (MotionValidator): the tables keep them too
    U = len(with_tables.levels.units)
    w = with_tables.edge_margins(np.random.default_rng(22).uniform(-0.01, 0.01, Q[:500].shape))
    w *= min(1.0, 0.0075 / w[:, :U].max(), 0.015 / w[:, U:].max())
    s.table_free = 0
    assert (with_tables.check_configs(Q[:500], w) == without.check_configs(Q[:500], w)).all()
    assert s.table_free > 0


def test_table_lower_bound_is_below_the_exact_distance(talos):
    """Off-grid configurations: the bound never exceeds FCL's distance of the pair."""
    checker = CollisionChecker(talos, None, "r_arm_torso", talos_arms_out(talos))
    checker.check_configs(checker.q_ref[checker.joint_indices][None])  # builds the tables

    rng = np.random.default_rng(4)
    for p, tab in checker._tables.items():
        assert isinstance(tab, PairTable) and len(tab.cols) <= 2
        q = np.tile(checker.q_ref[checker.joint_indices], (200, 1))
        q[:, tab.cols] = rng.uniform(tab.lo, tab.lo + tab.step * (np.array(tab.dist.shape) - 1), (200, len(tab.cols)))
        lb = tab.lower_bound(q)
        beyond = q[:1].copy()
        beyond[0, tab.cols[0]] = tab.lo[0] - 0.5  # outside the grid: the bound proves nothing
        assert tab.lower_bound(beyond)[0] == -np.inf
        R, t = checker.levels.fk(q)
        a, b = (checker.levels.unit_shape_tab[u][checker.levels.unit_shape_tab[u] >= 0] for u in (checker.levels.self_s[p], checker.levels.self_o[p]))
        for g in range(len(q)):
            for m in (*a, *b):
                f = checker.levels.frame_of[m]
                checker.levels.moving[m].obj.setRotation(R[g, f] @ checker.levels.shape_R[m])
                checker.levels.moving[m].obj.setTranslation(R[g, f] @ checker.levels.shape_t[m] + t[g, f])
            d = min(fcl.distance(checker.levels.moving[x].obj, checker.levels.moving[y].obj, fcl.DistanceRequest(), fcl.DistanceResult())
                    for x in a for y in b)
            assert lb[g] <= max(d, 0.0) + 1e-9


def test_talos_env_tables_unit_against_fixed_link(talos):
    """l_arm (torso fixed): arm_left_2 against the fixed torso_2 reaches FCL in nearly every
    configuration without a table; with one, far fewer FCL calls, the verdicts of brute-force FCL,
    and the bound stays below FCL's distance off the grid."""
    q_ref = talos_arms_out(talos)
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),))
    with_tables = CollisionChecker(talos, scene, "l_arm", q_ref)
    without = CollisionChecker(talos, scene, "l_arm", q_ref)
    without._env_tables = {}
    for checker in (with_tables, without):  # the numpy levels choose this pair (the kernels' hull tests clear it)
        checker.levels.use_compiled = False
    idx = with_tables.joint_indices
    Q = np.random.default_rng(23).uniform(talos.lower[idx], talos.upper[idx], (1000, len(idx)))
    ok = with_tables.check_configs(Q)
    names = {(with_tables.levels.units[u], with_tables.levels.fixed[e].name) for u, e in with_tables._env_tables}
    assert ("arm_left_2_link", "torso_2_link") in names
    brute = np.array([without.exact_check(q) for q in Q])
    assert (ok == brute).all()
    without.stats.reset()
    assert (without.check_configs(Q) == ok).all()
    assert with_tables.stats.exact_checks < 0.6 * without.stats.exact_checks
    rng = np.random.default_rng(5)
    for (u, e), tab in with_tables._env_tables.items():
        q = np.tile(q_ref[idx], (100, 1))
        q[:, tab.cols] = rng.uniform(tab.lo, tab.lo + tab.step * (np.array(tab.dist.shape) - 1), (100, len(tab.cols)))
        lb = tab.lower_bound(q)
        R, t = with_tables.levels.fk(q)
        shapes = with_tables.levels.unit_shape_tab[u][with_tables.levels.unit_shape_tab[u] >= 0]
        for g in range(len(q)):
            d = np.inf
            for m in shapes:
                f = with_tables.levels.frame_of[m]
                obj = with_tables.levels.moving[m].obj
                obj.setRotation(R[g, f] @ with_tables.levels.shape_R[m])
                obj.setTranslation(R[g, f] @ with_tables.levels.shape_t[m] + t[g, f])
                d = min(d, fcl.distance(obj, with_tables.levels.fixed[e].obj, fcl.DistanceRequest(), fcl.DistanceResult()))
            assert lb[g] <= max(d, 0.0) + 1e-9


def test_the_compiled_levels_choose_a_fixed_link_pair_level_1_flags_everywhere(talos):
    """With the compiled levels the hulls decide arm_left_2 against the fixed torso_2 without FCL, but level 1
    flags the pair in every configuration and the kernel runs its cover and hull tests each time: the env
    selection takes it by that share too (FLAG_SHARE), as the self selection does."""
    checker = CollisionChecker(talos, None, "l_arm", talos.state("half_sitting"))
    assert checker.levels.use_compiled
    chosen = pair_tables.select_env_pairs(checker, pair_tables.env_candidates(checker))
    assert ("arm_left_2_link", "torso_2_link") in {(checker.levels.units[u], checker.levels.fixed[e].name)
                                                   for u, e, _ in chosen}


def test_a_checker_whose_q_ref_rounds_across_a_selection_step_finds_its_tables(talos, monkeypatch):
    """TALOS's half_sitting has a torso joint at -0.5254: rounded to PATH_RESOLUTION (where tables are built,
    table_q_ref) it is -0.525, on the other side of a SELECTION_RESOLUTION step. The selection is keyed by
    the rounded values, so the checker at half_sitting finds what the checker at table_q_ref built (keyed by
    its own q_ref, every TALOS plan from half_sitting checked without tables)."""
    monkeypatch.setattr(RobotCollisionModel.for_robot(talos), "pair_tables", TableCache())
    monkeypatch.setattr(pair_tables, "select_env_pairs", lambda view, cand: [])  # one self table is enough
    q_ref = talos.state("half_sitting")
    checker = CollisionChecker(talos, None, "l_arm", q_ref)  # its tables are looked up at its first check
    others = np.setdiff1d(np.arange(talos.dof), checker.joint_indices)
    step = pair_tables.SELECTION_RESOLUTION
    built_at = np.round(q_ref / pair_tables.PATH_RESOLUTION) * pair_tables.PATH_RESOLUTION
    assert (np.round(q_ref[others] / step) != np.round(built_at[others] / step)).any()  # the case in point
    assert _tables_by_links(checker)
    idx = checker.joint_indices
    Q = np.random.default_rng(43).uniform(talos.lower[idx], talos.upper[idx], (300, len(idx)))
    ok = checker.check_configs(Q)
    assert checker.stats.table_free > 0
    assert (ok == np.array([checker.exact_check(q) for q in Q])).all()


def _tables_by_links(checker: CollisionChecker) -> dict[tuple[str, str], PairTable]:
    """The checker's self and env tables (built by one check), keyed by the names of the pair's links."""
    checker.check_configs(checker.q_ref[checker.joint_indices][None])
    out = {(checker.levels.units[checker.levels.self_s[p]], checker.levels.units[checker.levels.self_o[p]]): tab
           for p, tab in checker._tables.items()}
    out.update({(checker.levels.units[u], checker.levels.fixed[e].name): tab for (u, e), tab in checker._env_tables.items()})
    return out


def _path_joints(robot, a: str, b: str) -> set[str]:
    """Joints on the kinematic-tree path between links a and b (from the model, not from the keys)."""
    chains = [{j.name for j in robot.chain_joints(robot.root_link, link)} for link in (a, b)]
    return chains[0] ^ chains[1]


def test_tables_are_reused_when_joints_off_their_path_move(monkeypatch):
    """A live robot's q_ref changes between plans (the other arm, the head, the legs, the torso): a
    table depends only on the joints on the path between its pair's links, so after a move exactly the
    tables with a moved joint on that path are built anew and every other one is reused — computed from
    the kinematic tree for whichever pairs the selection chose on this CPU. Every env candidate gets a
    table here, so that tables both behind the moved joints (arm_left_2 vs head_2: torso and head joints
    on the path; the torso moves both sides) and not (vs torso_2) exist on every machine. Keying tables by the whole q_ref rebuilds
    them all and keying by nothing rebuilds none: both fail. Verdicts stay those of brute-force FCL."""
    robot = RobotModel.from_urdf_srdf(TALOS / "robots/talos_reduced.urdf", TALOS / "srdf/talos.srdf")  # own caches
    monkeypatch.setattr(pair_tables, "select_env_pairs", lambda view, cand: cand)
    q_ref = talos_arms_out(robot)
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),))
    first = CollisionChecker(robot, scene, "l_arm", q_ref)
    previous = _tables_by_links(first)
    idx = first.joint_indices
    Q = np.random.default_rng(29).uniform(robot.lower[idx], robot.upper[idx], (100, len(idx)))
    moves = (("arm_right", "head", "leg"), ("torso",))
    any_rebuilt = False
    for prefixes in moves:
        moved = [n for n in robot.joint_names if n.startswith(prefixes)]
        q_ref = q_ref.copy()
        q_ref[[robot.joint_names.index(n) for n in moved]] += 0.05
        q_ref = np.clip(q_ref, robot.lower, robot.upper)
        checker = CollisionChecker(robot, scene, "l_arm", q_ref)
        current = _tables_by_links(checker)
        assert current.keys() == previous.keys()
        rebuilt = {pair for pair in current if current[pair].dist is not previous[pair].dist}
        expected = {pair for pair in current if _path_joints(robot, *pair) & set(moved)}
        assert rebuilt == expected, prefixes
        assert len(expected) < len(current), prefixes  # keying by the whole q_ref would rebuild all
        any_rebuilt = any_rebuilt or bool(expected)
        assert (checker.check_configs(Q) == np.array([checker.exact_check(q) for q in Q])).all()
        previous = current
    assert any_rebuilt  # keying by nothing would rebuild none


def test_a_check_never_waits_for_tables_the_builder_makes_them(talos, monkeypatch):
    """No plan waits for a table (a TALOS l_arm set takes seconds; a first plan with a 1 s timeout timed out
    building one): with tables built in the background (the default), a checker whose tables are missing
    checks without them, hands them to pair_tables.BUILDER, and a later checker has them; same verdicts."""
    pair_tables.build_in_background(True)  # the conftest's fixture restores it
    model = RobotCollisionModel.for_robot(talos)
    monkeypatch.setattr(model, "pair_tables", TableCache())  # none built yet for this robot
    q_ref = talos_arms_out(talos)
    first = CollisionChecker(talos, None, "l_arm", q_ref)
    idx = first.joint_indices
    Q = np.random.default_rng(31).uniform(talos.lower[idx], talos.upper[idx], (300, len(idx)))
    ok = first.check_configs(Q)
    assert first._tables == {} and first._env_tables == {} and first._cluster_tables == {}
    assert pair_tables.BUILDER.wait_idle(120)
    later = CollisionChecker(talos, None, "l_arm", q_ref)
    assert (later.check_configs(Q) == ok).all()
    assert len(later._tables) + len(later._env_tables) + len(later._cluster_tables) > 0
    assert later.stats.table_free > 0 and first.stats.table_free == 0  # the later one uses them
    assert (ok == np.array([later.exact_check(q) for q in Q])).all()


def test_joint_states_that_jitter_on_the_path_reuse_the_tables_with_a_slack(talos, monkeypatch):
    """A live robot's other joints jitter between plans (joint_states noise, a simulator's drift): tables
    are built at the joints outside the group rounded to PATH_RESOLUTION, so a q_ref within half of it
    takes the same tables, their bounds lowered by how far the jitter may move each pair (PairTable.slack);
    the verdicts stay brute-force FCL's (a move past the resolution builds them anew: the test above)."""
    def behind_joints_off_the_group(view, cand):  # one env table with a joint off the group on its path
        return [(u, e, cols) for u, e, cols in cand
                if set(_path_joints(talos, view.levels.units[u], view.levels.fixed[e].name)) - set(view.joint_names)][:1]

    monkeypatch.setattr(pair_tables, "select_pairs", lambda view: [])
    monkeypatch.setattr(pair_tables, "select_env_pairs", behind_joints_off_the_group)
    monkeypatch.setattr(RobotCollisionModel.for_robot(talos), "pair_tables", TableCache())
    q_ref = talos_arms_out(talos)
    first = CollisionChecker(talos, None, "l_arm", q_ref)
    base = _tables_by_links(first)
    others = np.setdiff1d(np.arange(talos.dof), first.joint_indices)
    behind = {pair for pair in base if _path_joints(talos, *pair) & {talos.joint_names[i] for i in others}}
    assert behind
    jitter = pair_tables.table_q_ref(first)
    jitter[others] += np.random.default_rng(41).uniform(-4e-4, 4e-4, len(others))
    checker = CollisionChecker(talos, None, "l_arm", jitter)
    tabs = _tables_by_links(checker)
    assert tabs.keys() == base.keys() and all(tabs[pair].dist is base[pair].dist for pair in base)  # none rebuilt
    assert all(0 < tabs[pair].slack < 0.005 for pair in behind)
    idx = checker.joint_indices
    Q = np.random.default_rng(37).uniform(talos.lower[idx], talos.upper[idx], (300, len(idx)))
    assert (checker.check_configs(Q) == np.array([checker.exact_check(q) for q in Q])).all()


def _spheres_only_panda(tmp_path) -> RobotModel:
    """example-robot-data's Panda with only its collision spheres (the cylinders dropped): an arm of
    many small units, like the spherized arms of sphere-based planners."""
    text = (PANDA / "urdf/panda_collision.urdf").read_text()
    text = re.sub(r"<collision>(?:(?!</collision>).)*?<cylinder(?:(?!</collision>).)*?</collision>", "", text,
                  flags=re.S)
    path = tmp_path / "panda_spheres.urdf"
    path.write_text(text)
    return RobotModel.from_urdf_srdf(path, PANDA / "srdf/panda.srdf")


def test_cluster_tables_of_a_spheres_only_arm(tmp_path):
    """Cluster pairs moved by 1–2 joints (link5's spheres against the wrist's) get one table each, which
    the kernel reads before visiting their unit pairs: brute-force FCL's verdicts, those of the same
    checker without cluster tables with and without edge margins, and the bound below FCL's distance."""
    robot = _spheres_only_panda(tmp_path)
    scene = SceneSnapshot(1, robot.root_link, (
        SceneObject("table", pose(0.5, 0, 0.1), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("post", pose(0.4, -0.3, 0.5, rot([0, 0, 1], 0.4)), (Shape("box", np.eye(4), (0.06, 0.06, 0.8)),))))
    settings = CheckerSettings(margin=0.0075)
    checker = CollisionChecker(robot, scene, "arm", robot.home, settings)
    without = CollisionChecker(robot, scene, "arm", robot.home, settings)
    without._cluster_tables = {}
    idx = checker.joint_indices
    Q = np.random.default_rng(31).uniform(robot.lower[idx], robot.upper[idx], (1500, len(idx)))
    ok = checker.check_configs(Q)
    assert checker._cluster_tables and checker.stats.table_free > 0
    assert 0.05 * len(Q) < (~ok).sum() < 0.95 * len(Q)
    assert (ok == without.check_configs(Q)).all()
    assert (ok[:300] == np.array([checker.exact_check(q) for q in Q[:300]])).all()
    U = len(checker.levels.units)
    w = checker.edge_margins(np.random.default_rng(32).uniform(-0.01, 0.01, Q[:500].shape))
    w *= min(1.0, 0.0075 / w[:, :U].max(), 0.015 / w[:, U:].max())
    assert (checker.check_configs(Q[:500], w) == without.check_configs(Q[:500], w)).all()
    lv = checker.levels
    rng = np.random.default_rng(33)
    for g, tab in checker._cluster_tables.items():
        members = lv.cl_self.members[lv.cl_self.start[g]:lv.cl_self.start[g] + lv.cl_self.count[g]]
        q = np.tile(robot.home[idx], (50, 1))
        q[:, tab.cols] = rng.uniform(tab.lo, tab.lo + tab.step * (np.array(tab.dist.shape) - 1), (50, len(tab.cols)))
        lb = tab.lower_bound(q)
        R, t = lv.fk(q)
        for k in range(len(q)):
            c = {}
            for u in {*lv.self_s[members].tolist(), *lv.self_o[members].tolist()}:
                m = lv.unit_shape_tab[u][0]
                c[u] = (R[k, lv.frame_of[m]] @ lv.shape_t[m] + t[k, lv.frame_of[m]], lv.sbox_rho[m])
            d = min(np.linalg.norm(c[a][0] - c[b][0]) - c[a][1] - c[b][1]
                    for a, b in zip(lv.self_s[members], lv.self_o[members]))
            assert lb[k] <= max(d, 0.0) + 1e-9


def test_a_table_over_three_joints_bounds_its_pair_and_the_kernel_reads_it(talos, monkeypatch):
    """A self pair moved by three joints (TIAGo's torso lift against its upper arm: flagged by level 1 in
    every configuration) gets a 3-D grid: its bound stays below FCL's distance off the grid points, and the
    compiled levels read it (TablePack's rows of three) with the verdicts of brute-force FCL."""
    monkeypatch.setattr(pair_tables, "GRID_3D", 6)  # a coarse grid: quick to build, the same arithmetic
    checker = CollisionChecker(talos, None, "r_arm_torso", talos_arms_out(talos))
    lv = checker.levels
    meshes = lambda u: any(lv.shape_kind[m] == "mesh" for m in lv.unit_shape_tab[u] if m >= 0)  # noqa: E731
    p, cols = next((p, np.nonzero(lv.pair_levers[p])[0]) for p in range(len(lv.self_s))
                   if len(np.nonzero(lv.pair_levers[p])[0]) == 3 and meshes(lv.self_s[p]) and meshes(lv.self_o[p]))
    tab = pair_tables.build_table(checker, p, cols)
    assert tab.dist.shape == (6, 6, 6)
    rng = np.random.default_rng(5)
    q = np.tile(checker.q_ref[checker.joint_indices], (300, 1))
    q[:, cols] = rng.uniform(tab.lo, tab.lo + tab.step * 5, (300, 3))
    lb = tab.lower_bound(q)
    R, t = lv.fk(q)
    a, b = (lv.unit_shape_tab[u][lv.unit_shape_tab[u] >= 0] for u in (lv.self_s[p], lv.self_o[p]))
    for g in range(len(q)):
        for m in (*a, *b):
            f = lv.frame_of[m]
            lv.moving[m].obj.setRotation(R[g, f] @ lv.shape_R[m])
            lv.moving[m].obj.setTranslation(R[g, f] @ lv.shape_t[m] + t[g, f])
        d = min(fcl.distance(lv.moving[x].obj, lv.moving[y].obj, fcl.DistanceRequest(), fcl.DistanceResult())
                for x in a for y in b)
        assert lb[g] <= max(d, 0.0) + 1e-9
    # the kernel with this table alone: the same verdicts as brute force, and the table used
    checker._tables = {p: tab}
    lv.set_tables({p: tab}, {}, {})
    idx = checker.joint_indices
    Q = np.random.default_rng(6).uniform(talos.lower[idx], talos.upper[idx], (600, len(idx)))
    Q[:, cols] = rng.uniform(tab.lo, tab.lo + tab.step * 5, (600, 3))
    _, _, _, _, _, n_tab = lv.compiled_12(np.ascontiguousarray(Q), None, None)
    assert n_tab > 0
    ok = checker.check_configs(Q)
    assert (ok == np.array([checker.exact_check(x) for x in Q])).all()
