"""PlanningScene (core, no ROS): MoveIt operation semantics, validation, versions, snapshots, threads."""
import threading

import numpy as np
import pytest

from humanoid_planner.core.scene.planning_scene import (Operation, PlanningScene, SceneLimits, SceneUpdate,
                                                       SceneUpdateError)
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot, Shape


def T(x=0.0, y=0.0, z=0.0):
    M = np.eye(4)
    M[:3, 3] = (x, y, z)
    return M


def box(x=0.1, y=0.2, z=0.3, pose=None):
    return Shape("box", T() if pose is None else pose, (x, y, z))


def sphere(r=0.05, pose=None):
    return Shape("sphere", T() if pose is None else pose, (r,))


def grasp(gid="g0", hand=""):
    return GraspSpec(gid, hand, T(0, 0, 0.1), np.array([[0.0, 0.05, 0.0]]), np.array([[0.0, -2.0, 0.0]]), 0.4)


def tetra():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.1
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return Shape("mesh", T(), vertices=V, triangles=F)


@pytest.fixture
def scene():
    return PlanningScene("base_link")


def test_empty(scene):
    snap = scene.snapshot()
    assert isinstance(snap, SceneSnapshot)
    assert (snap.version, snap.frame, snap.objects) == (0, "base_link", ())
    assert len(scene) == 0 and scene.get("x") is None


def test_add_replace_and_version(scene):
    assert scene.add("a", T(1, 0, 0), [box()], [grasp()]) == 1
    assert scene.add("b", T(0, 1, 0), [sphere()]) == 2
    assert [o.id for o in scene.snapshot().objects] == ["a", "b"]
    # ADD with an existing id replaces it whole (shapes, grasps, pose) and moves it to the end
    assert scene.add("a", T(2, 0, 0), [sphere(0.1)]) == 3
    snap = scene.snapshot()
    assert [o.id for o in snap.objects] == ["b", "a"]
    a = snap.get("a")
    assert a.shapes[0].kind == "sphere" and a.grasps == ()
    np.testing.assert_allclose(a.pose, T(2, 0, 0))


def test_remove_one_and_all(scene):
    scene.add("a", T(), [box()])
    scene.add("b", T(), [box()])
    assert scene.remove("a") == 3
    assert [o.id for o in scene.snapshot().objects] == ["b"]
    assert scene.remove("") == 4
    assert scene.snapshot().objects == ()
    assert scene.remove() == 5  # removing all from an empty scene is still an applied update


def test_append_keeps_pose_and_extends(scene):
    scene.add("a", T(1, 0, 0), [box()], [grasp("g0")])
    v = scene.append("a", [sphere(pose=T(0, 0, 0.5))], [grasp("g1")], pose=T(9, 9, 9))
    a = scene.get("a")
    assert v == 2
    np.testing.assert_allclose(a.pose, T(1, 0, 0))  # the existing object's pose is kept (MoveIt)
    assert [s.kind for s in a.shapes] == ["box", "sphere"]
    assert [g.id for g in a.grasps] == ["g0", "g1"]


def test_append_creates_missing(scene):
    scene.append("new", [tetra()], pose=T(0, 0, 1))
    a = scene.get("new")
    np.testing.assert_allclose(a.pose, T(0, 0, 1))
    assert a.shapes[0].kind == "mesh" and a.shapes[0].triangles.shape == (4, 3)


def test_move_changes_pose_only(scene):
    scene.add("a", T(), [box()], [grasp()])
    before = scene.get("a")
    assert scene.move("a", T(0.5, 0.5, 0.5)) == 2
    after = scene.get("a")
    np.testing.assert_allclose(after.pose, T(0.5, 0.5, 0.5))
    assert after.shapes == before.shapes and after.grasps == before.grasps


def test_all_primitive_kinds(scene):
    shapes = [box(), sphere(), Shape("cylinder", T(), (0.2, 0.05)), Shape("cone", T(), (0.2, 0.05)), tetra()]
    scene.add("all", T(), shapes)
    assert [s.kind for s in scene.get("all").shapes] == ["box", "sphere", "cylinder", "cone", "mesh"]


