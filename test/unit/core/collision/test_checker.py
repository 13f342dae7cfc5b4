"""CollisionChecker (collision.checker): conservative prefilter + exact python-fcl, checked against brute force.

The reference (`brute_force`) shares nothing with the checker's fast path: generic FK
(RobotModel.link_poses), its own pair list from the SRDF, its own AABB broad phase, and fcl on every
pair whose AABBs overlap (AABBs are conservative, so this is every pair that can collide).
"""
from __future__ import annotations

import time

import fcl
import numpy as np
import pytest
import trimesh

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker, coarse_to_fine, default_hand_links
from humanoid_planner.core.collision.geometry import fcl_from_link_geometry, fcl_from_shape
from humanoid_planner.core.model.robot import LinkGeometry, RobotModel
from humanoid_planner.core.scene.types import AttachedObject, SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import talos_arms_out

from .shapes import pose, rot

N_RANDOM = 10_000
FALSE_COLLIDING_BOUND = 0.001
"""Largest allowed fraction of configurations called colliding that FCL calls free. Verdicts of
"colliding" come from FCL itself or from inner-sphere proofs that need 0.1 mm of penetration, far
beyond FCL's own tolerance, so the expected value is 0; the bound only leaves room for FCL's
GJK disagreeing with itself on grazing contacts."""


