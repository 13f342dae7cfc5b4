"""DAGRRT's pair completed (pipeline.pair_completion): both hands' straight approach at once and the
two-handed retreat, in other IK postures of the two grasps when the reached ones fail."""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.ik.solver import solve_ik_batch
from humanoid_planner.core.model.kinematics import GroupKinematics
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.completion import Completion
from humanoid_planner.core.pipeline.pair_completion import PairSides, pair_lines, pair_other_postures
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.pipeline.problem import held_scene
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.verification import verify_straight
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

UP = (0.0, 0.0, 1.0)


def test_a_dual_pair_whose_lines_fail_is_completed_by_other_postures():
    """DAGRRT's pair: reached postures of the two pre-grasps whose paired approach fails (pair_lines:
    the pair was skipped) are completed by other IK postures of the same grasps, joined by a free
    joint motion, both approaches straight, both hands lifted by the same displacement."""
    r = RobotModel.preset("dual_arm")
    gp = GraspPlanner(r)
    sc = make_scenario(r, "empty", 0, hand="both")
    groups, start = ("left_arm", "right_arm"), r.home.copy()
    appr_t = GripperTranslation(tuple(approach_axis(r, "left_arm")), 0.10, 0.05)
    lift = GripperTranslation(UP, 0.10, 0.05)
    kins = [GroupKinematics(r, g, start) for g in groups]
    limits = [(r.lower[i], r.upper[i]) for i in (r.group_joint_indices(g) for g in groups)]
    hands = [r.hand_links(g) for g in groups]
    grasps = [gp.targets(sc.object_pose, gs, g)[:1] for gs, g in zip((sc.left_grasps, sc.right_grasps), groups)]
    comps = [Completion(gp.problems.arm(sc.scene, groups[k], start, grasps[k], np.random.default_rng(0),
                                        object_id=OBJECT_ID), appr_t, None, retry_shorter=False) for k in (0, 1)]
    lt, rt = (c.pre_targets(g)[0] for c, g in zip(comps, grasps))
    pm = gp.problems.motion(sc.scene, groups, start, OBJECT_ID, hands[0] + hands[1])
    held = gp.problems.motion(held_scene(sc.scene, OBJECT_ID, r.group("left_arm").tip_link, grasps[0][0].T_target,
                                         hands[0] + hands[1]), groups, start, "", hands[0] + hands[1])
    sides = PairSides(tuple(kins), tuple(limits))
    dirs = [comps[0].direction[lt.index], comps[1].direction[rt.index]]
    rng = np.random.default_rng(0)
    postures = []
    for k, t in enumerate((lt, rt)):
        q, ok, _ = solve_ik_batch(kins[k], np.repeat(t.T_target[None], 12, axis=0),
                                  rng.uniform(*limits[k], size=(12, len(limits[k][0]))), *limits[k])
        postures.append(q[ok][comps[k].motion.check_configs(q[ok])])
    failing = [(ql, qr) for ql in postures[0] for qr in postures[1]
               if pm.check_configs(np.concatenate([ql, qr])[None])[0]
               and not pair_lines(sides, [ql, qr], dirs, appr_t, pm, lift, np.array(UP), held).ok]
    assert failing, "no reached pair whose lines fail: the test proves nothing"
    done = [(q, pair_other_postures(comps, np.concatenate(q), q, (lt, rt), pm, lift, np.array(UP), held))
            for q in failing[:4]]
    (ql, qr), (q_pre, lines) = next((q, out.value) for q, out in done if out.ok)
    appr, a_dist, back, r_dist = lines.approach, lines.approach_distance, lines.retreat, lines.retreat_distance
    nl = len(ql)
    assert pm.check_edge(np.concatenate([ql, qr]), q_pre)  # the reached pair joins the other postures
    assert pm.free_prefix(q_pre, appr) == len(appr) and held.free_prefix(appr[-1], back) == len(back)
    assert a_dist >= 0.05 - 1e-9 and r_dist >= 0.05 - 1e-9
    for k, sl in enumerate((slice(0, nl), slice(nl, None))):  # each hand straight onto its grasp
        assert verify_straight(r, (groups[k],), start, np.vstack([q_pre[sl], appr[:, sl]]), dirs[k],
                               min_distance=0.05 - 0.002) == []
        assert np.linalg.norm(kins[k].fk(appr[-1, sl])[:3, 3] - grasps[k][0].T_target[:3, 3]) < 0.002
    # the lift: both TCPs by the same displacement (relative pose within 2 mm / 1 deg)
    assert verify_straight(r, groups, start, np.vstack([appr[-1:], back]), UP, min_distance=r_dist - 0.002) == []
