"""Does a pick problem have a solution at all? An independent brute-force test, not the planner.

For every grasp of the set: many inverse-kinematics solutions of the grasp pose (multi-start,
collisions ignored), each one kept when it is collision-free (the target object may touch only the
hand, as during the reach); from it, the straight line *backwards* along the approach direction (the
approach run in reverse: the pre-grasp is where it ends) and the straight lift with the object
attached to the hand. A grasp is feasible when one solution has a free backward line of at least
the approach's min_distance and a free lift of at least the retreat's min_distance. No tree, no
sampling of paths: if this finds nothing, no planner can complete that problem (up to the IK's
coverage: `--ik-seeds` starts per grasp).

    .venv/bin/python benchmarks/pick_feasibility.py --seeds 18,23
    .venv/bin/python benchmarks/pick_feasibility.py --problems 50

It checks bench_planners' girrt_pick problems (the same scenarios and request): on the 50 problems
of the row, every one has a solution, so the bench keeps them all.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from humanoid_planner.core.grasp.approach import approach_axis  # noqa: E402
from humanoid_planner.core.ik.solver import solve_ik_batch  # noqa: E402
from humanoid_planner.core.model.kinematics import GroupKinematics  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.pipeline.problem import held_scene  # noqa: E402
from humanoid_planner.core.pipeline.problem import ProblemBuilder  # noqa: E402
from humanoid_planner.core.planners.cartesian import straight_line  # noqa: E402
from humanoid_planner.core.planners.common import PlannerOptions  # noqa: E402
from humanoid_planner.scenarios import OBJECT_ID, make_scenario  # noqa: E402

GROUP = "left_arm_torso"
DISTANCE, MIN_DISTANCE = 0.10, 0.05  # bench_planners' girrt_pick
LIFT = np.array([0.0, 0.0, 1.0])


@dataclass
class GraspVerdict:
    index: int
    solutions: int  # distinct collision-free IK solutions tried
    best_approach: float  # longest free backward approach line over the solutions (m)
    best_lift: float  # longest free lift over the solutions whose approach reaches min_distance (m)
    feasible: bool


def feasibility(robot: RobotModel, scene, object_pose: np.ndarray, grasps, group: str = GROUP,
                distance: float = DISTANCE, min_distance: float = MIN_DISTANCE, ik_seeds: int = 64,
                seed: int = 0) -> list[GraspVerdict]:
    """Per grasp: does one of `ik_seeds` IK solutions have a free approach and a free lift?"""
    builder = ProblemBuilder(robot, PlannerOptions())
    hands = robot.hand_links(group)
    tip = robot.group(group).tip_link
    kin = GroupKinematics(robot, group, robot.home)
    idx = robot.group_joint_indices(group)
    lo, hi = robot.lower[idx], robot.upper[idx]
    motion = builder.motion(scene, group, robot.home, OBJECT_ID, hands)
    axis = approach_axis(robot, group)
    rng = np.random.default_rng(seed)
    out = []
    for gi, g in enumerate(grasps):
        if not robot.hand_usable_by(g.hand, group):
            continue
        T = object_pose @ g.tcp_in_object
        starts = np.vstack([robot.home[idx][None], rng.uniform(lo, hi, size=(ik_seeds - 1, len(idx)))])
        q, ok, _ = solve_ik_batch(kin, np.repeat(T[None], ik_seeds, axis=0), starts, lo, hi, tol_pos=1e-4,
                                  tol_rot=1e-3, iterations=300)
        q = q[ok]
        if len(q):
            q = q[np.unique(np.round(q, 2), axis=0, return_index=True)[1]]
            q = q[motion.check_configs(q)]
        d_appr = T[:3, :3] @ axis
        held = builder.motion(held_scene(scene, OBJECT_ID, tip, T, hands), group, robot.home, "", hands)
        best_a = best_l = 0.0
        for qg in q:
            back = straight_line(kin, qg, -d_appr, distance, lo, hi, validate=motion.free_prefix, T0=T)
            best_a = max(best_a, back.distance)
            if back.distance < min_distance - 1e-9:
                continue
            lift = straight_line(kin, qg, LIFT, distance, lo, hi, validate=held.free_prefix, T0=T)
            best_l = max(best_l, lift.distance)
            if lift.distance >= min_distance - 1e-9:
                break
        out.append(GraspVerdict(gi, len(q), best_a, best_l,
                                best_a >= min_distance - 1e-9 and best_l >= min_distance - 1e-9))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="", help="comma-separated scenario seeds (default: the bench's first --problems)")
    ap.add_argument("--problems", type=int, default=50)
    ap.add_argument("--ik-seeds", type=int, default=64)
    a = ap.parse_args(argv)
    robot = RobotModel.preset("armar3")
    seeds = [int(s) for s in a.seeds.split(",") if s.strip()] or list(range(a.problems))
    unsolvable = []
    for s in seeds:
        sc = make_scenario(robot, "boxes6", s, left_group="left_arm", right_group="right_arm", hand="left")
        v = feasibility(robot, sc.scene, sc.object_pose, sc.grasps, ik_seeds=a.ik_seeds)
        ok = [x.index for x in v if x.feasible]
        print(f"seed {s}: {len(ok)}/{len(v)} grasps feasible {ok}; per grasp (solutions, approach cm, lift cm): "
              + ", ".join(f"{x.index}:({x.solutions},{x.best_approach * 100:.1f},{x.best_lift * 100:.1f})" for x in v),
              flush=True)
        if not ok:
            unsolvable.append(s)
    print(f"{len(unsolvable)} of {len(seeds)} problems have no grasp with a free approach and lift: {unsolvable}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