# ----------------------------------------------------------------------------- helpers
def local_aabb(g) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half extents, in the shape frame, of a box containing a shape (LinkGeometry or Shape)."""
    if g.kind == "mesh":
        lo, hi = g.vertices.min(0), g.vertices.max(0)
        return 0.5 * (lo + hi), 0.5 * (hi - lo)
    if g.kind == "box":
        return np.zeros(3), 0.5 * np.asarray(g.dims[:3])
    if g.kind == "sphere":
        return np.zeros(3), np.full(3, g.dims[0])
    r, h = (g.dims[0], g.dims[1]) if isinstance(g, LinkGeometry) else (g.dims[1], g.dims[0])
    return np.zeros(3), np.array([r, r, h / 2])  # cylinder, cone


def brute_force(robot: RobotModel, scene: SceneSnapshot | None, Q_full: np.ndarray, grasp: str | None = None,
                hand: frozenset = frozenset(), chunk: int = 500) -> np.ndarray:
    """(N,) True = free: fcl on every allowed pair (SRDF/adjacent/grasp rules) whose AABBs and
    bounding balls overlap, most overlapping first, until the first collision."""
    excluded = robot.disabled_collision_pairs | robot.adjacent_link_pairs
    links = list(robot.collision_geometry)
    shapes = [(li, g) for li, l in enumerate(links) for g in robot.collision_geometry[l]]
    objs = [fcl.CollisionObject(fcl_from_link_geometry(g)) for _, g in shapes]
    scene_shapes = [(o.id, o.pose @ s.pose, s) for o in (scene.objects if scene else ()) for s in o.shapes]
    for oid, T, s in scene_shapes:
        objs.append(fcl.CollisionObject(fcl_from_shape(s), fcl.Transform(T[:3, :3], T[:3, 3])))
    nr = len(shapes)
    pairs = [(i, j) for i in range(nr) for j in range(i + 1, nr)
             if shapes[i][0] != shapes[j][0] and frozenset((links[shapes[i][0]], links[shapes[j][0]])) not in excluded]
    pairs += [(i, nr + k) for i in range(nr) for k, (oid, _, _) in enumerate(scene_shapes)
              if not (oid == grasp and links[shapes[i][0]] in hand)]
    I, J = np.array(pairs).T
    origins = np.array([g.origin for _, g in shapes])
    lc = np.array([local_aabb(g)[0] for _, g in shapes])
    lh = np.array([local_aabb(g)[1] for _, g in shapes])
    sc = np.array([T[:3, :3] @ local_aabb(s)[0] + T[:3, 3] for _, T, s in scene_shapes]).reshape(-1, 3)
    sh = np.array([np.abs(T[:3, :3]) @ local_aabb(s)[1] for _, T, s in scene_shapes]).reshape(-1, 3)
    rad = np.linalg.norm(np.concatenate([lh, [local_aabb(s)[1] for _, _, s in scene_shapes]]).reshape(-1, 3), axis=1)
    free = np.ones(len(Q_full), dtype=bool)
    req = fcl.CollisionRequest()
    Il, Jl = I.tolist(), J.tolist()
    for c0 in range(0, len(Q_full), chunk):
        P = robot.link_poses(Q_full[c0:c0 + chunk], links)  # (n, L, 4, 4)
        W = P[:, [li for li, _ in shapes]] @ origins  # (n, S, 4, 4)
        n_ = len(W)
        C = np.concatenate([np.einsum("nsij,sj->nsi", W[:, :, :3, :3], lc) + W[:, :, :3, 3],
                            np.broadcast_to(sc, (n_,) + sc.shape)], 1)
        H = np.concatenate([np.einsum("nsij,sj->nsi", np.abs(W[:, :, :3, :3]), lh),
                            np.broadcast_to(sh, (n_,) + sh.shape)], 1)
        D = C[:, I] - C[:, J]
        near = np.all(np.abs(D) <= H[:, I] + H[:, J] + 1e-6, axis=2)  # AABBs overlap
        gap = np.linalg.norm(D, axis=2) - rad[I] - rad[J]
        near &= gap <= 1e-6  # and so do the balls around them
        cfg, pair = np.nonzero(near)
        first = np.lexsort((gap[cfg, pair], cfg))  # per configuration, the most overlapping pairs first
        cfg, pair = cfg[first], pair[first]
        bounds = np.flatnonzero(np.r_[True, cfg[1:] != cfg[:-1], True]) if len(cfg) else np.zeros(1, int)
        pl = pair.tolist()
        for s0, s1 in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
            n = int(cfg[s0])
            Rn, tn = W[n, :, :3, :3], W[n, :, :3, 3]
            for k in range(s0, s1):
                i, j = Il[pl[k]], Jl[pl[k]]
                for s in (i, j):
                    if s < nr:
                        objs[s].setRotation(Rn[s])
                        objs[s].setTranslation(tn[s])
                if fcl.collide(objs[i], objs[j], req, fcl.CollisionResult()):
                    free[c0 + n] = False
                    break
    return free


def check_against_brute_force(robot, scene, group, q_ref, n, seed, settings: CheckerSettings = CheckerSettings()):
    checker = CollisionChecker(robot, scene, group, q_ref, settings)
    assert checker.fixed_collisions() == ()  # else brute force and checker differ by design
    idx = checker.joint_indices
    rng = np.random.default_rng(seed)
    Q = rng.uniform(robot.lower[idx], robot.upper[idx], (n, len(idx)))
    t0 = time.perf_counter()
    verdict = checker.check_configs(Q)
    t_batch = time.perf_counter() - t0
    t0 = time.perf_counter()
    full = np.repeat(np.asarray(q_ref, float)[None], n, 0)
    full[:, idx] = Q
    truth = brute_force(robot, scene, full, settings.grasp_object_id, checker.hand_links)
    t_brute = time.perf_counter() - t0
    false_free = int((verdict & ~truth).sum())
    false_colliding = int((~verdict & truth).sum())
    print(f"\n{robot.name}/{group}: {n} configs, {truth.mean():.1%} free; false free {false_free}, "
          f"false colliding {false_colliding} ({false_colliding / max((~verdict).sum(), 1):.3%} of 'colliding'); "
          f"batch {t_batch:.2f} s, brute force {t_brute:.2f} s; {checker.summary()}")
    return false_free, false_colliding / max(int((~verdict).sum()), 1), checker


def cluttered_scene(with_target: bool = False) -> SceneSnapshot:
    """Table and a mix of every shape kind in front of ARMAR-III, all clear of its home pose."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.06)
    objs = [
        SceneObject("table", pose(0.8, 0, 0.86), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),
                                                  Shape("box", pose(0, 0, -0.43), (0.05, 0.05, 0.82)))),
        SceneObject("b1", pose(0.55, -0.45, 1.25, rot([1, 1, 0], 0.6)), (Shape("box", np.eye(4), (0.12, 0.08, 0.10)),)),
        SceneObject("b2", pose(0.70, 0.30, 1.00, rot([0, 0, 1], 0.4)), (Shape("box", np.eye(4), (0.10, 0.15, 0.20)),)),
        SceneObject("b3", pose(0.45, 0.05, 1.45), (Shape("box", np.eye(4), (0.08, 0.30, 0.05)),)),
        SceneObject("cyl", pose(0.65, -0.15, 1.02, rot([1, 0, 0], 0.3)), (Shape("cylinder", np.eye(4), (0.25, 0.04)),)),
        SceneObject("cone", pose(0.75, 0.55, 1.0), (Shape("cone", np.eye(4), (0.2, 0.06)),)),
        SceneObject("ball", pose(0.40, -0.60, 1.05), (Shape("sphere", np.eye(4), (0.07,)),)),
        SceneObject("blob", pose(0.50, 0.45, 1.30, rot([0, 1, 1], 1.0)),
                    (Shape("mesh", np.eye(4), (), np.asarray(sphere.vertices) * [1.5, 1, 0.7], np.asarray(sphere.faces)),)),
    ]
    if with_target:  # a box right at the right hand at home: only the hand may touch it
        objs.append(SceneObject("target", pose(0.50, -0.35, 1.09), (Shape("box", np.eye(4), (0.06, 0.06, 0.12)),)))
    return SceneSnapshot(3, "base_link", tuple(objs))


def test_coarse_to_fine_order():
    for n in range(1, 70):
        o = coarse_to_fine(n)
        assert o[0] == n and sorted(o.tolist()) == list(range(1, n + 1))
    assert coarse_to_fine(8).tolist()[:4] == [8, 4, 2, 6]


# ----------------------------------------------------------------------------- acceptance: vs brute force
def test_armar3_10k_random_configs_agree_with_brute_force_fcl(armar3):
    false_free, frac, checker = check_against_brute_force(
        armar3, cluttered_scene(with_target=True), "right_arm_torso", armar3.home, N_RANDOM, seed=11,
        settings=CheckerSettings(grasp_object_id="target"))
    assert false_free == 0
    assert frac <= FALSE_COLLIDING_BOUND
    s = checker.stats
    assert s.configs_checked == N_RANDOM and s.level2_colliding > 0 and s.exact_checks > 0
    assert {"right_hand", "right_tcp"} <= checker.hand_links


