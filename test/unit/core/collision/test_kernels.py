"""kernels.py: the compiled FK and levels 1–2 give the numpy levels' verdicts, with and without edge
margins, on capsules (ARMAR-III) and meshes (TALOS: inner spheres, fixed-link covers, hull vertex and
plane tests, a scene cylinder and mesh whose boxes are not exact), with no more FCL calls, and compile
once per argument types."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision import kernels
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import ARMS, load_humanoid, talos_arms_out

from .shapes import clutter, pose, rot


def _scene(root: str, x: float, z: float) -> SceneSnapshot:
    tetra = (np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.2, 0], [0, 0, 0.2]], float),
             np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    return SceneSnapshot(1, root, (
        SceneObject("table", pose(x, 0, z - 0.35), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("box", pose(x - 0.2, 0.3, z, rot([0, 0, 1], 0.5)), (Shape("box", np.eye(4), (0.1, 0.1, 0.3)),)),
        SceneObject("post", pose(x - 0.1, -0.25, z), (Shape("cylinder", np.eye(4), (0.5, 0.04)),)),
        SceneObject("ball", pose(x - 0.3, 0.0, z + 0.2), (Shape("sphere", np.eye(4), (0.06,)),)),
        SceneObject("tetra", pose(x - 0.25, -0.05, z - 0.1), (Shape("mesh", np.eye(4), (), *tetra),)),
    ))


@pytest.mark.parametrize("robot_name, group", [("armar3", "left_arm_torso"), ("talos", "l_arm"),
                                               ("talos", "r_arm_torso")])
def test_compiled_levels_match_the_numpy_levels(request, robot_name, group):
    robot = request.getfixturevalue(robot_name)
    talos = robot_name == "talos"
    q_ref = talos_arms_out(robot) if talos else robot.home
    scene = _scene(robot.root_link, 0.55 if talos else 0.6, 1.0 if talos else 1.1)
    settings = CheckerSettings(padding=0.01, margin=0.0075)
    compiled = CollisionChecker(robot, scene, group, q_ref, settings)
    numpy_levels = CollisionChecker(robot, scene, group, q_ref, settings)
    numpy_levels.levels.use_compiled = False
    assert compiled.levels.use_compiled and (compiled.levels.f_inner.counts > 0).any()
    idx = compiled.joint_indices
    rng = np.random.default_rng(7)
    home = q_ref[idx]
    Q = np.vstack([rng.uniform(robot.lower[idx], robot.upper[idx], (400, len(idx))),
                   np.clip(home + rng.uniform(-0.5, 0.5, (400, len(idx))), robot.lower[idx], robot.upper[idx])])
    U = len(compiled.levels.units)
    w = rng.uniform(0, 1, (len(Q), len(compiled._levers)))
    w[:, :U] *= compiled.margin
    w[:, U:] *= 2 * compiled.margin
    for margins in (None, w):
        a = np.concatenate([compiled.check_configs(Q[i:i + 50], None if margins is None else margins[i:i + 50])
                            for i in range(0, len(Q), 50)])
        b = numpy_levels.check_configs(Q, margins)
        assert np.array_equal(a, b)
        assert 0.1 * len(Q) < (~a).sum() < 0.9 * len(Q)  # both verdicts well represented
    s, r = compiled.stats, numpy_levels.stats
    assert s.level1_free == r.level1_free
    # the hull tests of meshes against exact boxes decide some of what the numpy levels leave to FCL
    assert s.level2_colliding >= r.level2_colliding > 0 and s.exact_checks <= r.exact_checks
    assert s.exact_checks > 0
    # the frames too
    R0, t0 = compiled.levels.fk(Q[:20])
    R1, t1 = compiled.levels.compiled_12(Q[:20], None, None)[:2]
    assert np.allclose(R0, R1, atol=1e-12) and np.allclose(t0, t1, atol=1e-12)


def test_one_compilation_serves_configurations_and_motions(armar3):
    """Checks with and without edge margins (and `kernels.warm`) use one specialization each: a second
    one would compile (seconds) inside a plan."""
    checker = CollisionChecker(armar3, _scene(armar3.root_link, 0.6, 1.1), "left_arm_torso", armar3.home,
                               CheckerSettings(margin=0.0075))
    q = armar3.home[checker.joint_indices][None].repeat(3, 0)
    checker.check_configs(q)
    checker.check_configs(q, np.zeros((3, len(checker._levers))))
    checker.first_collision(q, np.array([[0, 1], [1, 3]]))
    kernels.warm()
    assert len(kernels.levels_12.signatures) == 1
    assert len(kernels.screen_batches.signatures) == 1
    assert len(kernels.make_kernel_data.signatures) == 1  # the arrays' types are the same for every checker
    assert len(kernels.fk_batch.signatures) == 1


@pytest.mark.parametrize("robot_name, group", [("armar3", "left_arm_torso"), ("talos", "l_arm")])
def test_first_collision_finds_the_first_colliding_configuration(request, robot_name, group):
    """first_collision (one kernel call for the batches, back in Python only for FCL) finds the first
    colliding configuration that check_configs batch by batch finds, checking no configuration past it
    that the levels or triangles decide, on capsules (ARMAR-III) and meshes (TALOS: triangle tests, FCL)."""
    robot = request.getfixturevalue(robot_name)
    talos = robot_name == "talos"
    q_ref = talos_arms_out(robot) if talos else robot.home
    scene = _scene(robot.root_link, 0.55 if talos else 0.6, 1.0 if talos else 1.1)
    one, other, probe = (CollisionChecker(robot, scene, group, q_ref, CheckerSettings(padding=0.01)) for _ in range(3))
    idx = one.joint_indices
    lo, hi = robot.lower[idx], robot.upper[idx]
    rng = np.random.default_rng(5)
    A = np.clip(q_ref[idx] + rng.uniform(-1.0, 1.0, (400, len(idx))), lo, hi)
    A = A[probe.check_configs(A)]  # motions from free configurations
    found = []
    for a in A[:60]:  # motions of 40 samples in batches of 4, 8, 16, 12
        b = np.clip(a + rng.uniform(-1.0, 1.0, len(idx)), lo, hi)
        Q = a + np.linspace(0, 1, 41)[1:, None] * (b - a)
        bounds = np.array([[0, 4], [4, 12], [12, 28], [28, 40]])
        expect = len(Q)
        for s, e in bounds:
            bad = np.flatnonzero(~other.check_configs(Q[s:e]))
            if len(bad):
                expect = s + int(bad[0])
                break
        found.append(one.first_collision(Q, bounds))
        assert found[-1] == expect
    s, r = one.stats, other.stats
    assert len(found) == 60 and 10 < sum(f < 40 for f in found) < 50 and s.exact_checks > 0
    # it stops at the first collision, within its batch too: fewer checks, FCL calls no more
    assert s.configs_checked < r.configs_checked and s.exact_checks <= r.exact_checks
    assert s.configs_checked >= sum(found) + sum(f < 40 for f in found)  # every one up to the first collision
    assert s.level1_free + s.level2_free + s.level2_colliding + s.exact_checks == s.configs_checked
    assert not talos or one.stats.level2_colliding > 0 and len(one._wit_n) > 0


@pytest.mark.parametrize("robot_name", ["talos", "panda"])
def test_hull_tests_agree_with_brute_force_fcl(request, robot_name):
    """The hull vertex and plane tests (meshes against exact boxes: the scene's, Panda's finger boxes)
    decide pairs without FCL; every verdict stays brute-force FCL's (exact_check), near obstacles too."""
    if robot_name == "talos":
        robot, group = request.getfixturevalue("talos"), "l_arm"
        q_ref = talos_arms_out(robot)
        scene = _scene(robot.root_link, 0.55, 1.0)
    else:
        robot, group = load_humanoid("panda"), ARMS["panda"].left
        q_ref = robot.home
        scene = _scene(robot.root_link, 0.55, 0.4)
    checker = CollisionChecker(robot, scene, group, q_ref, CheckerSettings(padding=0.01))
    assert (checker.levels.hull_n > 0).sum() > 5
    assert robot_name == "talos" or checker.levels.sbox_ok.any()
    idx = checker.joint_indices
    rng = np.random.default_rng(3)
    Q = np.clip(q_ref[idx] + rng.uniform(-0.8, 0.8, (500, len(idx))), robot.lower[idx], robot.upper[idx])
    ok = checker.check_configs(Q)
    to_fcl = checker.stats.exact_checks
    assert np.array_equal(ok, np.array([checker.exact_check(q) for q in Q]))
    assert 50 < (~ok).sum() < 450
    numpy_levels = CollisionChecker(robot, scene, group, q_ref, CheckerSettings(padding=0.01))
    numpy_levels.levels.use_compiled = False
    numpy_levels.check_configs(Q)
    assert to_fcl <= numpy_levels.stats.exact_checks
    assert robot_name == "talos" or to_fcl < 0.8 * numpy_levels.stats.exact_checks  # Panda: 87 of 124 here


