"""compiled.warm_all: every kernel module's warm-up runs, so no plan loads a kernel (~15 ms each) in its time."""
from __future__ import annotations

from humanoid_planner.core import compiled
from humanoid_planner.core.collision import kernels as collision_kernels
from humanoid_planner.core.ik import kernels as ik_kernels
from humanoid_planner.core.planners import kernels as search_kernels


def test_warm_all_loads_the_kernels_of_every_module():
    compiled.warm_all()
    for kernel in (collision_kernels.screen_batches, collision_kernels.triangle_spheres, search_kernels.first_in_domain,
                   search_kernels.polyline, ik_kernels.dls_batch, ik_kernels.steer, ik_kernels.line):
        assert kernel.signatures, kernel
