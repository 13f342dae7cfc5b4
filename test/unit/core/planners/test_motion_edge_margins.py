"""Edge margins: what makes sampled motions safe never changes which configurations collide.

Two regressions (issue 12): a motion whose samples were free but whose middle self-collided was
accepted (robot–robot pairs had no margin between samples), and a start 0.8 mm from an obstacle was
refused with collision_padding 0 (the edge margin was applied to configurations).
"""
from __future__ import annotations

import fcl
import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CollisionChecker
from humanoid_planner.core.collision.geometry import fcl_from_link_geometry, fcl_transform
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.model.srdf_setup import generate_srdf
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.planners.common import PlannerOptions, PlanStatus
from humanoid_planner.core.planners.motion import LazyMotion
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import OBJECT_ID, example_robots_dir, make_scenario

# Two thin plates (2 mm) on links l1 and l3; j2 and j3 turn about the same vertical axis, so turning
# l3 sweeps its plate through l1's. l1 and l3 are not adjacent: the pair is checked.
_PLATE = '<collision><origin xyz="0.3 0 {z}"/><geometry><box size="0.1 0.002 0.1"/></geometry></collision>'
_LIMIT = '<limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>'
_URDF = f"""<robot name="plates">
  <link name="base"/>
  <link name="l1">{_PLATE.format(z=0)}</link>
  <link name="l2"/>
  <link name="l3">{_PLATE.format(z="{z3}")}</link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>{_LIMIT}</joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 0 1"/>{_LIMIT}</joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><axis xyz="0 0 1"/>{_LIMIT}</joint>
</robot>"""
_SRDF = """<robot name="plates">
  <group name="chain"><chain base_link="base" tip_link="l3"/></group>
  <group name="tip"><joint name="j3"/></group>
</robot>"""


def _plates(tmp_path, z3: float) -> RobotModel:
    urdf, srdf = tmp_path / f"plates{z3}.urdf", tmp_path / "plates.srdf"
    urdf.write_text(_URDF.replace("{z3}", str(z3)))
    srdf.write_text(_SRDF)
    return RobotModel.from_urdf_srdf(urdf, srdf)


def _motion(robot: RobotModel, group: str, scene=None):
    scene = scene or SceneSnapshot(0, robot.root_link, ())
    return GraspPlanner(robot).problems.motion(scene, group, robot.home, "", ())


@pytest.mark.parametrize("group", ["chain", "tip"])  # l1 moving with the group / fixed
def test_self_collision_between_samples_is_excluded(tmp_path, group):
    robot = _plates(tmp_path, 0.0)
    motion = _motion(robot, group)
    exact = CollisionChecker(robot, None, group, robot.home)
    n = robot.group_joint_indices(group).size
    q0, q1 = np.zeros(n), np.zeros(n)
    q0[-1], q1[-1] = -0.25, 0.25
    steps = int(motion.steps((q1 - q0)[None])[0])
    assert steps % 2 == 1  # samples straddle the crossing at 0 …
    samples = q0 + np.arange(steps + 1)[:, None] / steps * (q1 - q0)
    assert exact.check_configs(samples).all()  # … and every one of them is free,
    assert not exact.exact_check(np.zeros(n))  # while the middle of the motion collides
    assert not motion.check_edge(q0, q1)
    assert motion.free_prefix(q0, q1[None]) == 0
    assert not motion.polylines_free([np.vstack([q0, q1])])


def test_self_margin_does_not_block_clear_motions(tmp_path):
    """Plates 2 cm apart vertically never touch: the same sweep passes (the test above is not vacuous)."""
    robot = _plates(tmp_path, 0.12)
    motion = _motion(robot, "chain")
    q0, q1 = np.array([0.0, 0.0, -0.25]), np.array([0.0, 0.0, 0.25])
    assert motion.check_edge(q0, q1) and motion.free_prefix(q0, q1[None]) == 1