def test_grasp_normals_are_normalized(scene):
    scene.add("a", T(), [box()], [grasp()])
    np.testing.assert_allclose(scene.get("a").grasps[0].normals, [[0.0, -1.0, 0.0]])


def test_zero_dimensions_are_accepted_as_moveit_does(scene):
    """geometric_shapes refuses only negative sizes; a flat box or a point is still an obstacle."""
    scene.add("flat", T(), [box(0.3, 0.3, 0.0), sphere(0.0), Shape("cylinder", T(), (0.0, 0.1))])
    assert [s.dims for s in scene.get("flat").shapes] == [(0.3, 0.3, 0.0), (0.0,), (0.0, 0.1)]


def test_grasps_without_id_are_named_by_position_and_never_repeat(scene):
    scene.add("a", T(), [box()], [grasp(""), grasp("g1"), grasp("")])
    assert [g.id for g in scene.get("a").grasps] == ["#0", "g1", "#2"]
    scene.append("a", [box()], [grasp(""), grasp("")])
    ids = [g.id for g in scene.get("a").grasps]
    assert ids == ["#0", "g1", "#2", "#3", "#4"] and len(set(ids)) == len(ids)


def test_limits_refuse_big_messages_and_scenes_whole():
    lim = SceneLimits(max_triangles_per_message=10, max_triangles_per_scene=15, max_primitives_per_object=3,
                      max_grasps_per_object=2)
    scene = PlanningScene("base_link", lim)
    V = np.random.default_rng(0).uniform(size=(12, 3))

    def mesh(n):
        return Shape("mesh", T(), vertices=V, triangles=np.arange(3 * n).reshape(n, 3) % 12)

    scene.add("m", T(), [mesh(10)])
    for upd, words in [
            (SceneUpdate(Operation.ADD, "x", T(), (mesh(11),)), "max_triangles_per_message = 10"),
            (SceneUpdate(Operation.ADD, "x", T(), (mesh(6),)), "max_triangles_per_scene = 15"),
            (SceneUpdate(Operation.ADD, "x", T(), (box(),) * 4), "max_primitives_per_object = 3"),
            (SceneUpdate(Operation.ADD, "x", T(), (box(),), (grasp("a"), grasp("b"), grasp("c"))),
             "max_grasps_per_object = 2")]:
        with pytest.raises(SceneUpdateError, match=words):
            scene.apply(upd)
    assert scene.version == 1 and scene.triangles == 10
    scene.add("m", T(), [mesh(5)])  # replacing frees the old object's triangles
    scene.add("x", T(), [mesh(10), box(), box()], [grasp("a")])
    assert scene.triangles == 15
    with pytest.raises(SceneUpdateError, match="max_primitives_per_object = 3"):
        scene.append("x", [box(), box()])  # the object after the APPEND counts
    with pytest.raises(SceneUpdateError, match="max_grasps_per_object = 2"):
        scene.append("x", [box()], [grasp("b"), grasp("c")])
    scene.remove("m")
    assert scene.triangles == 10
    scene.remove()
    assert scene.triangles == 0


def test_stored_arrays_are_read_only_copies(scene):
    pose = T(1, 2, 3)
    scene.add("a", pose, [box()])
    pose[0, 3] = 99.0  # the caller's array is not aliased
    a = scene.get("a")
    assert a.pose[0, 3] == 1.0
    with pytest.raises(ValueError):
        a.pose[0, 3] = 5.0


def test_equal_primitives_share_one_checked_shape_and_the_rest_is_still_checked(scene):
    """A primitive equal in every bit to one checked before is that Shape (objects of one size share it);
    one that differs in a bit (-0.0), a shape of the pose array, or is invalid is not taken for it."""
    scene.add("a", T(1, 0, 0), [box()])
    scene.add("b", T(2, 0, 0), [box(), sphere()])
    scene.append("a", [Shape("box", T(), [0.1, 0.2, 0.3])])  # a list of the same numbers
    a, b = scene.get("a"), scene.get("b")
    assert a.shapes[0] is b.shapes[0] is a.shapes[1] and b.shapes[1] is not a.shapes[0]
    assert not a.shapes[0].pose.flags.writeable
    scene.add("c", T(), [box(-0.0)])
    assert scene.get("c").shapes[0] is not a.shapes[0] and str(scene.get("c").shapes[0].dims[0]) == "-0.0"
    flat = Shape("box", T().reshape(16), (0.1, 0.2, 0.3))  # the bytes of a checked pose, not a 4x4 matrix
    with pytest.raises(SceneUpdateError):
        scene.add("d", T(), [flat])
    with pytest.raises(SceneUpdateError):
        scene.add("d", T(), [box(0.1, 0.2, np.nan)])
    assert "d" not in scene


