"""kernels.mesh_box_entries: a mesh's triangles against an exact box, FCL's own test compiled. Every
contact it proves is an FCL collision, every pair it calls apart is at least the padding apart by FCL's
distance, and it decides most pairs next to contact (where the hull tests cannot)."""
from __future__ import annotations

import fcl
import numpy as np
import trimesh

from types import SimpleNamespace

from humanoid_planner.core.collision import kernels
from humanoid_planner.core.collision.checker import CollisionChecker, _triangle_leaves
from humanoid_planner.core.collision.geometry import fcl_mesh
from humanoid_planner.core.collision.levels import EPS

from .shapes import rot


def test_mesh_box_entries_agree_with_fcl():
    mesh = trimesh.creation.torus(major_radius=0.08, minor_radius=0.025)  # not convex: a box fits in its hole
    V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    frame = np.array([[0.0, 0.0, 0.0]])  # the mesh's offset in its frame: none
    tri = (V + frame)[F]
    tri = tri[np.concatenate(_triangle_leaves(tri.mean(axis=1), np.arange(len(tri))))]
    lv = SimpleNamespace()
    CollisionChecker._triangle_tables(SimpleNamespace(levels=lv), [tri])  # per-triangle and per-run spheres
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