def test_tight_configurations_are_valid_motion_ends(tmp_path):
    """A configuration 1 mm from an obstacle (inside the 7.5 mm edge margin) is free, and motions
    away from it and back to it pass; a motion into the obstacle does not."""
    robot = _plates(tmp_path, 0.12)
    # a box whose face is 1 mm beside l3's plate (plate faces at y = ±1 mm at q = 0)
    box = SceneObject("box", np.eye(4), (Shape("box", _at(0.3, 0.002 + 0.05, 0.12), (0.1, 0.1, 0.1)),))
    scene = SceneSnapshot(1, robot.root_link, (box,))
    motion = _motion(robot, "tip", scene)
    q_tight, q_away, q_into = np.array([0.0]), np.array([-0.3]), np.array([0.3])
    assert motion.check_configs(q_tight[None])[0]
    assert not motion.checker.check_configs(q_tight[None], motion.checker.edge_margins([0.02]))[0]  # tight
    assert motion.check_edge(q_tight, q_away) and motion.check_edge(q_away, q_tight)
    assert motion.free_prefix(q_away, np.array([[-0.1], q_tight])) == 2
    assert motion.free_prefix(q_tight, np.array([q_away])) == 1
    assert not motion.check_edge(q_tight, q_into)
    # a search's own nodes and samples may not be tight ends (no refinement next to them), so the
    # same motions stop before the tight configuration or do not leave it
    assert motion.free_prefix(q_away, np.array([[-0.1], q_tight]), tight_to=False) == 1
    assert motion.free_prefix(q_tight, np.array([q_away]), tight_from=False) == 0


def test_lazy_motion_is_the_discrete_check_and_validation_is_the_guarantee(tmp_path):
    """LazyMotion (what the fallback RRT-Connect grows its trees with) decides motions by their samples
    alone: a tight configuration is a valid end wherever it comes from, a motion stops at the waypoint
    before its first colliding sample, and a self-collision between two samples passes — which is why
    each edge of a path found on it must pass validate_edge (the validator, with its margins) to count."""
    robot = _plates(tmp_path, 0.12)
    box = SceneObject("box", np.eye(4), (Shape("box", _at(0.3, 0.002 + 0.05, 0.12), (0.1, 0.1, 0.1)),))
    motion = _motion(robot, "tip", SceneSnapshot(1, robot.root_link, (box,)))
    lazy = LazyMotion(motion)
    q_tight, q_away = np.array([0.0]), np.array([-0.3])
    # a search's own tight node: refused by the validator as an end, a valid end here, and proven by validation
    assert motion.free_prefix(q_away, np.array([[-0.1], q_tight]), tight_to=False) == 1
    assert lazy.free_prefix(q_away, np.array([[-0.1], q_tight]), tight_to=False) == 2
    assert lazy.validate_edge(q_away, q_tight) and lazy.validate_edge(q_tight, q_away)
    # into the box: the waypoints before the first colliding sample
    assert lazy.free_prefix(q_away, np.array([[-0.2], q_tight, [0.3], [0.4]])) == 2
    assert lazy.free_prefix(q_tight, np.array([[0.3]])) == 0 and not lazy.check_edge(q_tight, np.array([0.3]))
    assert not lazy.validate_edge(q_tight, np.array([0.3]))

    crossing = LazyMotion(_motion(_plates(tmp_path, 0.0), "tip"))  # plates that meet between two samples
    q0, q1 = np.array([-0.25]), np.array([0.25])
    assert crossing.check_edge(q0, q1) and not crossing.validate_edge(q0, q1)


def _at(x, y, z) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _robot_distance(robot: RobotModel, q: np.ndarray, link: str, geom: fcl.CollisionGeometry, T: np.ndarray):
    """Exact distance and nearest points between one link's shapes at q and a world shape."""
    Tl = robot.link_poses(q, [link])[0]
    best = None
    for g in robot.collision_geometry[link]:
        req, res = fcl.DistanceRequest(enable_nearest_points=True), fcl.DistanceResult()
        d = fcl.distance(fcl.CollisionObject(fcl_from_link_geometry(g), fcl_transform(Tl @ g.origin)),
                         fcl.CollisionObject(geom, fcl_transform(T)), req, res)
        if best is None or d < best[0]:
            best = (d, np.array(res.nearest_points[0]), np.array(res.nearest_points[1]))
    return best


