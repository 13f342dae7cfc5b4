"""RViz markers (`~/markers`, visualization_msgs/MarkerArray): the scene, the last plan's TCP path(s)
and reached grasp(s), all in the planning frame.

Namespaces: `scene` (one marker per shape; the grasped object of the last plan in green), `attached`
(objects held by the robot, at their link's pose in the latest joint state), `occupied_voxels` (one
CUBE_LIST of the point-cloud layer's cells), `tcp_path` (a LINE_STRIP per planning group, through the
TCP at every trajectory point), `retreat_path` (the same along the retreat trajectory), `grasp` (an ARROW per
reached grasp that ends at the TCP target and points along the hand's approach direction) and
`grasp_label` (TEXT). Every array starts with a DELETEALL marker, so a latched array always shows
exactly the current scene and the last plan.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneSnapshot, Shape

from humanoid_planner.ros.conversions import matrix_to_pose_msg
from humanoid_planner.ros.qos import MARKERS_QOS

OBSTACLE_COLOR = ColorRGBA(r=0.55, g=0.6, b=0.7, a=0.6)
TARGET_COLOR = ColorRGBA(r=0.2, g=0.8, b=0.3, a=0.8)
PATH_COLORS = (ColorRGBA(r=0.1, g=0.4, b=1.0, a=1.0), ColorRGBA(r=1.0, g=0.45, b=0.1, a=1.0))
GRASP_COLOR = ColorRGBA(r=0.9, g=0.1, b=0.1, a=1.0)
VOXEL_COLOR = ColorRGBA(r=0.85, g=0.55, b=0.2, a=0.7)
ATTACHED_COLOR = ColorRGBA(r=0.95, g=0.75, b=0.1, a=0.9)
CONE_SEGMENTS = 24
MARKER_PERIOD = 0.5  # s: the scene markers are refreshed at most this often


def _point(p) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _cone_triangles(height: float, radius: float) -> list[Point]:
    """Triangles of a cone along z, base at -h/2, tip at +h/2 (shape_msgs convention)."""
    a = np.linspace(0.0, 2 * np.pi, CONE_SEGMENTS + 1)
    rim = np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, -height / 2)], axis=1)
    tip, base = np.array([0, 0, height / 2]), np.array([0, 0, -height / 2])
    pts = []
    for p, q in zip(rim[:-1], rim[1:]):
        pts += [_point(tip), _point(p), _point(q), _point(base), _point(q), _point(p)]
    return pts


def shape_marker(shape: Shape, T_object: np.ndarray, frame: str, ns: str, mid: int, color: ColorRGBA) -> Marker:
    m = Marker(ns=ns, id=mid, action=Marker.ADD, color=color)
    m.header.frame_id = frame
    m.pose = matrix_to_pose_msg(T_object @ shape.pose)
    d = shape.dims
    if shape.kind == "box":
        m.type = Marker.CUBE
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in d)
    elif shape.kind == "sphere":
        m.type = Marker.SPHERE
        m.scale.x = m.scale.y = m.scale.z = 2.0 * float(d[0])
    elif shape.kind == "cylinder":
        m.type = Marker.CYLINDER
        m.scale.x = m.scale.y = 2.0 * float(d[1])
        m.scale.z = float(d[0])
    else:  # cone, mesh
        m.type = Marker.TRIANGLE_LIST
        m.scale.x = m.scale.y = m.scale.z = 1.0
        if shape.kind == "cone":
            m.points = _cone_triangles(float(d[0]), float(d[1]))
        else:
            m.points = [_point(shape.vertices[i]) for tri in shape.triangles for i in tri]
    return m


def voxel_marker(snapshot: SceneSnapshot, frame: str) -> Marker | None:
    """The point-cloud layer's cells as one CUBE_LIST (None without cells)."""
    layer = snapshot.voxels
    if layer is None or len(layer) == 0:
        return None
    m = Marker(ns="occupied_voxels", id=0, type=Marker.CUBE_LIST, action=Marker.ADD, color=VOXEL_COLOR)
    m.header.frame_id = frame
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = float(layer.size)
    m.points = [Point(x=x, y=y, z=z) for x, y, z in layer.centers.tolist()]
    return m


def scene_markers(snapshot: SceneSnapshot, frame: str, highlight: str = "",
                  link_pose: Callable[[str], np.ndarray] | None = None) -> list[Marker]:
    """Every scene shape; with link_pose (a link's pose now), the attached objects too."""
    out, mid = [], 0
    for obj in snapshot.objects:
        color = TARGET_COLOR if obj.id == highlight else OBSTACLE_COLOR
        for shape in obj.shapes:
            out.append(shape_marker(shape, obj.pose, frame, "scene", mid, color))
            mid += 1
    if link_pose is not None:
        for k, att in enumerate(snapshot.attached):
            T = link_pose(att.link) @ att.pose
            out += [shape_marker(shape, T, frame, "attached", 1000 * k + j, ATTACHED_COLOR)
                    for j, shape in enumerate(att.shapes)]
    cells = voxel_marker(snapshot, frame)
    return out if cells is None else out + [cells]


