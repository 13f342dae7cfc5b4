#!/usr/bin/env python3
"""Conformance sweep: every robot with arms in example-robot-data, generated problems, a reference planner.

For each robot (CATALOGUE; LEFT_OUT says why the others are not swept):
- loading as the node loads it: its own SRDF when that has the arm groups named in the catalogue, else
  `planner_setup`'s (generate_srdf, merged with the robot's own SRDF when it ships one); home = the SRDF's
  `home` / `half_sitting` group_state, else its first group_state, else the URDF zero pose clipped to the
  limits (planner_setup's rule);
- single-arm problems per arm group (with and without torso where the SRDF has such groups), seeded: a
  random collision-free configuration of the group, its TCP pose the grasp (plus three grasps rotated
  about it), a small object there, a table and boxes placed clear of the start and of that goal
  configuration (exact checker, 1 cm clearance);
- dual-arm problems for two-armed robots: `scenarios.make_scenario` (object between the hands);
- every problem is first given to a reference: plain RRT-Connect (baselines.GoalRRT) on the product's
  collision checker, every edge sampled at scenarios.REF_RESOLUTION rad, no edge margins, given the
  configuration the target was made from as its goal, --ref-budget s (default: the planner's --budget,
  so "solvable" means "a plain RRT-Connect solves it in the same time"). What the reference does not
  solve is reported as unsolvable and left out of the denominator. Its discrete check can pass between
  two samples through a corner (iCub right_arm_torso seed 1: its path enters a box by 0.5 mm between
  0.01 rad samples), so "solvable" may count a problem whose only paths found are not collision-free;
- then GIRRT (GraspPlanner.plan_grasp) or DAGRRT (plan_dual_grasp) with --budget s; every success is
  checked by core.verification.verify_plan on the exact meshes (a plan with a problem counts as failed).
Each robot runs in its own process (a crash or hang of one robot is a finding, not the end of the sweep).
Outputs: --out/results.json (per problem and per group) and --out/table.md.

    make sweep [SWEEP_ARGS="--robots panda,talos --problems 3"]
    .venv/bin/python scripts/robot_sweep.py [--robots ...] [--problems 5] [--budget 10] [--out out/sweep]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import multiprocessing as mp
import queue
import sys
import time
import traceback
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from humanoid_planner.core import compiled  # noqa: E402
from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402
from humanoid_planner.core.scene.types import GraspSpec, SceneObject, SceneSnapshot, Shape  # noqa: E402
from humanoid_planner.core.grasp.approach import approach_axis  # noqa: E402
from humanoid_planner.scenarios import (REF_RESOLUTION, example_robots_dir, finger_reach, fixed_scene_collisions,  # noqa: E402,F401
                                       reference_plan)

OBJECT_ID = "target"
OBJECT_SIZE = 0.04  # m: the single-arm object, a cube centred on the grasp's TCP
CLEARANCE = 0.01  # m: generated obstacles keep this far from the start and goal configurations
MIN_TRAVEL = 0.15  # m: a generated goal's TCP is at least this far from the start's (no trivial problems)
N_BOXES = 3
GRASP_TURNS = ((2, 0.4), (2, -0.4), (0, 0.4))  # (TCP axis, rad): the grasps around the sampled one
DUAL_FAMILIES = ("boxes6", "table_shelf", "empty")  # dual problem k uses family k mod 3


@dataclass(frozen=True)
class Entry:
    """One robot of the sweep: files relative to example-robot-data's robots/, the groups to plan."""

    urdf: str
    srdf: str | None
    singles: tuple[str, ...] = ()  # arm groups of its own SRDF; () or missing ones: planner_setup's
    dual: tuple[str, str] | None = None
    setup: bool = False  # planner_setup's SRDF (merged with its own) even where its own has the arm groups
    zero_home: bool = False  # start at the URDF zero pose (clipped), not at the SRDF's state


