"""python-fcl CollisionObjects lent out and taken back, never freed: python-fcl leaks memory on each one it frees.

python-fcl (0.7.0.11, and its master branch) releases a CollisionObject's C++ object with free()
instead of delete, so the destructor never runs and the shared_ptr inside it, which points to the
geometry, leaks its control block: 32 bytes for every CollisionObject collected. tracemalloc cannot
see this native memory. A dual_arm checker holds about 60 objects (robot shapes, their convex hulls,
scene shapes), 1.8 kB leaked per checker, and a node under load builds several checkers per plan: RSS
grew about 2 MB/min with 6 plan clients (test/soak.py).

So a checker borrows its objects here (`Loan`) and they come back when it is collected. A geometry
that lives as long as the pool (the robot's link shapes and their hulls, `RobotCollisionModel`) has
its own idle objects; scene and attached primitives share idle objects of their kind, whose geometry
is resized at each loan. The pool holds no more objects than the checkers alive at its busiest
moment borrowed. Meshes that are not the robot's (scene or attached meshes) get a new object each
time (`Loan.unpooled`), which still leaks 32 bytes when freed.
"""
from __future__ import annotations

import threading
import weakref
from typing import Callable

import fcl
import numpy as np

PRIMITIVES: dict[str, Callable[..., fcl.CollisionGeometry]] = {
    "box": fcl.Box, "sphere": fcl.Sphere, "cylinder": fcl.Cylinder, "cone": fcl.Cone}
"""fcl primitive kinds and their constructors: box (x, y, z), sphere (radius,), cylinder and cone
(radius, length)."""

_IDENTITY = np.eye(4)


def _transform(T: np.ndarray | None) -> fcl.Transform:
    T = _IDENTITY if T is None else T
    return fcl.Transform(np.ascontiguousarray(T[:3, :3], dtype=float), np.ascontiguousarray(T[:3, 3], dtype=float))


def _resize(geom: fcl.CollisionGeometry, kind: str, args: tuple[float, ...]) -> None:
    """Give a pooled primitive new dimensions (and the local bounding box fcl places it by)."""
    if kind == "box":
        geom.side = args
    elif kind == "sphere":
        geom.radius = args[0]
    else:
        geom.radius, geom.lz = args
    geom.computeLocalAABB()


def _new_primitive(kind: str, args: tuple[float, ...]) -> tuple[fcl.CollisionObject, fcl.CollisionGeometry]:
    geom = PRIMITIVES[kind](*args)
    return fcl.CollisionObject(geom, fcl.Transform()), geom


class CollisionObjectPool:
    """Idle CollisionObjects by geometry (the owner's geometries) and by primitive kind. Thread-safe."""

    def __init__(self) -> None:
        # reentrant: a checker's finalizer (give-back) may run in any thread, at any allocation,
        # also in a thread that holds the lock
        self._lock = threading.RLock()
        self._idle: dict[tuple, list] = {}  # ("geometry", id) -> objects; ("primitive", kind) -> (object, geometry)
        self._geometries: dict[int, fcl.CollisionGeometry] = {}  # alive while pooled, so their ids stay theirs
        self.created = 0  # objects made by this pool (each kept for its lifetime)

    def loan(self, owner: object) -> "Loan":
        """A loan whose objects come back when `owner` is garbage-collected."""
        return Loan(self, owner)

    @property
    def idle(self) -> int:
        """Objects waiting to be lent."""
        with self._lock:
            return sum(len(v) for v in self._idle.values())

    def _take(self, key: tuple, make: Callable[[], object]) -> object:
        with self._lock:
            idle = self._idle.get(key)
            if idle:
                return idle.pop()
            self.created += 1
        return make()

    def _give_back(self, items: list[tuple[tuple, object]]) -> None:
        with self._lock:
            for key, item in items:
                self._idle.setdefault(key, []).append(item)
        items.clear()

    def _keep(self, geom: fcl.CollisionGeometry) -> tuple:
        with self._lock:
            self._geometries.setdefault(id(geom), geom)
        return ("geometry", id(geom))


class Loan:
    """The objects one owner (a checker) has borrowed; returned to the pool when the owner is collected."""

    def __init__(self, pool: CollisionObjectPool, owner: object):
        self._pool = pool
        self._items: list[tuple[tuple, object]] = []
        weakref.finalize(owner, pool._give_back, self._items)

    def object(self, geom: fcl.CollisionGeometry, T: np.ndarray | None = None) -> fcl.CollisionObject:
        """An object of `geom`, a geometry that lives as long as the pool, posed at T (default identity)."""
        key = self._pool._keep(geom)
        obj = self._pool._take(key, lambda: fcl.CollisionObject(geom, fcl.Transform()))
        obj.setTransform(_transform(T))
        self._items.append((key, obj))
        return obj

    def primitive(self, kind: str, args: tuple[float, ...], T: np.ndarray | None = None) -> fcl.CollisionObject:
        """An object of an fcl primitive (`PRIMITIVES`) with these dimensions, posed at T (default identity)."""
        key = ("primitive", kind)
        obj, geom = self._pool._take(key, lambda: _new_primitive(kind, args))
        _resize(geom, kind, tuple(float(a) for a in args))
        obj.setTransform(_transform(T))  # after the resize: fcl bounds the object by its geometry's box
        self._items.append((key, (obj, geom)))
        return obj

    @staticmethod
    def unpooled(geom: fcl.CollisionGeometry, T: np.ndarray | None = None) -> fcl.CollisionObject:
        """A new object of a geometry that does not live as long as the pool (a scene or attached mesh)."""
        return fcl.CollisionObject(geom, _transform(T))


__all__ = ["CollisionObjectPool", "Loan", "PRIMITIVES"]
