"""A serialized CollisionObject (the bytes a raw subscription hands over) -> `RawObject`, with numpy.

Why not rclpy's own deserialization: it builds a Python object per mesh vertex and triangle while
holding the interpreter lock — a 10^6-triangle mesh (24 MB) took seconds during which no other
callback or planning thread could run — and it does so before any callback can look at the sizes.
Here the counts are read first and checked against `SceneLimits` (a too-big message is refused
before anything is built), and every large array (vertices, triangles, contacts, normals, poses) is
one `np.frombuffer` view. Libraries that deserialize CDR in Python (rosbags, pycdr2) also build one
object per element of a message array, so they have the same cost.

Format: XCDR1 (plain CDR) as rmw_fastrtps writes it — a 4-byte encapsulation header (byte 1: 1 =
little endian, 0 = big endian), then the fields in .msg order, each primitive aligned to its size
relative to the end of that header; strings and sequences are a uint32 count first (strings count
their terminating NUL); fixed arrays (MeshTriangle's uint32[3]) have no count. The tests check this
reader against rclpy's deserialization on many random messages.
"""
from __future__ import annotations

import struct

import numpy as np

from humanoid_planner.core.scene.planning_scene import SceneLimits, SceneUpdateError
from humanoid_planner.ros.conversions import RawObject

_HEADER = 4


_STRUCTS = {order: {code: struct.Struct(order + code).unpack_from for code in ("B", "b", "I", "d", "7d")}
            for order in "<>"}


class _Reader:
    def __init__(self, buf: bytes):
        if len(buf) < _HEADER or buf[0] != 0 or buf[1] not in (0, 1):
            raise SceneUpdateError("collision_object: not a plain-CDR serialized message "
                                   f"(encapsulation {bytes(buf[:2]).hex() or 'missing'})")
        self.buf = buf
        self.end = len(buf)
        self.order = "<" if buf[1] == 1 else ">"
        self._unpack = _STRUCTS[self.order]
        self.pos = _HEADER

    def _align(self, n: int) -> None:
        self.pos += (-(self.pos - _HEADER)) % n

    def _need(self, n: int) -> None:
        if self.pos + n > self.end:
            raise SceneUpdateError(f"collision_object: message truncated (needs {self.pos + n} bytes, has {self.end})")

    def _scalar(self, code: str, size: int):
        """One number (struct: a numpy view per scalar cost ten times more, and a box's ADD has 30);
        aligned and bounds-checked inline (a box's ADD reads 10 of them)."""
        pos = self.pos + (-(self.pos - _HEADER)) % size
        if pos + size > self.end:
            self.pos = pos
            self._need(size)
        self.pos = pos + size
        return self._unpack[code](self.buf, pos)[0]

    def u8(self) -> int:
        return self._scalar("B", 1)

    def i8(self) -> int:
        return self._scalar("b", 1)

    def u32(self) -> int:
        return self._scalar("I", 4)

    def f64(self) -> float:
        return self._scalar("d", 8)

    def count(self, min_bytes_each: int) -> int:
        """A sequence length, refused if the rest of the message cannot hold that many elements."""
        n = self.u32()
        if n * min_bytes_each > self.end - self.pos:
            raise SceneUpdateError(f"collision_object: a sequence of {n} elements does not fit in the message "
                                   f"({self.end - self.pos} bytes left)")
        return n

    def string(self) -> str:
        n = self.count(1)
        if n == 0:
            return ""
        raw = bytes(self.buf[self.pos:self.pos + n - 1])
        self.pos += n
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            raise SceneUpdateError("collision_object: a string is not valid UTF-8") from None

    def array(self, code: str, size: int, n: int, width: int) -> np.ndarray:
        """n rows of `width` numbers (a sequence of structs of one primitive type, or a fixed array)."""
        if n == 0:
            return np.zeros((0, width), dtype=np.dtype(code) if code != "f8" else float)
        self._align(size)
        self._need(size * n * width)
        out = np.frombuffer(self.buf, dtype=self.order + code, count=n * width, offset=self.pos).reshape(n, width)
        self.pos += size * n * width
        return out.astype(out.dtype.newbyteorder("="), copy=True)  # own, native-order memory

    def points(self) -> np.ndarray:
        return self.array("f8", 8, self.count(24), 3)

    def pose(self) -> tuple[float, ...]:
        """7 floats: position, then the xyzw quaternion."""
        self._align(8)
        self._need(56)
        v = self._unpack["7d"](self.buf, self.pos)
        self.pos += 56
        return v

    def doubles(self, n: int) -> tuple[float, ...]:
        """n float64 (a primitive's few dimensions)."""
        if n == 0:
            return ()
        self._align(8)
        self._need(8 * n)
        v = struct.unpack_from(f"{self.order}{n}d", self.buf, self.pos)
        self.pos += 8 * n
        return v

    def skip(self, align: int, n_bytes: int) -> None:
        if n_bytes:
            self._align(align)
            self._need(n_bytes)
            self.pos += n_bytes

    def small_poses(self) -> list[tuple[float, ...]]:
        """A sequence of poses, each 7 floats (primitive and mesh poses: few per message)."""
        return [self.pose() for _ in range(self.count(56))]


def parse_collision_object(buf: bytes, limits: SceneLimits | None = None) -> RawObject:
    """Bytes of a serialized humanoid_planner_interfaces/CollisionObject -> RawObject.

    Raises SceneUpdateError for bytes that are not such a message, and (when `limits` is given)
    for a message over the limits — checked on its counts, before its arrays are copied.
    """
    r = _Reader(memoryview(buf).cast("B") if not isinstance(buf, bytes) else buf)
    r.u32(), r.u32()  # header.stamp (sec, nanosec): not used
    frame = r.string()
    oid = r.string()
    what = f"object {oid!r}"
    pose = r.pose()
    primitives = []
    n_prim = r.count(9)  # type + dimensions count + polygon count
    if limits is not None and n_prim > limits.max_primitives_per_object:
        limits.check_message(n_prim, 0, 0, what)
    for _ in range(n_prim):
        ptype = r.u8()
        dims = r.doubles(r.count(8))
        r.skip(4, 12 * r.count(12))  # polygon (PRISM only)
        primitives.append((ptype, dims))
    primitive_poses = r.small_poses()
    meshes = []
    triangles = 0
    for _ in range(r.count(8)):
        n_tri = r.count(12)
        triangles += n_tri
        if limits is not None and triangles > limits.max_triangles_per_message:
            limits.check_message(0, triangles, 0, what)
        F = r.array("u4", 4, n_tri, 3).astype(np.int64)
        V = r.points()
        meshes.append((V, F))
    mesh_poses = r.small_poses()
    grasps = []
    n_grasps = r.count(4 + 4 + 56 + 4 + 4 + 8)
    if limits is not None and n_grasps > limits.max_grasps_per_object:
        limits.check_message(0, 0, n_grasps, what)
    for _ in range(n_grasps):
        gid, hand = r.string(), r.string()
        tcp = r.pose()
        contacts, normals = r.points(), r.points()
        grasps.append((gid, hand, tcp, contacts, normals, r.f64()))
    operation = r.i8()
    return RawObject(operation=operation, id=oid, frame=frame, pose=pose, primitives=primitives,
                     primitive_poses=primitive_poses, meshes=meshes, mesh_poses=mesh_poses, grasps=grasps)