def test_start_08mm_from_an_obstacle_plans():
    """armar3, an obstacle 0.8 mm from the left forearm at the start: with collision_padding 0 the
    start is free and GIRRT plans (exactly verified); with 2 mm of padding the start collides."""
    robot = RobotModel.preset("armar3")
    group = "left_arm"
    sc = make_scenario(robot, "empty", 3, hand="left")
    link = "left_forearm_link"
    size = 0.04
    geom = fcl.Box(size, size, size)
    # start beside the middle of the forearm, then slide the box along the line of nearest points
    # to a 0.8 mm gap
    cyl = next(g for g in robot.collision_geometry[link] if g.kind == "cylinder")
    T = robot.link_poses(robot.home, [link])[0] @ cyl.origin
    side = np.cross(T[:3, 2], [0.0, 0.0, 1.0])
    T[:3, 3] += 0.1 * side / np.linalg.norm(side)
    for _ in range(6):
        d, p_link, p_box = _robot_distance(robot, robot.home, link, geom, T)
        T[:3, 3] += (p_link - p_box) / np.linalg.norm(p_link - p_box) * (d - 0.0008)
    d = _robot_distance(robot, robot.home, link, geom, T)[0]
    assert abs(d - 0.0008) < 1e-5
    block = SceneObject("block", T, (Shape("box", np.eye(4), (size,) * 3),))
    scene = SceneSnapshot(2, robot.root_link, sc.scene.objects + (block,))
    req = GraspPlanRequest(group, robot.home.copy(), sc.object_pose, sc.left_grasps, OBJECT_ID, "girrt", 10.0, seed=5)
    plan = GraspPlanner(robot).plan_grasp(scene, req)
    assert plan.ok, plan.message
    target = sc.object_pose @ plan.grasps[0].tcp_in_object
    assert verify_plan(robot, scene, (group,), robot.home, plan, (target,), object_id=OBJECT_ID) == []
    padded = GraspPlanner(robot, PlannerOptions(collision_padding=0.002)).plan_grasp(scene, req)
    assert padded.status is PlanStatus.START_IN_COLLISION, padded.message


@pytest.fixture(scope="module")
def icub() -> RobotModel:
    try:
        d = example_robots_dir()
    except FileNotFoundError as e:
        pytest.skip(str(e))
    urdf = d / "icub_description/robots/icub.urdf"
    # its own SRDF leaves links that always touch enabled: planner_setup's, as a user would run it
    robot = RobotModel.from_urdf_srdf(urdf, generate_srdf(urdf, d / "icub_description/srdf/icub.srdf", samples=200).srdf)
    robot.home = robot.state("half_sitting")
    return robot


def _forearm_passing_box(icub: RobotModel, gap: float):
    """iCub's right elbow bends 0.8 rad from half_sitting; a 3 cm cube sits beside the forearm (along the
    elbow axis) at the middle of the motion, `gap` from it there (< 0: overlapping it by that much):
    (q0, q1, scene)."""
    group, link = "right_arm", "r_forearm"
    idx = icub.group_joint_indices(group)
    q0 = icub.home[idx].copy()
    q1 = q0.copy()
    q1[list(icub.group(group).joint_names).index("r_elbow")] += 0.8
    mid = icub.home.copy()
    mid[idx] = 0.5 * (q0 + q1)
    size = 0.03
    geom = fcl.Box(size, size, size)
    T = np.eye(4)
    T_el = icub.link_poses(mid, [link])[0]
    T[:3, 3] = T_el[:3, 3] + 0.1 * T_el[:3, 2]  # the elbow frame's z: beside the forearm's sweep
    for _ in range(8):  # slide the cube along the line of nearest points to the gap
        d, p_link, p_box = _robot_distance(icub, mid, link, geom, T)
        T[:3, 3] += (p_link - p_box) / np.linalg.norm(p_link - p_box) * (d - abs(gap))
    assert abs(_robot_distance(icub, mid, link, geom, T)[0] - abs(gap)) < 2e-5
    if gap < 0:
        T[:3, 3] += (p_link - p_box) / np.linalg.norm(p_link - p_box) * 2 * abs(gap)
    scene = SceneSnapshot(1, icub.root_link, (SceneObject("cube", T, (Shape("box", np.eye(4), (size,) * 3),)),))
    return q0, q1, scene


