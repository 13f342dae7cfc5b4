"""Seeded benchmark/test scenes (humanoid_planner.scenarios) on ARMAR-III: reproducible for a seed, the
object and its grasp sets present, the clutter clear of the home pose, bad arguments refused; the pick
families' target where the family puts it (in a shelf compartment, a cage, a box, on / under a table), a
problem the reference cannot solve refused, and a single arm's frame (Panda)."""
from __future__ import annotations

import numpy as np
import pytest

from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.transforms import pose_distance
from humanoid_planner.scenarios import (FAMILIES, MIN_FREE_GRASPS, OBJECT_ID, OBJECT_SIZE, PICK_FAMILIES,
                                        load_humanoid, make_scenario, robot_frame)


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


def placement(sc) -> list:
    """Every object's id, pose and shapes' poses and sizes, and every grasp's id and pose."""
    out = []
    for o in sc.scene.objects:
        out += [o.id, o.pose.tolist()] + [(s.kind, s.pose.tolist(), list(s.dims)) for s in o.shapes]
    return out + [(g.id, g.tcp_in_object.tolist()) for g in sc.grasps]


def same_scene(a, b) -> bool:
    return a.scene.version == b.scene.version and placement(a) == placement(b)


@pytest.mark.parametrize("family,hand", [(f, "left") for f in FAMILIES] + [("boxes6", "both"), ("table_shelf", "right")])
def test_scenes_hold_the_object_its_grasps_and_leave_home_free(armar3, family, hand):
    sc = make_scenario(armar3, family, 3, hand=hand)
    assert same_scene(sc, make_scenario(armar3, family, 3, hand=hand))  # a seed fixes the scene
    obj = sc.scene.get(OBJECT_ID)
    assert obj is not None and obj.shapes and np.array_equal(obj.pose, sc.object_pose)
    assert obj.grasps == sc.grasps and sc.scene.frame == armar3.root_link
    hands = {"left": ("left_arm",), "right": ("right_arm",), "both": ("left_arm", "right_arm")}[hand]
    for group, grasps in (("left_arm", sc.left_grasps), ("right_arm", sc.right_grasps)):
        if group in hands:
            assert len(grasps) >= MIN_FREE_GRASPS
            assert all(armar3.hand_usable_by(g.hand, group) for g in grasps)
            assert all(len(g.contacts) == len(g.normals) > 0 for g in grasps)
    if family != "empty":
        assert len(sc.scene.objects) > 1
    for group in ("left_arm_torso", "right_arm_torso"):  # clutter never touches the robot at home
        checker = CollisionChecker(armar3, sc.scene, group, armar3.home,
                                   CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=armar3.hand_links(group)))
        assert checker.exact_check(armar3.home[checker.joint_indices])


def test_seeds_differ_and_the_object_sits_where_the_hand_says(armar3):
    a, b = make_scenario(armar3, "boxes6", 1, hand="left"), make_scenario(armar3, "boxes6", 2, hand="left")
    assert not same_scene(a, b)
    fr = robot_frame(armar3)
    left, right = (make_scenario(armar3, "empty", 0, hand=h).object_pose[:3, 3] for h in ("left", "right"))
    both = make_scenario(armar3, "empty", 0, hand="both").object_pose[:3, 3]
    assert (left - fr.center) @ fr.left > 0 > (right - fr.center) @ fr.left
    assert abs((both - fr.center) @ fr.left) < 0.05  # centred between the shoulders
    for g in a.left_grasps:  # grasp targets lie within the arm's reach of the object
        dp, _ = pose_distance(a.object_pose @ g.tcp_in_object, a.object_pose)
        assert dp < 0.3


def test_bad_arguments_are_refused(armar3):
    with pytest.raises(ValueError, match="hand"):
        make_scenario(armar3, "empty", 0, hand="middle")
    with pytest.raises(ValueError, match="narrow"):
        make_scenario(armar3, "narrow", 0, hand="both")


# ------------------------------------------------------------------------------------------ pick families
def robot_coords(fr, p: np.ndarray) -> np.ndarray:
    """A world point in the robot's (forward, left, up) coordinates."""
    return np.array([p @ fr.forward, p @ fr.left, p @ fr.up])


