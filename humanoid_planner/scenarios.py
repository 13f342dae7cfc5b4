"""Seeded grasp scenarios for any two-armed robot: an object in front of the chest, its grasp set, clutter.

Shared by the tests, the benchmark and the demo, so that all three plan the same problems. The
object is placed from the robot's own geometry (between and in front of the shoulders, scaled by
arm reach; farther ahead, then smaller with its scene, where the body is in the way or the hands cannot
hold it: iCub), so the same families work for the presets and for users' robots with `left_arm` /
`right_arm` groups. Families: `empty`, `boxes6` (the DAGRRT paper's six random boxes around the object),
`table_shelf`, `narrow` (a slot open toward the robot); PICK_FAMILIES, one-hand scenes of the standard
manipulation benchmarks: `bookshelf_tall` / `_small` / `_thin`, `cage`, `box`, `table_pick`,
`table_under_pick` (see _pick_scenario). Single arms (Panda, UR5, TIAGo) pass their group as both arms.

The object stands still (as in the DAGRRT paper); only the clutter is random. A clutter draw is kept only
when it is a planning problem at all: the robot's home pose stays clear of it and at least
MIN_FREE_GRASPS grasps of each hand keep a collision-free inverse-kinematics solution (a scene
where every grasp is walled in has no answer for any planner).
"""
from __future__ import annotations

import functools
import importlib.metadata
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import GraspSpec, SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.grasp.approach import approach_axis
from humanoid_planner.core.transforms import invert

FAMILIES = ("empty", "boxes6", "table_shelf", "narrow")
# the scenes of the standard manipulation benchmarks (one hand): the object in a bookshelf's compartment,
# in a cage of bars, in an open box, on a table, under a table top
PICK_FAMILIES = ("bookshelf_tall", "bookshelf_small", "bookshelf_thin", "cage", "box", "table_pick",
                 "table_under_pick")
ALL_FAMILIES = FAMILIES + PICK_FAMILIES
OBJECT_ID = "target"
OBJECT_SIZE = np.array([0.06, 0.06, 0.20])  # m (forward, left, up): an upright box the size of a bottle
DUAL_OBJECT_SIZE = np.array([0.12, 0.30, 0.14])  # m: a box wide enough that each hand takes one end
CLEARANCE = 0.01  # m: clutter keeps this far from the robot's home pose and from the checked grasp solutions
MIN_FREE_GRASPS = 2  # a scene counts as a planning problem when this many grasps per hand stay reachable
MAX_CLUTTER_TRIES = 50
SINGLE_SPREAD = (10.0, 80.0)  # deg from straight ahead toward the hand's side: approach directions
DUAL_SPREAD = (50.0, 90.0)
NARROW_SPREAD = (-25.0, 25.0)  # into a slot a hand only fits from the front
TOP_TILT = 15.0  # deg: top grasps besides the vertical one lean this far (an upright bottle: still through its top)
DUAL_FINGER_SHARE = 0.5  # two-handed grasps: fingertips at most half way from the face to the mid-plane
PICK_DRAWS = 12  # random layouts tried per seed of a pick family before the seed is given up
PROOF_CYCLES = 30_000
"""The reference RRT-Connect's budget, in cycles, to prove a pick-family problem solvable: a count, not
seconds, so that a seed is a problem or not whatever the machine's load (10 s of wall time refused seeds
at load 6 that it proved on a quiet machine: there it got 4 s of CPU; Panda cage seeds 0-2, TIAGo cage
seed 0). About 10 s of CPU: the reference runs 2.5-3.4k cycles per CPU second on Panda, TALOS, TIAGo."""
PROOF_BUDGET = 120.0  # s: the proof's wall-clock safety net (PROOF_CYCLES is what decides on a working machine)
REF_RESOLUTION = 0.01  # rad: the reference's edge sampling, as fine as verify_plan's
REACH_SCALE = 0.65  # m: the arm reach at which pick-family fixtures have their nominal sizes
MAX_REFERENCE_GOALS = 64
PLACE_AHEAD = (0.0, 0.15, 0.3, 0.45)  # × reach: the object farther ahead of the shoulders, where the body is in the way
PLACE_SCALES = (1.0, 0.8, 0.64, 0.5)  # the object and its scene smaller, where no place fits the nominal ones
OUT_OF_REACH = 1.2  # × an arm's sampled reach: a place whose grasps are all farther from the shoulder gets no IK
_SOLUTION_CACHE: dict = {}
_PLACE_CACHE: dict = {}


@dataclass(frozen=True)
class Humanoid:
    """A real humanoid (or single arm: left = right) from the example-robot-data package, as the tests and
    the benchmark plan on it."""

    name: str
    urdf: str  # relative to example-robot-data's robots/ folder
    srdf: str | None
    left: str  # arm groups
    right: str
    home_state: str | None  # SRDF group_state used as the start pose (None: the URDF's zero pose)
    note: str
    setup: bool = False  # the SRDF is planner_setup's (from the URDF, merged with `srdf`): it ships no arm groups
    home_joints: tuple[tuple[str, float], ...] = ()  # joint values set on top of the home state
    torso: tuple[str, str] | None = None  # (left, right) groups of each arm with the torso joints, where it has them


HUMANOIDS = {
    # its all-zero pose has the hands inside the thighs; half_sitting is the robot's reference posture
    "talos": Humanoid("talos", "talos_data/robots/talos_reduced.urdf", "talos_data/srdf/talos.srdf", "l_arm", "r_arm",
                      "half_sitting", "TALOS talos_reduced.urdf + talos.srdf (example-robot-data, meshes); "
                      "start = SRDF half_sitting"),
    # no SRDF at all; planner_setup finds the arms (torso_link -> *_rubber_hand, 7 DoF) and the pairs
    "g1": Humanoid("g1", "g1_description/urdf/g1_29dof_rev_1_0.urdf", None, "left_arm", "right_arm", "home",
                   "Unitree G1 29 DoF (example-robot-data, meshes, 180k triangles); SRDF by planner_setup; "
                   "start = its zero pose", setup=True, torso=("left_arm_torso", "right_arm_torso")),
    # its SRDF has disabled pairs and half_sitting but no arm groups; planner_setup adds them (torso -> *_gripper)
    "romeo": Humanoid("romeo", "romeo_description/urdf/romeo.urdf", "romeo_description/srdf/romeo.srdf", "left_arm",
                      "right_arm", "home", "Aldebaran Romeo (example-robot-data, meshes); SRDF by planner_setup "
                      "merged with romeo.srdf; start = its half_sitting", setup=True),
}