# Groups named here are the robot's own SRDF's; a robot whose SRDF lacks them (or ships none) is swept with
# planner_setup's groups: left_arm / right_arm / left_arm_torso / right_arm_torso, or arm / arm_torso.
CATALOGUE: dict[str, Entry] = {
    "talos": Entry("talos_data/robots/talos_reduced.urdf", "talos_data/srdf/talos.srdf",
                   ("l_arm", "r_arm", "l_arm_torso", "r_arm_torso"), ("l_arm", "r_arm")),
    "g1": Entry("g1_description/urdf/g1_29dof_rev_1_0.urdf", None),
    "romeo": Entry("romeo_description/urdf/romeo.urdf", "romeo_description/srdf/romeo.srdf"),
    "icub": Entry("icub_description/robots/icub.urdf", "icub_description/srdf/icub.srdf",
                  ("l_arm", "r_arm", "l_arm_torso", "r_arm_torso"), ("l_arm", "r_arm")),
    # its own SRDF leaves pairs enabled that collide at home (arm links on chest and neck: a start in collision;
    # hips on thighs, fixed for the arms: reported): swept as shipped and with planner_setup's
    "icub_setup": Entry("icub_description/robots/icub.urdf", "icub_description/srdf/icub.srdf", setup=True),
    "alex": Entry("alex_description/urdf/alex_nub_hands.urdf", "alex_description/srdf/alex_nub_hands.srdf",
                  ("left_arm", "right_arm"), ("left_arm", "right_arm")),
    "simple_humanoid": Entry("simple_humanoid_description/urdf/simple_humanoid.urdf",
                             "simple_humanoid_description/srdf/simple_humanoid.srdf"),
    "human": Entry("human_description/robots/human.urdf", None),
    "baxter": Entry("baxter_description/urdf/baxter.urdf", "baxter_description/srdf/baxter_manipulation.srdf",
                    ("left_arm", "right_arm"), ("left_arm", "right_arm")),
    "baxter_zero": Entry("baxter_description/urdf/baxter.urdf", "baxter_description/srdf/baxter_manipulation.srdf",
                         ("left_arm", "right_arm"), ("left_arm", "right_arm"), zero_home=True),
    "pr2": Entry("pr2_description/urdf/pr2.urdf", "pr2_description/srdf/pr2.srdf",
                 ("left_arm", "right_arm", "left_arm_and_torso", "right_arm_and_torso"), ("left_arm", "right_arm")),
    "centauro": Entry("centauro_description/urdf/centauro.urdf", "centauro_description/srdf/centauro.srdf",
                      ("left_arm", "right_arm"), ("left_arm", "right_arm")),
    "tiago_dual": Entry("tiago_description/robots/tiago_dual.urdf", None),
    "tiago_pro": Entry("tiago_pro_description/robots/tiago_pro.urdf", None),
    "tiago": Entry("tiago_description/robots/tiago.urdf", None),
    "panda": Entry("panda_description/urdf/panda.urdf", "panda_description/srdf/panda.srdf", ("arm",)),
    "ur5": Entry("ur_description/urdf/ur5_robot.urdf", "ur_description/srdf/ur5.srdf"),
    "kinova": Entry("kinova_description/robots/kinova.urdf", "kinova_description/srdf/kinova.srdf",
                    ("end_effector",)),
    "xarm7": Entry("xarm_description/urdf/xarm7.urdf", "xarm_description/srdf/xarm7.srdf", ("xarm7",)),
    "z1": Entry("z1_description/urdf/z1.urdf", "z1_description/srdf/z1.srdf"),
    "b1_z1": Entry("b1_description/urdf/b1-z1.urdf", "b1_description/srdf/b1-z1.srdf", ("arm",)),
    "so100": Entry("so_arm_description/urdf/so100.urdf", None),
    "borinot": Entry("borinot_description/urdf/borinot_flying_arm_2.urdf",
                     "borinot_description/srdf/borinot_flying_arm_2.srdf"),
}
LEFT_OUT: dict[str, str] = {
    "talos_full_v2": "its mesh URIs name an empty package (package:///example-robot-data/...): does not load",
    "talos_left_arm, talos_reduced_box/_corrected": "variants of talos_reduced (same arms)",
    "icub_reduced": "icub without head joints (same arms)",
    "g1_29dof_with_hand": "g1 with hand joints (same arm chains)",
    "romeo_small, romeo_laas_small": "variants of romeo",
    "alex_sake_hands, alex_psyonic_hands": "alex with other hands (same arms)",
    "pr2_manipulation.srdf": "the same groups as pr2.srdf",
    "tiago_no_hand": "tiago without its hand",
    "ur3, ur10 (+ joint_limited, gripper)": "the same kinematics as ur5, scaled",
    "so101": "the same arm as so100",
    "panda_collision": "panda with primitive collision shapes",
    "simple_humanoid_classical": "variant of simple_humanoid",
    "allegro hands, finger_edu, asr_twodof": "hands / a finger / a planar 2-DoF toy: no arm",
    "alexander (lower body only), quadrupeds, bipeds, drones": "no arm",
}
SETUP_GROUPS = ("left_arm", "right_arm", "left_arm_torso", "right_arm_torso", "arm", "arm_torso")