def test_box_links_are_decided_by_their_corners_and_faces(armar3):
    """A box link's corners and face planes are its hull (geometry.box_hull_points): the kernels decide it
    against a scene box or another link's box without FCL where the spheres cannot, and every verdict stays
    brute-force FCL's. Without them (the hull tables of box shapes emptied) the same configurations
    send more pairs to FCL."""
    scene = SceneSnapshot(1, armar3.root_link, clutter(np.random.default_rng(9), 60, armar3, ("left_arm", "right_arm")))
    group = "right_arm_torso"
    with_hulls = CollisionChecker(armar3, scene, group, armar3.home)
    boxes = [m for m, kind in enumerate(with_hulls.levels.shape_kind) if kind == "box"]
    assert boxes and (with_hulls.levels.hull_n[boxes] == 8).all() and with_hulls.levels.hull_pts[boxes].all()
    without = CollisionChecker(armar3, scene, group, armar3.home)
    without.levels.hull_n = without.levels.hull_n.copy()  # (the arrays are the group's, shared by its checkers)
    without.levels.hull_n[boxes] = 0
    idx = with_hulls.joint_indices
    rng = np.random.default_rng(8)
    Q = np.clip(armar3.home[idx] + rng.uniform(-0.8, 0.8, (600, len(idx))), armar3.lower[idx], armar3.upper[idx])
    ok = with_hulls.check_configs(Q)
    assert np.array_equal(ok, np.array([with_hulls.exact_check(q) for q in Q]))
    assert 50 < (~ok).sum() < 550
    assert np.array_equal(without.check_configs(Q), ok)
    assert with_hulls.stats.exact_checks < 0.8 * without.stats.exact_checks  # 35 against 52 here


