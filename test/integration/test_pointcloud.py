"""The `pointcloud` topic: clouds become the scene's point-cloud layer (get_planning_scene, markers,
versions), in the planning frame or a robot link frame, malformed clouds change nothing, and a plan
goes around a wall that the node knows only as points. One armar3 node for the whole module."""
from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import CLOUD_GROUP as GROUP
from conftest import WALL_OFFSET, WALL_SIZE, RosGraph, wall_problem
from humanoid_planner_interfaces.msg import CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanGrasp
from plan_helpers import FRAME, SUCCESS, armar3, box_object, verify_response
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, PointField
from visualization_msgs.msg import Marker, MarkerArray

from humanoid_planner.clouds import (
    box_surface_points,
    look_at,
    render_depth,
    scene_boxes,
)
from humanoid_planner.core.scene.voxels import (
    CloudSettings,
    cloud_to_layer,
    robot_solids,
)
from humanoid_planner.ros.conversions import scene_object_to_msg
from humanoid_planner.ros.pointcloud import points_to_cloud
from humanoid_planner.ros.qos import (
    COLLISION_OBJECT_QOS,
    JOINT_STATES_QOS,
    MARKERS_QOS,
    POINTCLOUD_QOS,
)

pytestmark = pytest.mark.integration


class Graph:
    """The module's node, a client node and its endpoints."""

    def __init__(self, domain: int):
        from humanoid_planner.ros.node import PlannerNode

        self.ros = RosGraph(domain)
        self.node = self.ros.add(PlannerNode(context=self.ros.context,
                                             parameter_overrides=[Parameter("robot", value="armar3")]))
        self.client = self.ros.node("cloud_client")
        self.clouds = self.client.create_publisher(type(points_to_cloud(np.zeros((1, 3)), FRAME)), "pointcloud",
                                                   POINTCLOUD_QOS)
        self.objects = self.client.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
        self.joints = self.client.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
        self.scene_cli = self.client.create_client(GetPlanningScene, "get_planning_scene")
        self.plan_cli = self.client.create_client(PlanGrasp, "plan_grasp")
        self.markers: list[MarkerArray] = []
        self.client.create_subscription(MarkerArray, "humanoid_planner/markers", self.markers.append, MARKERS_QOS)
        for pub in (self.clouds, self.objects, self.joints):
            self.ros.wait_for_subscribers(pub, timeout=10.0)

    def scene(self):
        return self.ros.call(self.scene_cli, GetPlanningScene.Request())

    def send_cloud(self, msg, handled: int, timeout: float = 10.0) -> None:
        """Publish until the node has handled (converted or rejected) `handled` clouds; best-effort
        QoS may drop one, so the cloud is sent again each second until then."""
        last = [0.0]

        def done():
            if self.handled() >= handled:
                return True
            if time.monotonic() - last[0] > 1.0:
                self.clouds.publish(msg)
                last[0] = time.monotonic()
            return False

        self.ros.wait_until(done, timeout=timeout, what=f"cloud {handled} handled")

    def handled(self) -> int:
        return self.node.pointcloud.converted + self.node.pointcloud.rejected


@pytest.fixture(scope="module")
def graph(ros_domain_id):
    g = Graph(ros_domain_id)
    yield g
    g.ros.close()


def cells_of(layer) -> set:
    return set(map(tuple, layer.cells.tolist()))


def joint_state(names, positions) -> JointState:
    return JointState(name=list(names), position=[float(p) for p in positions])