# ------------------------------------------------------------------------------------------ loading
@dataclass
class Loaded:
    robot: RobotModel
    singles: tuple[str, ...]
    dual: tuple[str, str] | None
    srdf_source: str
    home_source: str
    load_time: float
    setup_time: float = 0.0


def home_pose(robot: RobotModel) -> tuple[np.ndarray, str]:
    """planner_setup's home rule: the SRDF's home / half_sitting state, else its first, else zero (clipped)."""
    from humanoid_planner.core.model.srdf_setup import HOME_STATE_NAMES

    names = list(robot.group_states)
    pick = next((n for n in HOME_STATE_NAMES if n in names), names[0] if names else None)
    if pick is None:
        return np.clip(np.zeros(robot.dof), robot.lower, robot.upper), "URDF zero pose (clipped)"
    return robot.state(pick), f"SRDF {pick}"


def load_entry(name: str, samples: int) -> Loaded:
    from humanoid_planner.core.model.srdf_setup import generate_srdf

    e = CATALOGUE[name]
    d = example_robots_dir()
    srdf = d / e.srdf if e.srdf else None
    t0 = time.perf_counter()
    robot = RobotModel.from_urdf_srdf(d / e.urdf, srdf)
    load = time.perf_counter() - t0
    if not e.setup and e.singles and all(g in robot.groups for g in e.singles + (e.dual or ())):
        singles, dual, source, setup = e.singles, e.dual, "own", 0.0
    else:
        t0 = time.perf_counter()
        res = generate_srdf(d / e.urdf, srdf, samples=samples)
        setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        robot = RobotModel.from_urdf_srdf(d / e.urdf, res.srdf)
        load = time.perf_counter() - t0
        singles = tuple(g for g in SETUP_GROUPS if g in robot.groups)
        dual = ("left_arm", "right_arm") if {"left_arm", "right_arm"} <= set(robot.groups) else None
        source = "planner_setup" + (" + own" if srdf else "")
    if e.zero_home:
        robot.home, home_src = np.clip(np.zeros(robot.dof), robot.lower, robot.upper), "URDF zero pose (clipped)"
    else:
        robot.home, home_src = home_pose(robot)
    return Loaded(robot, singles, dual, source, home_src, load, setup)


# ------------------------------------------------------------------------------------------ problems
@dataclass
class Problem:
    kind: str  # "single" or "dual"
    groups: tuple[str, ...]
    seed: int
    scene: SceneSnapshot
    object_pose: np.ndarray
    grasps: tuple[tuple[GraspSpec, ...], ...]  # per group
    goals: np.ndarray  # reference goal configurations (concatenated groups)
    family: str = "generated"
    obstacles: list[str] = field(default_factory=list)