def test_moving_meshes_with_big_hulls_get_a_bounding_polytope_that_only_proves_apart(talos):
    """TALOS's arm_left_1 / arm_left_3 hulls have more vertices than the kernels take (HULL_POINTS_MAX): they
    get their bounding polytope (geometry.bounding_polytope), whose vertices are not mesh points, so it may
    prove a pair apart but never a contact (hull_pts False). Fewer FCL calls than with no hull at all, every
    verdict brute-force FCL's, near contact too."""
    q_ref = talos_arms_out(talos)
    scene = _scene(talos.root_link, 0.55, 1.0)
    checker = CollisionChecker(talos, scene, "l_arm", q_ref, CheckerSettings(padding=0.01))
    lv = checker.levels
    bound = np.flatnonzero((lv.hull_n > 0) & ~lv.hull_pts)
    assert {lv.units[lv.unit_of_shape[m]] for m in bound} >= {"arm_left_1_link", "arm_left_3_link"}
    without = CollisionChecker(talos, scene, "l_arm", q_ref, CheckerSettings(padding=0.01))
    without.levels.hull_n = without.levels.hull_n.copy()  # (shared by the group's checkers)
    without.levels.hull_n[bound] = 0  # as before: no hull test for them
    idx = checker.joint_indices
    rng = np.random.default_rng(5)
    Q = np.clip(q_ref[idx] + rng.uniform(-1.2, 1.2, (600, len(idx))), talos.lower[idx], talos.upper[idx])
    ok = checker.check_configs(Q)
    assert np.array_equal(ok, without.check_configs(Q))
    assert checker.stats.exact_checks < 0.7 * without.stats.exact_checks  # 90 against 215 here
    assert np.array_equal(ok, np.array([checker.exact_check(q) for q in Q]))
    assert 50 < (~ok).sum() < 550