def plan_markers(robot: RobotModel, plan, groups: tuple[str, ...], start: np.ndarray, targets: tuple[np.ndarray, ...],
                 frame: str) -> list[Marker]:
    """TCP path of each group along the trajectory, and an arrow onto each reached grasp target
    (targets: one per group, or none for a plan to a joint-space goal)."""
    from humanoid_planner.core.grasp.approach import approach_axis

    out = []
    col = 0
    for k, group in enumerate(groups):
        n = len(robot.group(group).joint_names)
        if not robot.group(group).tip_link:  # both arms as one group (a joint goal): no TCP to draw the path of
            col += n
            continue
        kin = GroupKinematics(robot, group, start)
        for ns, traj in (("tcp_path", plan.trajectory), ("retreat_path", plan.retreat_trajectory)):
            if traj is None:
                continue
            pos = np.atleast_2d(traj.positions)[:, col:col + n]
            line = Marker(ns=ns, id=k, type=Marker.LINE_STRIP, action=Marker.ADD, color=PATH_COLORS[k % 2])
            line.header.frame_id = frame
            line.pose.orientation.w = 1.0
            line.scale.x = 0.006
            line.points = [_point(p) for p in kin.fk(pos).reshape(-1, 4, 4)[:, :3, 3]]
            out.append(line)
        col += n
        if k >= len(targets):
            continue
        T = targets[k]
        d = T[:3, :3] @ approach_axis(robot, group)
        arrow = Marker(ns="grasp", id=k, type=Marker.ARROW, action=Marker.ADD, color=GRASP_COLOR)
        arrow.header.frame_id = frame
        arrow.pose.orientation.w = 1.0
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.01, 0.02, 0.03  # shaft, head diameters, head length
        arrow.points = [_point(T[:3, 3] - 0.12 * d), _point(T[:3, 3])]
        out.append(arrow)
        label = Marker(ns="grasp_label", id=k, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, color=GRASP_COLOR)
        label.header.frame_id = frame
        label.pose.position = _point(T[:3, 3] - 0.14 * d + np.array([0, 0, 0.03]))
        label.pose.orientation.w = 1.0
        label.scale.z = 0.03
        label.text = f"{group}: {plan.grasps[k].id}"
        out.append(label)
    return out


def marker_array(markers: list[Marker]) -> MarkerArray:
    return MarkerArray(markers=[Marker(action=Marker.DELETEALL)] + list(markers))


class MarkerPublisher:
    """`~/markers` of `node`: the scene and the last plan, republished by a slow timer (own group)
    when the scene has changed. Plan markers are built on a thread of their own (RViz can wait).
    Nothing is built while nobody subscribes (a plan's markers are built when a subscriber comes: the
    array is latched, so a late RViz still gets them), and every array is built on the markers thread,
    never on the executor's: thousands of scene shapes take long enough to delay services."""

    def __init__(self, node, robot: RobotModel, scene, period: float = MARKER_PERIOD,
                 link_pose: Callable[[str], np.ndarray] | None = None):
        """link_pose(link): a link's pose now (where attached objects are drawn)."""
        self._node = node
        self._link_pose = link_pose
        self._robot = robot
        self._scene = scene
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="markers")
        self._lock = threading.Lock()
        self._last_plan_markers: list = []
        self._last_plan_object = ""
        self._pending_plan: tuple | None = None  # (prep, plan) whose markers nobody has asked for yet
        self._version = -1
        self._closed = False
        self._busy = threading.Event()  # a build is queued or running on the markers thread
        self.publisher = node.create_publisher(MarkerArray, "~/markers", MARKERS_QOS)
        self.group = MutuallyExclusiveCallbackGroup()
        self.timer = node.create_timer(period, self._on_timer, callback_group=self.group)

    def show_plan(self, prep, plan) -> None:
        """Publish the markers of a finished plan (`prep`: the PreparedRequest it ran), off the caller's
        thread; with no subscriber, only remember it."""
        if self._closed:
            return
        if self.publisher.get_subscription_count() == 0:
            self._pending_plan = (prep, plan)
            self._version = -1  # the first subscriber's timer tick builds it
            return
        self._busy.set()
        self._pool.submit(self._show_plan_safely, prep, plan)

    def close(self) -> None:
        """Stop the timer and drop queued builds before the node and its context go away."""
        self._closed = True
        self.timer.cancel()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def _show_plan_safely(self, prep, plan) -> None:
        try:
            targets = tuple(prep.core.object_pose @ g.tcp_in_object for g in plan.grasps)
            markers = plan_markers(self._robot, plan, prep.groups, prep.start, targets, self._scene.frame)
            with self._lock:
                self._last_plan_markers = markers
                self._last_plan_object = getattr(prep.core, "object_id", "")  # joint goals grasp nothing
                if not self._closed:
                    self._publish(prep.snapshot)
        except Exception as e:  # noqa: BLE001 - markers are a view, never a reason to fail a plan
            if not self._closed:
                self._node.get_logger().warning(f"markers of the last plan not published: {e!r}")
        finally:
            self._busy.clear()

    def _publish(self, snap: SceneSnapshot) -> None:
        """Scene + last plan markers (call with _lock held)."""
        scene = scene_markers(snap, self._scene.frame, highlight=self._last_plan_object, link_pose=self._link_pose)
        self.publisher.publish(marker_array(scene + self._last_plan_markers))
        self._version = snap.version

    def _on_timer(self) -> None:
        try:
            if (self._closed or self._scene.version == self._version
                    or self.publisher.get_subscription_count() == 0):
                return
            if self._busy.is_set():  # the last tick's build is still running: next tick
                return
            self._busy.set()
            pending, self._pending_plan = self._pending_plan, None
            if pending is not None:
                self._pool.submit(self._show_plan_safely, *pending)
            else:
                self._pool.submit(self._publish_scene_safely)
        except Exception as e:  # noqa: BLE001
            if not self._closed:
                self._node.get_logger().warning(f"scene markers not published: {e!r}")

    def _publish_scene_safely(self) -> None:
        """The timer's work, on the markers thread: thousands of shapes take a while to convert."""
        try:
            with self._lock:
                if not self._closed:
                    self._publish(self._scene.snapshot())
        except Exception as e:  # noqa: BLE001
            if not self._closed:
                self._node.get_logger().warning(f"scene markers not published: {e!r}")
        finally:
            self._busy.clear()