def extent(fr, obj) -> tuple[np.ndarray, np.ndarray]:
    """The (forward, left, up) bounds of an object's shapes; the fixtures are boxes and upright cylinders
    aligned with the robot's axes, so the corners' bounds are exact for boxes and hold cylinders too."""
    pts = []
    for s in obj.shapes:
        h = np.array(s.dims) / 2 if s.kind == "box" else np.array([s.dims[1], s.dims[1], s.dims[0] / 2])
        T = obj.pose @ s.pose
        pts += [T[:3, :3] @ (h * c) + T[:3, 3] for c in np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3)]
    P = np.array([robot_coords(fr, p) for p in pts])
    return P.min(axis=0), P.max(axis=0)


def assert_inside(fr, sc) -> None:
    """The target sits where its family says (within 1 mm of touching where it stands on something)."""
    half = OBJECT_SIZE / 2
    c = robot_coords(fr, sc.object_pose[:3, 3])
    lo, hi = c - half, c + half
    box = {o.id: extent(fr, o) for o in sc.scene.objects if o.id != OBJECT_ID}

    def under(name):  # the target stands on it, within its footprint
        a, b = box[name]
        return abs(b[2] - lo[2]) < 1e-3 and np.all(a[:2] <= c[:2]) and np.all(c[:2] <= b[:2])

    def over(name):  # it covers the target from above
        a, b = box[name]
        return a[2] >= hi[2] - 1e-9 and np.all(a[:2] <= c[:2]) and np.all(c[:2] <= b[:2])

    fam = sc.family
    if fam.startswith("bookshelf"):
        boards = [n for n in box if n.startswith("board")]
        assert any(under(n) for n in boards) and any(over(n) for n in boards)  # in a compartment
        assert box["side_right"][1][1] <= lo[1] and hi[1] <= box["side_left"][0][1]
        assert hi[0] <= box["back"][0][0]
        # open toward the robot: the shelf starts in front of the target, nothing but items lie there
        front = min(box[n][0][0] for n in boards)
        assert front < lo[0]
    elif fam == "cage":
        bars = [n for n in box if n.startswith("bar_")]
        assert len(bars) >= 12 and under("cage_bottom")
        a = np.min([box[n][0] for n in bars], axis=0)
        b = np.max([box[n][1] for n in bars], axis=0)
        assert np.all(a <= lo + 1e-9) and np.all(hi < b)  # the posts stand on the bottom plate
    elif fam == "box":
        assert under("box_bottom")
        assert box["box_wall_x-1"][1][0] <= lo[0] and hi[0] <= box["box_wall_x+1"][0][0]
        assert box["box_wall_y-1"][1][1] <= lo[1] and hi[1] <= box["box_wall_y+1"][0][1]
        for g in sc.grasps:  # grasped from above: the hand's TCP over the object's top
            assert robot_coords(fr, (sc.object_pose @ g.tcp_in_object)[:3, 3])[2] > hi[2]
    elif fam == "table_pick":
        assert under("table_top")
    elif fam == "table_under_pick":
        assert under("lower_board") and over("table_top")
    else:
        raise AssertionError(f"no placement rule for {fam}")


@pytest.mark.parametrize("family", PICK_FAMILIES)
def test_pick_families_put_the_target_in_place_and_leave_home_free(armar3, family):
    fr = robot_frame(armar3)
    built = 0
    for seed in range(3):
        try:  # the layout alone (the reference's proof costs up to seconds: one test below runs it)
            sc = make_scenario(armar3, family, seed, hand="left", proof_budget=None)
        except ValueError as e:
            assert family in str(e) and "seed" in str(e)  # a skipped seed says which and why
            continue
        built += 1
        assert sc.family == family and sc.right_grasps == () and len(sc.left_grasps) >= MIN_FREE_GRASPS
        assert len(sc.scene.objects) >= 4
        assert_inside(fr, sc)
        for group in ("left_arm_torso", "right_arm_torso"):  # the fixtures never touch the robot at home
            checker = CollisionChecker(armar3, sc.scene, group, armar3.home,
                                       CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=armar3.hand_links(group)))
            assert checker.exact_check(armar3.home[checker.joint_indices])
    assert built >= 2, f"{family}: fewer than 2 of seeds 0..2 give a scene on armar3"


