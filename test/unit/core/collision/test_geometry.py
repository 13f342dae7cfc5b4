"""Collision geometry (collision.geometry): sphere covers contain their shapes, inner spheres lie
inside them, bounding boxes contain meshes and unions; real TALOS link meshes are covered."""
from __future__ import annotations

import numpy as np
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_planner.core.collision.geometry import (HULL_POINTS_MAX, BoundingBox, RobotCollisionModel, bounding_polytope,
                                                      box_cover, box_is_tight, mesh_hull,
                                                      cylinder_cover, inner_spheres, link_geometry_box, mesh_cover,
                                                      mesh_inner_spheres, mesh_obb, union_box)
from humanoid_planner.core.model.robot import LinkGeometry

from .shapes import in_rounded_box, inside_cover, pose, rot


@settings(max_examples=40, deadline=None)
@given(st.tuples(*[st.floats(0.01, 0.5)] * 3), st.floats(0.002, 0.05), st.integers(0, 2**31))
def test_box_cover_contains_the_box(dims, tol, seed):
    pts = (np.random.default_rng(seed).uniform(-0.5, 0.5, (2000, 3))) * dims
    corners = np.array(np.meshgrid(*[[-d / 2, d / 2] for d in dims])).reshape(3, -1).T
    assert inside_cover(np.vstack([pts, corners]), box_cover(dims, tol)).all()


@settings(max_examples=40, deadline=None)
@given(st.floats(0.005, 0.3), st.floats(0.01, 0.8), st.floats(0.002, 0.05), st.integers(0, 2**31))
def test_cylinder_cover_contains_the_cylinder(r, length, tol, seed):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 2 * np.pi, 3000)
    rad = r * np.sqrt(rng.uniform(0, 1, 3000))
    rad[:500] = r  # rim
    z = rng.uniform(-length / 2, length / 2, 3000)
    z[500:700] = length / 2
    pts = np.column_stack([rad * np.cos(a), rad * np.sin(a), z])
    assert inside_cover(pts, cylinder_cover(r, length, tol)).all()


@settings(max_examples=25, deadline=None)
@given(st.sampled_from(["box", "sphere", "cylinder"]), st.tuples(*[st.floats(0.01, 0.4)] * 3), st.integers(0, 2**31))
def test_inner_spheres_lie_inside_the_primitive(kind, d, seed):
    dims = {"box": d, "sphere": (d[0],), "cylinder": (d[0], d[1])}[kind]
    g = LinkGeometry(kind, dims, pose(0.1, -0.2, 0.3, rot([1, 2, 3], 0.7)))
    inner = inner_spheres(g)
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    pts = (inner.centers[:, None, :] + inner.radii[:, None, None] * dirs[None]).reshape(-1, 3)
    local = (pts - g.origin[:3, 3]) @ g.origin[:3, :3]
    if kind == "box":
        ok = np.all(np.abs(local) <= np.asarray(dims) / 2 + 1e-9, axis=1)
    elif kind == "sphere":
        ok = np.linalg.norm(local, axis=1) <= dims[0] + 1e-9
    else:
        ok = (np.linalg.norm(local[:, :2], axis=1) <= dims[0] + 1e-9) & (np.abs(local[:, 2]) <= dims[1] / 2 + 1e-9)
    assert ok.all()


def test_mesh_cover_and_obb_contain_the_surface():
    rng = np.random.default_rng(0)
    meshes = [trimesh.creation.icosphere(subdivisions=2, radius=0.1),
              trimesh.creation.box((0.3, 0.05, 0.1)),
              trimesh.creation.capsule(height=0.3, radius=0.04),
              trimesh.creation.torus(0.1, 0.03)]
    for m in meshes:
        m.apply_transform(pose(0.02, 0.1, -0.05, rot(rng.normal(size=3), 1.0)))
        pts, _ = trimesh.sample.sample_surface(m, 4000, seed=1)
        pts = np.vstack([pts, m.vertices])
        for tol in (0.005, 0.02):
            assert inside_cover(pts, mesh_cover(m.vertices, m.faces, tol)).all()
        T, half = mesh_obb(m.vertices)
        assert in_rounded_box(pts, BoundingBox(T, half)).all()


