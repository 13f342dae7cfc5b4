"""CollisionChecker.exempting: a checker that no longer checks some named pairs, made from another
without building its geometry again, must answer exactly as a checker built with that exemption."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape, attach

LEFT = "left_arm_torso"


def box(oid: str, center, size) -> SceneObject:
    T = np.eye(4)
    T[:3, 3] = center
    return SceneObject(oid, T, (Shape("box", np.eye(4), tuple(size)),))


def near_configs(robot, group: str, T_target: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Group configurations, many with the hand near T_target (random, kept where the TCP is within 15 cm)."""
    rng = np.random.default_rng(seed)
    idx = robot.group_joint_indices(group)
    lo, hi = robot.lower[idx], robot.upper[idx]
    Q = rng.uniform(lo, hi, size=(20 * n, len(idx)))
    full = np.repeat(robot.home[None], len(Q), axis=0)
    full[:, idx] = Q
    tcp = robot.link_poses(full, [robot.group(group).tip_link])[:, 0, :3, 3]
    near = np.linalg.norm(tcp - T_target[:3, 3], axis=1) < 0.15
    return np.vstack([Q[near][:n], Q[~near][:n]])


def test_a_hand_exempt_from_an_object_answers_as_a_grasp_exemption(armar3):
    r = armar3
    hands = r.hand_links(LEFT)
    T_tcp = r.link_poses(r.home, [r.group(LEFT).tip_link])[0]
    obj = box("target", T_tcp[:3, 3] + (0.02, 0.0, 0.0), (0.06, 0.06, 0.2))
    scene = SceneSnapshot(1, "base_link", (obj, box("wall", (0.6, 0.0, 1.0), (0.02, 1.0, 1.0))))
    built = CollisionChecker(r, scene, LEFT, r.home,
                             CheckerSettings(margin=0.0075, grasp_object_id="target", hand_links=hands))
    strict = CollisionChecker(r, scene, LEFT, r.home, CheckerSettings(margin=0.0075))
    derived = strict.exempting([(h, "target") for h in hands])
    Q = near_configs(r, LEFT, obj.pose, 150, 0)
    want, got, before = built.check_configs(Q), derived.check_configs(Q), strict.check_configs(Q)
    assert np.array_equal(got, want)
    assert (want & ~before).sum() >= 5  # the exemption matters on these configurations
    assert np.array_equal(strict.check_configs(Q), before)  # the original is unchanged
    assert [derived.check_edge(a, b) for a, b in zip(Q[:40], Q[1:41])] == \
           [built.check_edge(a, b) for a, b in zip(Q[:40], Q[1:41])]
    assert ("left_hand", "target") not in derived.colliding_pairs(r.home[r.group_joint_indices(LEFT)])


def test_an_attached_object_exempt_from_its_support_answers_as_touch_links(armar3):
    r = armar3
    tip, hands = r.group(LEFT).tip_link, r.hand_links(LEFT)
    T_tcp = r.link_poses(r.home, [tip])[0]
    held = box("target", T_tcp[:3, 3] + (0.05, 0.0, 0.0), (0.06, 0.06, 0.2))
    att = attach(held, tip, T_tcp, hands)
    board = box("board", T_tcp[:3, 3] + (0.05, 0.0, -0.11), (0.3, 0.3, 0.02))
    plain = SceneSnapshot(1, "base_link", (board,), attached=(att,))
    touching = SceneSnapshot(1, "base_link", (board,), attached=(attach(held, tip, T_tcp, hands + ("board",)),))
    built = CollisionChecker(r, touching, LEFT, r.home, CheckerSettings(margin=0.0075))
    derived = CollisionChecker(r, plain, LEFT, r.home, CheckerSettings(margin=0.0075)).exempting([("target", "board")])
    Q = near_configs(r, LEFT, board.pose, 150, 1)
    assert np.array_equal(derived.check_configs(Q), built.check_configs(Q))
    q0 = r.home[r.group_joint_indices(LEFT)]
    assert not CollisionChecker(r, plain, LEFT, r.home).check_configs(q0[None])[0]  # it rests on the board
    assert derived.check_configs(q0[None])[0]
