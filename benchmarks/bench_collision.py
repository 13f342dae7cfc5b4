#!/usr/bin/env python3
"""Collision-checking throughput: the batch path against per-configuration python-fcl, same run.

    python benchmarks/bench_collision.py                 # armar3, right_arm_torso (10 DoF), 6 boxes + table
    python benchmarks/bench_collision.py --robot talos   # TALOS meshes, l_arm and r_arm_torso, same kind of scene
    python benchmarks/bench_collision.py --robot panda   # Panda's meshes in a cage of box bars (primitives)
    python benchmarks/bench_collision.py --robot mbm_panda --mbm DIR --scene cage_panda   # MotionBenchMaker
    python benchmarks/bench_collision.py --robot mbm_panda_spheres --mbm DIR              # its spherized Panda
    python benchmarks/bench_collision.py --robot mbm_panda --mbm DIR --scene-meshes       # the scene as meshes
    python benchmarks/bench_collision.py --json out.json

MotionBenchMaker robots (--mbm: the robot folder, <name>.urdf, <name>.srdf, meshes/ and problems/, as
for bench_mbm.py): `mbm_panda` is its Panda with the collision meshes, `mbm_panda_spheres` the same arm
as 58 spheres (panda_spherized.urdf, what sphere-based planners check), group panda_arm at the all-zero
pose, in problem --problem's scene of family --scene (cage_panda, bookshelf_tall_panda, box_panda, ...).
--scene-meshes turns every primitive of the scene into a closed triangle mesh (box: 12 triangles,
cylinder: 96, sphere: 320), so the same obstacles go through the mesh path.

Workloads (seeded; every figure is the median of --repeats runs, with the min–max spread):
- random: configurations uniform within the joint limits (a new set per repeat), checked in batches of --batch by
  CollisionChecker.check_configs, and one by one by CollisionChecker.exact_check (fcl only:
  DynamicAABBTree per moving shape against fixed bodies, pairwise between moving shapes);
- edges: RRT-like motions (from a free configuration, a step of up to --step rad per joint)
  through check_edge (coarse-to-fine chunks of 16, early exit) against exact_check on the same
  interpolated points in order, stopping at the first collision.
Both paths' verdicts are compared on every configuration measured (they must agree).
- paths: the batch path with the compiled levels (kernels.py) and with the numpy levels, in batches of
  --batch and of 16 (a search's edge), same configurations;
- near (--near N): configurations next to contact, where a search's fallback spends its checks (the
  edges it extends past obstacles): N pairs (free, colliding) of random configurations, each segment
  bisected to its first contact (12 halvings, from the free end), and one configuration per pair within
  ±--near-step rad (along the segment) of that contact; configs/s in batches of --batch (a new set per
  repeat, after one set of warm-up) and of 16, which level decided them, and the share of the time
  spent in FCL (level 3);
- verify (--verify N, e.g. 10000): N random configurations through the batch path and through
  brute-force exact FCL (exact_check); false "free" (the batch path calls free what FCL finds
  colliding) must be 0.

    python benchmarks/bench_collision.py --robot talos --cpu --verify 10000
    python benchmarks/bench_collision.py --robot talos --groups l_arm --repeats 3
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from humanoid_planner.core.compiled import warm_all  # noqa: E402
from humanoid_planner.core.collision import pair_tables  # noqa: E402
from humanoid_planner.core.collision.checker import CollisionChecker  # noqa: E402
from humanoid_planner.core.collision.geometry import RobotCollisionModel  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape  # noqa: E402
from humanoid_planner.scenarios import talos_arms_out  # noqa: E402

TALOS_DIR = ROOT / ".venv/lib/python3.11/site-packages/cmeel.prefix/share/example-robot-data/robots/talos_data"


def pose(x: float, y: float, z: float, R: np.ndarray | None = None) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    if R is not None:
        T[:3, :3] = R
    return T


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def table_and_boxes(robot: RobotModel, groups: list[str], q_ref: np.ndarray, *, table_x: float, table_top: float,
                    box_region: tuple[tuple[float, float], ...], n_boxes: int = 6, seed: int = 1) -> SceneSnapshot:
    """A table (top + 4 legs, one object) and n randomly placed, rotated boxes (5–15 cm) that leave
    q_ref free for every group given (the DAGRRT paper's "6 random boxes around the object")."""
    rng = np.random.default_rng(seed)
    legs = tuple(Shape("box", pose(sx * 0.25, sy * 0.55, -table_top / 2), (0.04, 0.04, table_top - 0.02))
                 for sx in (-1, 1) for sy in (-1, 1))
    table = SceneObject("table", pose(table_x, 0.0, table_top - 0.02),
                        (Shape("box", np.eye(4), (0.6, 1.2, 0.04)),) + legs)
    objects = [table]
    while len(objects) < n_boxes + 1:
        p = [rng.uniform(lo, hi) for lo, hi in box_region]
        box = SceneObject(f"box{len(objects)}", pose(*p, random_rotation(rng)),
                          (Shape("box", np.eye(4), tuple(rng.uniform(0.05, 0.15, 3))),))
        snap = SceneSnapshot(0, robot.root_link, tuple(objects) + (box,))
        if all(CollisionChecker(robot, snap, g, q_ref).exact_check(q_ref[robot.group_joint_indices(g)])
               for g in groups):
            objects.append(box)
    return SceneSnapshot(1, robot.root_link, tuple(objects))


def setup(name: str) -> tuple[RobotModel, str, np.ndarray, SceneSnapshot]:
    if name == "armar3":
        robot = RobotModel.preset("armar3")
        q_ref = robot.home.copy()
        scene = table_and_boxes(robot, ["left_arm_torso", "right_arm_torso"], q_ref, table_x=0.8, table_top=0.88,
                                box_region=((0.35, 0.85), (-0.55, 0.55), (0.95, 1.45)))
        return robot, "right_arm_torso", q_ref, scene
    if name == "talos":
        robot = RobotModel.from_urdf_srdf(TALOS_DIR / "robots/talos_reduced.urdf", TALOS_DIR / "srdf/talos.srdf")
        q_ref = talos_arms_out(robot)
        scene = table_and_boxes(robot, ["l_arm_torso", "r_arm_torso"], q_ref, table_x=0.75, table_top=0.78,
                                box_region=((0.35, 0.8), (-0.55, 0.55), (0.85, 1.35)))
        return robot, "r_arm_torso", q_ref, scene
    if name == "panda":  # meshes (its own URDF), a scene of primitives: a cage of box bars around the target
        from humanoid_planner.scenarios import ARMS, load_humanoid, make_scenario

        robot = load_humanoid("panda")
        spec = ARMS["panda"]
        scene = make_scenario(robot, "cage", 1, left_group=spec.left, right_group=spec.right, hand="left",
                              proof_budget=None).scene
        return robot, spec.left, robot.home.copy(), scene
    if name.startswith("mbm_panda"):
        import yaml

        from humanoid_planner.moveit_yaml import planning_scene

        if MBM_DIR is None:
            raise SystemExit(f"--robot {name} needs --mbm DIR (MotionBenchMaker's panda folder)")
        urdf = "panda_spherized.urdf" if name == "mbm_panda_spheres" else "panda.urdf"
        robot = RobotModel.from_urdf_srdf(MBM_DIR / urdf, MBM_DIR / "panda.srdf", package_dirs=[MBM_DIR])
        text = (MBM_DIR / "problems" / MBM_SCENE[0] / f"scene{MBM_SCENE[1]:04d}.yaml").read_text()
        scene = planning_scene(yaml.safe_load(text), robot).snapshot()
        return robot, "panda_arm", robot.home.copy(), scene
    raise SystemExit(f"unknown robot {name!r}")


MBM_DIR: Path | None = None  # --mbm
MBM_SCENE = ("cage_panda", 1)  # --scene, --problem


def as_meshes(scene: SceneSnapshot) -> SceneSnapshot:
    """The scene with every box, cylinder and sphere replaced by a closed triangle mesh of it."""
    import trimesh

    def mesh(s: Shape) -> Shape:
        if s.kind == "box":
            m = trimesh.creation.box(extents=s.dims[:3])
        elif s.kind == "cylinder":
            m = trimesh.creation.cylinder(radius=s.dims[1], height=s.dims[0], sections=24)
        elif s.kind == "sphere":
            m = trimesh.creation.icosphere(subdivisions=2, radius=s.dims[0])
        else:
            return s
        return Shape("mesh", s.pose, (), np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))

    objects = tuple(replace(o, shapes=tuple(mesh(s) for s in o.shapes)) for o in scene.objects)
    return replace(scene, version=scene.version + 1, objects=objects)