def _translation(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _box(size, center, yaw: float = 0.0) -> Shape:
    T = np.eye(4)
    T[:3, 3] = center
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    return Shape("box", T, tuple(float(x) for x in size))


def _clear(robot: RobotModel, group: str, objects: list[SceneObject], configs: np.ndarray, hands) -> bool:
    """Are these group configurations (and the fixed links) at least CLEARANCE from every object?"""
    ch = CollisionChecker(robot, SceneSnapshot(1, robot.root_link, tuple(objects)), group, robot.home,
                          CheckerSettings(padding=CLEARANCE, grasp_object_id=OBJECT_ID, hand_links=hands))
    return bool(ch.check_configs(configs).all()) and not fixed_scene_collisions(ch, objects)


def start_problem(robot: RobotModel, groups: tuple[str, ...]) -> tuple[str | None, list[str]]:
    """Why the robot's home cannot start a plan of these groups (None: it can), and the collisions at home
    between links no joint of the groups moves: the plan neither makes nor removes those, the node plans
    and says so (GraspPlanner.fixed_collisions), and so does the sweep."""
    ch = CollisionChecker(robot, SceneSnapshot(0, robot.root_link, ()), groups, robot.home)
    fixed = [f"{a}–{b}" for a, b in ch.fixed_collisions()]
    q = robot.home[ch.joint_indices]
    if not ch.check_config(q):
        return f"home pose in self-collision ({', '.join(f'{a}–{b}' for a, b in ch.colliding_pairs(q)[:3])})", fixed
    return None, fixed


def single_problem(robot: RobotModel, group: str, seed: int) -> Problem:
    """A reachable target, its grasps, a table and boxes clear of start and goal (ValueError: none found)."""
    rng = np.random.default_rng([seed, zlib.crc32(group.encode())])
    idx = robot.group_joint_indices(group)
    lo, hi = robot.lower[idx], robot.upper[idx]
    tip = robot.group(group).tip_link
    hands = robot.hand_links(group)
    q_start = robot.home[idx]
    p_start = robot.link_poses(robot.home, [tip])[0][:3, 3]
    empty = CollisionChecker(robot, SceneSnapshot(0, robot.root_link, ()), group, robot.home)
    # the object sits between the fingers (a cube at the TCP itself would lie inside the wrist, and only a
    # retreat along the hand axis would leave it: a needle-eye for any planner)
    axis = approach_axis(robot, group)
    depth = max(0.02, finger_reach(robot, group) - OBJECT_SIZE / 2)
    for _ in range(20):
        Q = rng.uniform(lo, hi, size=(64, len(idx)))
        T = robot.link_poses(robot.expand(group, Q, robot.home), [tip])[:, 0]
        far = np.linalg.norm(T[:, :3, 3] - p_start, axis=1) >= MIN_TRAVEL
        cand = np.nonzero(far)[0]
        free = empty.check_configs(Q[cand]) if len(cand) else np.zeros(0, bool)
        for k in cand[free]:
            target = SceneObject(OBJECT_ID, T[k] @ _translation(depth * axis), (Shape("box", np.eye(4), (OBJECT_SIZE,) * 3),))
            if _clear(robot, group, [target], np.vstack([q_start, Q[k]]), hands):
                break
        else:
            continue
        break
    else:
        raise ValueError(f"no collision-free configuration of {group} with its TCP >= {MIN_TRAVEL} m from home "
                         "and room for the object")
    q_goal = Q[k]
    grasps = [GraspSpec("g0", "", _translation(-depth * axis))]
    for ax, angle in GRASP_TURNS:  # the same grasp turned about the object's centre
        R = np.eye(4)
        a, b = [(1, 2), (2, 0), (0, 1)][ax]
        c, s = np.cos(angle), np.sin(angle)
        R[a, a], R[a, b], R[b, a], R[b, b] = c, -s, s, c
        grasps.append(GraspSpec(f"g{len(grasps)}", "", R @ grasps[0].tcp_in_object))
    configs = np.vstack([q_start, q_goal])
    objects, names = [target], []
    p_goal = target.pose[:3, 3]
    for _ in range(8):  # a table under the target, lowered until it clears start and goal
        size = (rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.7), 0.03)
        top = p_goal[2] - rng.uniform(0.06, 0.3)
        centre = np.r_[p_goal[:2] + rng.normal(0, 0.05, 2), top - 0.015]
        table = SceneObject("table", np.eye(4), (_box(size, centre, rng.uniform(-np.pi, np.pi)),))
        if _clear(robot, group, objects + [table], configs, hands):
            objects.append(table)
            names.append("table")
            break
    for b in range(N_BOXES):  # boxes near the straight line from the start TCP to the target
        for _ in range(40):
            dims = rng.uniform(0.04, 0.12, 3)
            centre = p_start + rng.uniform(0.2, 0.8) * (p_goal - p_start) + rng.normal(0, 0.08, 3)
            if np.linalg.norm(centre - p_goal) < np.linalg.norm(dims) / 2 + OBJECT_SIZE + CLEARANCE:
                continue  # never into the object
            box = SceneObject(f"box{b}", np.eye(4), (_box(dims, centre, rng.uniform(-np.pi, np.pi)),))
            if _clear(robot, group, objects + [box], configs, hands):
                objects.append(box)
                names.append(box.id)
                break
    scene = SceneSnapshot(1, robot.root_link, tuple(objects))
    return Problem("single", (group,), seed, scene, target.pose, (tuple(grasps),), q_goal[None], obstacles=names)


