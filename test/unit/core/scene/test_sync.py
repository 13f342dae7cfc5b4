"""core/scene/sync.py: a replica fed only deltas equals the scene it copies, and each Shape travels once."""
from __future__ import annotations

import pickle

import numpy as np

from humanoid_planner.core.scene.planning_scene import AttachUpdate, Operation, PlanningScene, SceneUpdate
from humanoid_planner.core.scene.sync import SceneFeed, SceneReplica
from humanoid_planner.core.scene.types import GraspSpec, SceneSnapshot, Shape, VoxelLayer

LINKS = ("base", "hand")


def _T(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _box(s=0.1) -> Shape:
    return Shape("box", np.eye(4), (s, s, s))


def _mesh() -> Shape:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.1
    return Shape("mesh", np.eye(4), (), v, np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]))


def content(snap: SceneSnapshot) -> tuple:
    """Everything a plan reads of a snapshot, as comparable values."""
    def shapes(ss):
        return tuple((s.kind, s.pose.tobytes(), s.dims, None if s.vertices is None else s.vertices.tobytes(),
                      None if s.triangles is None else s.triangles.tobytes()) for s in ss)

    def grasps(gs):
        return tuple((g.id, g.hand, g.tcp_in_object.tobytes()) for g in gs)

    return (snap.version, snap.frame,
            tuple((o.id, np.asarray(o.pose).tobytes(), shapes(o.shapes), grasps(o.grasps)) for o in snap.objects),
            tuple((a.id, a.link, np.asarray(a.pose).tobytes(), shapes(a.shapes), a.touch_links, grasps(a.grasps))
                  for a in snap.attached),
            None if snap.voxels is None else (snap.voxels.size, snap.voxels.cells.tobytes()))


def sync(feed: SceneFeed, replica: SceneReplica, scene: PlanningScene):
    """One hand-off, pickled as it travels to a worker; returns (the replica's snapshot, the delta)."""
    delta = pickle.loads(pickle.dumps(feed.delta(scene.snapshot())))
    return replica.apply(delta), delta


def test_adds_moves_removes_appends_attach_detach_and_voxels_keep_the_replica_equal():
    scene, feed, replica = PlanningScene("base"), SceneFeed(), SceneReplica()
    hand = {"hand": _T(0.5), "base": np.eye(4)}
    grasp = GraspSpec("g", "", _T(0, 0, 0.1))
    steps = [
        lambda: scene.add("a", _T(1), (_box(),), (grasp,)),
        lambda: scene.add("b", _T(2), (_box(0.2), _mesh())),
        lambda: scene.add("c", _T(3), (_box(),)),
        lambda: scene.move("a", _T(1.5)),
        lambda: scene.append("b", (_box(0.05),), (grasp,)),
        lambda: scene.add("a", _T(0.7), (_box(0.3),)),  # replaced: to the end of the order
        lambda: scene.remove("c"),
        lambda: scene.apply_attach(AttachUpdate("hand", SceneUpdate(Operation.ADD, "b")), hand.__getitem__, LINKS),
        lambda: scene.set_voxels(VoxelLayer(0.02, np.array([[1, 2, 3], [4, 5, 6]], np.int32))),
        lambda: scene.add("d", _T(4), (_box(),)),
        lambda: scene.apply_attach(AttachUpdate("", SceneUpdate(Operation.REMOVE, "b")), hand.__getitem__, LINKS),
        lambda: scene.set_voxels(None),
        lambda: scene.remove(""),
        lambda: scene.add("e", _T(5), (_box(),)),
    ]
    for k, step in enumerate(steps):
        step()
        got, _ = sync(feed, replica, scene)
        assert content(got) == content(scene.snapshot()), f"after step {k}"
    # a worker that starts afresh (restarted) gets the whole scene again
    feed.reset()
    got, delta = sync(feed, SceneReplica(), scene)
    assert delta.reset and content(got) == content(scene.snapshot())


def test_a_move_sends_only_the_pose_and_the_replica_keeps_its_shape_objects():
    scene, feed, replica = PlanningScene("base"), SceneFeed(), SceneReplica()
    scene.add("mesh", _T(1), (_mesh(),), (GraspSpec("g", "", np.eye(4)),))
    scene.add("box", _T(2), (_box(),))
    first, delta = sync(feed, replica, scene)
    assert len(delta.shapes) == 2
    mesh_shape = first.get("mesh").shapes[0]
    scene.move("mesh", _T(1.2))
    moved, delta = sync(feed, replica, scene)
    assert not delta.shapes and [o.id for o in delta.objects] == ["mesh"] and delta.objects[0].grasps is None
    assert moved.get("mesh").shapes[0] is mesh_shape  # its geometry (built per Shape object) is reused
    assert moved.get("box") is first.get("box")  # unchanged objects are the same objects
    same, delta = sync(feed, replica, scene)
    assert delta.empty and same is moved
    scene.remove("mesh")
    _, delta = sync(feed, replica, scene)
    assert len(delta.dropped_shapes) == 1  # the mesh: no object uses it any more
    assert replica.shape_count == 1


def test_an_unchanged_scene_costs_a_small_delta_whatever_its_size():
    scene, feed, replica = PlanningScene("base"), SceneFeed(), SceneReplica()
    for k in range(500):
        scene.add(f"o{k}", _T(k), (_box(),))
    sync(feed, replica, scene)
    scene.move("o7", _T(0.5))
    _, delta = sync(feed, replica, scene)
    assert len(pickle.dumps(delta)) < 1500 and delta.order is None