def test_real_link_meshes_are_covered(talos):
    model = RobotCollisionModel.for_robot(talos)
    assert RobotCollisionModel.for_robot(talos) is model  # built once per robot
    for name in ("arm_right_4_link", "torso_2_link", "gripper_right_base_link"):
        lc = model.links[name]
        g = lc.shapes[0]
        m = trimesh.Trimesh(g.vertices, g.triangles, process=False)
        pts, _ = trimesh.sample.sample_surface(m, 3000, seed=2)
        pts = pts @ g.origin[:3, :3].T + g.origin[:3, 3]
        assert inside_cover(pts, lc.covers[0]).all()
        assert in_rounded_box(pts, lc.boxes[0]).all()
        inner = lc.inners[0]
        solid = trimesh.Trimesh(g.vertices, g.triangles)
        if solid.is_watertight:  # every inner sphere lies inside the solid: its centre at least r from the surface
            if solid.volume < 0:
                solid.invert()  # signed_distance is positive inside for outward faces only
            assert inner is not None and len(inner.radii) >= 1
            local = (inner.centers - g.origin[:3, 3]) @ g.origin[:3, :3]
            assert (trimesh.proximity.signed_distance(solid, local) >= inner.radii - 1e-9).all()
        else:  # an open mesh has no inside
            assert inner is None