# single arms: the scenario helpers take their one group as both arms (robot_frame)
ARMS = {
    "panda": Humanoid("panda", "panda_description/urdf/panda.urdf", "panda_description/srdf/panda.srdf", "arm", "arm",
                      "default", "Franka Panda (example-robot-data, meshes) + its SRDF; start = SRDF default"),
    # its SRDF has no groups; its zero pose stretches the arm level through the workspace in front of it
    "ur5": Humanoid("ur5", "ur_description/urdf/ur5_robot.urdf", "ur_description/srdf/ur5.srdf", "arm", "arm", None,
                    "UR5 (example-robot-data, meshes); SRDF by planner_setup merged with ur5.srdf; start = arm "
                    "pointing up (shoulder_lift = wrist_1 = -pi/2)", setup=True,
                    home_joints=(("shoulder_lift_joint", -np.pi / 2), ("wrist_1_joint", -np.pi / 2))),
    # no SRDF; planner_setup finds the one arm (arm_1_link -> hand_tool_link, 7 DoF) and the torso lift below it
    # (arm_torso, 8 DoF); its zero pose holds the arm level out to the side: start = PAL's tucked "home" motion
    "tiago": Humanoid("tiago", "tiago_description/robots/tiago.urdf", None, "arm", "arm", None,
                      "PAL TIAGo with the Hey5 hand (example-robot-data, meshes); SRDF by planner_setup; start = "
                      "arm tucked (PAL's home), torso at 0.15 m", setup=True, torso=("arm_torso", "arm_torso"),
                      home_joints=tuple(zip(("torso_lift_joint", *(f"arm_{i}_joint" for i in range(1, 8))),
                                            (0.15, 0.20, -1.34, -0.20, 1.94, -1.57, 1.37, 0.0)))),
}


def talos_arms_out(robot: RobotModel) -> np.ndarray:
    """TALOS (robot's home, the URDF's zero pose by default) with elbows bent and arms slightly out: its
    all-zero pose has the hands inside the thighs. The collision tests' and benchmark's reference."""
    q = robot.home.copy()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        q[robot.joint_names.index(f"arm_{side}_2_joint")] = sign * 0.3
        q[robot.joint_names.index(f"arm_{side}_4_joint")] = -1.2
    return np.clip(q, robot.lower, robot.upper)


def example_robots_dir() -> Path:
    """example-robot-data's robots/ folder (pip package `example-robot-data`); FileNotFoundError without it."""
    try:
        root = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"))
    except importlib.metadata.PackageNotFoundError:
        raise FileNotFoundError("example-robot-data is not installed (pip install example-robot-data)") from None
    if not root.is_dir():
        raise FileNotFoundError(f"example-robot-data's robots not found at {root}")
    return root


def load_humanoid(name: str, samples: int | None = None) -> RobotModel:
    """One of HUMANOIDS or ARMS, loaded with its meshes, home = its reference pose. samples: configurations
    planner_setup samples for the disabled pairs of a robot whose SRDF it writes (None: its default)."""
    h = HUMANOIDS[name] if name in HUMANOIDS else ARMS[name]
    d = example_robots_dir()
    srdf = d / h.srdf if h.srdf else None
    if h.setup:
        srdf = _setup_srdf(str(d / h.urdf), None if srdf is None else str(srdf), samples)
    robot = RobotModel.from_urdf_srdf(d / h.urdf, srdf)
    if h.home_state:
        robot.home = robot.state(h.home_state)
    for joint, value in h.home_joints:
        robot.home[robot.joint_names.index(joint)] = value
    return robot


@functools.lru_cache(maxsize=8)
def _setup_srdf(urdf: str, srdf: str | None, samples: int | None) -> str:
    """planner_setup's SRDF (seconds to tens of seconds of sampling: once per process)."""
    from humanoid_planner.core.model.srdf_setup import DEFAULT_SAMPLES, generate_srdf

    return generate_srdf(urdf, srdf, samples=samples or DEFAULT_SAMPLES).srdf


@dataclass(frozen=True)
class Frame:
    """The robot-centred directions scenarios are built in (world-frame unit vectors)."""

    center: np.ndarray  # object centre for two-handed grasps (between the shoulders)
    half_width: float  # half the shoulder distance
    forward: np.ndarray
    left: np.ndarray
    up: np.ndarray
    reach: float


@dataclass(frozen=True)
class Scenario:
    """A scene snapshot plus the object and its grasp sets (single arm: both hands' grasps)."""

    family: str
    seed: int
    scene: SceneSnapshot
    object_pose: np.ndarray
    left_grasps: tuple[GraspSpec, ...]
    right_grasps: tuple[GraspSpec, ...]

    @property
    def grasps(self) -> tuple[GraspSpec, ...]:
        return self.left_grasps + self.right_grasps


