"""The checker tests check its steady state: a checker's first check builds the pair tables it lacks
(pair_tables.build_in_background(False)), as a planning process's checkers find them once its table
builder has run. test_pair_tables tests the builder itself."""
from __future__ import annotations

import pytest

from humanoid_planner.core.collision import pair_tables


@pytest.fixture(autouse=True)
def tables_built_inline():
    was = pair_tables.building_in_background()
    pair_tables.build_in_background(False)
    yield
    pair_tables.build_in_background(was)