def dual_problem(robot: RobotModel, left: str, right: str, seed: int, max_goals: int = 64) -> Problem:
    """make_scenario's two-handed problem; the reference's goals: collision-free IK pairs of grasp pairs whose
    score DAGRRT would accept (ValueError: no scene, or no such pair)."""
    from humanoid_planner.core.grasp.quality import DualGraspScorer
    from humanoid_planner.core.ik.solver import solve_ik_batch
    from humanoid_planner.core.model.kinematics import GroupKinematics
    from humanoid_planner.core.planners.common import PlannerOptions
    from humanoid_planner.scenarios import make_scenario

    family = DUAL_FAMILIES[seed % len(DUAL_FAMILIES)]
    sc = make_scenario(robot, family, seed, left_group=left, right_group=right, hand="both")
    o = PlannerOptions()
    rng = np.random.default_rng(seed)
    sols = []
    for g, grasps in ((left, sc.left_grasps), (right, sc.right_grasps)):
        idx = robot.group_joint_indices(g)
        lo, hi = robot.lower[idx], robot.upper[idx]
        S = 16
        seeds = np.vstack([robot.home[idx][None], rng.uniform(lo, hi, size=(S - 1, len(idx)))])
        T = np.stack([sc.object_pose @ gr.tcp_in_object for gr in grasps])
        q, ok, _ = solve_ik_batch(GroupKinematics(robot, g, robot.home), np.repeat(T, S, axis=0),
                                  np.tile(seeds, (len(T), 1)), lo, hi, tol_pos=o.goal_tolerance_pos,
                                  tol_rot=o.goal_tolerance_rot)
        which = np.repeat(np.arange(len(T)), S)[ok]
        q = q[ok]
        ch = CollisionChecker(robot, sc.scene, g, robot.home,
                              CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=robot.hand_links(g)))
        free = ch.check_configs(q) if len(q) else np.zeros(0, bool)
        keep: dict[int, list[np.ndarray]] = {}
        for qi, w in zip(q[free], which[free]):
            if len(keep.setdefault(int(w), [])) < 3 and all(np.max(np.abs(qi - x)) > 0.05 for x in keep[int(w)]):
                keep[int(w)].append(qi)
        sols.append(keep)
    scorer = DualGraspScorer(o.friction, min_contacts_per_hand=o.min_contacts_per_hand, cone_edges=o.cone_edges)
    pairs = [np.concatenate([a, b]) for i, qa in sols[0].items() for j, qb in sols[1].items()
             if scorer(sc.left_grasps[i], sc.right_grasps[j]).epsilon >= o.min_grasp_score for a in qa for b in qb]
    if not pairs:
        raise ValueError(f"{family} seed {seed}: no grasp pair with collision-free IK solutions scores "
                         f">= {o.min_grasp_score}")
    P = np.array(pairs)
    hands = robot.hand_links(left) + robot.hand_links(right)
    both = CollisionChecker(robot, sc.scene, (left, right), robot.home,
                            CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=hands))
    P = P[both.check_configs(P)]
    if len(P) == 0:
        raise ValueError(f"{family} seed {seed}: every IK pair of the two arms collides")
    P = P[rng.permutation(len(P))[:max_goals]]
    clutter = [o.id for o in sc.scene.objects if o.id != OBJECT_ID]
    return Problem("dual", (left, right), seed, sc.scene, sc.object_pose, (sc.left_grasps, sc.right_grasps), P,
                   family, clutter)