def test_a_bounding_polytopes_vertex_inside_a_box_proves_nothing():
    """kernels._shape_pair: a hull vertex inside the other shape's box proves contact when the vertices are
    mesh points (hv_pts), and nothing when they are a bounding polytope's (the mesh may end short of them);
    a box beyond one of the polytope's faces is still proven apart."""
    V = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])[None]
    P = np.array([[1, 0, 0, 0.1], [-1, 0, 0, 0.1], [0, 1, 0, 0.1], [0, -1, 0, 0.1], [0, 0, 1, 0.1],
                  [0, 0, -1, 0.1]], float)[None]
    hv, hp = np.concatenate([V, np.zeros_like(V)]), np.concatenate([P, np.zeros_like(P)])
    hv_n, hp_n = np.array([8, 0]), np.array([6, 0])
    R, t = np.tile(np.eye(3), (1, 1, 1, 1)), np.zeros((1, 1, 3))
    sb_ok, sb_h, sb_rho = np.array([False, True]), np.array([[0, 0, 0], [0.02, 0.02, 0.02]], float), np.zeros(2)
    shape_R, frame_of = np.tile(np.eye(3), (2, 1, 1)), np.zeros(2, dtype=np.int64)
    scratch = (np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(3))

    def verdict(points: bool, box_at) -> int:
        shape_t = np.array([[0, 0, 0], box_at], float)
        return kernels._shape_pair(R, t, 0, 0, 1, hv, hv_n, hp, hp_n, np.array([points, True]), sb_ok, sb_h, sb_rho,
                                   shape_R, shape_t, frame_of, 0.0, 1e-4, *scratch)

    assert verdict(True, (0.1, 0.1, 0.1)) == 1  # a mesh point inside the box: contact
    assert verdict(False, (0.1, 0.1, 0.1)) == 0  # a bounding polytope's corner: undecided (FCL's word)
    assert verdict(False, (0.2, 0.0, 0.0)) == -1  # beyond a face: apart either way
    assert verdict(True, (0.2, 0.0, 0.0)) == -1


def test_a_mesh_point_within_a_pairs_clearance_proves_it_too_close():
    """kernels._hull_box: a hull vertex (a mesh point) closer to an exact box than the pair's required
    clearance proves the pair too close, as FCL's padded check finds it (a motion's samples next to a shelf
    board or a cage's floor miss their edge margins: they were FCL distance queries, one per sample); a
    bounding polytope's vertices prove nothing; beyond the clearance a face proves the pair apart."""
    V = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])
    P = np.array([[1, 0, 0, 0.1], [-1, 0, 0, 0.1], [0, 1, 0, 0.1], [0, -1, 0, 0.1], [0, 0, 1, 0.1],
                  [0, 0, -1, 0.1]], float)
    R, t = np.tile(np.eye(3), (1, 1, 1, 1)), np.zeros((1, 1, 3))
    eps = 1e-4

    def verdict(clearance: float, gap: float, rho: float = 0.0, points: bool = True) -> int:
        """The cube against a box (or a rounded one) `gap` beyond its +x face."""
        h = np.array([0.05, 0.3, 0.3])
        bt = np.array([0.1 + gap + rho + h[0], 0.0, 0.0])
        return kernels._hull_box(R, t, 0, 0, V, 8, P, 6, np.eye(3), bt, h, rho, clearance + eps,
                                 eps if points else np.inf)

    assert verdict(0.01, 0.005) == 1  # 5 mm away, 1 cm asked: too close
    assert verdict(0.01, 0.005, rho=0.02) == 1
    assert verdict(0.01, 0.005, points=False) == 0  # a bounding polytope: FCL's word
    assert verdict(0.004, 0.005) == -1 and verdict(0.004, 0.005, points=False) == -1  # apart by more than asked
    assert verdict(0.0, 0.005) == -1 and verdict(0.0, -0.001) == 1  # no clearance: apart / overlapping
    assert verdict(0.0, -eps / 2) == 0  # within rounding of touching: FCL's word