def test_armar3_both_arms_10k_random_configs(armar3):
    """Two groups at once (the dual-arm pair check): arm–arm pairs, no torso motion."""
    false_free, frac, _ = check_against_brute_force(armar3, cluttered_scene(), ("left_arm", "right_arm"),
                                                    armar3.home, N_RANDOM, seed=12)
    assert false_free == 0 and frac <= FALSE_COLLIDING_BOUND


def test_talos_meshes_10k_random_configs_agree_with_brute_force_fcl(talos):
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("post", pose(0.45, -0.3, 1.0, rot([1, 0, 0], 0.4)), (Shape("cylinder", np.eye(4), (0.5, 0.03)),)),
        SceneObject("box", pose(0.5, 0.35, 1.1, rot([0, 0, 1], 0.5)), (Shape("box", np.eye(4), (0.1, 0.1, 0.3)),))))
    false_free, frac, checker = check_against_brute_force(talos, scene, "all_arms_torso", talos_arms_out(talos),
                                                          N_RANDOM, seed=13)
    assert false_free == 0 and frac <= FALSE_COLLIDING_BOUND
    assert checker.summary()["self_pairs"] > 100
    # TALOS's links are closed meshes: their inner spheres prove collisions before FCL (self, table, post)
    assert checker.stats.level2_colliding > 0.2 * N_RANDOM


# ----------------------------------------------------------------------------- edges and paths
def test_edges_match_dense_checks(armar3):
    checker = CollisionChecker(armar3, cluttered_scene(), "right_arm", armar3.home,
                               CheckerSettings(edge_resolution=0.05))
    idx = checker.joint_indices
    rng = np.random.default_rng(5)
    Q = rng.uniform(armar3.lower[idx], armar3.upper[idx], (3000, len(idx)))
    free = Q[checker.check_configs(Q)]
    q0 = free[:150]
    q1 = np.clip(q0 + rng.uniform(-0.8, 0.8, q0.shape), armar3.lower[idx], armar3.upper[idx])
    batch = checker.check_edges(q0, q1)
    assert 0 < batch.sum() < len(batch)
    for a, b, ok in zip(q0, q1, batch):
        n = checker.edge_steps(a, b)
        assert n == max(1, int(np.ceil(np.max(np.abs(b - a)) / 0.05 - 1e-9)))
        dense = checker.check_configs(a + np.outer(np.arange(1, n + 1) / n, b - a))
        assert checker.check_edge(a, b) == ok == dense.all()
        t = checker.first_collision_along(a, b)
        first_bad = n + 1 if dense.all() else int(np.argmin(dense)) + 1
        assert np.isclose(t, (first_bad - 1) / n)
    path = np.vstack([q0[0], q0[0] + 0.01, q0[0] + 0.02])
    assert checker.check_path(path) == bool(checker.check_edges(path[:-1], path[1:]).all())


def test_edge_stops_at_first_collision(armar3):
    checker = CollisionChecker(armar3, cluttered_scene(), "right_arm", armar3.home,
                               CheckerSettings(edge_resolution=0.01))
    idx = checker.joint_indices
    rng = np.random.default_rng(6)
    Q = rng.uniform(armar3.lower[idx], armar3.upper[idx], (400, 7))
    free = Q[checker.check_configs(Q)]
    early = 0
    for q0, q1 in zip(free[:40], free[40:80]):  # long edges between free configurations
        checker.stats.reset()
        ok = checker.check_edge(q0, q1)
        n = checker.edge_steps(q0, q1)
        assert checker.stats.edges_checked == 1 and checker.stats.configs_checked <= n
        if not ok:
            early += checker.stats.configs_checked < n
    assert early >= 10  # blocked edges rarely need every point


# ----------------------------------------------------------------------------- semantics
def test_grasped_object_is_an_obstacle_except_for_the_hand(armar3):
    idx = armar3.group_joint_indices("right_arm")
    tcp = armar3.link_poses(armar3.home, ["right_tcp"])[0]
    target = SceneSnapshot(1, "base_link", (SceneObject("cup", tcp, (Shape("cylinder", np.eye(4), (0.1, 0.03)),)),))
    q = armar3.home[idx]
    assert not CollisionChecker(armar3, target, "right_arm").check_config(q)
    assert CollisionChecker(armar3, target, "right_arm",
                            settings=CheckerSettings(grasp_object_id="cup")).check_config(q)
    # the same object against the forearm (not a hand link) still collides
    arm = armar3.link_poses(armar3.home, ["right_forearm_link"])[0]
    obstacle = SceneSnapshot(1, "base_link", (SceneObject("cup", arm @ pose(0, 0, 0.12),
                                                          (Shape("sphere", np.eye(4), (0.05,)),)),))
    assert not CollisionChecker(armar3, obstacle, "right_arm",
                                settings=CheckerSettings(grasp_object_id="cup")).check_config(q)
    assert set(default_hand_links(armar3, "right_arm")) == {"right_wrist_2_link", "right_hand", "right_tcp"}