# ------------------------------------------------------------------------------------------ running
def run_problem(robot: RobotModel, gp, prob: Problem, budget: float, ref_budget: float) -> dict:
    from humanoid_planner.core.pipeline.planner import DualGraspPlanRequest, GraspPlanRequest
    from humanoid_planner.core.verification import verify_plan

    rec: dict = {"kind": prob.kind, "groups": list(prob.groups), "seed": prob.seed, "family": prob.family,
                 "obstacles": prob.obstacles, "goals": len(prob.goals)}
    t0 = time.perf_counter()
    ref = reference_plan(robot, prob.scene, prob.groups, robot.home, prob.goals, ref_budget, prob.seed)
    rec.update(solvable=bool(ref.ok), ref_time=time.perf_counter() - t0, ref_status=ref.status.value,
               ref_tree=int(ref.tree_size))
    if prob.kind == "dual":
        req = DualGraspPlanRequest(prob.groups[0], prob.groups[1], robot.home.copy(), prob.object_pose,
                                   prob.grasps[0], prob.grasps[1], OBJECT_ID, "dagrrt", timeout=budget, seed=prob.seed)
        plan = gp.plan_dual_grasp(prob.scene, req)
    else:
        req = GraspPlanRequest(prob.groups[0], robot.home.copy(), prob.object_pose, prob.grasps[0], OBJECT_ID, "girrt",
                               budget, seed=prob.seed)
        plan = gp.plan_grasp(prob.scene, req)
    rec.update(status=plan.status.value, time=float(plan.planning_time), message=plan.message[:300])
    if "tree_size" in plan.stats:
        rec["tree_size"] = int(plan.stats["tree_size"])
    problems: list[str] = []
    if plan.ok:
        targets = tuple(prob.object_pose @ g.tcp_in_object for g in plan.grasps)
        try:
            problems = verify_plan(robot, prob.scene, prob.groups, robot.home, plan, targets, object_id=OBJECT_ID)
        except Exception as e:  # noqa: BLE001 - a crash of the checker is a finding
            problems = [f"verify_plan raised {e!r}"]
        rec["verify_problems"] = problems
    rec["ok"] = bool(plan.ok and not problems)
    return rec


