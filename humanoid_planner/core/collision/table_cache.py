"""The per-robot caches: pair clearance tables and pair selections (pair_tables.py), bounded in bytes; the
robot's part of checker builds (RecentCache), bounded in entries.

Its own module because RobotCollisionModel (geometry.py) owns one per robot while pair_tables.py,
which fills it, reads the checker's compiled levels (levels.py, which imports geometry.py).
Keys hold q_ref values, so a live robot whose path joints keep moving adds entries with every plan:
least recently used entries go first.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

CACHE_BYTES = 64 * 2**20
"""Largest size of one robot's cache of tables and selections (TALOS: a table is 2-29 kB)."""
ENTRY_BYTES = 512
"""Counted per cache entry beside its arrays (key, Python objects)."""


class TableCache:
    """One robot's pair tables and pair selections (RobotCollisionModel.pair_tables): a dict whose
    least recently used entries go once the entries' sizes pass `max_bytes`. Not locked: callers
    hold pair_tables' module lock."""

    def __init__(self, max_bytes: int = CACHE_BYTES):
        self.max_bytes = max_bytes
        self.bytes = 0
        self._entries: OrderedDict[tuple, tuple[Any, int]] = OrderedDict()  # key -> (value, its size)

    def __contains__(self, key: tuple) -> bool:
        return key in self._entries

    def __iter__(self):
        return iter(list(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def __getitem__(self, key: tuple) -> Any:
        self._entries.move_to_end(key)
        return self._entries[key][0]

    def __setitem__(self, key: tuple, value: Any) -> None:
        if key in self._entries:
            self.bytes -= self._entries.pop(key)[1]
        size = _entry_bytes(value)
        self._entries[key] = (value, size)
        self.bytes += size
        while self.bytes > self.max_bytes and len(self._entries) > 1:
            self.bytes -= self._entries.popitem(last=False)[1][1]


def _entry_bytes(value: Any) -> int:
    """A table's arrays (`nbytes`), or a selection's (a list of tuples ending in an array)."""
    if hasattr(value, "nbytes"):
        return ENTRY_BYTES + int(value.nbytes)
    return ENTRY_BYTES + sum(ENTRY_BYTES // 4 + getattr(item[-1], "nbytes", 0) for item in value)  # a selection


SEEN_KEYS = 64
"""Keys a RecentCache remembers having been offered once (a key is a few hundred bytes)."""


class RecentCache:
    """A few entries by key, the least recently used out first past `size`; locked (checkers are built on
    several threads). An entry is kept only when its key is offered a second time (`offer`): the keys of
    RobotCollisionModel.group_parts (the robot's part of a checker's build per group and posture) hold
    q_ref values, and a live robot whose other joints jitter between plans would otherwise fill it with
    parts (TALOS: 3.3 MB each) that no later plan uses."""

    def __init__(self, size: int):
        self.size = size
        self._entries: OrderedDict[tuple, Any] = OrderedDict()
        self._seen: OrderedDict[tuple, None] = OrderedDict()  # keys offered once, not kept yet
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def get(self, key: tuple) -> Any:
        """The entry of key, or None."""
        with self._lock:
            value = self._entries.get(key)
            if value is not None:
                self._entries.move_to_end(key)
            return value

    def offer(self, key: tuple, value: Any) -> None:
        """Keep value under key if the key was offered before (else remember the key only)."""
        with self._lock:
            if key not in self._seen and key not in self._entries:
                self._seen[key] = None
                while len(self._seen) > SEEN_KEYS:
                    self._seen.popitem(last=False)
                return
            self._seen.pop(key, None)
        self.put(key, value)

    def put(self, key: tuple, value: Any) -> None:
        with self._lock:
            self._entries[key] = value
            self._entries.move_to_end(key)
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)