def clearance(robot: RobotModel, q_full: np.ndarray, links, scene: SceneSnapshot) -> float:
    """Smallest fcl distance between the links' shapes and the scene's shapes."""
    P = dict(zip(links, robot.link_poses(q_full, list(links))))
    out = np.inf
    for link in links:
        for g in robot.collision_geometry.get(link, ()):
            T = P[link] @ g.origin
            a = fcl.CollisionObject(fcl_from_link_geometry(g), fcl.Transform(T[:3, :3], T[:3, 3]))
            for o in scene.objects:
                for s in o.shapes:
                    U = o.pose @ s.pose
                    b = fcl.CollisionObject(fcl_from_shape(s), fcl.Transform(U[:3, :3], U[:3, 3]))
                    out = min(out, fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult()))
    return out


def test_padding_is_a_clearance(armar3):
    idx = armar3.group_joint_indices("right_arm")
    tcp = armar3.link_poses(armar3.home, ["right_tcp"])[0]
    probe = SceneSnapshot(1, "base_link", (SceneObject("wall", tcp @ pose(0.15, 0, 0),
                                                       (Shape("box", np.eye(4), (0.1, 0.3, 0.3)),)),))
    d = clearance(armar3, armar3.home, armar3.moving_links("right_arm"), probe)
    assert 0.01 < d < 0.2
    q = armar3.home[idx]
    for pad, free in ((0.0, True), (0.8 * d, True), (1.2 * d, False)):
        c = CollisionChecker(armar3, probe, "right_arm", settings=CheckerSettings(padding=pad))
        assert c.check_config(q) == free == c.exact_check(q), pad
    c = CollisionChecker(armar3, cluttered_scene(), "right_arm", settings=CheckerSettings(padding=0.03))
    rng = np.random.default_rng(8)
    Q = rng.uniform(armar3.lower[idx], armar3.upper[idx], (300, 7))
    padded = c.check_configs(Q)
    assert (padded == np.array([c.exact_check(x) for x in Q])).all()
    assert padded.sum() < CollisionChecker(armar3, cluttered_scene(), "right_arm").check_configs(Q).sum()
    # self_padding: robot–robot clearance, separate from the scene's
    both = CollisionChecker(armar3, cluttered_scene(), "right_arm_torso",
                            settings=CheckerSettings(padding=0.02, self_padding=0.01))
    idx = both.joint_indices
    Q = rng.uniform(armar3.lower[idx], armar3.upper[idx], (300, len(idx)))
    v = both.check_configs(Q)
    assert (v == np.array([both.exact_check(x) for x in Q])).all()
    assert v.sum() < CollisionChecker(armar3, cluttered_scene(), "right_arm_torso",
                                      settings=CheckerSettings(padding=0.02)).check_configs(Q).sum()


def test_fixed_collisions_are_reported_not_counted(armar3):
    idx = armar3.group_joint_indices("right_arm")
    torso = armar3.link_poses(armar3.home, ["torso_link"])[0]
    scene = SceneSnapshot(1, "base_link", (SceneObject("in_torso", torso @ pose(0, 0, 0.3),
                                                       (Shape("box", np.eye(4), (0.05, 0.05, 0.05)),)),))
    c = CollisionChecker(armar3, scene, "right_arm")
    assert ("torso_link", "in_torso") in c.fixed_collisions()
    assert c.check_config(armar3.home[idx])  # the arm itself is free


def test_two_arm_checker_sees_arm_arm_contact_that_single_arm_checkers_ignore(armar3):
    both = CollisionChecker(armar3, None, ("left_arm", "right_arm"))
    left = CollisionChecker(armar3, None, "left_arm",
                            settings=CheckerSettings(ignore_links=armar3.moving_links("right_arm")))
    right = CollisionChecker(armar3, None, "right_arm",
                             settings=CheckerSettings(ignore_links=armar3.moving_links("left_arm")))
    rng = np.random.default_rng(9)
    il, ir = armar3.group_joint_indices("left_arm"), armar3.group_joint_indices("right_arm")
    L = rng.uniform(armar3.lower[il], armar3.upper[il], (3000, 7))
    R = rng.uniform(armar3.lower[ir], armar3.upper[ir], (3000, 7))
    L, R = L[left.check_configs(L)], R[right.check_configs(R)]
    # pair up configurations whose hands are within 5 cm: each arm alone is free, together not
    tl = armar3.link_poses(armar3.expand("left_arm", L, armar3.home), ["left_tcp"])[:, 0, :3, 3]
    tr = armar3.link_poses(armar3.expand("right_arm", R, armar3.home), ["right_tcp"])[:, 0, :3, 3]
    i, j = np.nonzero(np.linalg.norm(tl[:, None] - tr[None], axis=2) < 0.05)
    assert len(i) > 5
    Q = np.hstack([L[i], R[j]])
    v = both.check_configs(Q)
    assert (~v).mean() > 0.9
    assert (v == np.array([both.exact_check(q) for q in Q])).all()