def test_a_motion_passing_1mm_from_a_box_is_free_between_search_nodes(icub):
    """A search's own motion (neither end a configuration the problem gives) that passes 1 mm from a box
    — inside its edge margins (1.7 mm for the forearm at 0.02 rad per sample), as a plain RRT-Connect's
    paths past iCub's and TALOS's boxes do — is accepted, proven by bisecting the intervals next to the tight samples; the same motion
    into the box (0.5 mm of overlap) is refused. Samples that missed their margins away from a start
    or goal used to block, so such passages were closed to the search (iCub and TALOS sweep timeouts)."""
    q0, q1, scene = _forearm_passing_box(icub, 0.001)
    motion = _motion(icub, "right_arm", scene)
    pts = motion.samples(q0, q1[None])[0]
    tight = ~motion.checker.check_configs(pts, motion._point_margins(pts))
    assert not tight[0] and not tight[-1]  # the ends keep their margins: no refinement next to an end
    assert tight.any() and motion.checker.check_configs(pts[tight]).all()  # free samples that miss theirs
    exact = CollisionChecker(icub, scene, "right_arm", icub.home)
    assert exact.check_configs(q0 + np.linspace(0, 1, 2001)[:, None] * (q1 - q0)).all()
    assert motion.free_prefix(q0, q1[None], tight_from=False, tight_to=False) == 1
    assert motion.check_edge(q0, q1) and motion.polylines_free([np.vstack([q0, q1])])
    q0, q1, scene = _forearm_passing_box(icub, -0.0005)
    assert not CollisionChecker(icub, scene, "right_arm", icub.home).check_config(0.5 * (q0 + q1))
    motion = _motion(icub, "right_arm", scene)
    assert motion.free_prefix(q0, q1[None], tight_from=False, tight_to=False) == 0
    assert not motion.check_edge(q0, q1)


@pytest.mark.parametrize("case", ["icub 1 mm", "icub 0.3 mm", "plates crossing"])
def test_refinement_decides_as_the_fine_points_checking_each_once(icub, tmp_path, case):
    """Next to tight samples the refinement refuses exactly the first interval holding a colliding point
    1/2**MAX_REFINE of an interval apart (a proven piece holds none; an unproven one is decided by those
    points), and checks each point at most once per level: at most 2 + 2**MAX_REFINE configurations per
    refined interval and one more end per pass (checking every piece's ends apart at three proof levels
    cost up to 39). Free motions: iCub's forearm past a cube; refused: plates that cross between free
    samples."""
    from humanoid_planner.core.planners.motion import MAX_REFINE

    if case.startswith("icub"):
        q0, q1, scene = _forearm_passing_box(icub, 0.001 if "1 mm" in case else 0.0003)
        motion = _motion(icub, "right_arm", scene)
    else:
        motion = _motion(_plates(tmp_path, 0.0), "chain")
        q0, q1 = np.array([0.0, 0.0, -0.25]), np.array([0.0, 0.0, 0.25])
    x = motion.samples(q0, q1[None])[0]
    free, tight = motion._screen(x, motion._point_margins(x))
    assert free.all() and tight.any()  # every sample is free, some only without their margins
    S = 1 << MAX_REFINE
    live = sorted({j for i in np.flatnonzero(tight) for j in (i - 1, i) if 0 <= j < len(x) - 1})
    fine = x[live][:, None] + np.arange(S + 1)[None, :, None] / S * (x[np.add(live, 1)] - x[live])[:, None]
    ok = motion.checker.check_configs(fine.reshape(-1, x.shape[1])).reshape(len(live), S + 1)
    expected = min([j for j, row in zip(live, ok) if not row.all()], default=len(x) - 1)
    assert (expected == len(x) - 1) == case.startswith("icub")
    before = motion.checker.stats.configs_checked
    assert motion._refine(x, tight, np.ones(len(x), dtype=bool)) == expected
    assert motion.checker.stats.configs_checked - before <= (2 + S) * len(live) + 2  # shared ends: + 1 a pass