def _verts_box_one_by_one(R, t, V, bR, bt, bh, rho, pad, reach) -> int:
    """kernels._verts_box's definition, vertex by vertex in the world: 1 at the first vertex inside the box
    by more than -(reach + rho) (reach + rho ≤ 0) or within reach + rho of it (> 0); -1 when all lie beyond
    one of its faces grown by rho + pad; else 0."""
    if len(V) == 0:
        return -1  # no points: none near the box
    L = ((V @ R.T + t) - bt) @ bR  # box coordinates
    r = reach + rho
    for x in np.abs(L) - bh:
        if x.max() < min(r, 0.0) or (r > 0.0 and np.sum(np.maximum(x, 0.0) ** 2) < r * r):
            return 1
    e = bh + rho + pad
    return -1 if (L.min(0) > e).any() or (L.max(0) < -e).any() else 0


def test_hull_vertices_against_a_box_decide_as_one_by_one():
    """kernels._verts_box scans a hull's vertices in one composed transform without a branch (minima and
    maxima, decided after the loop): its verdicts are those of the vertex-by-vertex definition, for
    boxes around, inside, beside and far from random hulls, rounded or not, with a reach below zero, above
    zero and -inf (a bounding polytope: no contact proof); and for no vertex at all (the rows past nv are padding)."""
    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(3000):
        V = rng.normal(size=(int(rng.integers(0, 40)), 3)) * 0.05
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        bR, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        t, bt = rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.1
        bh = rng.uniform(0.01, 0.15, size=3)
        rho = float(rng.choice([0.0, rng.uniform(0, 0.02)]))
        pad = float(rng.uniform(0, 0.02))
        reach = float(rng.choice([-np.inf, -rng.uniform(0, 0.01), rng.uniform(0, 0.02)]))
        want = _verts_box_one_by_one(R, t, V, bR, bt, bh, rho, pad, reach)
        padded = np.vstack([V, rng.normal(size=(3, 3)) * 0.05])  # rows past nv are padding (a hull array's)
        got = kernels._verts_box(R[None, None], t[None, None], 0, 0, padded, len(V), bR, bt, bh, rho, pad, reach)
        assert got == want
        seen.add(want)
    assert seen == {-1, 0, 1}


def _lowest_points(robot, q: np.ndarray, links: list[str]) -> np.ndarray:
    """World points of the links' mesh vertices and box corners at q."""
    out = []
    for link, T in zip(links, robot.link_poses(q, links)):
        for g in robot.collision_geometry.get(link, ()):
            if g.kind == "mesh":
                p = np.asarray(g.vertices, float)
            elif g.kind == "box":
                h = np.asarray(g.dims[:3], float) / 2
                p = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1]) for z in (-h[2], h[2])])
            else:
                continue
            G = T @ g.origin
            out.append(p @ G[:3, :3].T + G[:3, 3])
    return np.vstack(out)