def test_counters_and_validation(armar3):
    c = CollisionChecker(armar3, cluttered_scene(), "right_arm")
    idx = c.joint_indices
    Q = np.random.default_rng(2).uniform(armar3.lower[idx], armar3.upper[idx], (2500, 7))
    c.check_configs(Q)
    s = c.stats
    assert s.configs_checked == 2500
    assert s.level1_free + s.level2_free + s.level2_colliding + s.exact_checks == 2500
    assert s.exact_pairs >= s.exact_checks
    c.check_edge(Q[0], Q[1])
    assert s.edges_checked == 1
    s.reset()
    assert s.configs_checked == s.edges_checked == s.exact_checks == 0
    with pytest.raises(ValueError):
        c.check_configs(np.zeros((3, 6)))
    with pytest.raises(ValueError):
        CollisionChecker(armar3, None, "right_arm", np.zeros(3))
    with pytest.raises(ValueError):
        CollisionChecker(armar3, None, ("left_arm_torso", "right_arm_torso"))  # shared torso joints
    with pytest.raises(KeyError):
        CollisionChecker(armar3, None, "no_such_group")
    assert c.check_configs(np.zeros((0, 7))).shape == (0,)
    with pytest.raises(ValueError):
        CollisionChecker(armar3, None, ())


def test_settings_are_checked_and_hold_link_names_as_tuples():
    for bad in ({"padding": -0.01}, {"self_padding": float("nan")}, {"margin": -1.0}, {"edge_resolution": 0.0},
                {"edge_chunk": 0}):
        with pytest.raises(ValueError):
            CheckerSettings(**bad)
    s = CheckerSettings(hand_links=["a", "b"], ignore_links={"c"})
    assert s.hand_links == ("a", "b") and s.ignore_links == ("c",)
    assert hash(s) == hash(CheckerSettings(hand_links=("a", "b"), ignore_links=("c",)))


# ----------------------------------------------------------------------------- a hand-written robot
MESH_URDF = """<?xml version="1.0"?>
<robot name="slider">
  <link name="base"><collision><geometry><box size="0.4 0.4 0.1"/></geometry></collision></link>
  <link name="carriage"><collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.05" length="0.2"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0.15 0 0"/><geometry><mesh filename="{mesh}" scale="1 1 1"/></geometry></collision></link>
  <link name="tip"><collision><geometry><sphere radius="0.03"/></geometry></collision></link>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="carriage"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.5" velocity="1" effort="1"/></joint>
  <joint name="turn" type="continuous"><parent link="carriage"/><child link="arm"/><origin xyz="0 0 0.25"/>
    <axis xyz="0 0 1"/><limit velocity="1" effort="1"/></joint>
  <joint name="bend" type="revolute"><parent link="arm"/><child link="tip"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
</robot>"""
MESH_SRDF = """<?xml version="1.0"?><robot name="slider">
  <group name="all"><chain base_link="base" tip_link="tip"/></group></robot>"""


def test_prismatic_joint_and_mesh_link(tmp_path):
    mesh = trimesh.creation.box((0.3, 0.04, 0.04))
    mesh.export(tmp_path / "arm.stl")
    robot = RobotModel.from_urdf_srdf(MESH_URDF.format(mesh=tmp_path / "arm.stl"), MESH_SRDF)
    scene = SceneSnapshot(1, "base", (
        SceneObject("shelf", pose(0.3, 0, 0.55), (Shape("box", np.eye(4), (0.2, 0.6, 0.02)),)),
        SceneObject("pole", pose(-0.3, 0, 0.5), (Shape("cylinder", np.eye(4), (1.0, 0.02)),))))
    false_free, frac, checker = check_against_brute_force(robot, scene, "all", robot.home, 3000, seed=4)
    assert false_free == 0 and frac <= FALSE_COLLIDING_BOUND
    assert checker.stats.exact_checks > 0


def test_cross_groups_only_checks_exactly_the_arm_against_arm_pairs(armar3):
    """DAGRRT's pairing checker: scene and same-arm pairs are left out, every left-link vs right-link
    pair the SRDF allows is checked (truth: fcl on every such shape pair)."""
    groups = ("left_arm", "right_arm")
    scene = cluttered_scene()
    cross = CollisionChecker(armar3, scene, groups, armar3.home, CheckerSettings(cross_groups_only=True))
    full = CollisionChecker(armar3, scene, groups, armar3.home)
    idx = cross.joint_indices
    rng = np.random.default_rng(5)
    Q = rng.uniform(armar3.lower[idx], armar3.upper[idx], (1500, len(idx)))
    verdict = cross.check_configs(Q)
    assert np.all(verdict[full.check_configs(Q)])  # never stricter than the full check
    left, right = (set(armar3.moving_links(g)) & set(armar3.collision_geometry) for g in groups)
    excluded = armar3.disabled_collision_pairs | armar3.adjacent_link_pairs
    pairs = [(a, b) for a in sorted(left) for b in sorted(right) if frozenset((a, b)) not in excluded]
    objs = {l: [(g, fcl.CollisionObject(fcl_from_link_geometry(g))) for g in armar3.collision_geometry[l]]
            for l in left | right}
    full_q = np.repeat(armar3.home[None], len(Q), 0)
    full_q[:, idx] = Q
    names = sorted(left | right)
    P = armar3.link_poses(full_q, names)
    truth = np.ones(len(Q), dtype=bool)
    for n in range(len(Q)):
        for li, l in enumerate(names):
            for g, o in objs[l]:
                T = P[n, li] @ g.origin
                o.setRotation(T[:3, :3])
                o.setTranslation(T[:3, 3])
        truth[n] = not any(fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult())
                           for a, b in pairs for _, oa in objs[a] for _, ob in objs[b])
    assert 0 < (~truth).sum() < len(Q)  # both outcomes occur
    np.testing.assert_array_equal(verdict, truth)
    assert cross.summary()["env_pairs"] == 0