def _translation(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _arm_reach(robot: RobotModel, group: str, other: str | None, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """Shoulder position and the largest shoulder–TCP distance sampled.

    The shoulder is the frame of the second joint the arm does not share with the other arm (torso
    joints are shared; other=None: a single arm); the second, because D-H arms often put the lateral
    offset into joint 1's link.
    """
    g = robot.group(group)
    shared = robot.group(other).joint_names if other else ()
    own = [j for j in g.joint_names if j not in shared]
    first = robot.joints[own[min(1, len(own) - 1)]].child
    idx = robot.group_joint_indices(group)
    Q = np.repeat(robot.home[None], 256, axis=0)
    Q[:, idx] = rng.uniform(robot.lower[idx], robot.upper[idx], size=(256, len(idx)))
    P = robot.link_poses(np.vstack([robot.home[None], Q]), [first, g.tip_link])
    shoulder = P[0, 0, :3, 3]
    return shoulder, float(np.max(np.linalg.norm(P[:, 1, :3, 3] - P[:, 0, :3, 3], axis=1)))


def robot_frame(robot: RobotModel, left_group: str = "left_arm", right_group: str = "right_arm") -> Frame:
    """Where 'in front of the robot' is, from the shoulders: left = right→left shoulder, up = +z.

    One group given twice is a single arm (Panda, UR5): in front of its shoulder along the root frame's
    x axis, the direction those arms' own examples work in.
    """
    rng = np.random.default_rng(0)
    up = np.array([0.0, 0.0, 1.0])
    if left_group == right_group:
        shoulder, reach = _arm_reach(robot, left_group, None, rng)
        forward, left = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
        return Frame(shoulder + 0.55 * reach * forward - 0.3 * reach * up, 0.0, forward, left, up, reach)
    sl, rl = _arm_reach(robot, left_group, right_group, rng)
    sr, rr = _arm_reach(robot, right_group, left_group, rng)
    left = sl - sr
    left -= up * (left @ up)
    left /= np.linalg.norm(left)
    forward = np.cross(left, up)
    reach = min(rl, rr)
    center = (sl + sr) / 2 + 0.55 * reach * forward - 0.3 * reach * up
    half = float(np.linalg.norm(sl - sr)) / 2
    return Frame(center, half, forward, left, up, reach)


def finger_reach(robot: RobotModel, group: str) -> float:
    """How far the hand's collision geometry reaches past the TCP along the approach axis (m)."""
    g = robot.group(group)
    a = approach_axis(robot, group)
    hand = robot.hand_links(group)
    P = robot.link_poses(robot.home, list(hand) + [g.tip_link])
    T_tcp_inv = invert(P[-1])
    reach = 0.0
    for link, T_link in zip(hand, P[:-1]):
        for geo in robot.collision_geometry.get(link, ()):
            if geo.kind == "mesh":
                pts = geo.vertices
            else:
                h = np.array(geo.dims if geo.kind == "box" else
                             [geo.dims[0]] * 3 if geo.kind == "sphere" else
                             [geo.dims[0], geo.dims[0], geo.dims[1] / 2])
                h = h / 2 if geo.kind == "box" else h
                pts = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
            M = T_tcp_inv @ T_link @ geo.origin
            reach = max(reach, float(np.max((pts @ M[:3, :3].T + M[:3, 3]) @ a)))
    return reach


def _surface_point(half: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the ray from the box centre along u leaves the box, and the inward normal there."""
    with np.errstate(divide="ignore"):
        t = np.where(np.abs(u) > 1e-12, half / np.abs(u), np.inf)
    i = int(np.argmin(t))
    normal = np.zeros(3)
    normal[i] = -np.sign(u[i])
    return u * t[i], normal


def _rotation_aligning(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A rotation R with R @ a = b (unit vectors)."""
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-9:  # opposite: turn π about any axis normal to a
        axis = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def side_grasps(robot: RobotModel, group: str, frame: Frame, hand: str, side: float,
                object_rot: np.ndarray, count: int = 8, spread: tuple[float, float] = (10.0, 80.0),
                size: np.ndarray = OBJECT_SIZE, finger_share: float = 1.0) -> tuple[GraspSpec, ...]:
    """Grasps whose hand approaches the object from the robot's side (`side` = +1 left, -1 right, 0 front).

    Approach directions fan out over the front half-space toward that side; each has two hand
    rolls (approach_grasps says where the palm and fingers go).
    """
    angles = np.linspace(-60, 60, count // 2) if side == 0 else np.linspace(*spread, count // 2)
    lateral = frame.left * (side if side else 1.0)
    dirs = [-np.cos(a) * frame.forward + np.sin(a) * lateral for a in np.radians(angles)]
    return approach_grasps(robot, group, hand, dirs, object_rot, size, finger_share)


def top_grasps(robot: RobotModel, group: str, frame: Frame, hand: str, side: float, object_rot: np.ndarray,
               count: int = 8, tilt: float = TOP_TILT, size: np.ndarray = OBJECT_SIZE) -> tuple[GraspSpec, ...]:
    """Grasps whose hand comes down onto the object: straight from above, and tilted by `tilt` degrees
    toward the robot and toward the hand's side (`side` = +1 left, -1 right), two rolls each. For objects
    in an open box, where only the top is open."""
    n = count // 2
    t = np.radians(tilt)
    dirs = [frame.up]
    for az in np.radians(np.linspace(-45.0, 90.0, n - 1)):
        toward = -np.cos(az) * frame.forward + np.sin(az) * (side if side else 1.0) * frame.left
        dirs.append(np.cos(t) * frame.up + np.sin(t) * toward)
    return approach_grasps(robot, group, hand, dirs[:n], object_rot, size, 1.0, "top")


def approach_grasps(robot: RobotModel, group: str, hand: str, directions, object_rot: np.ndarray,
                    size: np.ndarray = OBJECT_SIZE, finger_share: float = 1.0, tag: str = "") -> tuple[GraspSpec, ...]:
    """Two grasps (hand rolls 0 and 90°) per approach direction (world, from the object toward the hand).

    Contacts: the palm on the approached face plus two fingers on the faces across the closing axis,
    with inward normals — what GraspScore needs. The fingers reach into the object at most 1 cm short
    of its mid-plane and at most finger_share of the way there (two hands at once: a half, or long
    fingers — TALOS's reach 18 cm past its TCP — meet the other hand's inside it).
    """
    a_tcp = approach_axis(robot, group)
    reach = finger_reach(robot, group)
    half = np.asarray(size) / 2
    out = []
    Rw = object_rot.T  # world → object rotation
    for k, d_world in enumerate(directions):
        d = Rw @ np.asarray(d_world, float)
        d /= np.linalg.norm(d)
        for roll in (0.0, np.pi / 2):
            R0 = _rotation_aligning(a_tcp, -d)  # TCP approach axis points into the object
            c, s = np.cos(roll), np.sin(roll)
            K = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
            Rroll = np.eye(3) + s * K + (1 - c) * K @ K
            R = Rroll @ R0
            palm, n_palm = _surface_point(half, d)
            T = np.eye(4)
            T[:3, :3] = R
            # TCP off the face so the fingers stop 1 cm short of the object's mid-plane: two hands
            # grasping from opposite sides must not meet inside the object
            depth = float(np.linalg.norm(palm))
            T[:3, 3] = palm + max(0.02, reach - min(depth - 0.01, finger_share * depth)) * d
            closing = R @ np.cross(a_tcp, [1.0, 0, 0] if abs(a_tcp[0]) < 0.9 else [0, 1.0, 0])
            closing /= np.linalg.norm(closing)
            f1, n1 = _surface_point(half, closing)
            f2, n2 = _surface_point(half, -closing)
            out.append(GraspSpec(id=f"{hand or 'any'}_{tag}{k}_{int(np.degrees(roll))}", hand=hand,
                                 tcp_in_object=T, contacts=np.array([palm, f1, f2]),
                                 normals=np.array([n_palm, n1, n2])))
    return tuple(out)


def _box(size, center, rot=None) -> Shape:
    T = np.eye(4)
    T[:3, 3] = center
    if rot is not None:
        T[:3, :3] = rot
    return Shape("box", T, tuple(float(x) for x in size))


def _gap(a: Shape, b: Shape) -> float:
    """Distance between two shapes in the world frame (negative or 0 when they overlap)."""
    import fcl

    from humanoid_planner.core.collision.geometry import fcl_from_shape, fcl_transform

    oa, ob = (fcl.CollisionObject(fcl_from_shape(s), fcl_transform(s.pose)) for s in (a, b))
    if fcl.collide(oa, ob, fcl.CollisionRequest(), fcl.CollisionResult()):
        return 0.0
    return float(fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult()))


def _clutter(family: str, fr: Frame, rng: np.random.Generator, free, size: np.ndarray,
             scale: float = 1.0) -> list[SceneObject]:
    """The family's obstacles around the object at fr.center; scale: that of the object (_place_object),
    applied to every fixture's size and distance."""
    c, f, l, u = fr.center, fr.forward, fr.left, fr.up
    basis = np.stack([f, l, u], axis=1)  # robot-frame (forward, left, up) → world
    obs: list[SceneObject] = []
    z = scale
    if family == "boxes6":
        target = _box(size, c, basis)
        while len(obs) < 6:
            dims = rng.uniform(0.04, 0.12, size=3) * z
            r = rng.uniform(0.14, 0.32) * z
            az = rng.uniform(-np.pi, np.pi)
            el = rng.uniform(-0.6, 0.9)
            p = c + r * (np.cos(el) * (np.cos(az) * f + np.sin(az) * l) + np.sin(el) * u)
            if np.linalg.norm(p - c) - np.linalg.norm(dims) / 2 < 0.09 * z:
                continue  # keep clear of the object itself
            yaw = rng.uniform(-np.pi, np.pi)
            R = basis @ np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
            if _gap(_box(dims, p, R), target) < CLEARANCE:
                continue  # a wide object reaches past the distance test: never put clutter into it
            box = SceneObject(f"box{len(obs)}", np.eye(4), (_box(dims, p, R),))
            if free(box):  # never put clutter where the robot already is at home
                obs.append(box)
    elif family == "table_shelf":
        top = c - u * (size[2] / 2 + 0.015 * z)
        obs.append(SceneObject("table", np.eye(4), (_box(np.array([0.4, 0.44, 0.03]) * z, top + 0.12 * z * f, basis),)))
        obs.append(SceneObject("shelf", np.eye(4), (_box(np.array([0.3, 0.44, 0.02]) * z, c + u * 0.2 * z + 0.1 * z * f,
                                                         basis),)))
        obs.append(SceneObject("back", np.eye(4), (_box(np.array([0.02, 0.44, 0.45]) * z,
                                                        c + 0.2 * z * f + 0.05 * z * u, basis),)))
    elif family == "narrow":
        top = c - u * (size[2] / 2 + 0.015 * z)
        obs.append(SceneObject("floor", np.eye(4), (_box(np.array([0.36, 0.3, 0.03]) * z, top + 0.1 * z * f, basis),)))
        for side in (+1, -1):  # slot walls, 0.20 m apart (at scale 1), open toward the robot
            obs.append(SceneObject(f"wall{side:+d}", np.eye(4),
                                   (_box(np.array([0.25, 0.02, 0.35]) * z,
                                         c + 0.10 * z * side * l + 0.08 * z * f + 0.05 * z * u, basis),)))
        obs.append(SceneObject("lid", np.eye(4), (_box(np.array([0.30, 0.22, 0.02]) * z,
                                                       c + 0.24 * z * u + 0.08 * z * f, basis),)))
    elif family != "empty":
        raise ValueError(f"unknown scene family {family!r}; known: {FAMILIES}")
    placed = []
    for o in obs:  # fixtures that hit the robot at home are pushed away from it, 3 cm at a time
        for _ in range(10):
            if free(o):
                break
            o = SceneObject(o.id, _translation(0.03 * f) @ o.pose, o.shapes)
        else:
            raise ValueError(f"scenario fixture {o.id!r} collides with the robot's home pose")
        placed.append(o)
    return placed


# ------------------------------------------------------------------------------------------ pick families
# Fixture sizes are metres at REACH_SCALE and scale with the arm's reach (within PICK_SCALE), except where
# a hand has to pass: those openings keep a floor, because hands do not shrink with the arm.
PICK_SCALE = (0.7, 1.4)
MIN_COMPARTMENT = 0.28  # m: a shelf compartment's height, room for the object (0.2 m) and a hand beside it
HAND_ROOM = 0.15  # m at scale 1: other objects keep this far beside the target, where the fingers go
BOOKSHELVES = {  # levels, the target's compartment (lowest, highest), compartment height, depth, width, board
    "bookshelf_tall": (4, (1, 2), (0.30, 0.36), (0.30, 0.40), (0.60, 0.80), 0.02),
    "bookshelf_small": (2, (0, 1), (0.32, 0.40), (0.26, 0.34), (0.45, 0.60), 0.02),
    "bookshelf_thin": (3, (0, 2), (0.28, 0.32), (0.16, 0.22), (0.60, 0.80), 0.012),  # shallow, thin boards
}
PICK_DROP = {"box": 0.10, "table_under_pick": 0.10}  # × reach: lower than the other families' objects
PICK_SPREAD = {"cage": (-20.0, 60.0), "table_pick": SINGLE_SPREAD, "table_under_pick": (-25.0, 40.0)}
BAR = 0.02  # m: the cage's bars
# (forward, left, up) moves tried, smallest first, to take a layout off the robot's home pose
PLACEMENT_STEPS = sorted((np.array([dx, 0.0, dz]) for dx in np.arange(0.0, 0.25, 0.06)
                          for dz in np.arange(-0.36, 0.25, 0.06)),
                         key=lambda v: float(np.hypot(v[0], v[2] * (1.0 if v[2] <= 0 else 1.5))))


class _Fixtures:
    """Boxes placed in the object's frame (forward, left, up from its centre), named for the tests."""

    def __init__(self, center: np.ndarray, basis: np.ndarray):
        self.center, self.basis, self.objects = center, basis, []

    def add(self, name: str, dims, offset) -> None:
        p = self.center + self.basis @ np.asarray(offset, float)
        self.objects.append(SceneObject(name, np.eye(4), (_box(dims, p, self.basis),)))

    def add_cylinder(self, name: str, height: float, radius: float, offset) -> None:
        T = np.eye(4)
        T[:3, :3] = self.basis
        T[:3, 3] = self.center + self.basis @ np.asarray(offset, float)
        self.objects.append(SceneObject(name, np.eye(4), (Shape("cylinder", T, (float(height), float(radius))),)))


def _items(fx: _Fixtures, rng: np.random.Generator, k: float, floors, depth: tuple[float, float],
           width: tuple[float, float], max_height, n: int) -> None:
    """n small boxes and cylinders standing on the given floors (up offset of the surface, its own
    max height), inside the (forward, left) ranges, never within HAND_ROOM of the target's sides."""
    half = OBJECT_SIZE / 2
    placed = 0
    for _ in range(20 * n):
        if placed == n:
            break
        i = int(rng.integers(len(floors)))
        z, hmax = floors[i], max_height[i]
        h = rng.uniform(0.10, 0.24)
        if h > hmax:
            continue
        r = rng.uniform(0.02, 0.045)
        x = rng.uniform(depth[0] + r, depth[1] - r)
        y = rng.uniform(width[0] + r, width[1] - r)
        if abs(z + half[2]) < 1e-9 and (abs(y) < half[1] + HAND_ROOM * k + r and abs(x) < half[0] + HAND_ROOM * k + r):
            continue  # beside the target: where the fingers go
        if rng.random() < 0.5:
            fx.add_cylinder(f"item{placed}", h, r, (x, y, z + h / 2))
        else:
            fx.add(f"item{placed}", (2 * r, rng.uniform(0.6, 1.6) * r, h), (x, y, z + h / 2))
        placed += 1


def _bookshelf(family: str, fx: _Fixtures, k: float, rng: np.random.Generator) -> None:
    """Boards (board0 lowest), side walls, a back, open toward the robot; the target stands on board j,
    the floor of compartment j; books and cans stand on the other boards."""
    levels, (jlo, jhi), hr, dr, wr, t = BOOKSHELVES[family]
    half = OBJECT_SIZE / 2
    h, d, w = max(MIN_COMPARTMENT, k * rng.uniform(*hr)), k * rng.uniform(*dr), k * rng.uniform(*wr)
    j = int(rng.integers(jlo, jhi + 1))
    a = float(np.clip(rng.uniform(0.35, 0.6) * d, half[0] + 0.03, d - half[0] - 0.02))  # behind the front edge
    xc, yc = d / 2 - a, rng.uniform(-0.25, 0.25) * w
    tops = [-half[2] + (i - j) * (h + t) for i in range(levels + 1)]  # board i's top; compartment i above it
    for i, z in enumerate(tops):
        fx.add(f"board{i}", (d, w, t), (xc, yc, z - t / 2))
    lo, hi = tops[0] - t, tops[-1]
    for name, sgn in (("side_left", 1), ("side_right", -1)):
        fx.add(name, (d, t, hi - lo), (xc, yc + sgn * (w + t) / 2, (lo + hi) / 2))
    fx.add("back", (t, w + 2 * t, hi - lo), (xc + (d + t) / 2, yc, (lo + hi) / 2))
    _items(fx, rng, k, tops[:-1], (xc - d / 2, xc + d / 2), (yc - w / 2, yc + w / 2), [h - 0.04] * levels,
           int(rng.integers(2, 5)))


def _cage(fx: _Fixtures, k: float, rng: np.random.Generator) -> None:
    """A bottom plate the target stands on and bars along the box's twelve edges, plus one bar across each
    face but the bottom (the front's high up): every opening stays a hand wide."""
    half = OBJECT_SIZE / 2
    w, d, H = (max(0.30, k * rng.uniform(0.30, 0.38)), max(0.30, k * rng.uniform(0.30, 0.38)),
               max(0.32, k * rng.uniform(0.36, 0.44)))
    xc, yc = rng.uniform(-0.03, 0.03, size=2) * k
    z0, b = -half[2], BAR
    fx.add("cage_bottom", (d + 2 * b, w + 2 * b, 0.02), (xc, yc, z0 - 0.01))
    X, Y, Z = (d + b) / 2, (w + b) / 2, z0 + H + b / 2
    for sx in (-1, 1):
        for sy in (-1, 1):
            fx.add(f"bar_post{sx:+d}{sy:+d}", (b, b, H), (xc + sx * X, yc + sy * Y, z0 + H / 2))
    for s in (-1, 1):
        fx.add(f"bar_top_y{s:+d}", (d + 2 * b, b, b), (xc, yc + s * Y, Z))
        fx.add(f"bar_top_x{s:+d}", (b, w + 2 * b, b), (xc + s * X, yc, Z))
    fx.add("bar_back", (b, b, H), (xc + X, yc + rng.uniform(-0.2, 0.2) * w, z0 + H / 2))
    for s in (-1, 1):
        fx.add(f"bar_side{s:+d}", (b, b, H), (xc + rng.uniform(-0.3, 0.3) * d, yc + s * Y, z0 + H / 2))
    fx.add("bar_roof", (d + 2 * b, b, b), (xc, yc + rng.uniform(-0.3, 0.3) * w, Z))
    fx.add("bar_front", (b, w + 2 * b, b), (xc - X, yc, z0 + rng.uniform(0.75, 0.9) * H))


def _open_box(fx: _Fixtures, k: float, rng: np.random.Generator) -> None:
    """An open-top box: a bottom the target stands on and four walls; the target off-centre inside."""
    half = OBJECT_SIZE / 2
    w, d, hw, t = max(0.24, k * rng.uniform(0.26, 0.34)), max(0.24, k * rng.uniform(0.26, 0.34)), \
        k * rng.uniform(0.10, 0.18), 0.015
    xc, yc = (rng.uniform(-0.25, 0.25, size=2) * (np.array([d, w]) / 2 - half[:2]))
    z0 = -half[2]
    fx.add("box_bottom", (d + 2 * t, w + 2 * t, t), (xc, yc, z0 - t / 2))
    for s in (-1, 1):
        fx.add(f"box_wall_x{s:+d}", (t, w + 2 * t, hw), (xc + s * (d + t) / 2, yc, z0 + hw / 2))
        fx.add(f"box_wall_y{s:+d}", (d, t, hw), (xc, yc + s * (w + t) / 2, z0 + hw / 2))


def _table(fx: _Fixtures, k: float, rng: np.random.Generator, under: bool) -> None:
    """A table top with four legs. On it (table_pick): the target and a few other objects. Under it
    (table_under_pick): the target on a lower board, a hand's height below the top."""
    half = OBJECT_SIZE / 2
    tw, td, t, leg = k * rng.uniform(0.7, 1.0), k * rng.uniform(0.45, 0.65), 0.03, 0.04
    a = k * rng.uniform(0.06, 0.15) if under else k * rng.uniform(0.12, 0.25)  # object behind the front edge
    xc, yc = td / 2 - a, rng.uniform(-0.2, 0.2) * k
    z0 = -half[2]
    top = half[2] + max(0.08, k * rng.uniform(0.10, 0.16)) if under else z0 - t
    fx.add("table_top", (td, tw, t), (xc, yc, top + t / 2))
    foot = z0 - 0.02 if under else top - k * rng.uniform(0.5, 0.7)
    if under:
        fx.add("lower_board", (td, tw, 0.02), (xc, yc, z0 - 0.01))
    for sx in (-1, 1):
        for sy in (-1, 1):
            fx.add(f"leg{sx:+d}{sy:+d}", (leg, leg, top - foot),
                   (xc + sx * (td - leg) / 2, yc + sy * (tw - leg) / 2, (top + foot) / 2))
    if not under:
        _items(fx, rng, k, [z0], (xc - td / 2, xc + td / 2), (yc - tw / 2, yc + tw / 2), [0.3],
               int(rng.integers(2, 4)))


def _pick_layout(family: str, fx: _Fixtures, k: float, rng: np.random.Generator) -> str:
    """Place the family's fixtures around the object; returns how it is grasped ("side" or "top")."""
    if family in BOOKSHELVES:
        _bookshelf(family, fx, k, rng)
    elif family == "cage":
        _cage(fx, k, rng)
    elif family == "box":
        _open_box(fx, k, rng)
        return "top"
    elif family in ("table_pick", "table_under_pick"):
        _table(fx, k, rng, family == "table_under_pick")
    else:
        raise ValueError(f"unknown pick family {family!r}; known: {PICK_FAMILIES}")
    return "side"


def fixed_scene_collisions(checker, objects) -> tuple[tuple[str, str], ...]:
    """The checker's fixed collisions (links no joint of its groups moves) that involve these scene
    objects. Those among the robot's own links (iCub's hips in its own SRDF) are a start state no plan
    changes, not the scene's doing: a scene generator keeps clear of the robot, not of them."""
    ids = {o.id for o in objects}
    return tuple(p for p in checker.fixed_collisions() if p[0] in ids or p[1] in ids)


def _home_clear(robot: RobotModel, group: str, objects) -> bool:
    """Does the robot at home (every link: the group's and the fixed ones) keep CLEARANCE from them?"""
    from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker

    ch = CollisionChecker(robot, SceneSnapshot(0, robot.root_link, tuple(objects)), group, robot.home,
                          CheckerSettings(padding=CLEARANCE))
    return bool(ch.check_config(robot.home[ch.joint_indices])) and not fixed_scene_collisions(ch, objects)


def _clear_offset(robot: RobotModel, group: str, shapes, basis: np.ndarray) -> np.ndarray | None:
    """The smallest move of a layout (PLACEMENT_STEPS: down first, away from the robot, up) after which
    the robot at home keeps clear of it: humanoids rest their forearms forward, where the scene goes."""
    layout = SceneObject("layout", np.eye(4), tuple(shapes))
    for off in PLACEMENT_STEPS:
        o = SceneObject("layout", _translation(basis @ off), layout.shapes)
        if _home_clear(robot, group, (o,)):
            return basis @ off
    return None


def _pick_scenario(robot: RobotModel, family: str, seed: int, fr: Frame, group: str, side: float, count: int,
                   rng: np.random.Generator, proof_budget: float | None) -> Scenario:
    """A one-hand problem of a pick family, proven solvable.

    Up to PICK_DRAWS random layouts (object position jittered by ±6 % of the reach, fixture sizes drawn
    within their ranges), each moved as little as needed to leave the robot's home pose clear
    (_clear_offset), until one where MIN_FREE_GRASPS grasps keep a collision-free IK solution; then the
    reference RRT-Connect (reference_plan, PROOF_CYCLES cycles, proof_budget seconds at most) must connect home to one of those
    solutions, or the seed has no problem (ValueError): a benchmark must not count unsolvable scenes
    against a planner. Grasps: from the open side (side_grasps; shelves from the front) or from above
    (box: top_grasps).
    """
    k = float(np.clip(fr.reach / REACH_SCALE, *PICK_SCALE))
    basis = np.stack([fr.forward, fr.left, fr.up], axis=1)
    body = (Shape("box", np.eye(4), tuple(OBJECT_SIZE)),)
    why = "the robot at home touches every layout, however it is moved"
    for _ in range(PICK_DRAWS):
        jitter = fr.reach * (rng.uniform(-0.06, 0.06, size=3) - np.array([0.0, 0.0, PICK_DROP.get(family, 0.0)]))
        fx = _Fixtures(fr.center + basis @ jitter, basis)
        kind = _pick_layout(family, fx, k, rng)
        pose = _translation(fx.center)
        pose[:3, :3] = basis
        shapes = [Shape("box", pose, tuple(OBJECT_SIZE))] + [sh for o in fx.objects for sh in o.shapes]
        off = _clear_offset(robot, group, shapes, basis)
        if off is None:
            continue
        pose = _translation(off) @ pose
        fixtures = [SceneObject(o.id, _translation(off), o.shapes) for o in fx.objects]
        at = Frame(pose[:3, 3], fr.half_width, fr.forward, fr.left, fr.up, fr.reach)
        if kind == "top":
            grasps = top_grasps(robot, group, at, group, side, basis, count)
        else:
            grasps = side_grasps(robot, group, at, group, side, basis, count, PICK_SPREAD.get(family, NARROW_SPREAD))
        scene = SceneSnapshot(1, robot.root_link, (SceneObject(OBJECT_ID, pose, body, grasps), *fixtures))
        q, tidx = grasp_solutions(robot, group, pose, grasps)
        ok = _free_solutions(robot, scene, group, q)
        if len(np.unique(tidx[ok])) < MIN_FREE_GRASPS:
            why = f"fewer than {MIN_FREE_GRASPS} grasps keep a collision-free inverse-kinematics solution"
            continue
        goals = q[ok][np.random.default_rng(seed).permutation(int(ok.sum()))[:MAX_REFERENCE_GOALS]]
        ref = None if proof_budget is None else reference_plan(robot, scene, (group,), robot.home, goals,
                                                               proof_budget, seed, PROOF_CYCLES)
        if ref is not None and not ref.ok:
            raise ValueError(f"{family} seed {seed} for {robot.name} ({group}): the reference RRT-Connect found no "
                             f"path in {ref.iterations} cycles ({ref.status.value}); not counted as a problem")
        left, right = (grasps, ()) if side > 0 else ((), grasps)
        return Scenario(family, seed, scene, pose, left, right)
    raise ValueError(f"no {family} scene for {robot.name} ({group}, seed {seed}) in {PICK_DRAWS} layouts: {why}")


SHELF_BOARD = (0.30, 0.36, 0.02)  # m: depth, width, thickness of the shelf's boards
SHELF_GAP = 0.40  # m between the boards: a 20 cm object goes in from the front or from above


def shelf(robot: RobotModel, top: float = 0.85, left: float = 0.55, forward: float = 0.45) -> tuple[SceneObject, ...]:
    """A shelf beside the one-hand scenes' clutter, on the left: a board whose top is `top` above the
    root frame's origin, centred `forward` ahead of it and `left` to its left, and a second board SHELF_GAP
    above it. The place benchmark and the demo put objects on the first (its id "shelf_board")."""
    fr = robot_frame(robot)
    c = forward * fr.forward + left * fr.left
    basis = np.stack([fr.forward, fr.left, fr.up], axis=1)
    out = []
    for oid, z in (("shelf_board", top - SHELF_BOARD[2] / 2), ("shelf_top", top + SHELF_GAP + SHELF_BOARD[2] / 2)):
        T = np.eye(4)
        T[:3, :3] = basis
        T[:3, 3] = c + z * fr.up
        out.append(SceneObject(oid, T, (Shape("box", np.eye(4), SHELF_BOARD),)))
    return tuple(out)


def make_scenario(robot: RobotModel, family: str, seed: int, *, left_group: str = "left_arm",
                  right_group: str = "right_arm", grasps_per_hand: int = 8, hand: str = "both",
                  proof_budget: float | None = PROOF_BUDGET) -> Scenario:
    """A reproducible problem: the same (robot, family, seed, hand) always gives the same scene.

    hand = "both" centres the object between the shoulders (two-handed grasps); "left"/"right"
    puts it in front of that shoulder, where one arm alone can reach around it. proof_budget: the
    wall-clock cap (s) of the reference RRT-Connect's PROOF_CYCLES cycles that prove a pick-family problem
    solvable (ValueError when it does not; None: no proof, for tests of the layout alone).
    """
    if hand not in ("both", "left", "right"):
        raise ValueError(f"hand must be 'both', 'left' or 'right', got {hand!r}")
    if family in ("narrow", *PICK_FAMILIES) and hand == "both":
        raise ValueError(f"the {family} scene holds a one-hand object: it has no two-handed problems")
    rng = np.random.default_rng([seed, ALL_FAMILIES.index(family) if family in ALL_FAMILIES else 99])
    fr = robot_frame(robot, left_group, right_group)
    if hand != "both" and family != "narrow":  # the narrow slot stays centred: there is no room beside it
        side = 1.0 if hand == "left" else -1.0
        fr = Frame(fr.center + side * 0.8 * fr.half_width * fr.left, fr.half_width, fr.forward, fr.left, fr.up,
                   fr.reach)
    from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker

    def free(o: SceneObject) -> bool:
        for g in dict.fromkeys((left_group, right_group)):
            ch = CollisionChecker(robot, SceneSnapshot(0, robot.root_link, (o,)), g, robot.home,
                                  CheckerSettings(padding=CLEARANCE))
            if not ch.check_config(robot.home[ch.joint_indices]) or fixed_scene_collisions(ch, (o,)):
                return False
        return True

    if family in PICK_FAMILIES:
        group = left_group if hand == "left" else right_group
        return _pick_scenario(robot, family, seed, fr, group, 1.0 if hand == "left" else -1.0, grasps_per_hand, rng,
                              proof_budget)

    groups = {"both": (left_group, right_group), "left": (left_group,), "right": (right_group,)}[hand]
    key = (robot.name, robot.source, robot.home.tobytes(), left_group, right_group, hand, family == "narrow",
           grasps_per_hand)
    if key not in _PLACE_CACHE:
        _PLACE_CACHE[key] = _place_object(robot, fr, family, hand, left_group, right_group, groups, grasps_per_hand,
                                          free)
    place = _PLACE_CACHE[key]
    if place is None:
        raise ValueError(f"no place for the object in front of {robot.name}: its home pose fills the workspace, "
                         "or no grasp there has a collision-free inverse-kinematics solution")
    pose, at, size, scale, left, right, solutions = place
    obj = SceneObject(OBJECT_ID, pose, (Shape("box", np.eye(4), tuple(size)),), left + right)
    hands = tuple((g, left if g == left_group else right) for g in groups)
    fr = at
    for _ in range(MAX_CLUTTER_TRIES if family == "boxes6" else 1):  # only boxes6 is random
        clutter = _clutter(family, fr, rng, free, size, scale)
        scene = SceneSnapshot(1, robot.root_link, (obj, *clutter))
        if all(_solvable(robot, scene, g, q, t) for (g, _), (q, t) in zip(hands, solutions)):
            return Scenario(family, seed, scene, pose, left, right)
    raise ValueError(f"no solvable {family} scene for {robot.name} (hand {hand}, seed {seed}): too few grasps "
                     "keep a collision-free inverse-kinematics solution")


def _place_object(robot: RobotModel, fr: Frame, family: str, hand: str, left_group: str, right_group: str,
                  groups: tuple[str, ...], grasps_per_hand: int, free):
    """Where the object of make_scenario goes: (pose, its frame, size, scale, left grasps, right grasps, the
    IK solutions per hand of `groups`), or None. The nominal object at the nominal place first, lowered 3
    cm at a time where the arms rest at home and, where that leaves no grasp free to reach (G1 rests its
    forearms level, forward, at the object's height), raised; then the same farther forward, then the
    object and its scene smaller (PLACE_SCALES) — the first that fits. A robot with room at the
    nominal place keeps its problems; iCub (its chest reaches 19 cm ahead of its shoulder joints, its
    thighs lie forward, its hands 22 cm apart cannot hold a 30 cm box at once) gets a smaller object
    farther forward."""
    base_size = DUAL_OBJECT_SIZE if hand == "both" else OBJECT_SIZE
    # one hand alone may come from the front; two hands at once come from the sides, or they meet
    spread = DUAL_SPREAD if hand == "both" else NARROW_SPREAD if family == "narrow" else SINGLE_SPREAD
    share = DUAL_FINGER_SHARE if hand == "both" else 1.0
    rot = np.stack([fr.forward, fr.left, fr.up], axis=1)
    others = {left_group: right_group, right_group: left_group} if left_group != right_group else {left_group: None}
    arms = {g: _arm_reach(robot, g, others[g], np.random.default_rng(0)) for g in groups}  # (shoulder, reach)

    def in_reach(g: str, pose: np.ndarray, grasps) -> bool:
        """Is some grasp's TCP within OUT_OF_REACH × the arm's sampled reach of its shoulder (IK can succeed)?"""
        shoulder, reach = arms[g]
        tcp = np.array([(pose @ gr.tcp_in_object)[:3, 3] for gr in grasps])
        return bool(np.any(np.linalg.norm(tcp - shoulder, axis=1) <= OUT_OF_REACH * reach))

    for scale in PLACE_SCALES:
        size = base_size * scale
        body = (Shape("box", np.eye(4), tuple(size)),)
        for ahead in PLACE_AHEAD:
            for k in [*range(12), *range(-1, -9, -1)]:
                pose = _translation(fr.center + ahead * fr.reach * fr.forward - 0.03 * k * fr.up)
                pose[:3, :3] = rot
                if not free(SceneObject(OBJECT_ID, pose, body)):
                    continue
                at = Frame(pose[:3, 3], fr.half_width, fr.forward, fr.left, fr.up, fr.reach)
                left = side_grasps(robot, left_group, at, left_group, +1.0, rot, grasps_per_hand, spread, size, share)
                right = side_grasps(robot, right_group, at, right_group, -1.0, rot, grasps_per_hand, spread, size,
                                    share)
                alone = SceneSnapshot(1, robot.root_link, (SceneObject(OBJECT_ID, pose, body, left + right),))
                solutions = []
                for g in groups:  # the next hand's IK only while each so far has grasps to reach
                    if not in_reach(g, pose, left if g == left_group else right):
                        break
                    q, t = grasp_solutions(robot, g, pose, left if g == left_group else right)
                    if not _solvable(robot, alone, g, q, t):
                        break
                    solutions.append((q, t))
                else:
                    return pose, at, size, scale, left, right, solutions
    return None


def grasp_solutions(robot: RobotModel, group: str, pose: np.ndarray, grasps) -> tuple[np.ndarray, np.ndarray]:
    """Collision-ignoring IK solutions of each grasp (batched, 32 seeds each; the group's other joints
    at home) and their grasp index. Cached per (robot, group, pose, grasps)."""
    from humanoid_planner.core.ik.solver import solve_ik_batch
    from humanoid_planner.core.model.kinematics import GroupKinematics

    key = (robot.name, robot.source, group, pose.tobytes(), tuple(g.tcp_in_object.tobytes() for g in grasps))
    if key in _SOLUTION_CACHE:
        return _SOLUTION_CACHE[key]
    idx = robot.group_joint_indices(group)
    lo, hi = robot.lower[idx], robot.upper[idx]
    rng = np.random.default_rng(0)
    S = 32
    seeds = np.vstack([robot.home[idx][None], rng.uniform(lo, hi, size=(S - 1, len(idx)))])
    T = np.stack([pose @ g.tcp_in_object for g in grasps])
    q, ok, _ = solve_ik_batch(GroupKinematics(robot, group, robot.home), np.repeat(T, S, axis=0),
                              np.tile(seeds, (len(T), 1)), lo, hi)
    out = (q[ok], np.repeat(np.arange(len(T)), S)[ok])
    _SOLUTION_CACHE[key] = out
    return out


def _free_solutions(robot: RobotModel, scene: SceneSnapshot, group: str, q: np.ndarray) -> np.ndarray:
    """Which IK solutions keep CLEARANCE from everything but the object their hand grasps."""
    from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker

    if len(q) == 0:
        return np.zeros(0, bool)
    ch = CollisionChecker(robot, scene, group, robot.home,
                          CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=robot.hand_links(group), padding=CLEARANCE))
    return ch.check_configs(q)


def _solvable(robot: RobotModel, scene: SceneSnapshot, group: str, q: np.ndarray, tidx: np.ndarray) -> bool:
    """At least MIN_FREE_GRASPS grasps keep a collision-free IK solution among the clutter."""
    return len(np.unique(tidx[_free_solutions(robot, scene, group, q)])) >= MIN_FREE_GRASPS


def reference_plan(robot: RobotModel, scene: SceneSnapshot, groups: tuple[str, ...], start: np.ndarray,
                   goals: np.ndarray, budget: float, seed: int, max_cycles: int | None = None):
    """Plain RRT-Connect from start to any of `goals` (configurations of the concatenated groups), every
    edge sampled at REF_RESOLUTION, no padding: what proves a generated problem solvable. budget: seconds;
    max_cycles: a cycle budget besides (deterministic: the same answer under any load)."""
    from humanoid_planner.core.collision.checker import CheckerSettings, CollisionChecker
    from humanoid_planner.core.planners.arm_problem import ArmProblem
    from humanoid_planner.core.planners.baselines import GoalRRT
    from humanoid_planner.core.planners.common import PlannerOptions, Termination
    from humanoid_planner.core.planners.motion import SampledMotion

    idx = np.concatenate([robot.group_joint_indices(g) for g in groups])
    hands = tuple(h for g in groups for h in robot.hand_links(g))
    checker = CollisionChecker(robot, scene, groups, start,
                               CheckerSettings(grasp_object_id=OBJECT_ID, hand_links=hands, edge_resolution=REF_RESOLUTION))
    rrt = GoalRRT("rrt_connect", ArmProblem(None, SampledMotion(checker), robot.lower[idx], robot.upper[idx],
                                            PlannerOptions(dynamic_domain=0.0), np.random.default_rng(seed)))
    return rrt.plan(start[idx], np.atleast_2d(goals), Termination(budget, max_cycles=max_cycles))