def test_a_hand_hovering_within_the_padding_is_decided_without_fcl():
    """Panda's hand tilted, a corner 3 mm above a plate, and configurations around it with random edge
    margins (a motion's samples along a shelf board or a cage's floor): the kernels prove the pairs too
    close from the hand's mesh points, where its inner spheres lie too deep to (an FCL distance query
    each before: 71 of 200 configurations here, 3 now), and every verdict is brute-force FCL's."""
    robot, group = load_humanoid("panda"), ARMS["panda"].left
    hand = ["panda_hand", "panda_leftfinger", "panda_rightfinger"]
    q0 = robot.home.copy()
    q0[robot.group_joint_indices(group)[5]] += 0.6  # the hand tilted: a corner lowest
    pts = _lowest_points(robot, q0, hand)
    low = pts[np.argmin(pts[:, 2])]
    plate = SceneObject("plate", pose(low[0], low[1], low[2] - 0.003 - 0.01), (Shape("box", np.eye(4), (0.2, 0.2, 0.02)),))
    checker = CollisionChecker(robot, SceneSnapshot(1, robot.root_link, (plate,)), group, q0,
                               CheckerSettings(margin=0.0075))
    idx = checker.joint_indices
    rng = np.random.default_rng(4)
    Q = q0[idx] + rng.uniform(-0.005, 0.005, (200, len(idx)))
    W = rng.uniform(0.5, 1.0, (len(Q), checker.edge_margins(np.zeros((1, len(idx)))).shape[1]))
    U = len(checker.levels.units)
    W[:, :U] *= checker.margin
    W[:, U:] *= 2 * checker.margin
    ok = checker.check_configs(Q, W)
    to_fcl = checker.stats.exact_checks
    assert np.array_equal(ok, np.array([checker.exact_check(q, w) for q, w in zip(Q, W)]))
    assert (~ok).sum() > 150  # nearly all too close
    assert to_fcl < 0.1 * len(Q)


def test_grid_gives_the_kd_tree_verdicts_among_hundreds_of_boxes(armar3):
    """400 boxes and a table in reach: the kernels' level 1 visits the grid cells around each unit
    (levels.PairGrid) where the numpy levels ask a k-d tree; same verdicts with and without edge margins,
    and brute-force FCL's on a sample."""
    rng = np.random.default_rng(9)
    scene = SceneSnapshot(1, armar3.root_link, clutter(rng, 400, armar3, ("left_arm", "right_arm")))
    settings = CheckerSettings(padding=0.01, margin=0.0075, grasp_object_id="b0")
    compiled = CollisionChecker(armar3, scene, "left_arm_torso", armar3.home, settings)
    numpy_levels = CollisionChecker(armar3, scene, "left_arm_torso", armar3.home, settings)
    numpy_levels.levels.use_compiled = False
    grid = compiled.levels.env_grid
    assert grid is not None and len(grid.big) >= 1 and len(grid.body) >= 300  # the table, the boxes in reach
    idx = compiled.joint_indices
    Q = np.vstack([rng.uniform(armar3.lower[idx], armar3.upper[idx], (150, len(idx))),
                   np.clip(armar3.home[idx] + rng.uniform(-0.25, 0.25, (250, len(idx))), armar3.lower[idx], armar3.upper[idx])])
    U = len(compiled.levels.units)
    w = rng.uniform(0, 1, (len(Q), len(compiled._levers)))
    w[:, :U] *= compiled.margin
    w[:, U:] *= 2 * compiled.margin
    for margins in (None, w):
        ok = compiled.check_configs(Q, margins)
        assert np.array_equal(ok, numpy_levels.check_configs(Q, margins))
        assert 10 <= ok.sum() < len(Q) - 50  # dense clutter: most collide
    ok = compiled.check_configs(Q[-100:])
    assert np.array_equal(ok, np.array([compiled.exact_check(q) for q in Q[-100:]]))


