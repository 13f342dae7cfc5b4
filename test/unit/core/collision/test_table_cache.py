"""TableCache: a robot's pair tables and selections, bounded in bytes, least recently used out first."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.collision.pair_tables import PairTable
from humanoid_planner.core.collision.table_cache import ENTRY_BYTES, TableCache


def table(n: int) -> PairTable:
    return PairTable(np.array([0]), np.zeros(1), np.ones(1), np.ones(1), np.zeros(n))


def test_the_cache_drops_least_recently_used_entries_over_its_byte_bound():
    size = ENTRY_BYTES + table(1000).dist.nbytes + 4 * 8
    cache = TableCache(max_bytes=3 * size)
    for k in range(3):
        cache[("pair", k)] = table(1000)
    cache[("pair", 0)]  # used: the oldest is now 1
    for k in range(3, 50):
        cache[("pair", k)] = table(1000)
        assert cache.bytes <= cache.max_bytes
    assert len(cache) == 3 and ("pair", 49) in cache and ("pair", 1) not in cache
    assert ("pair", 0) not in cache  # recently used once, then 47 newer entries