def test_big_hulls_get_a_bounding_polytope_that_contains_the_mesh(talos):
    """outer_hull: a hull with more than HULL_POINTS_MAX vertices (TALOS's pelvis, 758) is bounded by a
    polytope of fewer vertices, every mesh vertex inside its planes and below its vertices' support along
    any direction, within a few mm of the hull; a small hull is its own bound; a primitive has none."""
    model = RobotCollisionModel.for_robot(talos)
    g = model.links["base_link"].shapes[0]
    hull = mesh_hull(g)
    assert len(hull.vertices) > HULL_POINTS_MAX and model.links["base_link"].hull_points[0] is None
    V, P = model.outer_hull("base_link", 0)
    assert model.outer_hull("base_link", 0)[0] is V  # computed once
    assert len(V) <= HULL_POINTS_MAX
    pts = np.asarray(g.vertices, float)
    assert (pts @ P[:, :3].T <= P[:, 3]).all()
    assert (V @ P[:, :3].T <= P[:, 3] + 1e-12).all()
    U = np.random.default_rng(0).normal(size=(500, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    excess = (V @ U.T).max(axis=0) - (pts @ U.T).max(axis=0)
    assert excess.min() >= 0 and np.median(excess) < 0.005 and excess.max() < 0.03
    small = model.links["torso_2_link"]
    assert small.hull_points[0] is not None and model.outer_hull("torso_2_link", 0) is small.hull_points[0]
    assert bounding_polytope(mesh_hull(small.shapes[0])) is None  # small enough for the exact hull
    assert bounding_polytope(None) is None


def test_mesh_inner_spheres_skip_meshes_past_the_face_budget(monkeypatch):
    import humanoid_planner.core.collision.geometry as geometry

    box = trimesh.creation.box((0.3, 0.1, 0.1))
    monkeypatch.setattr(geometry, "INNER_MAX_FACES", len(box.faces) - 1)  # a load-time bound: FCL decides those
    assert mesh_inner_spheres(box.vertices, box.faces) is None


def test_mesh_inner_spheres_closed_and_open():
    box = trimesh.creation.box((0.3, 0.1, 0.1))
    inner = mesh_inner_spheres(box.vertices, box.faces)
    assert inner is not None and 0.025 <= inner.radii.max() <= 0.05 + 1e-9  # a grid of centres: near the best
    assert (np.abs(inner.centers) + inner.radii[:, None] <= np.array([0.15, 0.05, 0.05]) + 1e-9).all()
    ring = trimesh.creation.annulus(0.1, 0.2, 0.1)  # not convex: the hole holds no sphere
    inner = mesh_inner_spheres(ring.vertices, ring.faces)
    assert inner is not None and (np.linalg.norm(inner.centers[:, :2], axis=1) - inner.radii >= 0.1 - 1e-9).all()
    assert mesh_inner_spheres(box.vertices, box.faces[:-2]) is None  # open: no inside


def test_triangles_meet_box_agrees_with_fcl():
    """The separating-axis test of mesh_inner_box gives FCL's verdict for one triangle against a box."""
    import fcl

    from humanoid_planner.core.collision.geometry import _triangles_meet_box, fcl_mesh

    rng = np.random.default_rng(5)
    half = np.array([0.1, 0.05, 0.2])
    box = fcl.CollisionObject(fcl.Box(*(2 * half)), fcl.Transform())
    met = 0
    for _ in range(300):
        tri = rng.normal(0, 0.15, (1, 3, 3)) + rng.normal(0, 0.1, 3)
        ours = _triangles_meet_box(tri, half)
        theirs = fcl.collide(fcl.CollisionObject(fcl_mesh(tri[0], np.array([[0, 1, 2]])), fcl.Transform()), box,
                             fcl.CollisionRequest(), fcl.CollisionResult()) > 0
        assert ours == theirs
        met += ours
    assert 50 < met < 250  # both verdicts well represented


def test_mesh_inner_box_lies_inside_closed_meshes():
    """A box inside the solid (sampled points in it are inside; no triangle meets it), nearly the best for
    a box and a drum; none for an open mesh."""
    from humanoid_planner.core.collision.geometry import _triangles_meet_box, mesh_inner_box

    rng = np.random.default_rng(2)
    box = trimesh.creation.box((0.3, 0.2, 0.1))
    drum = trimesh.creation.cylinder(radius=0.28, height=0.36, sections=32)
    ring = trimesh.creation.annulus(0.1, 0.2, 0.1)  # its middle is the hole: a (small) box in the wall
    for mesh, share in ((box, 0.99), (drum, 0.5), (ring, 0.0005)):
        b = mesh_inner_box(mesh.vertices, mesh.faces)
        assert b is not None and 8 * np.prod(b.half) >= share * mesh.volume
        pts = (rng.uniform(-1, 1, (3000, 3)) * b.half) @ b.pose[:3, :3].T + b.pose[:3, 3]
        assert mesh.contains(pts).all()
        local = (np.asarray(mesh.triangles) - b.pose[:3, 3]) @ b.pose[:3, :3]
        assert not _triangles_meet_box(local, 0.999 * b.half)
    assert mesh_inner_box(box.vertices, box.faces[:-2]) is None  # open: no inside


def test_union_box_and_capsule_tightness():
    T = pose(0.1, 0, 0.2, rot([0, 1, 0], 0.5))
    cyl = LinkGeometry("cylinder", (0.05, 0.3), T)
    ends = [LinkGeometry("sphere", (0.05,), T @ pose(0, 0, s * 0.15)) for s in (-1, 1)]
    u = union_box([link_geometry_box(g) for g in [cyl] + ends])
    assert np.allclose(u.half, [0, 0, 0.15]) and np.isclose(u.rounding, 0.05)  # the exact capsule
    shapes = [(g.kind, g.dims, g.origin) for g in [cyl] + ends]
    assert box_is_tight(shapes)
    off = [(g.kind, g.dims, g.origin @ pose(0.01, 0, 0)) if g.kind == "sphere" else (g.kind, g.dims, g.origin)
           for g in [cyl] + ends]
    assert not box_is_tight(off)
    assert not box_is_tight([("cylinder", (0.05, 0.3), T)])
    rng = np.random.default_rng(3)
    boxes = [BoundingBox(pose(*rng.normal(0, 0.1, 3), rot(rng.normal(size=3), 1)), rng.uniform(0, 0.1, 3), r)
             for r in (0.0, 0.02, 0.05)]
    ub = union_box(boxes)
    for b in boxes:
        dirs = rng.normal(size=(300, 3))
        dirs /= np.linalg.norm(dirs, axis=1)[:, None]
        corners = np.array(np.meshgrid(*[[-h, h] for h in b.half])).reshape(3, -1).T
        pts = (corners[:, None] + b.rounding * dirs[None]).reshape(-1, 3) @ b.pose[:3, :3].T + b.pose[:3, 3]
        assert in_rounded_box(pts, ub, 1e-9).all()