def sweep_robot(name: str, problems: int = 3, budget: float = 10.0, ref_budget: float = 10.0, samples: int = 1000,
                groups: tuple[str, ...] | None = None, parallel: str = "process") -> dict:
    """One robot: load, generate, reference, plan, verify. Never raises (a crash is recorded)."""
    from humanoid_planner.core.pipeline.planner import GraspPlanner

    rec: dict = {"robot": name, "urdf": CATALOGUE[name].urdf, "groups": []}
    stage = "load"
    gp = None
    try:
        ld = load_entry(name, samples)
        robot = ld.robot
        rec.update(dof=robot.dof, srdf=ld.srdf_source, home=ld.home_source, load_time=ld.load_time,
                   setup_time=ld.setup_time)
        cases: list[tuple[str, tuple[str, ...]]] = [("single", (g,)) for g in ld.singles]
        if ld.dual:
            cases.append(("dual", ld.dual))
        if groups:
            cases = [c for c in cases if "+".join(c[1]) in groups]
        if not cases:
            rec["error"] = {"stage": "groups", "type": "NoArms", "message": "no arm group to plan"}
            return rec
        gp = GraspPlanner(robot, parallel=parallel)
        for kind, gs in cases:
            stage = f"{'+'.join(gs)}"
            g: dict = {"group": "+".join(gs), "kind": kind, "dof": int(sum(len(robot.group(x).joint_names) for x in gs)),
                       "tcp": [robot.group(x).tip_link for x in gs], "problems": [], "not_generated": []}
            rec["groups"].append(g)
            why, fixed = start_problem(robot, gs)
            if fixed:
                g["fixed_collisions"] = fixed
            if why:
                g["not_generated"].append(why)
                continue
            for k in range(problems):
                try:
                    prob = dual_problem(robot, *gs, k) if kind == "dual" else single_problem(robot, gs[0], k)
                except ValueError as e:
                    g["not_generated"].append(f"seed {k}: {str(e)[:200]}")
                    continue
                g["problems"].append(run_problem(robot, gp, prob, budget, ref_budget))
    except Exception as e:  # noqa: BLE001 - a crash is the finding being recorded
        rec["error"] = {"stage": stage, "type": type(e).__name__, "message": str(e)[:500],
                        "trace": traceback.format_exc(limit=4)[-1500:]}
    finally:
        if gp is not None:
            gp.close()
    for g in rec["groups"]:
        g.update(summarize(g["problems"]))
    return rec


# ------------------------------------------------------------------------------------------ statistics
def summarize(recs: list[dict]) -> dict:
    """solved / solvable, and times over the solvable problems (failures counted at the time they returned)."""
    solvable = [r for r in recs if r["solvable"]]
    times = [r["time"] for r in solvable]
    failures = sorted({f"{r['status']}: {r['message'][:120]}" if not r.get("verify_problems")
                       else f"verify: {r['verify_problems'][0][:120]}" for r in solvable if not r["ok"]})
    return {"generated": len(recs), "solvable": len(solvable), "solved": sum(r["ok"] for r in solvable),
            "solved_unsolvable": sum(r["ok"] for r in recs if not r["solvable"]),
            "verify_failures": sum(bool(r.get("verify_problems")) for r in recs),
            "time_median": float(np.percentile(times, 50)) if times else None,
            "time_p95": float(np.percentile(times, 95)) if times else None,
            "ref_time_median": float(np.median([r["ref_time"] for r in solvable])) if solvable else None,
            "failures": failures}


def _s(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f} s"