def test_hull_bounds_never_change_a_padded_verdict(talos):
    """Convex-hull distances only skip mesh distance queries they prove unnecessary: with padding
    and edge margins, every verdict equals the checker's without hull bounds (TALOS's meshes and a
    cluttered scene, 600 random configurations)."""
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("box", pose(0.5, 0.35, 1.1, rot([0, 0, 1], 0.5)), (Shape("box", np.eye(4), (0.1, 0.1, 0.3)),))))
    ref = talos_arms_out(talos)
    fast = CollisionChecker(talos, scene, "l_arm_torso", ref, CheckerSettings(padding=0.01, margin=0.01))
    exact = CollisionChecker(talos, scene, "l_arm_torso", ref, CheckerSettings(padding=0.01, margin=0.01))
    exact._hulls.clear()
    idx = fast.joint_indices
    rng = np.random.default_rng(21)
    Q = rng.uniform(talos.lower[idx], talos.upper[idx], (600, len(idx)))
    W = fast.edge_margins(rng.uniform(-0.05, 0.05, Q.shape))
    W *= min(1.0, 0.009 / W.max())  # within the checkers' margin (units; pairs may take twice)
    np.testing.assert_array_equal(fast.check_configs(Q), exact.check_configs(Q))
    np.testing.assert_array_equal(fast.check_configs(Q, W), exact.check_configs(Q, W))
    assert len(fast._hulls) > 10  # TALOS's link meshes have hulls, the boxes bound themselves


