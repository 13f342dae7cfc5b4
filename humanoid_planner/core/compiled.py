"""Every compiled (numba) kernel of the core loaded from numba's cache, or compiled once on a new install
(seconds): the node before its first plan, `make test` before the tests, the benchmarks before timing. A
kernel a plan meets first otherwise costs that plan ~15 ms to load (seven on a Panda shelf plan: 120 ms)."""
from __future__ import annotations

from humanoid_planner.core.collision import kernels as collision_kernels
from humanoid_planner.core.ik import kernels as ik_kernels
from humanoid_planner.core.planners import kernels as search_kernels


def warm_all() -> None:
    """Load (or compile) the collision checker's, the searches' and the IK's kernels for the types they are
    called with."""
    collision_kernels.warm()
    search_kernels.warm()
    ik_kernels.warm()


if __name__ == "__main__":  # `make test` and a new install: every compiled kernel into the cache
    warm_all()
