"""RViz markers (ros.markers), no ROS graph: the marker array of a scene and a plan on the small test
arm — one marker per shape of the right type and size, the grasped object green, the TCP path through
the TCP at every trajectory point, the arrow ending on the grasp target."""
from __future__ import annotations

import numpy as np
import pytest
from visualization_msgs.msg import Marker

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlan
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.postprocess.timing import time_parameterize
from humanoid_planner.core.scene.types import AttachedObject, GraspSpec, SceneObject, SceneSnapshot, Shape, VoxelLayer
from humanoid_planner.ros.markers import (OBSTACLE_COLOR, TARGET_COLOR, marker_array, plan_markers, scene_markers)

FRAME = "base_link"


def at(x, y, z) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


@pytest.fixture(scope="module")
def arm(test_robot_description) -> RobotModel:
    return RobotModel.from_urdf_srdf(*test_robot_description)


def scene(**kw) -> SceneSnapshot:
    tetra = (np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]), np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]))
    return SceneSnapshot(2, FRAME, (
        SceneObject("table", at(0.5, 0, 0), (Shape("box", np.eye(4), (0.4, 0.6, 0.02)),
                                             Shape("cylinder", at(0, 0, -0.2), (0.4, 0.02)))),
        SceneObject("cup", at(0.3, 0.1, 0.2), (Shape("sphere", np.eye(4), (0.03,)), Shape("cone", np.eye(4), (0.1, 0.05)),
                                              Shape("mesh", np.eye(4), (), *tetra)))), **kw)


def test_scene_markers_one_per_shape_target_green():
    markers = scene_markers(scene(), FRAME, highlight="cup")
    assert [m.type for m in markers] == [Marker.CUBE, Marker.CYLINDER, Marker.SPHERE, Marker.TRIANGLE_LIST,
                                         Marker.TRIANGLE_LIST]
    assert len({m.id for m in markers}) == 5 and {m.ns for m in markers} == {"scene"}
    assert all(m.header.frame_id == FRAME for m in markers)
    assert [m.color == TARGET_COLOR for m in markers] == [False, False, True, True, True]
    assert markers[0].color == OBSTACLE_COLOR
    box, cyl, ball, cone, mesh = markers
    assert (box.scale.x, box.scale.y, box.scale.z) == pytest.approx((0.4, 0.6, 0.02))
    assert (cyl.scale.x, cyl.scale.z) == pytest.approx((0.04, 0.4)) and cyl.pose.position.z == pytest.approx(-0.2)
    assert ball.scale.x == pytest.approx(0.06) and ball.pose.position.x == pytest.approx(0.3)
    assert len(cone.points) % 3 == 0 and max(p.z for p in cone.points) == pytest.approx(0.05)
    assert len(mesh.points) == 12


def test_voxels_and_attached_objects_are_shown(arm):
    layer = VoxelLayer(0.05, np.array([[0, 0, 0], [1, 2, 3]], dtype=np.int32))
    held = AttachedObject("tool", "hand", at(0, 0, 0.1), (Shape("box", np.eye(4), (0.02, 0.02, 0.02)),))
    snap = scene(voxels=layer, attached=(held,))
    markers = scene_markers(snap, FRAME, link_pose=lambda link: arm.link_poses(arm.home, [link])[0])
    cells = [m for m in markers if m.ns == "occupied_voxels"]
    assert len(cells) == 1 and cells[0].type == Marker.CUBE_LIST and len(cells[0].points) == 2
    tool = [m for m in markers if m.ns == "attached"]
    hand = arm.link_poses(arm.home, ["hand"])[0]
    assert len(tool) == 1 and tool[0].pose.position.z == pytest.approx(hand[2, 3] + 0.1)


def test_plan_markers_follow_the_tcp_and_point_at_the_grasp(arm):
    path = np.array([arm.home, [0.5, -0.4, 0.2], [0.9, -0.8, 0.4]])
    traj = time_parameterize(path, arm.max_velocity, arm.max_acceleration)
    target = arm.link_poses(path[-1], ["tcp"])[0]
    plan = GraspPlan(PlanStatus.SUCCESS, joint_names=arm.joint_names, path=path, trajectory=traj,
                     grasps=(GraspSpec("top", "", np.eye(4)),), tcp_poses=(target,))
    markers = plan_markers(arm, plan, ("arm",), arm.home, (target,), FRAME)
    by_ns = {m.ns: m for m in markers}
    assert set(by_ns) == {"tcp_path", "grasp", "grasp_label"}
    line = by_ns["tcp_path"]
    tcp = arm.link_poses(traj.positions, ["tcp"])[:, 0, :3, 3]  # the generic FK, at every trajectory point
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in line.points], tcp, atol=1e-9)
    tip = by_ns["grasp"].points[1]
    np.testing.assert_allclose([tip.x, tip.y, tip.z], target[:3, 3])
    tail = by_ns["grasp"].points[0]
    along = target[:3, 3] - [tail.x, tail.y, tail.z]
    np.testing.assert_allclose(along / np.linalg.norm(along), target[:3, 2], atol=1e-9)  # the hand's approach: z here
    assert by_ns["grasp_label"].text == "arm: top"
    array = marker_array(markers)
    assert array.markers[0].action == Marker.DELETEALL and array.markers[1:] == markers
