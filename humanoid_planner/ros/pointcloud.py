"""The `pointcloud` subscription: sensor_msgs/PointCloud2 → the planning scene's point-cloud layer.

The subscription callback only keeps the newest message and wakes one converter thread, so a 30 Hz
stream of 640 × 480 clouds never holds the executor: the conversion (parse, transform, filters,
cells; core/scene/voxels.py) runs on that thread, and clouds that arrive while it works replace
each other (only the newest is converted; the layer is about the present). Each converted cloud
replaces the layer whole and bumps the scene version.

A malformed cloud is rejected with a warning and changes nothing: x, y, z missing or not FLOAT32
with count 1, a field or point_step that does not fit (offset + 4 > point_step), row_step smaller
than width × point_step, data not exactly row_step × height bytes, a frame that is neither the
planning frame nor a robot link.

Frames: "" or the planning frame (or the URDF root when the planning frame is outside the URDF), or
any link of the robot, placed by forward kinematics at the latest `joint_states` merged over the
home pose (the same state the self-filter uses).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2, PointField

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.planning_scene import PlanningScene
from humanoid_planner.core.scene.voxels import (
    CloudError,
    CloudSettings,
    CloudStats,
    cloud_to_layer,
    object_solids,
    robot_solids,
)
from humanoid_planner.ros.qos import POINTCLOUD_QOS
from humanoid_planner.ros.frames import FrameError, Frames

AXES = ("x", "y", "z")


def cloud_points(msg: PointCloud2) -> np.ndarray:
    """(width·height, 3) float32 x, y, z of a PointCloud2 in its own frame (NaN points kept).

    Raises CloudError on a malformed cloud."""
    fields = {f.name: f for f in msg.fields}
    missing = [a for a in AXES if a not in fields]
    if missing:
        raise CloudError(f"fields {missing} missing (has {sorted(fields)})")
    width, height, step, row = int(msg.width), int(msg.height), int(msg.point_step), int(msg.row_step)
    for a in AXES:
        f = fields[a]
        if f.datatype != PointField.FLOAT32 or f.count != 1:
            raise CloudError(f"field {a!r} must be one FLOAT32 ({PointField.FLOAT32}), got datatype {f.datatype} "
                             f"count {f.count}")
        if f.offset + 4 > step:
            raise CloudError(f"field {a!r} at offset {f.offset} does not fit in point_step {step}")
    n = width * height
    if n and row < width * step:
        raise CloudError(f"row_step {row} is smaller than width × point_step = {width * step}")
    size = len(msg.data)
    if size != (row * height if n else size):
        raise CloudError(f"data has {size} bytes, row_step × height = {row * height}")
    if n == 0:
        return np.zeros((0, 3), dtype=np.float32)
    buf = np.frombuffer(msg.data, dtype=np.uint8)
    if row != width * step:  # padded rows: drop the padding
        buf = buf.reshape(height, row)[:, :width * step].reshape(-1)
    dt = np.dtype({"names": list(AXES), "formats": [">f4" if msg.is_bigendian else "<f4"] * 3,
                   "offsets": [fields[a].offset for a in AXES], "itemsize": step})
    rec = buf[:n * step].view(dt)
    out = np.empty((n, 3), dtype=np.float32)
    for i, a in enumerate(AXES):
        out[:, i] = rec[a]
    return out


def points_to_cloud(points: np.ndarray, frame_id: str, organized_shape: tuple[int, int] | None = None) -> PointCloud2:
    """A PointCloud2 (x, y, z FLOAT32, little-endian, dense rows) of (P, 3) points; organized_shape =
    (height, width) for an image-shaped cloud. For clients, tests and the demo."""
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f4").reshape(-1, 3))
    height, width = organized_shape if organized_shape is not None else (1, len(pts))
    if height * width != len(pts):
        raise ValueError(f"{len(pts)} points do not make a {height} x {width} cloud")
    msg = PointCloud2()
    msg.header.frame_id = frame_id
    msg.height, msg.width = height, width
    msg.fields = [PointField(name=a, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, a in enumerate(AXES)]
    msg.is_bigendian = False
    msg.point_step, msg.row_step = 12, 12 * width
    msg.data = pts.tobytes()
    msg.is_dense = bool(np.isfinite(pts).all())
    return msg


class PointCloudLayer:
    """The `pointcloud` subscription of `node` (own MutuallyExclusive group) and the converter
    thread: the callback `submit`s the message, the thread converts the newest one.

    settings: called per cloud (parameters may change at run time); frames: the node's frame
    resolver (the cloud's frame at the latest joint_states). Rejected clouds are logged as warnings (at most one a second), layers at
    debug level.
    """

    def __init__(self, node: Node, robot: RobotModel, scene: PlanningScene, frames: Frames,
                 settings: Callable[[], CloudSettings]):
        self.robot = robot
        self.scene = scene
        self.frames = frames  # the cloud's frame at the latest joint_states
        self._settings = settings
        self._log = node.get_logger()
        self._cond = threading.Condition()
        self._pending: PointCloud2 | None = None
        self._closed = False
        self.converted = 0  # clouds turned into layers
        self.rejected = 0
        self.skipped = 0  # replaced by a newer cloud before their turn
        self.last_stats: CloudStats | None = None
        self._thread = threading.Thread(target=self._run, name="pointcloud", daemon=True)
        self._thread.start()
        self.group = MutuallyExclusiveCallbackGroup()
        self.subscription = node.create_subscription(PointCloud2, "pointcloud", self._on_cloud, POINTCLOUD_QOS,
                                                     callback_group=self.group)

    def _on_cloud(self, msg: PointCloud2) -> None:
        try:
            self.submit(msg)
        except Exception as e:  # noqa: BLE001 - never let a callback kill the executor
            self._log.error(f"pointcloud callback failed: {e!r}")

    def _warn(self, text: str) -> None:
        self._log.warning(text, throttle_duration_sec=1.0)

    def submit(self, msg: PointCloud2) -> None:
        """Keep the newest cloud and wake the converter (O(1): called in the executor)."""
        with self._cond:
            if self._pending is not None:
                self.skipped += 1
            self._pending = msg
            self._cond.notify()

    def close(self, timeout: float = 2.0) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout)

    def convert(self, msg: PointCloud2) -> CloudStats:
        """One cloud → the scene's layer (raises CloudError, scene unchanged, on a bad cloud)."""
        t0 = time.perf_counter()
        settings = self._settings()
        points = cloud_points(msg)
        q = self.frames.configuration()
        try:
            T = self.frames.pose(msg.header.frame_id, q)
        except FrameError as e:
            raise CloudError(str(e)) from None
        snap = self.scene.snapshot()
        layer, stats = cloud_to_layer(points, T, settings, robot_solids(self.robot, q), object_solids(snap.objects))
        stats.stages["parse_fk"] = stats.stages.get("parse_fk", 0.0) + (time.perf_counter() - t0 - stats.seconds)
        self.scene.set_voxels(layer)
        stats.seconds = time.perf_counter() - t0
        return stats

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                msg, self._pending = self._pending, None
            try:
                stats = self.convert(msg)
            except CloudError as e:
                self.rejected += 1
                self._warn(f"pointcloud rejected, layer unchanged: {e}")
                continue
            except Exception as e:  # noqa: BLE001 - the converter thread must outlive any cloud
                self.rejected += 1
                self._warn(f"pointcloud failed, layer unchanged: {e!r}")
                continue
            self.converted += 1
            self.last_stats = stats
            self._log.debug(
                f"pointcloud: {stats.cells} cells from {stats.used}/{stats.points} points ({stats.on_robot} on the "
                f"robot, {stats.in_objects} in objects) in {stats.seconds * 1e3:.1f} ms")


__all__ = ["PointCloudLayer", "cloud_points", "points_to_cloud"]
