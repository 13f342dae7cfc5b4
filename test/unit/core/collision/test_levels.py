"""levels.py: level 1's cluster step (one sphere per cluster of a frame's units first) on TALOS: the same
(configuration, unit, fixed body) and (configuration, unit pair) entries as testing every unit pair."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.scenarios import talos_arms_out

from .shapes import clutter, pose, rot


def _entries(checker: CollisionChecker, Q: np.ndarray) -> tuple[set, set]:
    R, t = checker.levels.fk(Q)
    f = checker.levels.unit_frame
    B = np.matmul(R[:, f], checker.levels.bound_c[:, :, None])[..., 0] + t[:, f]
    n, u, e = checker.levels.level1_env(R, t, B)
    ns, p, _, _ = checker.levels.level1_self(R, t, B)
    return set(zip(n.tolist(), u.tolist(), e.tolist())), set(zip(ns.tolist(), p.tolist()))


@pytest.mark.parametrize("group", ["l_arm", "r_arm_torso"])
def test_clusters_flag_exactly_what_unit_spheres_flag(talos, group):
    scene = SceneSnapshot(1, "base_link", (
        SceneObject("table", pose(0.7, 0, 0.75), (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),)),
        SceneObject("box", pose(0.5, 0.3, 1.1, rot([0, 0, 1], 0.5)), (Shape("box", np.eye(4), (0.1, 0.1, 0.3)),))))
    q_ref = talos_arms_out(talos)
    clustered = CollisionChecker(talos, scene, group, q_ref, CheckerSettings(margin=0.0075))
    assert clustered.levels.cl_env is not None  # TALOS's grippers: clusters pay here
    assert len(clustered.levels.cl_env.keys) < 0.5 * len(clustered.levels.env_u)
    # every cluster sphere contains its units' bounding spheres
    c = clustered
    k = c.levels.cl_slot
    assert (c.levels.cl_frame[k] == c.levels.unit_frame).all()
    assert (np.linalg.norm(c.levels.bound_c - c.levels.cl_c[k], axis=1) + c.levels.bound_r <= c.levels.cl_r[k] + 1e-12).all()
    flat = CollisionChecker(talos, scene, group, q_ref, CheckerSettings(margin=0.0075))
    flat.levels.cl_env = flat.levels.cl_self = None  # every unit pair, densely
    idx = clustered.joint_indices
    Q = np.random.default_rng(31).uniform(talos.lower[idx], talos.upper[idx], (3000, len(idx)))
    env_c, self_c = _entries(clustered, Q)
    env_f, self_f = _entries(flat, Q)
    assert env_c == env_f and len(env_f) > 1000
    assert self_c == self_f
    assert (clustered.check_configs(Q) == flat.check_configs(Q)).all()


@pytest.mark.parametrize("robot_name, group, clusters", [("armar3", "left_arm_torso", False), ("talos", "l_arm", True)])
def test_env_index_gives_the_dense_entries_and_verdicts(request, robot_name, group, clusters):
    """Hundreds of boxes in reach: level 1 through the k-d tree returns the dense test's entries in the
    same order, so every verdict and counter is the same (with and without edge margins)."""
    robot = request.getfixturevalue(robot_name)
    rng = np.random.default_rng(5)
    idx = robot.group_joint_indices(group)
    q_ref = talos_arms_out(robot) if robot_name == "talos" else robot.home
    scene = SceneSnapshot(1, robot.root_link, clutter(rng, 400, robot, ("l_arm", "r_arm") if robot_name == "talos" else ("left_arm", "right_arm")))
    indexed = CollisionChecker(robot, scene, group, q_ref, CheckerSettings(padding=0.01, margin=0.0075, grasp_object_id="b0"))
    dense = CollisionChecker(robot, scene, group, q_ref, CheckerSettings(padding=0.01, margin=0.0075, grasp_object_id="b0"))
    dense.levels.env_index = None
    for checker in (indexed, dense):  # the numpy levels on both sides (test_kernels.py compares the kernels)
        checker.levels.use_compiled = False
    assert indexed.levels.env_index is not None and (indexed.levels.cl_env is not None) == clusters
    assert len(indexed.levels.env_index.big) > 0  # the table: tested with every configuration
    Q = np.vstack([rng.uniform(robot.lower[idx], robot.upper[idx], (300, len(idx))),
                   np.clip(q_ref[idx] + rng.normal(0, 0.3, (300, len(idx))), robot.lower[idx], robot.upper[idx])])
    R, t = indexed.levels.fk(Q)
    f = indexed.levels.unit_frame
    B = np.matmul(R[:, f], indexed.levels.bound_c[:, :, None])[..., 0] + t[:, f]
    got, want = indexed.levels.level1_env(R, t, B), dense.levels.level1_env(R, t, B)
    assert len(want[0]) > 1000 and all(np.array_equal(a, b) for a, b in zip(got, want))
    U = len(indexed.levels.units)
    w = indexed.edge_margins(rng.uniform(0, 0.02, Q.shape))
    w[:, :U] = np.minimum(w[:, :U], 0.0075)
    w[:, U:] = np.minimum(w[:, U:], 0.015)
    ok = indexed.check_configs(Q)
    assert 0 < ok.sum() < len(Q)
    assert np.array_equal(ok, dense.check_configs(Q))
    assert np.array_equal(indexed.check_configs(Q, w), dense.check_configs(Q, w))
    assert indexed.summary() == dense.summary()
