"""kernels.py, the triangle tests before FCL: mesh_box_entries (a mesh's triangles against an exact box)
proves only FCL collisions and FCL-apart pairs and decides most pairs next to contact; tri_tri_gap agrees
with FCL on triangle pairs; tri_tri_upper never understates a distance; a checker's witnesses prove repeated mesh
contacts and pairs closer than their clearance with FCL's verdicts."""
from __future__ import annotations

import fcl
import numpy as np
import pytest
import trimesh

from types import SimpleNamespace

from humanoid_planner.core.collision import kernels
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker, _triangle_leaves, _triangle_tables
from humanoid_planner.core.collision.geometry import fcl_mesh
from humanoid_planner.core.collision.levels import EPS
from humanoid_planner.scenarios import ARMS, load_humanoid

from .shapes import rot


def test_mesh_box_entries_agree_with_fcl():
    mesh = trimesh.creation.torus(major_radius=0.08, minor_radius=0.025)  # not convex: a box fits in its hole
    V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    frame = np.array([[0.0, 0.0, 0.0]])  # the mesh's offset in its frame: none
    tri = (V + frame)[F]
    tri = tri[np.concatenate(_triangle_leaves(tri.mean(axis=1), np.arange(len(tri))))]
    lv = SimpleNamespace(**_triangle_tables([(tri, np.arange(len(tri)))]))  # the bounding spheres
    tables = (tri, lv.tri_c, lv.tri_r, lv.run_lo, lv.run_hi, lv.run_c, lv.run_r, lv.run_off)
    h = np.array([0.05, 0.03, 0.02])
    rng = np.random.default_rng(3)
    K = 600
    R = np.empty((K, 1, 3, 3))
    t = np.empty((K, 1, 3))
    for k in range(K):
        axis = rng.normal(size=3)
        R[k, 0] = rot(axis / np.linalg.norm(axis), rng.uniform(0, np.pi))[:3, :3]
        t[k, 0] = rng.uniform(-0.14, 0.14, 3)  # the torus around the box: most poses within a few cm of contact
    box = fcl.CollisionObject(fcl.Box(*(2 * h)), fcl.Transform())
    body = fcl.CollisionObject(fcl_mesh(V, F), fcl.Transform())
    fR, ft, fh = np.eye(3)[None], np.zeros((1, 3)), h[None]
    for pad in (0.0, 0.01):
        v = kernels.mesh_box_entries(R, t, np.arange(K), np.zeros(K, np.int64), np.zeros(K, np.int64),
                                     np.full(K, pad), np.zeros(1, np.int64), *tables,
                                     fR, ft, fh, np.zeros(1), np.ones(1, bool), EPS)
        for k in range(K):
            body.setTransform(fcl.Transform(R[k, 0], t[k, 0]))
            hit = fcl.collide(body, box, fcl.CollisionRequest(), fcl.CollisionResult())
            d = fcl.distance(body, box, fcl.DistanceRequest(), fcl.DistanceResult())
            if v[k] > 0:  # colliding, or closer than the padding (the checker's verdict with a padding)
                assert hit or d < pad
            elif v[k] < 0:
                assert not hit and d >= pad
        # undecided: within eps of the box, or (padding) between (pad - eps) / √3 and pad + eps of it
        assert (v > 0).sum() > 0.2 * K and (v < 0).sum() > 0.2 * K and (v == 0).sum() < (0.1 if pad else 0.01) * K
    # a box in the torus' hole touches no triangle: apart, as FCL (the mesh is its surface) finds it
    R1, t1 = np.eye(3)[None, None], np.zeros((1, 1, 3))
    small = np.array([[0.02, 0.02, 0.02]])
    v = kernels.mesh_box_entries(R1, t1, np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64),
                                 np.zeros(1), np.zeros(1, np.int64), *tables, fR, ft, small,
                                 np.zeros(1), np.ones(1, bool), EPS)
    assert v[0] == -1


def test_tri_tri_gap_agrees_with_fcl():
    """An overlap by more than EPS along every axis is an FCL intersection; a gap is FCL's "apart" by at
    least that distance; both occur (random triangles in a 10 cm cube)."""
    rng = np.random.default_rng(5)
    E, N = np.empty((2, 3, 3)), np.empty((2, 3))
    req = fcl.CollisionRequest()
    seen = {"hit": 0, "apart": 0}
    for _ in range(1500):
        P, Q = rng.uniform(0, 0.1, (2, 3, 3))
        g = kernels.tri_tri_gap(P, Q, E, N)
        o1 = fcl.CollisionObject(fcl_mesh(P, np.array([[0, 1, 2]])), fcl.Transform())
        o2 = fcl.CollisionObject(fcl_mesh(Q, np.array([[0, 1, 2]])), fcl.Transform())
        hit = fcl.collide(o1, o2, req, fcl.CollisionResult())
        if g < -EPS:
            assert hit
            seen["hit"] += 1
        elif g > 0:
            assert not hit and fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult()) >= g - 1e-9
            seen["apart"] += 1
    assert seen["hit"] > 100 and seen["apart"] > 500


@pytest.mark.parametrize("self_padding, seed", [(0.0, 2), (0.02, 3)])
def test_witnesses_prove_repeated_mesh_contacts_and_pairs_closer_than_their_clearance(self_padding, seed):
    """A checker remembers the triangles FCL found intersecting, and with a self padding those it measured
    nearest in a pair closer than the padding, and proves the same contacts and the same pairs too close
    (tri_tri_upper below the clearance) again in the kernel: far fewer FCL calls the second time over the same
    configurations (Panda's meshes, self pairs and its base; no padding and 2 cm), with brute-force FCL's
    verdicts."""
    robot = load_humanoid("panda")
    a = CollisionChecker(robot, None, ARMS["panda"].left, robot.home, CheckerSettings(self_padding=self_padding))
    idx = a.joint_indices
    Q = np.random.default_rng(seed).uniform(robot.lower[idx], robot.upper[idx], (1500, len(idx)))
    first = a.check_configs(Q)
    calls = a.stats.exact_checks
    assert len(a._wit_n) > 0 and calls >= 10
    a.stats.reset()
    second = a.check_configs(Q)
    assert np.array_equal(first, second) and a.stats.exact_checks < 0.5 * calls
    assert np.array_equal(second, [a.exact_check(q) for q in Q])


def test_tri_tri_upper_never_understates_fcls_distance():
    """tri_tri_upper (the least distance from a vertex of either triangle to the other and between their edges)
    is never below FCL's distance of the two triangles, and equals it for triangles apart (random triangles in a
    10 cm cube, apart and intersecting, and degenerate ones)."""
    rng = np.random.default_rng(6)
    exact = apart = 0
    for k in range(1500):
        P, Q = rng.uniform(0, 0.1, (2, 3, 3))
        if k % 100 == 0:
            P[2] = P[1]  # a degenerate triangle (an edge)
        u = kernels.tri_tri_upper(P, Q)
        o1 = fcl.CollisionObject(fcl_mesh(P, np.array([[0, 1, 2]])), fcl.Transform())
        o2 = fcl.CollisionObject(fcl_mesh(Q, np.array([[0, 1, 2]])), fcl.Transform())
        d = max(fcl.distance(o1, o2, fcl.DistanceRequest(), fcl.DistanceResult()), 0.0)
        assert np.isfinite(u) and u >= d - 1e-9
        apart += d > 0
        exact += d > 0 and u <= d + 1e-9
    assert apart > 500 and exact == apart
