"""Limits on what one client may ask (README "Limits"), on an in-process armar3 node with small limits:
scene messages over a limit are rejected whole and later ones still apply in order; a plan request
over max_grasps_per_request is refused; a timeout above max_timeout is clamped (and said so) and the
planning thread is free again by then."""
from __future__ import annotations

import time

import pytest
from shape_msgs.msg import SolidPrimitive

from humanoid_planner.scenarios import OBJECT_ID
from humanoid_planner_interfaces.msg import CollisionObject, ErrorCode, Grasp

from plan_helpers import Graph, caged, scenario, single_request
from ros_messages import obj, pose, prim, tetra_mesh  # test/ros_messages.py

pytestmark = pytest.mark.integration


def test_scene_and_request_limits(ros):
    g = Graph(ros, max_triangles_per_message=8, max_triangles_per_scene=12, max_primitives_per_object=2,
              max_grasps_per_object=20, max_grasps_per_request=3, max_timeout=0.6, default_timeout=0.5)
    pub = g.node.create_publisher(CollisionObject, "collision_object", 100)
    g.ros.wait_for_subscribers(pub)
    box = (prim(SolidPrimitive.BOX, 0.1, 0.1, 0.1), pose(5, 0, 0))
    msgs = [obj("three_meshes", meshes=[(tetra_mesh(), pose(5, 0, 0))] * 3),  # 12 triangles > 8: rejected
            obj("two_meshes", meshes=[(tetra_mesh(), pose(5, 0, 0))] * 2),  # 8: accepted
            obj("more", meshes=[(tetra_mesh(), pose(5, 1, 0))] * 2),  # scene would hold 16 > 12: rejected
            obj("three_boxes", primitives=[box] * 3),  # rejected
            obj("two_boxes", primitives=[box] * 2),  # accepted
            obj("two_boxes", op=CollisionObject.APPEND, primitives=[box]),  # the object would have 3: rejected
            obj("grasps", primitives=[box], grasps=[Grasp(id=str(i)) for i in range(21)]),  # rejected
            obj("last", primitives=[box])]
    for m in msgs:
        for gr in m.grasps:
            gr.tcp_in_object.orientation.w = 1.0
        pub.publish(m)
    g.ros.wait_until(lambda: g.planner.scene.get("last") is not None, what="the last message applied")
    snap = g.planner.scene.snapshot()
    assert [o.id for o in snap.objects] == ["two_meshes", "two_boxes", "last"]
    assert snap.version == 3 and len(snap.get("two_boxes").shapes) == 2

    resp = g.call(g.plan, single_request(object_id="", grasps=[Grasp()] * 4))
    assert resp.error_code.val == ErrorCode.FAILURE and "max_grasps_per_request = 3" in resp.message

    sc = scenario("table_shelf", 1, "left")
    pub.publish(CollisionObject(operation=CollisionObject.REMOVE))
    g.load(caged(sc).objects)
    t0 = time.monotonic()
    resp = g.call(g.plan, single_request(object_id=OBJECT_ID, timeout=1e9))
    took = time.monotonic() - t0
    assert resp.error_code.val == ErrorCode.TIMED_OUT, resp.message
    assert resp.message.startswith("timeout 1e+09 s clamped to max_timeout 0.6 s"), resp.message
    assert took < 5.0 and resp.planning_time < 1.5, (took, resp.planning_time)


def test_requests_with_many_grasps_are_checked_in_the_planning_thread(ros):
    """Above CHECK_IN_THREAD_ABOVE grasps the callback checks only the counts and the timeout; the
    planning thread checks the rest: a bad grasp at the end is still INVALID_GOAL_CONSTRAINTS, a good
    set plans, and get_planning_scene is answered while the big set is being checked."""
    from humanoid_planner.ros.conversions import grasp_to_msg
    from humanoid_planner.ros.plan_server import CHECK_IN_THREAD_ABOVE
    from humanoid_planner_interfaces.srv import GetPlanningScene

    g = Graph(ros)
    sc = scenario("table_shelf", 1, "left")
    g.load(sc.scene.objects)
    n = 6 * CHECK_IN_THREAD_ABOVE
    grasps = [grasp_to_msg(sc.left_grasps[i % len(sc.left_grasps)]) for i in range(n)]
    for gr in grasps:
        gr.id = ""  # named #k: no duplicates
    bad = list(grasps)
    bad[-1] = grasp_to_msg(sc.left_grasps[0])
    bad[-1].id, bad[-1].friction = "", -1.0
    f_bad = g.plan.call_async(single_request(object_id=OBJECT_ID, grasps=bad, timeout=20.0))
    scene = g.call(g.scene_cli, GetPlanningScene.Request(), timeout=20.0)  # served while f_bad is checked
    assert scene.version >= 1
    resp = g.ros.wait_for(f_bad, 60.0)
    assert resp.error_code.val == ErrorCode.INVALID_GOAL_CONSTRAINTS and f"grasps[{n - 1}]" in resp.message, \
        resp.message
    resp = g.call(g.plan, single_request(object_id=OBJECT_ID, grasps=grasps, timeout=20.0), timeout=60.0)
    assert resp.error_code.val == ErrorCode.SUCCESS, resp.message
    assert resp.grasp.id.startswith("#")