def test_pick_scenes_are_seeded_one_handed_and_proven(armar3, monkeypatch):
    a = make_scenario(armar3, "box", 0, hand="left")  # with the reference's proof (a quick one)
    assert same_scene(a, make_scenario(armar3, "box", 0, hand="left"))
    assert not same_scene(a, make_scenario(armar3, "box", 1, hand="left", proof_budget=None))
    with pytest.raises(ValueError, match="two-handed"):
        make_scenario(armar3, "cage", 0, hand="both")
    import humanoid_planner.scenarios as scenarios
    from humanoid_planner.core.planners.common import PlanResult, PlanStatus

    calls = []

    def no_path(*args, **kw):
        calls.append(args[3:5] + args[7:])
        return PlanResult(PlanStatus.PLANNING_FAILED, iterations=scenarios.PROOF_CYCLES)

    monkeypatch.setattr(scenarios, "reference_plan", no_path)
    with pytest.raises(ValueError, match="reference RRT-Connect found no path in 30000 cycles"):
        make_scenario(armar3, "box", 0, hand="left")  # unsolvable: the seed has no problem
    (start, goals, cycles), = calls
    assert np.array_equal(start, armar3.home) and len(goals) >= MIN_FREE_GRASPS
    assert cycles == scenarios.PROOF_CYCLES  # a count, not seconds: the same seeds are problems under any load


def test_the_reference_stops_after_its_cycle_budget(armar3):
    """reference_plan's max_cycles ends a search that has not connected by then, whatever time is left."""
    from humanoid_planner.core.planners.common import PlanStatus
    from humanoid_planner.scenarios import reference_plan

    sc = make_scenario(armar3, "cage", 0, hand="left", proof_budget=None)
    idx = armar3.group_joint_indices("left_arm")
    far = armar3.home[idx] + 0.0
    far[:2] = armar3.upper[idx][:2] - 1e-3  # a goal a few cycles cannot reach through the cage's bars
    res = reference_plan(armar3, sc.scene, ("left_arm",), armar3.home, far[None], 60.0, 0, max_cycles=2)
    assert res.status is PlanStatus.PLANNING_FAILED and res.iterations == 2


def test_a_single_arm_is_its_own_frame():
    try:
        panda = load_humanoid("panda")
    except FileNotFoundError as e:
        pytest.skip(str(e))
    fr = robot_frame(panda, "arm", "arm")
    shoulder = panda.link_poses(panda.home, ["panda_link2"])[0][:3, 3]
    assert fr.half_width == 0.0 and np.allclose(fr.forward, [1, 0, 0]) and 0.6 < fr.reach < 1.0
    assert (fr.center - shoulder) @ fr.forward > 0.4 * fr.reach  # in front of the shoulder, below it
    assert (fr.center - shoulder) @ fr.up < 0
    sc = make_scenario(panda, "table_under_pick", 0, left_group="arm", right_group="arm", hand="left",
                       proof_budget=None)
    assert_inside(fr, sc) and all(g.hand == "arm" for g in sc.grasps)


def test_an_object_too_big_for_the_robot_goes_farther_ahead_and_smaller(armar3, monkeypatch):
    """Where no place in front fits the nominal object — iCub: its chest reaches 19 cm ahead of its
    shoulder joints, and its hands, 22 cm apart, cannot hold the 30 cm box at once — the object goes
    farther ahead, then smaller, its scene scaled with it; here the object is made five times as big."""
    import humanoid_planner.scenarios as sc_mod

    nominal = make_scenario(armar3, "table_shelf", 0, hand="both")
    monkeypatch.setattr(sc_mod, "DUAL_OBJECT_SIZE", 5.0 * sc_mod.DUAL_OBJECT_SIZE)
    monkeypatch.setattr(sc_mod, "_PLACE_CACHE", {})
    sc = make_scenario(armar3, "table_shelf", 0, hand="both")
    obj = sc.scene.get(OBJECT_ID)
    scale = obj.shapes[0].dims[1] / (5.0 * 0.30)
    assert any(np.isclose(scale, s) for s in sc_mod.PLACE_SCALES[1:])  # the nominal size did not fit
    table, table0 = sc.scene.get("table").shapes[0], nominal.scene.get("table").shapes[0]
    assert np.allclose(table.dims, scale * np.asarray(table0.dims))  # the fixtures scale with the object
    # still a problem: each hand keeps MIN_FREE_GRASPS grasps with a collision-free IK solution
    for group, grasps in (("left_arm", sc.left_grasps), ("right_arm", sc.right_grasps)):
        q, which = sc_mod.grasp_solutions(armar3, group, sc.object_pose, grasps)
        assert len(np.unique(which[sc_mod._free_solutions(armar3, sc.scene, group, q)])) >= MIN_FREE_GRASPS