def test_a_hull_vertex_inside_a_fixed_meshs_inner_box_proves_contact(talos):
    """kernels.levels_12: with a fixed robot mesh's inner box (f_ibox), an entry of that body whose hull
    vertex lies inside the box is a contact (STATUS_HIT) without FCL; the body's own bounding box stands in
    for an inner box here (geometry's tests check real ones lie inside their meshes)."""
    robot, group = talos, "r_arm_torso"
    q_ref = talos_arms_out(robot)
    checker = CollisionChecker(robot, SceneSnapshot(1, robot.root_link, ()), group, q_ref, CheckerSettings())
    lv = checker.levels
    idx = checker.joint_indices
    rng = np.random.default_rng(4)
    Q = np.clip(q_ref[idx] + rng.uniform(-1.2, 1.2, (600, len(idx))), robot.lower[idx], robot.upper[idx])
    lv.f_ibox_ok[:] = False
    lv._kernel_args = None
    _, _, before, env, _, _ = lv.compiled_12(Q, None, None)
    e = np.bincount(env[2][lv.f_tight[env[2]] == 0], minlength=len(lv.fixed)).argmax()  # the mesh most left to FCL
    assert (env[2] == e).any()
    lv.f_ibox_ok[e] = True
    lv.f_ibox.R[e], lv.f_ibox.t[e], lv.f_ibox.h[e] = lv.fbox.R[e], lv.fbox.t[e], lv.fbox.h[e]
    lv._kernel_args = None
    _, _, after, env2, _, _ = lv.compiled_12(Q, None, None)
    newly = (after == kernels.STATUS_HIT) & (before != kernels.STATUS_HIT)
    assert newly.any() and (before[newly] == kernels.STATUS_OPEN).all()  # only configurations FCL would have seen
    assert np.array_equal(after == kernels.STATUS_HIT, (before == kernels.STATUS_HIT) | newly)
    assert not np.isin(env2[0], np.flatnonzero(newly)).any()  # no entry left of a proven configuration


def test_triangle_spheres_bound_each_triangle_and_run():
    """Centres at the bounding boxes' centres, radii reaching the farthest vertex: numpy's formulas."""
    rng = np.random.default_rng(7)
    tri = rng.normal(size=(50, 3, 3))
    lo, hi = np.array([0, 16, 32, 48]), np.array([16, 32, 48, 50])
    tc, tr, rc, rr = kernels.triangle_spheres(tri, lo, hi)
    c = (tri.min(axis=1) + tri.max(axis=1)) / 2
    np.testing.assert_allclose(tc, c, atol=1e-15)
    np.testing.assert_allclose(tr, np.sqrt(((tri - c[:, None]) ** 2).sum(axis=2).max(axis=1)), atol=1e-15)
    for k, (a, b) in enumerate(zip(lo, hi)):
        pts = tri[a:b].reshape(-1, 3)
        cc = (pts.min(axis=0) + pts.max(axis=0)) / 2
        np.testing.assert_allclose(rc[k], cc, atol=1e-15)
        assert rr[k] == pytest.approx(np.sqrt(((pts - cc) ** 2).sum(axis=1).max()), abs=1e-15)


def test_axis_apart_proves_edges_facing_apart_and_never_overlap():
    """_axis_apart (kernels' hull test past the face normals): on random convex hulls at random poses it
    never calls apart two hulls that FCL finds within the padding, and it proves apart pairs whose
    nearest features are edges, where no face normal separates them."""
    import fcl
    import trimesh
    from scipy.spatial.transform import Rotation

    from humanoid_planner.core.collision.geometry import hull_bound, hull_points

    rng = np.random.default_rng(3)
    pad = 0.01
    edge_cases = proven = 0
    for _ in range(1000):
        hulls = [trimesh.Trimesh(rng.normal(scale=0.1, size=(12, 3))).convex_hull for _ in range(2)]
        Ts = [pose(*rng.normal(scale=0.12, size=3), R=Rotation.random(random_state=rng).as_matrix()) for _ in range(2)]
        (Va, Pa), (Vb, Pb) = [hull_points(h) for h in hulls]
        (Ra, ta), (Rb, tb) = [(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])) for T in Ts]
        objs = [fcl.CollisionObject(hull_bound(h), fcl.Transform(T[:3, :3], T[:3, 3])) for h, T in zip(hulls, Ts)]
        touching = fcl.collide(*objs, fcl.CollisionRequest(), fcl.CollisionResult())
        distance = 0.0 if touching else fcl.distance(*objs, fcl.DistanceRequest(), fcl.DistanceResult())
        apart = kernels._axis_apart(Ra, ta, Va, len(Va), Rb, tb, Vb, len(Vb), pad)
        if apart:
            assert distance > pad - 1e-9
        planes = (kernels._beyond_planes(Ra, ta, Pa, len(Pa), Rb, tb, Vb, len(Vb), pad)
                  or kernels._beyond_planes(Rb, tb, Pb, len(Pb), Ra, ta, Va, len(Va), pad))
        if distance > pad + 0.005 and not planes:  # apart, but along no face normal
            edge_cases += 1
            proven += apart
    assert edge_cases >= 8 and proven >= 0.6 * edge_cases, (proven, edge_cases)


