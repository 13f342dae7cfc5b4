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


def test_recent_cache_keeps_an_entry_from_its_second_offer_and_drops_the_least_recently_used():
    """RobotCollisionModel.group_parts: a key offered once is only remembered (a live robot's jittering postures
    never repeat, and must not fill the cache with parts no plan reuses); offered again, its value is kept; past
    `size` entries the least recently used goes; the remembered keys are bounded too."""
    from humanoid_planner.core.collision.table_cache import SEEN_KEYS, RecentCache

    cache = RecentCache(2)
    cache.offer(("a",), 1)
    assert cache.get(("a",)) is None and len(cache) == 0
    cache.offer(("a",), 2)
    assert cache.get(("a",)) == 2
    for key in (("b",), ("c",)):
        cache.offer(key, 3)
        cache.offer(key, 4)
    assert len(cache) == 2 and cache.get(("a",)) is None and cache.get(("c",)) == 4
    cache.get(("b",))  # used: ("c",) is now the oldest
    cache.offer(("d",), 5)
    cache.offer(("d",), 6)
    assert cache.get(("b",)) == 4 and cache.get(("c",)) is None
    for k in range(SEEN_KEYS + 10):  # jitter: every key new
        cache.offer(("x", k), k)
    assert len(cache) == 2 and len(cache._seen) == SEEN_KEYS
    cache.offer(("x", 0), 0)  # forgotten since: remembered again, not kept
    assert cache.get(("x", 0)) is None