CPU = False  # --cpu: time with process CPU time (robust on a shared machine) instead of wall clock


def clock() -> float:
    return time.process_time() if CPU else time.perf_counter()


def timed(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        out.append(clock() - t0)
    return out


def per_config_edge(checker: CollisionChecker, q0: np.ndarray, q1: np.ndarray) -> tuple[bool, int]:
    """The per-configuration baseline for an edge: exact_check at each step, in order."""
    n = checker.edge_steps(q0, q1)
    for k in range(1, n + 1):
        if not checker.exact_check(q0 + (k / n) * (q1 - q0)):
            return False, k
    return True, n


def near_contact(checker: CollisionChecker, lo: np.ndarray, hi: np.ndarray, n: int, step: float,
                 rng: np.random.Generator) -> np.ndarray:
    """n configurations within ±step rad (along a segment) of a contact: (free, colliding) random pairs,
    each segment bisected from its free end to its first contact; seeded."""
    free, hit = [], []
    while min(len(free), len(hit)) < n:
        Q = rng.uniform(lo, hi, (4 * n, len(lo)))
        ok = checker.check_configs(Q)
        free += list(Q[ok])
        hit += list(Q[~ok])
    a, b = np.array(free[:n]), np.array(hit[:n])
    s0, s1 = np.zeros(n), np.ones(n)  # free at s0, colliding at s1
    for _ in range(12):
        m = (s0 + s1) / 2
        ok = checker.check_configs(a + m[:, None] * (b - a))
        s0, s1 = np.where(ok, m, s0), np.where(ok, s1, m)
    length = np.linalg.norm(b - a, axis=1)
    s = s1 + rng.uniform(-step, step, n) / length
    return np.clip(a + s[:, None] * (b - a), lo, hi)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="armar3", choices=["armar3", "talos", "panda", "mbm_panda", "mbm_panda_spheres"])
    ap.add_argument("--mbm", type=Path, help="MotionBenchMaker's panda folder (for the mbm_* robots)")
    ap.add_argument("--scene", default="cage_panda", help="MotionBenchMaker family of the mbm_* robots' scene")
    ap.add_argument("--problem", type=int, default=1, help="... and its problem number")
    ap.add_argument("--scene-meshes", action="store_true", help="the scene's primitives as triangle meshes")
    ap.add_argument("--groups", nargs="+", help="planning groups to measure (default: TALOS l_arm and r_arm_torso, "
                    "armar3 right_arm_torso)")
    ap.add_argument("--configs", type=int, default=4000, help="random configurations per batch-path repeat")
    ap.add_argument("--per-config", type=int, default=600, help="configurations per exact_check repeat")
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--edges", type=int, default=300)
    ap.add_argument("--step", type=float, default=0.5, help="max joint change of an edge (rad)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cpu", action="store_true", help="process CPU time instead of wall clock")
    ap.add_argument("--near", type=int, default=4000, help="near-contact configurations (0: none)")
    ap.add_argument("--near-step", type=float, default=0.05, help="their spread around the contact (rad along "
                    "the segment)")
    ap.add_argument("--verify", type=int, default=0, help="configurations compared with brute-force FCL (0: none)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    # steady-state figures: each robot's first check builds its pair tables (as a planning process has them
    # after its first plans; the node builds them in the background instead, pair_tables.BUILDER)
    pair_tables.build_in_background(False)
    global CPU, MBM_DIR, MBM_SCENE
    CPU = args.cpu
    MBM_DIR, MBM_SCENE = args.mbm, (args.scene, args.problem)

    robot, group, q_ref, scene = setup(args.robot)
    if args.scene_meshes:
        scene = as_meshes(scene)
    groups = args.groups or DEFAULT_GROUPS.get(args.robot, [group])
    results, code = [], 0
    for g in groups:
        res, ok = run(args, robot, g, q_ref, scene)
        results.append(res)
        code |= 0 if ok else 1
    if args.json:
        args.json.write_text(json.dumps(results[0] if len(results) == 1 else results, indent=2, default=float))
    return code


DEFAULT_GROUPS = {"talos": ["l_arm", "r_arm_torso"]}
"""Groups measured when --groups is not given (else the robot's setup group): on TALOS the issue's
l_arm (torso fixed: arm_left_2 against the fixed torso_2 is the hard pair) and r_arm_torso (39 units,
372 unit pairs)."""


def run(args: argparse.Namespace, robot: RobotModel, group: str, q_ref: np.ndarray, scene: SceneSnapshot
        ) -> tuple[dict, bool]:
    """One group's measurements (printed); the results and whether all verdicts agreed."""
    warm_all()  # load every compiled kernel first, as the node does before its first plan
    t0 = clock()
    RobotCollisionModel(robot)  # what the per-robot cache holds, built from scratch
    t_model = clock() - t0
    t_build = float(np.median(timed(lambda: CollisionChecker(robot, scene, group, q_ref), 5)))
    checker = CollisionChecker(robot, scene, group, q_ref)
    idx = checker.joint_indices
    lo, hi = robot.lower[idx], robot.upper[idx]
    rng = np.random.default_rng(args.seed)
    Q = rng.uniform(lo, hi, (args.configs, len(idx)))
    info = checker.summary()

    # --- random configurations
    # a new set per repeat (the first is Q): the checker remembers contacts it found (kernels.triangle_tests),
    # so the same configurations again would be cheaper than new ones
    fresh = [Q] + [rng.uniform(lo, hi, Q.shape) for _ in range(args.repeats - 1)]
    checker.check_configs(rng.uniform(lo, hi, (50, len(idx))))
    checker.stats.reset()
    t_batch = []
    for Qs in fresh:
        t0 = clock()
        for i in range(0, len(Qs), args.batch):
            checker.check_configs(Qs[i:i + args.batch])
        t_batch.append(clock() - t0)
    batch_stats = {k: v / args.repeats for k, v in vars(checker.stats).items()}
    # small batches (a search's edges and extensions), and the numpy levels in the same run
    small = {}
    for label, compiled in (("kernels", True), ("numpy levels", False)):
        checker.levels.use_compiled = compiled
        for b in (args.batch, 16):
            t = timed(lambda b=b: [checker.check_configs(Q[i:i + b]) for i in range(0, len(Q), b)],
                      max(3, args.repeats // 2))
            small[f"{label}, batches of {b}"] = args.configs / float(np.median(t))
    checker.levels.use_compiled = True
    verdict_batch = checker.check_configs(Q)
    Qp = Q[:args.per_config]
    checker.exact_check(Qp[0])
    t_pc = timed(lambda: [checker.exact_check(q) for q in Qp], max(3, args.repeats // 2))
    verdict_pc = np.array([checker.exact_check(q) for q in Qp])
    mismatch = int((verdict_batch[:len(Qp)] != verdict_pc).sum())
    # where the per-configuration time goes: FK of one configuration vs fcl
    t_fk = timed(lambda: [checker.levels.fk(q[None]) for q in Qp], 3)

    # --- RRT-like edges from free configurations
    free = Q[verdict_batch]
    starts = free[rng.integers(0, len(free), args.edges)]
    ends = np.clip(starts + rng.uniform(-args.step, args.step, starts.shape), lo, hi)
    checker.stats.reset()
    t_edges = timed(lambda: [checker.check_edge(a, b) for a, b in zip(starts, ends)], args.repeats)
    edge_configs = checker.stats.configs_checked / args.repeats
    edge_ok = np.array([checker.check_edge(a, b) for a, b in zip(starts, ends)])
    t_edges_pc, pc_counts, pc_ok = [], 0, None
    for _ in range(max(3, args.repeats // 2)):
        t0 = clock()
        res = [per_config_edge(checker, a, b) for a, b in zip(starts, ends)]
        t_edges_pc.append(clock() - t0)
        pc_counts = sum(k for _, k in res)
        pc_ok = np.array([ok for ok, _ in res])
    edge_mismatch = int((edge_ok != pc_ok).sum())

    # --- configurations next to a contact
    near = None
    if args.near:
        # sets made by another checker (its checks teach this one nothing), each checked once: what the
        # checker learns from its own checks (kernels.triangle_tests) comes from configurations it saw before
        gen = CollisionChecker(robot, scene, group, q_ref)
        near_rng = np.random.default_rng(args.seed + 2)
        n16 = max(3, args.repeats // 2)
        sets = [near_contact(gen, lo, hi, args.near, args.near_step, near_rng) for _ in range(args.repeats + n16 + 2)]
        checker.check_configs(sets[0])  # warm-up, not timed
        Qn = sets[1]
        exact_fn, t_fcl = checker._exact, [0.0]

        def timed_exact(*a, **kw):
            t0 = clock()
            out = exact_fn(*a, **kw)
            t_fcl[0] += clock() - t0
            return out

        checker._exact = timed_exact
        checker.stats.reset()
        t_near = []
        for Qs in sets[2:2 + args.repeats]:
            t0 = clock()
            for i in range(0, len(Qs), args.batch):
                checker.check_configs(Qs[i:i + args.batch])
            t_near.append(clock() - t0)
        c = {k: v / args.repeats for k, v in vars(checker.stats).items()}
        fcl_share = t_fcl[0] / sum(t_near)
        t16 = []
        for Qs in sets[2 + args.repeats:]:
            t0 = clock()
            for i in range(0, len(Qs), 16):
                checker.check_configs(Qs[i:i + 16])
            t16.append(clock() - t0)
        checker._exact = exact_fn
        v_near = checker.check_configs(Qn)
        exact_near = np.array([checker.exact_check(q) for q in Qn])
        near = {"configs": len(Qn), "free_fraction": float(v_near.mean()),
                "batch_configs_per_s": len(Qn) / float(np.median(t_near)),
                "batch_spread": [len(Qn) / max(t_near), len(Qn) / min(t_near)],
                "batch16_configs_per_s": len(Qn) / float(np.median(t16)),
                "fcl_time_share": fcl_share, "counters_per_repeat": c,
                "false_free": int((v_near & ~exact_near).sum()),
                "false_colliding": int((~v_near & exact_near).sum())}

    # --- brute force: every configuration through exact FCL
    verify = None
    if args.verify:
        Qv = np.random.default_rng(args.seed + 1).uniform(lo, hi, (args.verify, len(idx)))
        fast = checker.check_configs(Qv)
        exact = np.array([checker.exact_check(q) for q in Qv])
        verify = {"configs": args.verify, "false_free": int((fast & ~exact).sum()),
                  "false_colliding": int((~fast & exact).sum()), "colliding": int((~exact).sum())}

    med = float(np.median(t_batch))
    rate_batch = args.configs / med
    rate_pc = len(Qp) / float(np.median(t_pc))
    fk_share = float(np.median(t_fk)) / float(np.median(t_pc))
    res = {
        "robot": args.robot, "group": group, "machine": {"cpus": os.cpu_count(), "load_avg": os.getloadavg()},
        "clock": "process CPU time" if CPU else "wall clock",
        "checker": info, "robot_collision_model_s": t_model, "construct_s": t_build,
        "random": {
            "free_fraction": float(verdict_batch.mean()),
            "batch_configs_per_s": rate_batch,
            "batch_spread": [args.configs / max(t_batch), args.configs / min(t_batch)],
            "per_config_fcl_configs_per_s": rate_pc,
            "per_config_spread": [len(Qp) / max(t_pc), len(Qp) / min(t_pc)],
            "speedup": rate_batch / rate_pc,
            "per_config_fk_share": fk_share,
            "verdict_mismatches": mismatch, "compared": len(Qp),
            "batch_counters_per_repeat": batch_stats,
            "configs_per_s_by_path": small,
        },
        "edges": {
            "edges": args.edges, "free_fraction": float(edge_ok.mean()),
            "batch_edges_per_s": args.edges / float(np.median(t_edges)),
            "batch_configs_per_s": edge_configs / float(np.median(t_edges)),
            "per_config_edges_per_s": args.edges / float(np.median(t_edges_pc)),
            "per_config_configs_per_s": pc_counts / float(np.median(t_edges_pc)),
            "speedup": float(np.median(t_edges_pc)) / float(np.median(t_edges)),
            "configs_per_edge_batch": edge_configs / args.edges, "configs_per_edge_per_config": pc_counts / args.edges,
            "verdict_mismatches": edge_mismatch,
        },
        "near": near,
        "verify": verify,
    }
    r, e = res["random"], res["edges"]
    print(f"robot {args.robot}, group {group} ({info['dof']} DoF): {info['moving_shapes']} moving shapes in "
          f"{info['units']} units, {info['fixed_bodies']} fixed bodies, {info['self_pairs']} unit pairs; "
          f"load avg {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    print(f"timing: {'process CPU time' if CPU else 'wall clock'}; per-robot collision model "
          f"{1e3 * t_model:.0f} ms (built once, cached), checker construction {1e3 * t_build:.1f} ms")
    print(f"random configs ({100 * r['free_fraction']:.0f}% free), medians of {args.repeats}:")
    print(f"  batch path (batches of {args.batch}) : {rate_batch:9.0f} configs/s  "
          f"(spread {r['batch_spread'][0]:.0f}–{r['batch_spread'][1]:.0f})")
    print(f"  per-config fcl (exact_check)   : {rate_pc:9.0f} configs/s  "
          f"(spread {r['per_config_spread'][0]:.0f}–{r['per_config_spread'][1]:.0f}; "
          f"{100 * fk_share:.0f}% of it is FK)")
    print(f"  speed-up                       : {r['speedup']:9.1f}×   verdicts differ on {mismatch}/{len(Qp)}")
    for k, v in small.items():
        print(f"  {k:31s}: {v:9.0f} configs/s")
    c = batch_stats
    n = args.configs
    print(f"  batch path decided: level 1 free {100 * c['level1_free'] / n:.0f}%, level 2 free "
          f"{100 * c['level2_free'] / n:.0f}%, proven colliding {100 * c['level2_colliding'] / n:.0f}%, "
          f"fcl {100 * c['exact_checks'] / n:.0f}% ({c['exact_pairs'] / max(c['exact_checks'], 1):.1f} pairs each)")
    print(f"edges (step ≤ {args.step} rad, res {checker.edge_resolution}; {100 * e['free_fraction']:.0f}% free):")
    print(f"  check_edge     : {e['batch_edges_per_s']:8.0f} edges/s, {e['batch_configs_per_s']:8.0f} configs/s "
          f"({e['configs_per_edge_batch']:.1f} configs/edge)")
    print(f"  per-config fcl : {e['per_config_edges_per_s']:8.0f} edges/s, {e['per_config_configs_per_s']:8.0f} "
          f"configs/s ({e['configs_per_edge_per_config']:.1f} configs/edge)")
    print(f"  speed-up       : {e['speedup']:8.1f}×   verdicts differ on {edge_mismatch}/{args.edges}")
    if near:
        c, n = near["counters_per_repeat"], near["configs"]
        print(f"near contact (±{args.near_step} rad of a contact, {100 * near['free_fraction']:.0f}% free), "
              f"medians of {args.repeats}:")
        print(f"  batches of {args.batch}: {near['batch_configs_per_s']:9.0f} configs/s (spread "
              f"{near['batch_spread'][0]:.0f}–{near['batch_spread'][1]:.0f}); batches of 16: "
              f"{near['batch16_configs_per_s']:9.0f} configs/s; {100 * near['fcl_time_share']:.0f}% of the time in FCL")
        print(f"  decided: level 1 free {100 * c['level1_free'] / n:.0f}%, level 2 free "
              f"{100 * c['level2_free'] / n:.0f}%, proven colliding {100 * c['level2_colliding'] / n:.0f}%, "
              f"fcl {100 * c['exact_checks'] / n:.0f}% ({c['exact_pairs'] / max(c['exact_checks'], 1):.1f} pairs each); "
              f"against exact_check: false free {near['false_free']}, false colliding {near['false_colliding']}")
    if verify:
        print(f"brute force on {verify['configs']} configs ({verify['colliding']} colliding): false free "
              f"{verify['false_free']}, false colliding {verify['false_colliding']}")
    return res, (mismatch == 0 and edge_mismatch == 0 and not (verify and verify["false_free"])
                 and not (near and near["false_free"]))


if __name__ == "__main__":
    sys.exit(main())