R_BAD = T()
R_BAD[:3, :3] *= 2.0
NAN_POSE = T(np.nan, 0, 0)

INVALID = {
    "unknown operation": SceneUpdate(7, "x", T(), (box(),)),
    "empty id on ADD": SceneUpdate(Operation.ADD, "", T(), (box(),)),
    "ADD without shapes": SceneUpdate(Operation.ADD, "x", T(), ()),
    "APPEND without shapes": SceneUpdate(Operation.APPEND, "a", T(), ()),
    "MOVE with shapes": SceneUpdate(Operation.MOVE, "a", T(1, 1, 1), (box(),)),
    "MOVE with grasps": SceneUpdate(Operation.MOVE, "a", T(1, 1, 1), (), (grasp(),)),
    "MOVE of a missing object": SceneUpdate(Operation.MOVE, "missing", T(1, 1, 1)),
    "REMOVE of a missing object": SceneUpdate(Operation.REMOVE, "missing"),
    "REMOVE with shapes": SceneUpdate(Operation.REMOVE, "a", None, (box(),)),
    "ADD without pose": SceneUpdate(Operation.ADD, "x", None, (box(),)),
    "NaN pose": SceneUpdate(Operation.ADD, "x", NAN_POSE, (box(),)),
    "non-rigid pose": SceneUpdate(Operation.ADD, "x", R_BAD, (box(),)),
    "other frame": SceneUpdate(Operation.ADD, "x", T(), (box(),), frame="world"),
    "negative box dim": SceneUpdate(Operation.ADD, "x", T(), (box(-0.1),)),
    "negative sphere radius": SceneUpdate(Operation.ADD, "x", T(), (sphere(-1e-9),)),
    "wrong dim count": SceneUpdate(Operation.ADD, "x", T(), (Shape("cylinder", T(), (0.1,)),)),
    "inf dim": SceneUpdate(Operation.ADD, "x", T(), (Shape("sphere", T(), (np.inf,)),)),
    "unknown kind": SceneUpdate(Operation.ADD, "x", T(), (Shape("torus", T(), (1.0, 0.5)),)),
    "NaN shape pose": SceneUpdate(Operation.ADD, "x", T(), (box(pose=NAN_POSE),)),
    "mesh index out of range": SceneUpdate(Operation.ADD, "x", T(), (
        Shape("mesh", T(), vertices=np.zeros((3, 3)), triangles=np.array([[0, 1, 3]])),)),
    "mesh negative index": SceneUpdate(Operation.ADD, "x", T(), (
        Shape("mesh", T(), vertices=np.zeros((3, 3)), triangles=np.array([[0, 1, -1]])),)),
    "empty mesh": SceneUpdate(Operation.ADD, "x", T(), (
        Shape("mesh", T(), vertices=np.zeros((0, 3)), triangles=np.zeros((0, 3), int)),)),
    "mesh NaN vertex": SceneUpdate(Operation.ADD, "x", T(), (
        Shape("mesh", T(), vertices=np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]),
              triangles=np.array([[0, 1, 2]])),)),
    "contacts/normals count mismatch": SceneUpdate(Operation.ADD, "x", T(), (box(),), (
        GraspSpec("g", "", T(), np.zeros((2, 3)), np.array([[0.0, 0.0, 1.0]])),)),
    "zero normal": SceneUpdate(Operation.ADD, "x", T(), (box(),), (
        GraspSpec("g", "", T(), np.zeros((1, 3)), np.zeros((1, 3))),)),
    "normal whose length overflows": SceneUpdate(Operation.ADD, "x", T(), (box(),), (
        GraspSpec("g", "", T(), np.zeros((1, 3)), np.array([[1e200, 1e200, 0.0]])),)),
    "negative friction": SceneUpdate(Operation.ADD, "x", T(), (box(),), (
        GraspSpec("g", "", T(), friction=-0.1),)),
    "NaN grasp pose": SceneUpdate(Operation.ADD, "x", T(), (box(),), (GraspSpec("g", "", NAN_POSE),)),
    "duplicate grasp id": SceneUpdate(Operation.ADD, "x", T(), (box(),), (grasp("g"), grasp("g"))),
    "APPEND duplicating a grasp id": SceneUpdate(Operation.APPEND, "a", T(), (box(),), (grasp("g0"),)),
    "explicit id equal to a generated one": SceneUpdate(Operation.ADD, "x", T(), (box(),), (grasp(""), grasp("#0"))),
}