def test_cloud_becomes_the_layer_with_versions_and_markers(graph):
    robot = armar3()
    pts = box_surface_points(box_object("b", (0.6, 0.0, 1.0), (0.1, 0.3, 0.2)).pose, (0.1, 0.3, 0.2), 0.01)
    pts = pts.astype(np.float32)  # as the message carries them (cell boundaries fall on the grid)
    expected, _ = cloud_to_layer(pts, np.eye(4), CloudSettings(), robot_solids(robot, robot.home), [])
    before, converted = graph.scene(), graph.node.pointcloud.converted
    graph.send_cloud(points_to_cloud(pts, FRAME), graph.handled() + 1)
    after = graph.scene()
    assert after.occupied_voxels == len(expected) > 100
    assert after.version == before.version + graph.node.pointcloud.converted - converted  # each cloud counts
    assert cells_of(graph.node.scene.voxels) == cells_of(expected)
    # an organized cloud with NaN holes, the frame left empty: same layer for the same surface
    img = np.full((20, len(pts) // 20 + 1, 3), np.nan, dtype=np.float32).reshape(-1, 3)
    img[:len(pts)] = pts
    graph.send_cloud(points_to_cloud(img, "", (20, len(img) // 20)), graph.handled() + 1)
    assert graph.scene().occupied_voxels == len(expected)

    def cubes():
        for arr in reversed(graph.markers):
            m = [m for m in arr.markers if m.ns == "occupied_voxels"]
            if m:
                return m[0]
        return None

    m = graph.ros.wait_until(cubes, timeout=5.0, what="occupied_voxels marker")
    assert m.type == Marker.CUBE_LIST and len(m.points) == len(expected) and m.scale.x == pytest.approx(0.02)
    # an empty cloud clears the layer
    graph.send_cloud(points_to_cloud(np.zeros((0, 3)), FRAME), graph.handled() + 1)
    assert graph.scene().occupied_voxels == 0


def _bad_clouds(good):
    def variant(**changes):
        msg = points_to_cloud(good, FRAME)
        for k, v in changes.items():
            setattr(msg, k, v)
        return msg

    no_z = variant(fields=[PointField(name=a, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                           for i, a in enumerate("xy")])
    doubles = variant(fields=[PointField(name=a, offset=4 * i, datatype=PointField.FLOAT64, count=1)
                              for i, a in enumerate("xyz")])
    return {
        "missing z": no_z,
        "FLOAT64 fields": doubles,
        "field past point_step": variant(point_step=8, row_step=8 * len(good)),
        "row_step too small": variant(row_step=12 * len(good) - 1),
        "data too short": variant(data=points_to_cloud(good, FRAME).data[:-12]),
        "unknown frame": variant(header=points_to_cloud(good, "camera_somewhere").header),
    }


def test_malformed_clouds_change_nothing(graph):
    good = box_surface_points(box_object("b", (0.6, 0.2, 1.0), (0.1, 0.1, 0.1)).pose, (0.1, 0.1, 0.1), 0.01)
    graph.send_cloud(points_to_cloud(good, FRAME), graph.handled() + 1)
    before = graph.scene()
    cells = cells_of(graph.node.scene.voxels)
    assert before.occupied_voxels > 0
    for what, msg in _bad_clouds(good).items():
        rejected = graph.node.pointcloud.rejected
        graph.send_cloud(msg, graph.handled() + 1)
        assert graph.node.pointcloud.rejected == rejected + 1, what
        now = graph.scene()
        assert (now.version, now.occupied_voxels) == (before.version, before.occupied_voxels), what
        assert cells_of(graph.node.scene.voxels) == cells, what


def test_cloud_in_a_link_frame_lands_where_the_planning_frame_cloud_does(graph):
    robot = armar3()
    torso = [robot.joint_names.index(n) for n in ("torso_yaw_joint", "torso_pitch_joint", "torso_roll_joint")]
    q = robot.home.copy()
    q[torso] = [0.3, -0.2, 0.1]
    graph.ros.publish_until(graph.joints, joint_state([robot.joint_names[i] for i in torso], q[torso]),
                            lambda: (js := graph.node.latest_joint_state()) is not None
                            and list(js.position) == list(q[torso]), what="joint_states")
    link = "torso_link"
    T = robot.link_poses(q, [link])[0]
    cam = look_at([0.1, 0.0, 1.6], [0.7, -0.1, 1.1])
    seen = render_depth(scene_boxes((box_object("shelf", (0.7, -0.1, 1.1), (0.3, 0.5, 0.4)),)), cam, 80, 60)
    seen = seen.reshape(-1, 3)[np.isfinite(seen.reshape(-1, 3)).all(1)]
    world = (seen @ cam[:3, :3].T + cam[:3, 3]).astype(np.float32)
    in_link = (world - T[:3, 3]) @ T[:3, :3]
    graph.send_cloud(points_to_cloud(world, FRAME), graph.handled() + 1)
    a = cells_of(graph.node.scene.voxels)
    graph.send_cloud(points_to_cloud(in_link, link), graph.handled() + 1)
    b = cells_of(graph.node.scene.voxels)
    assert len(a) > 100 and len(a ^ b) <= 0.01 * len(a)  # float32 points: one may round across a cell face
    # the joint state matters: the same link-frame cloud with the torso at home lands elsewhere
    graph.ros.publish_until(graph.joints, joint_state([robot.joint_names[i] for i in torso], [0.0, 0.0, 0.0]),
                            lambda: list(graph.node.latest_joint_state().position) == [0.0, 0.0, 0.0])
    graph.send_cloud(points_to_cloud(in_link, link), graph.handled() + 1)
    assert len(cells_of(graph.node.scene.voxels) & a) < 0.5 * len(a)


def test_plan_goes_around_a_wall_seen_as_points(graph):
    robot = armar3()
    graph.ros.publish_until(graph.joints, joint_state(robot.joint_names, robot.home),
                            lambda: (js := graph.node.latest_joint_state()) is not None
                            and list(js.position) == list(robot.home))
    problem, target, wall, walled = wall_problem(robot)
    version = graph.scene().version
    graph.objects.publish(scene_object_to_msg(target, FRAME))
    graph.ros.wait_until(lambda: graph.scene().version > version, what="target added")
    graph.send_cloud(points_to_cloud(box_surface_points(wall.pose, WALL_SIZE, 0.01), FRAME), graph.handled() + 1)
    assert graph.scene().occupied_voxels > 100
    req = PlanGrasp.Request(group=GROUP, object_id=target.id, timeout=10.0, seed=1)
    resp = graph.ros.call(graph.plan_cli, req, timeout=20.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert resp.scene_version == graph.scene().version
    assert verify_response(resp, walled, (GROUP,), robot.home, problem.object_pose) == []
    assert np.allclose(WALL_OFFSET, wall.pose[:3, 3] - problem.object_pose[:3, 3])


def test_a_burst_of_clouds_converts_the_newest_and_services_keep_answering(graph):
    """The subscription hands clouds over in O(1); clouds that arrive while one is converted replace
    each other, so the layer ends as the newest cloud's and the node never queues a backlog."""
    robot = armar3()
    msgs, layers = [], []
    for k in range(10):
        pts = box_surface_points(box_object("b", (0.6, -0.3 + 0.06 * k, 1.0), (0.1, 0.1, 0.1)).pose,
                                 (0.1, 0.1, 0.1), 0.005).astype(np.float32)
        msgs.append(points_to_cloud(pts, FRAME))
        layers.append(cloud_to_layer(pts, np.eye(4), CloudSettings(), robot_solids(robot, robot.home), [])[0])
    layer = graph.node.pointcloud
    converted, skipped = layer.converted, layer.skipped
    for msg in msgs:  # what the subscription callback does, ten times in a row
        layer.submit(msg)
    answers = [graph.scene() for _ in range(5)]  # served while the converter works
    graph.ros.wait_until(lambda: cells_of(graph.node.scene.voxels) == cells_of(layers[-1]), what="newest layer")
    assert all(a.planning_frame == FRAME for a in answers)
    assert layer.skipped - skipped >= 5 and layer.converted - converted <= 5  # replaced, not queued