def markdown(results: list[dict], meta: dict) -> str:
    lines = [f"Conformance sweep, {meta['date']}, commit {meta['commit']}: {meta['problems']} problems per group, "
             f"budget {meta['budget']} s; solvable = solved by the reference RRT-Connect (0.01 rad discrete edges, "
             f"no margins) within {meta['ref_budget']} s.", "",
             "| Robot | group (DoF) | SRDF / home | solved / solvable | median | p95 | notes |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        if "groups" not in r or not r["groups"]:
            err = r.get("error", {})
            lines.append(f"| {r['robot']} | – | {r.get('srdf', '–')} | – | – | – | "
                         f"{err.get('type', '')}: {err.get('message', '')[:160]} |")
            continue
        for g in r["groups"]:
            notes = []
            if g["generated"] - g["solvable"]:
                notes.append(f"{g['generated'] - g['solvable']} unsolvable by the reference")
            if g["not_generated"]:
                notes.append(f"not generated: {g['not_generated'][0]}" +
                             (f" (+{len(g['not_generated']) - 1})" if len(g["not_generated"]) > 1 else ""))
            if g.get("fixed_collisions"):
                notes.append(f"fixed links collide at home (no plan changes it; planned, reported): "
                             f"{', '.join(g['fixed_collisions'][:3])}")
            if g["verify_failures"]:
                notes.append(f"{g['verify_failures']} failed verification")
            notes += g["failures"][:2]
            lines.append(f"| {r['robot']} | `{g['group']}` ({g['dof']}) | {r.get('srdf', '')} / {r.get('home', '')} "
                         f"| {g['solved']} / {g['solvable']} | {_s(g['time_median'])} | {_s(g['time_p95'])} "
                         f"| {'; '.join(notes).replace('|', '/')} |")
        if "error" in r:
            lines.append(f"| {r['robot']} | (crash in {r['error']['stage']}) | | | | | "
                         f"{r['error']['type']}: {r['error']['message'][:160]} |")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------ main
def _child(name: str, kw: dict, q) -> None:
    # every compiled kernel loaded (or compiled, after a source change) before the first plan, as the node and
    # the benchmarks do: otherwise the first plan that meets a kernel pays its compilation (~15 s) and times out
    compiled.warm_all()
    q.put(sweep_robot(name, **kw))


def _commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "?"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default=",".join(CATALOGUE), help="comma-separated names (default: all)")
    ap.add_argument("--groups", default="", help="only these groups (e.g. l_arm,l_arm+r_arm)")
    ap.add_argument("--problems", type=int, default=5, help="problems per robot and group")
    ap.add_argument("--budget", type=float, default=10.0, help="GIRRT / DAGRRT budget per problem (s)")
    ap.add_argument("--ref-budget", type=float, default=None,
                    help="reference RRT-Connect budget per problem (s); default: --budget (the same time)")
    ap.add_argument("--samples", type=int, default=1000, help="planner_setup's sampled configurations")
    ap.add_argument("--parallel", choices=("process", "thread"), default="process", help="DAGRRT's arms")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per robot, whole (s)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "sweep")
    a = ap.parse_args(argv)
    a.ref_budget = a.budget if a.ref_budget is None else a.ref_budget
    names = [n for n in a.robots.split(",") if n]
    unknown = [n for n in names if n not in CATALOGUE]
    if unknown:
        print(f"unknown robots {unknown}; known: {', '.join(CATALOGUE)}", file=sys.stderr)
        return 2
    kw = dict(problems=a.problems, budget=a.budget, ref_budget=a.ref_budget, samples=a.samples,
              groups=tuple(x for x in a.groups.split(",") if x) or None, parallel=a.parallel)
    meta = {"date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"), "commit": _commit(), "problems": a.problems,
            "budget": a.budget, "ref_budget": a.ref_budget, "samples": a.samples, "parallel": a.parallel,
            "left_out": LEFT_OUT}
    a.out.mkdir(parents=True, exist_ok=True)
    ctx = mp.get_context("spawn")
    results = []
    for name in names:
        q = ctx.Queue()
        p = ctx.Process(target=_child, args=(name, kw, q))
        t0 = time.perf_counter()
        p.start()
        rec = None
        while rec is None and time.perf_counter() - t0 < a.timeout and (p.is_alive() or not q.empty()):
            try:
                rec = q.get(timeout=1.0)
            except queue.Empty:
                pass
        if rec is None:  # a hang or a crash of the child
            rec = {"robot": name, "error": {"stage": "?", "type": "Timeout" if p.is_alive() else "Crash",
                                            "message": f"no result within {a.timeout} s (exit code {p.exitcode})"}}
        p.join(5)
        if p.is_alive():
            p.kill()
        rec["total_time"] = time.perf_counter() - t0
        results.append(rec)
        for g in rec.get("groups", []):
            print(f"{name:16s} {g['group']:24s} {g['solved']}/{g['solvable']} solvable of {g['generated']} "
                  f"(+{len(g['not_generated'])} not generated)  median {_s(g['time_median'])}  "
                  f"{'; '.join(g['failures'][:1])}", flush=True)
        if "error" in rec:
            print(f"{name:16s} ERROR {rec['error']['stage']}: {rec['error']['type']}: {rec['error']['message'][:200]}",
                  flush=True)
        (a.out / "results.json").write_text(json.dumps({"meta": meta, "robots": results}, indent=1))
        (a.out / "table.md").write_text(markdown(results, meta))
    print(f"wrote {a.out / 'results.json'} and {a.out / 'table.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
