"""The FK engine (model.fk.KinematicTree): every link pose of a tree compiled for some free joints
(the others at q_ref) equals a plain chain of URDF transforms (origin · joint motion, link by link),
for single configurations and small and large batches, on ARMAR-III, dual_arm and TALOS."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.model.fk import LARGE_BATCH, align_z, joint_motion
from humanoid_planner.core.model.robot import RobotModel


def reference_link_poses(robot: RobotModel, q_full: np.ndarray) -> dict[str, np.ndarray]:
    """The textbook definition, one configuration: child = parent · origin · motion(q)."""
    out = {robot.root_link: np.eye(4)}
    for link in robot.link_names[1:]:
        j = robot.parent_joint(link)
        value = q_full[j.index] if j.index >= 0 else 0.0
        out[link] = out[j.parent] @ j.origin @ joint_motion(j.type, j.axis, value)
    return out


@pytest.mark.parametrize("which,groups", [("armar3", ("right_arm_torso",)), ("armar3", ("left_arm", "right_arm")),
                                          ("dual_arm", ("right_arm", "left_arm")),
                                          ("talos", ("all_arms_torso",)), ("talos", ("r_leg", "head"))])
def test_tree_matches_the_urdf_chain(which, groups, request):
    robot = request.getfixturevalue(which)
    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    rng = np.random.default_rng(1)
    q_ref = rng.uniform(robot.lower, robot.upper)
    tree = robot.kinematic_tree(idx, q_ref)
    for N in (3, LARGE_BATCH + 1):  # both batch paths
        Q = rng.uniform(robot.lower[idx], robot.upper[idx], (N, len(idx)))
        R, t = tree(Q)
        for i in (0, N - 1):
            full = q_ref.copy()
            full[idx] = Q[i]
            want = reference_link_poses(robot, full)
            single = tree.single(Q[i])
            for link, P in want.items():
                f, T = tree.anchors[link]
                if f == -2:
                    continue
                if f < 0:
                    assert np.allclose(T, P, atol=1e-12), link
                    continue
                F = np.eye(4)
                F[:3, :3], F[:3, 3] = R[i, f], t[i, f]
                assert np.allclose(F @ T, P, atol=1e-12), link
                assert np.allclose(single[f] @ T, P, atol=1e-12), link
    # each frame's origin is its joint's origin and its z axis the joint axis
    full = q_ref.copy()
    full[idx] = Q[0]
    want = reference_link_poses(robot, full)
    for k, fr in enumerate(tree.frames):
        joint = robot.parent_joint(next(link for link, (f, T) in tree.anchors.items()
                                        if f == k and robot.parent_joint(link) is not None
                                        and robot.parent_joint(link).index == idx[fr.column]))
        child = want[joint.child]
        assert np.allclose(t[0, k], child[:3, 3], atol=1e-12)
        assert np.allclose(R[0, k] @ fr.axis, child[:3, :3] @ joint.axis, atol=1e-12)


def test_needed_links_prune_frames(armar3):
    idx = armar3.group_joint_indices("left_arm_torso")
    tip = armar3.group("left_arm_torso").tip_link
    tree = armar3.kinematic_tree(idx, needed=[tip])
    full = armar3.kinematic_tree(idx)
    assert len(tree) <= len(full)
    q = np.random.default_rng(2).uniform(armar3.lower[idx], armar3.upper[idx])
    assert np.allclose(tree.link_poses(q, [tip]), full.link_poses(q, [tip]), atol=1e-12)
    hidden = [link for link, (f, _) in tree.anchors.items() if f == -2]
    if hidden:
        with pytest.raises(ValueError, match="not compiled"):
            tree.link_poses(q, hidden[:1])


def test_link_poses_single_and_batched_agree(armar3):
    rng = np.random.default_rng(3)
    Q = rng.uniform(armar3.lower, armar3.upper, (LARGE_BATCH + 2, armar3.dof))
    batched = armar3.link_poses(Q)
    small = armar3.link_poses(Q[:5])
    for i in (0, 4):
        assert np.allclose(armar3.link_poses(Q[i]), batched[i], atol=1e-12)
        assert np.allclose(small[i], batched[i], atol=1e-12)
    with pytest.raises(ValueError):
        armar3.link_poses(Q[:, :-1])


@pytest.mark.parametrize("axis", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.5, 0.8)])
def test_align_z_turns_z_onto_the_axis(axis):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    R = align_z(a)
    assert np.allclose(R[:3, :3] @ [0, 0, 1], a)
    assert np.allclose(R[:3, :3].T @ R[:3, :3], np.eye(3))