@pytest.mark.parametrize("kind", sorted(INVALID))
def test_invalid_update_leaves_scene_unchanged(scene, kind):
    scene.add("a", T(1, 0, 0), [box()], [grasp("g0")])
    before = scene.snapshot()
    with pytest.raises(SceneUpdateError) as err:
        scene.apply(INVALID[kind])
    assert str(err.value)  # a clear message
    after = scene.snapshot()
    assert after.version == before.version == 1
    assert len(after.objects) == len(before.objects) == 1
    assert after.objects[0] is before.objects[0]  # the very same immutable object: nothing touched


def test_frame_equal_to_planning_frame_is_accepted(scene):
    scene.apply(SceneUpdate(Operation.ADD, "x", T(), (box(),), frame="base_link"))
    assert "x" in scene


def test_snapshot_is_frozen(scene):
    scene.add("a", T(), [box()])
    snap = scene.snapshot()
    scene.add("b", T(), [box()])
    scene.move("a", T(1, 0, 0))
    assert [o.id for o in snap.objects] == ["a"] and snap.version == 1
    np.testing.assert_allclose(snap.get("a").pose, T())


def test_concurrent_updates_are_all_applied(scene):
    n_threads, per_thread = 4, 50

    def work(k):
        for i in range(per_thread):
            scene.add(f"o{k}_{i}", T(i, k, 0), [sphere()])
            scene.snapshot()

    threads = [threading.Thread(target=work, args=(k,)) for k in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    snap = scene.snapshot()
    assert snap.version == n_threads * per_thread == len(snap.objects)


# ---------------------------------------------------------------------- property: the scene is a MoveIt-like dict
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

IDS = st.sampled_from(["a", "b", "c", ""])
OPS = st.tuples(st.sampled_from(list(Operation)), IDS, st.integers(0, 2))


@settings(max_examples=60, deadline=None)
@given(st.lists(OPS, max_size=25))
def test_random_operation_sequences_match_a_simple_model(ops):
    scene = PlanningScene("base_link")
    model: dict[str, tuple[float, int]] = {}  # id -> (x of pose, number of shapes)
    version = 0
    for op, oid, n in ops:
        shapes = tuple(sphere() for _ in range(n))
        upd = SceneUpdate(op, oid, T(float(n), 0, 0) if op != Operation.REMOVE else None, shapes)
        valid = {
            Operation.ADD: bool(oid) and n > 0,
            Operation.APPEND: bool(oid) and n > 0,
            Operation.MOVE: bool(oid) and n == 0 and oid in model,
            Operation.REMOVE: n == 0 and (oid == "" or oid in model),
        }[op]
        if not valid:
            with pytest.raises(SceneUpdateError):
                scene.apply(upd)
            continue
        scene.apply(upd)
        version += 1
        if op == Operation.ADD:
            model.pop(oid, None)
            model[oid] = (float(n), n)
        elif op == Operation.APPEND:
            x, k = model.get(oid, (float(n), 0))
            model[oid] = (x, k + n)
        elif op == Operation.MOVE:
            model[oid] = (float(n), model[oid][1])
        elif oid:
            del model[oid]
        else:
            model.clear()
    snap = scene.snapshot()
    assert snap.version == version
    assert [(o.id, o.pose[0, 3], len(o.shapes)) for o in snap.objects] == [(k, x, m) for k, (x, m) in model.items()]
