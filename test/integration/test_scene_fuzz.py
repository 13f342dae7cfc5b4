"""Seeded fuzz of collision_object messages against the reference model of the README's rules
(scene_model.py): every message accepted or rejected as the model says, and the scene equal to the
model's after each one — in process through the node's own path (serialized bytes -> raw reader ->
checks -> PlanningScene), then through a planner_node process over the topic. `make soak` runs the
same with ≥ 5000 messages (scripts/soak.py)."""
from __future__ import annotations

import pytest
from rclpy.serialization import serialize_message

from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneLimits, SceneUpdateError
from humanoid_planner.ros.collision_object_cdr import parse_collision_object
from humanoid_planner.ros.conversions import raw_object_to_update, scene_object_to_msg
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS
from humanoid_planner_interfaces.msg import CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene

from plan_helpers import wait_for_services
from scene_model import FRAME, Limits, MessageFuzzer, SceneModel, same_state, state_of

pytestmark = pytest.mark.integration

SMALL = Limits(triangles_per_message=12, triangles_per_scene=30, primitives_per_object=5, grasps_per_object=6)


def _core_limits(lim: Limits) -> SceneLimits:
    return SceneLimits(lim.triangles_per_message, lim.triangles_per_scene, lim.primitives_per_object,
                       lim.grasps_per_object)


def run_in_process(seed: int, n: int, limits: Limits) -> dict:
    """Apply n fuzzed messages to a PlanningScene the node's way and to the model; compare after each."""
    fuzz, model = MessageFuzzer(seed), SceneModel(limits)
    scene = PlanningScene(FRAME, _core_limits(limits))
    accepted = 0
    for i in range(n):
        msg = fuzz.message()
        want = model.apply(msg)
        try:
            raw = parse_collision_object(serialize_message(msg), scene.limits)
            scene.apply(raw_object_to_update(raw, FRAME, (), scene.limits))
            got = True
        except SceneUpdateError:
            got = False
        assert got == want, f"message {i} (seed {seed}): node {'accepted' if got else 'rejected'}, model " \
                            f"{'accepted' if want else 'rejected'}: {msg}"
        accepted += got
        snap = scene.snapshot()
        assert snap.version == model.version
        have = state_of([scene_object_to_msg(o, FRAME) for o in snap.objects])
        assert same_state(have, model.state()), f"message {i} (seed {seed}): {have} != {model.state()}"
    return {"messages": n, "accepted": accepted}


@pytest.mark.parametrize("seed,limits", [(1, Limits()), (2, SMALL)])
def test_fuzzed_messages_match_the_model_in_process(seed, limits):
    counts = run_in_process(seed, 700, limits)
    assert 0.2 < counts["accepted"] / counts["messages"] < 0.9, counts  # both outcomes well exercised


def test_fuzzed_messages_match_the_model_through_the_node_process(ros, start_planner_process):
    proc = start_planner_process(params={"max_triangles_per_message": SMALL.triangles_per_message,
                                         "max_triangles_per_scene": SMALL.triangles_per_scene,
                                         "max_primitives_per_object": SMALL.primitives_per_object,
                                         "max_grasps_per_object": SMALL.grasps_per_object})
    node = ros.node("fuzz_client")
    cli = node.create_client(GetPlanningScene, "get_planning_scene")
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    wait_for_services(proc, cli)
    ros.wait_for_subscribers(pub, timeout=30.0)
    fuzz, model = MessageFuzzer(3), SceneModel(SMALL)
    for batch in range(6):  # batches of 50: the topic keeps the last 100, so none is lost
        for _ in range(50):
            msg = fuzz.message()
            model.apply(msg)
            pub.publish(msg)
        ros.wait_until(lambda: ros.call(cli, GetPlanningScene.Request()).version >= model.version, timeout=20.0,
                       what=f"batch {batch}: scene version {model.version}")
        resp = ros.call(cli, GetPlanningScene.Request())
        assert resp.version == model.version
        assert same_state(state_of(resp.objects), model.state()), (state_of(resp.objects), model.state())
    assert proc.proc.poll() is None and "Traceback" not in proc.output()