def test_objects_out_of_reach_are_culled_and_change_no_verdict(armar3):
    """3,000 boxes beyond any link's reach (behind the robot, 3-6 m away) plus the cluttered scene: the
    checker builds bodies for the near objects only (a plan's cost must not grow with far objects) and
    gives every verdict of the checker without the far boxes. A box just inside the reach is kept."""
    near = cluttered_scene()
    far = tuple(SceneObject(f"far{i}", pose(-3.0 - 0.001 * i, 0.1 * (i % 50) - 2.5, 0.05 * (i // 50)),
                            (Shape("box", np.eye(4), (0.05, 0.05, 0.05)),)) for i in range(3000))
    edge = SceneObject("edge", pose(0.0, -0.9, 1.2), (Shape("sphere", np.eye(4), (0.02,)),))
    big = SceneSnapshot(4, "base_link", near.objects + far + (edge,))
    group = "right_arm_torso"
    with_far = CollisionChecker(armar3, big, group, armar3.home)
    without = CollisionChecker(armar3, SceneSnapshot(5, "base_link", near.objects + (edge,)), group, armar3.home)
    assert with_far.scene_objects_culled >= 3000
    assert {b.name for b in with_far.levels.fixed} == {b.name for b in without.levels.fixed}
    assert "edge" in {b.name for b in with_far.levels.fixed}  # within reach of the right arm: kept
    idx = with_far.joint_indices
    Q = np.random.default_rng(31).uniform(armar3.lower[idx], armar3.upper[idx], (2000, len(idx)))
    assert (with_far.check_configs(Q) == without.check_configs(Q)).all()


def test_an_object_out_of_reach_still_shows_in_fixed_collisions(armar3):
    """Culling drops objects no moving unit can reach from the checks, but an object through a fixed link
    (a box in ARMAR-III's base, far below the left arm) is still reported as a fixed collision."""
    block = SceneObject("block", pose(0.0, 0.0, 0.2), (Shape("box", np.eye(4), (0.3, 0.3, 0.3)),))
    culled = CollisionChecker(armar3, SceneSnapshot(1, "base_link", (block,)), "left_arm", armar3.home)
    assert culled.scene_objects_culled == 1
    assert ("base_link", "block") in culled.fixed_collisions()
    clear = SceneObject("clear", pose(0.0, 0.0, -2.0), (Shape("box", np.eye(4), (0.3, 0.3, 0.3)),))
    assert CollisionChecker(armar3, SceneSnapshot(2, "base_link", (clear,)), "left_arm",
                            armar3.home).fixed_collisions() == ()


def _surface_points(g: LinkGeometry) -> np.ndarray:
    """Points of a link shape in the link frame whose motion bounds the whole shape's: mesh vertices,
    box corners, cylinder rims, sphere poles."""
    if g.kind == "mesh":
        P = g.vertices
    elif g.kind == "box":
        P = 0.5 * np.array(g.dims[:3]) * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    elif g.kind == "cylinder":
        a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        r, h = g.dims[0], g.dims[1] / 2
        P = np.vstack([np.c_[r * np.cos(a), r * np.sin(a), np.full(24, z)] for z in (-h, h)])
    else:
        P = g.dims[0] * np.vstack([np.eye(3), -np.eye(3)])
    return P @ g.origin[:3, :3].T + g.origin[:3, 3]


@pytest.mark.parametrize("robot_name, group", [("talos", "r_arm_torso"), ("armar3", "left_arm_torso")])
def test_unit_levers_bound_how_far_link_points_move(request, robot_name, group):
    """unit_levers[u, j] (from the joint's axis, not its origin) bounds how far any point of unit u moves
    per radian of joint j: the link geometry's own points, placed by the generic FK, move at most
    Σ |Δq_j| · lever over small random joint steps; and the bound is not vacuous (some step comes
    within half of it)."""
    robot = request.getfixturevalue(robot_name)
    ref = talos_arms_out(robot) if robot_name == "talos" else robot.home
    ch = CollisionChecker(robot, None, group, ref)
    idx = ch.joint_indices
    lever: dict[str, np.ndarray] = {}
    for name, row in zip(ch.levels.units, ch.unit_levers):  # a link split into units: the largest of theirs
        lever[name] = np.maximum(lever.get(name, 0.0), row)
    links = list(lever)
    pts = {n: np.vstack([_surface_points(g) for g in robot.collision_geometry[n]]) for n in links}
    rng = np.random.default_rng(5)
    tightest = 0.0
    for _ in range(40):
        q = ref.copy()
        q[idx] = rng.uniform(robot.lower[idx], robot.upper[idx])
        d = rng.normal(0, 0.003, len(idx)) * (rng.random(len(idx)) < 0.5)
        q2 = q.copy()
        q2[idx] += d
        for n, A, B in zip(links, robot.link_poses(q, links), robot.link_poses(q2, links)):
            moved = np.linalg.norm(pts[n] @ (B - A)[:3, :3].T + (B - A)[:3, 3], axis=1).max()
            bound = np.abs(d) @ lever[n]
            assert moved <= bound + 1e-9, (n, moved, bound)
            tightest = max(tightest, moved / bound if bound > 0 else 0.0)
    assert tightest > 0.5


@pytest.mark.parametrize("cross", [False, True])
def test_allowed_env_is_pair_allowed_of_every_unit_and_fixed_body(armar3, cross):
    """The (unit, fixed body) table built by name equals `_pair_allowed` pair by pair: the grasped
    object against the hand, an attached object's touch_links naming a scene object, fixed links."""
    from humanoid_planner.core.collision.levels import Body
    from humanoid_planner.core.scene.types import AttachedObject
    held = AttachedObject("held", "left_hand", pose(0.0, 0.0, 0.05), (Shape("box", np.eye(4), (0.04, 0.04, 0.1)),),
                          frozenset({"shelf"}))
    objs = cluttered_scene(with_target=True).objects
    shelf = SceneObject("shelf", pose(0.5, 0.2, 1.0), (Shape("box", np.eye(4), (0.3, 0.3, 0.02)),))
    scene = SceneSnapshot(1, "base_link", (*objs, shelf), attached=(held,))
    groups = ("left_arm_torso", "right_arm") if cross else ("left_arm_torso",)
    c = CollisionChecker(armar3, scene, groups, armar3.home,
                         CheckerSettings(grasp_object_id="target", cross_groups_only=cross))
    probe = [Body(n, True, 0, np.eye(4), None) for n in c.levels.units]
    want = np.array([[c._pair_allowed(p, f) and not cross for f in c.levels.fixed] for p in probe], dtype=bool)
    assert np.array_equal(c._allowed_env, want)
    if not cross:
        names = [f.name for f in c.levels.fixed]
        assert "left_hand" in c.levels.units and "held" in c.levels.units
        assert not want[c.levels.units.index("held"), names.index("shelf")]
        assert not want[c.levels.units.index("left_hand"), names.index("target")]
        assert want[c.levels.units.index("left_hand"), names.index("shelf")]


def test_fixed_collisions_of_culled_objects_as_without_their_prefilter(armar3):
    """fixed_collisions tests culled objects against the fixed links only where their bounding balls
    reach a link's box: the same pairs as testing every culled object (boxes scattered around ARMAR-III's
    base and legs, out of the left arm's reach or not)."""
    rng = np.random.default_rng(8)
    boxes = tuple(SceneObject(f"b{i}", pose(*rng.uniform((-0.6, -0.6, -0.2), (0.6, 0.6, 0.9)),
                                            R=rot(rng.normal(size=3), rng.uniform(0, 3))),
                              (Shape("box", np.eye(4), tuple(rng.uniform(0.02, 0.2, 3))),))
                  for i in range(300))
    snap = SceneSnapshot(1, "base_link", boxes)

    class Unfiltered(CollisionChecker):
        def _culled_near_fixed_links(self):
            return tuple(self.scene.objects[i] for i in self._culled.tolist())

    for padding in (0.0, 0.03):
        settings = CheckerSettings(padding=padding)
        fast = CollisionChecker(armar3, snap, "left_arm", armar3.home, settings)
        slow = Unfiltered(armar3, snap, "left_arm", armar3.home, settings)
        assert 0 < len(fast._culled_near_fixed_links()) < fast.scene_objects_culled
        assert set(fast.fixed_collisions()) == set(slow.fixed_collisions())
        assert any(not a.startswith("b") and b.startswith("b") for a, b in fast.fixed_collisions())


def test_attached_meshes_leave_the_leaf_order_cache_with_their_arrays(armar3):
    """Each mesh's triangle order is computed once (checker._leaf_order), but the cache holds no mesh alive:
    a node that attaches a new mesh at every pick for days does not grow by it."""
    import gc

    from humanoid_planner.core.collision import checker as checker_module
    from humanoid_planner.core.scene.types import attach

    def check_once(k: int) -> None:
        m = trimesh.creation.icosphere(subdivisions=2, radius=0.03 + 0.001 * k)  # 320 triangles: kernel-tested
        obj = SceneObject(f"held{k}", pose(0.3, 0.2, 1.0), (Shape("mesh", np.eye(4), (), np.asarray(m.vertices),
                                                                    np.asarray(m.faces)),))
        tip = armar3.group("left_arm").tip_link
        held = attach(obj, tip, armar3.link_poses(armar3.home, [tip])[0], armar3.hand_links("left_arm"))
        c = CollisionChecker(armar3, SceneSnapshot(k, "base_link", attached=(held,)), "left_arm", armar3.home)
        c.check_configs(np.tile(armar3.home[armar3.group_joint_indices("left_arm")], (4, 1)))
        assert any(ref() is held.shapes[0].triangles for ref, _ in checker_module._LEAF_ORDERS.values())

    check_once(0)
    gc.collect()
    before = len(checker_module._LEAF_ORDERS)
    for k in range(1, 6):
        check_once(k)
    gc.collect()
    assert len(checker_module._LEAF_ORDERS) <= before


def test_checkers_of_a_group_share_its_robot_part_and_decide_as_if_built_alone(armar3):
    """A checker is built per plan; what comes from the robot alone (GroupPart: the group's shapes, units,
    triangles, self pairs) is built once per group, posture of its other joints and paddings, and shared.
    A checker made from the shared part decides every configuration and motion as one built from nothing
    does, for another scene, another posture of the other joints (its own part), an attached object (never
    shared: it comes with the request) and an `exempting` copy (which leaves the shared part as it was)."""
    from humanoid_planner.core.collision.table_cache import RecentCache

    group = "right_arm_torso"
    model = CollisionChecker(armar3, None, group, armar3.home).collision_model
    idx = CollisionChecker(armar3, None, group, armar3.home).joint_indices
    Q = np.random.default_rng(5).uniform(armar3.lower[idx], armar3.upper[idx], (1500, len(idx)))
    lifted = armar3.home.copy()
    other = [i for i in range(armar3.dof) if i not in set(idx.tolist())]
    lifted[other] = np.clip(lifted[other] + 0.3, armar3.lower[other], armar3.upper[other])
    held = AttachedObject("held", "right_hand", pose(0.0, 0.0, 0.05), (Shape("box", np.eye(4), (0.04, 0.04, 0.1)),))
    cases = [(cluttered_scene(True), armar3.home), (cluttered_scene(), lifted),
             (SceneSnapshot(9, "base_link", cluttered_scene().objects, attached=(held,)), armar3.home)]
    shared = model.group_parts
    try:
        for scene, q_ref in cases:
            model.group_parts = shared
            model.group_parts = RecentCache(shared.size)
            first = CollisionChecker(armar3, scene, group, q_ref)  # its part is not kept: the key is new
            a = CollisionChecker(armar3, scene, group, q_ref)  # kept: the key comes again
            b = CollisionChecker(armar3, scene, group, q_ref)  # from the shared part, if any
            model.group_parts = RecentCache(0)  # nothing kept: built from nothing
            alone = CollisionChecker(armar3, scene, group, q_ref)
            assert a.levels.hull_v is not first.levels.hull_v
            assert (b.levels.hull_v is a.levels.hull_v) == (not scene.attached)
            assert alone.levels.hull_v is not a.levels.hull_v
            ok = alone.check_configs(Q)
            assert 100 < (~ok).sum() < len(Q) - 100
            assert np.array_equal(b.check_configs(Q), ok)
            for q0, q1 in zip(Q[:40], Q[40:80]):
                assert b.check_edge(q0, q1) == alone.check_edge(q0, q1)
            assert b.fixed_collisions() == alone.fixed_collisions()
        model.group_parts = shared
        CollisionChecker(armar3, cluttered_scene(), group, armar3.home)
        s_before = CollisionChecker(armar3, cluttered_scene(), group, armar3.home).levels.self_s.copy()
        c = CollisionChecker(armar3, cluttered_scene(), group, armar3.home)
        pair = (c.levels.moving[int(c.levels.unit_shape_tab[c.levels.self_s[0], 0])].name,
                c.levels.moving[int(c.levels.unit_shape_tab[c.levels.self_o[0], 0])].name)
        ex = c.exempting([pair])
        assert len(ex.levels.self_s) < len(s_before)
        # the left arm folded into the torso (rigid on the torso joint): fixed collisions, kept with the part
        folded = np.random.default_rng(6).uniform(armar3.lower, armar3.upper)
        for _ in range(2):
            CollisionChecker(armar3, cluttered_scene(), group, folded).fixed_collisions()
        c = CollisionChecker(armar3, cluttered_scene(), group, folded)
        found = c.fixed_collisions()
        model.group_parts = RecentCache(0)
        assert len(found) >= 2 and found == CollisionChecker(armar3, cluttered_scene(), group, folded).fixed_collisions()
        model.group_parts = shared
        assert c.exempting(found[:1]).fixed_collisions() == found[1:]  # the copy's own, not the group's
        assert np.array_equal(CollisionChecker(armar3, cluttered_scene(), group, armar3.home).levels.self_s, s_before)
    finally:
        model.group_parts = shared