def test_level_one_clears_a_small_unit_beside_a_big_ones_box(talos):
    """Level 1 tests a self pair's bounding spheres, then each side's sphere against the other's box, both
    ways round: a big link's sphere reaches the small links beside it (TIAGo's torso column and its 41 hand
    links: one way only, those pairs went to the covers and hulls, 7 of the robot's 10.6 µs per configuration
    in its cage), while the small links' own spheres mostly miss the big one's box. On TALOS r_arm_torso (its
    torso and the arm's links) the pairs level 1 keeps are those both tests keep, 15 % fewer than one way,
    and the kernels decide as the numpy levels, level 1 included."""
    from humanoid_planner.core.collision.levels import EPS, touch

    robot, group = talos, "r_arm_torso"
    compiled = CollisionChecker(robot, None, group, robot.home, CheckerSettings())
    numpy_levels = CollisionChecker(robot, None, group, robot.home, CheckerSettings())
    numpy_levels.levels.use_compiled = False
    idx = compiled.joint_indices
    rng = np.random.default_rng(3)
    Q = np.clip(robot.home[idx] + rng.uniform(-0.8, 0.8, (150, len(idx))), robot.lower[idx], robot.upper[idx])
    lv = numpy_levels.levels
    R, t = lv.fk(Q)
    f = lv.unit_frame
    B = np.matmul(R[:, f], lv.bound_c[:, :, None])[..., 0] + t[:, f]
    n, p, _, _ = lv.level1_self(R, t, B)
    a, b = lv.self_s[p], lv.self_o[p]
    reach = lv.self_padding + 2 * lv.margin + EPS
    for x, y in ((a, b), (b, a)):  # every pair kept: each side's sphere reaches the other's box
        Ry, ty = lv.unit_box_world(R, t, n, y)
        assert touch(B[n, x][:, None, :], (lv.bound_r[x] + reach)[:, None], Ry, ty, lv.ubox.h[y], lv.ubox.rho[y]).all()
    # one way only (the pair's first unit's sphere against the second's box, as before) keeps more of them
    d = B[:, lv.self_s] - B[:, lv.self_o]
    n1, p1 = np.nonzero(np.einsum("npi,npi->np", d, d) < lv.self_thr2)
    a1, b1 = lv.self_s[p1], lv.self_o[p1]
    Rb, tb = lv.unit_box_world(R, t, n1, b1)
    one_way = touch(B[n1, a1][:, None, :], (lv.bound_r[a1] + reach)[:, None], Rb, tb, lv.ubox.h[b1],
                    lv.ubox.rho[b1])[:, 0].sum()
    assert len(n) < 0.9 * one_way
    a_ok, b_ok = compiled.check_configs(Q), numpy_levels.check_configs(Q)
    assert np.array_equal(a_ok, b_ok) and 0 < a_ok.sum() < len(Q)
    assert compiled.stats.level1_free == numpy_levels.stats.level1_free
