#!/usr/bin/env python3
"""Generate the built-in robot presets (config/robots/<name>.urdf + .srdf) from the papers' D-H tables.

    python scripts/gen_presets.py            # all presets, writes config/robots/
    python scripts/gen_presets.py armar3     # one preset
    python scripts/gen_presets.py --check    # exit 1 if a committed URDF differs from what this script makes

The D-H tables live in humanoid_planner/core/dh_tables.py; the sources and every choice are in
config/robots/README.md.  How a D-H row becomes URDF (exact, tested to 1e-9 in test_presets.py):

    A_i(q) = Rz(offset_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i) = Rz(q_i) · C_i,
    C_i    = Rz(offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)      (constant)

so joint 1 has origin Sigma_0 (the arm base), joint i > 1 has origin C_{i-1} in link i-1, every
revolute joint turns about its own z axis, a fixed `<side>_hand` link sits at C_n (= D-H frame n) and
the group tip `<side>_tcp` at the hand/TCP offset after it.  q = 0 in the URDF is q = 0 in the table.

Collision geometry: capsules (a cylinder plus a sphere at each end, three <collision> elements, since
URDF has no capsule) along every link with length, spheres for joint housings of zero-length links,
boxes for hands, torso, head and base.  The SRDF's <disable_collisions> come from sampling, as MoveIt's
setup assistant does: Adjacent (joined by a joint), Always (in collision in every sample) and Never (no
contact in any of 20000 random configurations even with every shape inflated by 2 cm).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from preset_generation import dh_tables as dh  # noqa: E402
from preset_generation.dh_tables import DHArm, rot_x, rot_y, rot_z, trans  # noqa: E402

OUT_DIR = ROOT / "config" / "robots"
NEVER_SAMPLES = 20000
ALWAYS_SAMPLES = 1000
NEVER_MARGIN = 0.02     # m added to every shape when looking for pairs that never touch
HOME_MARGIN = 0.01      # home must stay free with every shape inflated by this much
EFFORT = 100.0          # URDF requires an effort limit; nothing here uses it


# ----------------------------------------------------------------------------- model being built
@dataclass
class Shape:
    kind: str                 # 'box' (full sizes) | 'sphere' (r,) | 'cylinder' / 'capsule' (r, length along z)
    dims: tuple[float, ...]
    origin: np.ndarray        # 4x4 in the link frame
    material: str = "grey"


@dataclass
class Joint:
    name: str
    type: str                 # 'revolute' | 'fixed'
    parent: str
    child: str
    origin: np.ndarray
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    lower: float = 0.0
    upper: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass
class Robot:
    name: str
    root: str
    frame_note: str
    links: dict[str, list[Shape]] = field(default_factory=dict)
    joints: list[Joint] = field(default_factory=list)
    groups: list[tuple[str, str, str]] = field(default_factory=list)      # (name, base_link, tip_link)
    hands: list[tuple[str, str, str, tuple[str, ...]]] = field(default_factory=list)  # (ee, parent_link, arm group, links)
    home: dict[str, float] = field(default_factory=dict)
    home_groups: list[tuple[str, list[str]]] = field(default_factory=list)

    def link(self, name: str, *shapes: Shape) -> str:
        self.links.setdefault(name, []).extend(shapes)
        return name

    def joint(self, j: Joint) -> None:
        self.link(j.child)
        self.joints.append(j)


def capsule_between(p0: np.ndarray, p1: np.ndarray, r: float, material: str) -> Shape:
    """Capsule with its axis from p0 to p1 (z of the shape frame along the segment)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    v = p1 - p0
    L = float(np.linalg.norm(v))
    return Shape("capsule", (r, L), _frame_along(v, (p0 + p1) / 2.0), material)


def box_between(p0: np.ndarray, p1: np.ndarray, width: float, thickness: float, material: str,
                width_hint: np.ndarray | None = None) -> Shape:
    """Box whose long (z) axis runs from p0 to p1; width along the frame axis most normal to it."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    v = p1 - p0
    T = _frame_along(v, (p0 + p1) / 2.0, width_hint)
    return Shape("box", (width, thickness, float(np.linalg.norm(v))), T, material)


def _frame_along(v: np.ndarray, center: np.ndarray, x_hint: np.ndarray | None = None) -> np.ndarray:
    """Frame at center with z along v; x along x_hint made normal to v (else the most normal axis)."""
    z = v / np.linalg.norm(v)
    if x_hint is None or np.linalg.norm(np.cross(x_hint, z)) < 1e-6:
        x_hint = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = np.asarray(x_hint, float) - np.dot(x_hint, z) * z
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, center
    return _clean(T)


def _clean(T: np.ndarray) -> np.ndarray:
    """Snap round-off (|x| < 1e-15 → 0) so the XML stays readable; keeps the transform exact to 1e-15."""
    T = np.array(T, dtype=float)
    T[np.abs(T) < 1e-15] = 0.0
    return T


# ----------------------------------------------------------------------------- D-H arm → links/joints
@dataclass
class HandSize:
    palm_width: float = 0.09
    palm_thickness: float = 0.04
    finger_length: float = 0.06
    finger_width: float = 0.08
    finger_thickness: float = 0.03
    palm_extension: float = 0.0  # palm box runs this far past the TCP; the fingers box starts there


def add_dh_arm(robot: Robot, arm: DHArm, hand: HandSize, material: str) -> list[str]:
    """Joints <side>_<name>_joint, links <side>_<name>_link, then <side>_hand and <side>_tcp."""
    names = []
    parent = arm.parent_link
    origin = arm.base
    n = len(arm.joints)
    for i, j in enumerate(arm.joints):
        link = f"{arm.side}_{j.name}_link"
        jn = f"{arm.side}_{j.name}_joint"
        robot.joint(Joint(jn, "revolute", parent, link, _clean(origin), (0.0, 0.0, 1.0),
                          j.lower, j.upper, j.velocity, j.acceleration))
        names.append(jn)
        C = rot_z(j.offset) @ trans(0.0, 0.0, j.d) @ trans(j.a, 0.0, 0.0) @ rot_x(j.alpha)
        p_next = C[:3, 3]
        if i < n - 1 and np.linalg.norm(p_next) > 1e-6:
            robot.link(link, capsule_between(np.zeros(3), p_next, j.radius, material))
        else:  # zero-length link or the wrist: a joint housing
            robot.link(link, Shape("sphere", (j.radius,), np.eye(4), material))
        parent, origin = link, C
    # hand = D-H frame n; palm box from the wrist centre to the TCP, fingers box beyond the TCP.
    hand_link, tcp_link = f"{arm.side}_hand", f"{arm.side}_tcp"
    robot.joint(Joint(f"{arm.side}_hand_joint", "fixed", parent, hand_link, _clean(origin)))
    robot.joint(Joint(f"{arm.side}_tcp_joint", "fixed", hand_link, tcp_link, _clean(arm.tool)))
    wrist_in_hand = np.linalg.inv(origin)[:3, 3]
    tcp_in_hand = arm.tool[:3, 3]
    approach = tcp_in_hand - wrist_in_hand
    approach /= np.linalg.norm(approach)
    width_dir = np.eye(3)[int(np.argmin(np.abs(approach)))]
    start = wrist_in_hand + approach * arm.joints[-1].radius * 0.5
    palm_end = tcp_in_hand + approach * hand.palm_extension
    robot.link(hand_link, box_between(start, palm_end, hand.palm_width, hand.palm_thickness, "hand", width_dir))
    R_tool_inv = arm.tool[:3, :3].T
    a_tcp, w_tcp = R_tool_inv @ approach, R_tool_inv @ width_dir
    robot.link(tcp_link, box_between(a_tcp * hand.palm_extension, a_tcp * (hand.palm_extension + hand.finger_length),
                                     hand.finger_width, hand.finger_thickness, "hand", w_tcp))
    return names


# ----------------------------------------------------------------------------- the three presets
def build_armar3() -> Robot:
    r = Robot("armar3", "base_link", "ROS REP-103: x forward, y left, z up; base_link on the floor under the hip")
    r.link("base_link", Shape("cylinder", (0.30, 0.75), trans(0, 0, 0.375), "dark"))  # platform, top at 0.75 m
    t = dh.ARMAR3_TORSO
    r.joint(Joint("torso_yaw_joint", "revolute", "base_link", "torso_yaw_link", trans(0, 0, dh.ARMAR3_HIP_HEIGHT),
                  (0, 0, 1), t[0].lower, t[0].upper, t[0].velocity, t[0].acceleration))
    r.link("torso_yaw_link", capsule_between([0, 0, -0.14], [0, 0, -0.10], t[0].radius, "body"))
    r.joint(Joint("torso_pitch_joint", "revolute", "torso_yaw_link", "torso_pitch_link", np.eye(4),
                  (0, 1, 0), t[1].lower, t[1].upper, t[1].velocity, t[1].acceleration))
    r.link("torso_pitch_link", Shape("sphere", (t[1].radius,), np.eye(4), "body"))
    r.joint(Joint("torso_roll_joint", "revolute", "torso_pitch_link", "torso_link", np.eye(4),
                  (1, 0, 0), t[2].lower, t[2].upper, t[2].velocity, t[2].acceleration))
    cx, _, cz = dh.ARMAR3_COA_FROM_HIP
    # chest narrower than the shoulders (±0.10 m vs ±0.232 m) so an upper arm can swing inward in front of it
    r.link("torso_link", Shape("box", (0.18, 0.20, 0.36), trans(cx, 0, cz - 0.19), "body"),
           capsule_between([cx, 0, cz - 0.01], [cx, 0, cz + 0.11], 0.045, "body"),
           Shape("sphere", (0.11,), trans(cx + 0.02, 0, cz + 0.22), "head"))
    hand = HandSize()
    left = add_dh_arm(r, dh.ARMAR3_LEFT, hand, "arm")
    right = add_dh_arm(r, dh.ARMAR3_RIGHT, hand, "arm")
    torso = ["torso_yaw_joint", "torso_pitch_joint", "torso_roll_joint"]
    r.groups = [("left_arm", "torso_link", "left_tcp"), ("right_arm", "torso_link", "right_tcp"),
                ("left_arm_torso", "base_link", "left_tcp"), ("right_arm_torso", "base_link", "right_tcp"),
                ("torso", "base_link", "torso_link")]
    _hands(r)
    arm_home = [0.35, -0.25, 0.0, 1.2, 1.571, 0.0, 0.0]   # same q on both arms = mirror-image pose
    r.home = dict(zip(torso, [0.0, 0.0, 0.0])) | dict(zip(left, arm_home)) | dict(zip(right, arm_home))
    r.home_groups = [("torso", torso), ("left_arm", left), ("right_arm", right)]
    return r


def build_dual_arm() -> Robot:
    r = Robot("dual_arm", "base_link",
              "the DAGRRT paper / Simox ARMAR-III frame (NOT REP-103): x to the robot's right, y forward, z up, "
              "origin on the floor; so the paper's example TCP poses are used as printed (mm -> m)")
    cx, cy, cz = dh.DUAL_COA
    r.link("base_link", Shape("cylinder", (0.30, 0.75), trans(cx, cy, 0.375), "dark"))  # platform, top at 0.75 m
    r.joint(Joint("torso_joint", "fixed", "base_link", "torso_link", trans(cx, cy, cz)))
    # torso_link axes = base axes (x right, y forward): chest, waist column, neck, head
    # chest narrower than the shoulders (±0.10 m vs ±0.232 m) so an upper arm can swing inward in front of it
    r.link("torso_link", Shape("box", (0.20, 0.18, 0.50), trans(0, 0, -0.255), "body"),
           capsule_between([0, 0, -0.62], [0, 0, -0.52], 0.12, "body"),
           capsule_between([0, 0, -0.01], [0, 0, 0.11], 0.045, "body"),
           Shape("sphere", (0.11,), trans(0, 0.02, 0.22), "head"))
    hand = HandSize()
    left = add_dh_arm(r, dh.DUAL_LEFT, hand, "arm")
    right = add_dh_arm(r, dh.DUAL_RIGHT, hand, "arm")
    r.groups = [("left_arm", "torso_link", "left_tcp"), ("right_arm", "torso_link", "right_tcp")]
    _hands(r)
    r.home = dict(zip(left, DUAL_HOME_LEFT)) | dict(zip(right, DUAL_HOME_RIGHT))
    r.home_groups = [("left_arm", left), ("right_arm", right)]
    return r


# Upper arms down and a little forward/out, elbows bent ~75 deg, forearms forward, wrists near mid-range:
# `python scripts/gen_presets.py --dual-home` (a bounded least-squares posture fit), rounded to 3 decimals.
# Table 1's two arms are not mirror images (REPORT §2.1), so the two joint vectors differ.
DUAL_HOME_LEFT = [-0.617, -0.204, -3.367, -1.346, 0.0, -0.164, -0.201]
DUAL_HOME_RIGHT = [0.954, -0.204, 0.225, -1.346, 0.555, 0.081, -0.867]


def build_maru1() -> Robot:
    r = Robot("maru1", "base_link", "ROS REP-103: x forward, y left, z up; base_link = pelvis frame B on the waist yaw axis")
    r.link("base_link", Shape("box", (0.18, 0.28, 0.14), trans(0, 0, -0.07), "dark"),
           capsule_between([0, 0.085, -0.16], [0, 0.085, -0.50], 0.065, "dark"),
           capsule_between([0, -0.085, -0.16], [0, -0.085, -0.50], 0.065, "dark"))
    w = dh.MARU1_TORSO[0]
    r.joint(Joint("waist_yaw_joint", "revolute", "base_link", "torso_link", np.eye(4), (0, 0, 1),
                  w.lower, w.upper, w.velocity, w.acceleration))
    r.link("torso_link", Shape("box", (0.20, 0.28, 0.29), trans(0.02, 0, 0.145), "body"),
           capsule_between([0.02, 0, 0.30], [0.02, 0, 0.37], 0.04, "body"),
           Shape("sphere", (0.10,), trans(0.03, 0, 0.47), "head"))
    # D-H frame 6 (the TCP) is only 41 mm past the wrist: the palm runs 30 mm beyond it so that the
    # fingers box clears the forearm whatever the wrist angle.
    hand = HandSize(palm_width=0.08, palm_thickness=0.035, finger_length=0.07, finger_width=0.07,
                    finger_thickness=0.03, palm_extension=0.03)
    left = add_dh_arm(r, dh.MARU1_LEFT, hand, "arm")
    right = add_dh_arm(r, dh.MARU1_RIGHT, hand, "arm")
    r.groups = [("left_arm", "torso_link", "left_tcp"), ("right_arm", "torso_link", "right_tcp"),
                ("left_arm_torso", "base_link", "left_tcp"), ("right_arm_torso", "base_link", "right_tcp"),
                ("torso", "base_link", "torso_link")]
    _hands(r)
    # Elbows bent, forearms forward and turned in. This 6-DoF arm (no spherical wrist) is singular
    # whenever the forearm yaw is 0 (wrist axis parallel to the elbow axis), so home turns it by
    # -0.9 rad (sigma_min of the 6x6 Jacobian 0.078 instead of 0).
    arm_home = [0.4, 0.2, 0.5, 1.3, -0.9, 0.0]
    r.home = {"waist_yaw_joint": 0.0} | dict(zip(left, arm_home)) | dict(zip(right, arm_home))
    r.home_groups = [("torso", ["waist_yaw_joint"]), ("left_arm", left), ("right_arm", right)]
    return r


def _hands(r: Robot) -> None:
    for side in ("left", "right"):
        r.hands.append((f"{side}_hand", f"{side}_tcp", f"{side}_arm", (f"{side}_hand", f"{side}_tcp")))


BUILDERS = {"armar3": build_armar3, "dual_arm": build_dual_arm, "maru1": build_maru1}

# ----------------------------------------------------------------------------- XML output
MATERIALS = {"grey": "0.6 0.6 0.6 1", "dark": "0.25 0.25 0.28 1", "body": "0.75 0.75 0.8 1",
             "head": "0.85 0.85 0.9 1", "arm": "0.35 0.45 0.7 1", "hand": "0.8 0.55 0.3 1"}


def _f(x: float) -> str:
    """x rounded to 1e-12 (keeps FK exact to far below the 1e-9 test tolerance, and the XML readable)."""
    x = round(float(x), 12)
    return "0" if x == 0 else repr(x)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF rpy (R = Rz(y) Ry(p) Rx(r)); exact inverse of the URDF convention, gimbal lock included."""
    sp = -R[2, 0]
    if abs(sp) >= 1.0 - 1e-12:  # gimbal lock: yaw folded into roll (same for p = +-pi/2)
        return float(np.arctan2(-R[1, 2], R[1, 1])), float(np.copysign(np.pi / 2, sp)), 0.0
    p = np.arctan2(sp, np.hypot(R[0, 0], R[1, 0]))
    r = np.arctan2(R[2, 1], R[2, 2])
    y = np.arctan2(R[1, 0], R[0, 0])
    return float(r), float(p), float(y)


def origin_xml(T: np.ndarray) -> str:
    r, p, y = rpy_from_matrix(T[:3, :3])
    back = rot_z(y) @ rot_y(p) @ rot_x(r)
    if np.max(np.abs(back[:3, :3] - T[:3, :3])) > 1e-12:
        raise AssertionError(f"rpy round trip failed for\n{T}")
    xyz = " ".join(_f(v) for v in T[:3, 3])
    return f'<origin xyz="{xyz}" rpy="{_f(r)} {_f(p)} {_f(y)}"/>'


def _geometry_xml(s: Shape) -> list[tuple[str, np.ndarray]]:
    """(geometry element, origin) pairs; a capsule is a cylinder plus two end spheres."""
    if s.kind == "box":
        return [(f'<box size="{" ".join(_f(v) for v in s.dims)}"/>', s.origin)]
    if s.kind == "sphere":
        return [(f'<sphere radius="{_f(s.dims[0])}"/>', s.origin)]
    if s.kind == "cylinder":
        return [(f'<cylinder radius="{_f(s.dims[0])}" length="{_f(s.dims[1])}"/>', s.origin)]
    if s.kind == "capsule":
        rad, L = s.dims
        out = [(f'<cylinder radius="{_f(rad)}" length="{_f(L)}"/>', s.origin)]
        for z in (-L / 2, L / 2):
            out.append((f'<sphere radius="{_f(rad)}"/>', _clean(s.origin @ trans(0, 0, z))))
        return out
    raise ValueError(s.kind)


def urdf_text(r: Robot) -> str:
    lines = ['<?xml version="1.0"?>',
             "<!-- Generated by scripts/gen_presets.py from humanoid_planner/core/dh_tables.py; do not edit.",
             f"     Preset {r.name}. Frame: {r.frame_note}.",
             "     Sources and modelling choices: config/robots/README.md.",
             "     <limit acceleration> is an extension read by humanoid_planner's RobotModel (URDF has no",
             "     acceleration limits); other URDF parsers ignore it. -->",
             f"<robot name={quoteattr(r.name)}>"]
    for m, rgba in MATERIALS.items():
        lines.append(f'  <material name="{m}"><color rgba="{rgba}"/></material>')
    for name, shapes in r.links.items():
        lines.append(f'  <link name="{name}">')
        for s in shapes:
            for geom, T in _geometry_xml(s):
                lines.append(f'    <visual>{origin_xml(T)}<geometry>{geom}</geometry><material name="{s.material}"/></visual>')
        for s in shapes:
            for geom, T in _geometry_xml(s):
                lines.append(f"    <collision>{origin_xml(T)}<geometry>{geom}</geometry></collision>")
        lines.append("  </link>")
    for j in r.joints:
        lines.append(f'  <joint name="{j.name}" type="{j.type}">')
        lines.append(f'    <parent link="{j.parent}"/><child link="{j.child}"/>')
        lines.append(f"    {origin_xml(j.origin)}")
        if j.type != "fixed":
            lines.append(f'    <axis xyz="{" ".join(_f(v) for v in j.axis)}"/>')
            lines.append(f'    <limit lower="{_f(j.lower)}" upper="{_f(j.upper)}" effort="{_f(EFFORT)}" '
                         f'velocity="{_f(j.velocity)}" acceleration="{_f(j.acceleration)}"/>')
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def srdf_text(r: Robot, disabled: list[tuple[str, str, str]]) -> str:
    lines = ['<?xml version="1.0"?>',
             "<!-- Generated by scripts/gen_presets.py; do not edit. Groups: chain base -> tip, tip = TCP.",
             "     disable_collisions: Adjacent / Always / Never as found by sampling (see the script). -->",
             f"<robot name={quoteattr(r.name)}>",
             f'  <virtual_joint name="world_joint" type="fixed" parent_frame="world" child_link="{r.root}"/>']
    for name, base, tip in r.groups:
        lines.append(f'  <group name="{name}"><chain base_link="{base}" tip_link="{tip}"/></group>')
    for ee, parent, arm, links in r.hands:
        inner = "".join(f'<link name="{lk}"/>' for lk in links)
        lines.append(f'  <group name="{ee}_links">{inner}</group>')
    for gname, joints in r.home_groups:
        lines.append(f'  <group_state name="home" group="{gname}">')
        for jn in joints:
            lines.append(f'    <joint name="{jn}" value="{_f(r.home[jn])}"/>')
        lines.append("  </group_state>")
    for ee, parent, arm, links in r.hands:
        lines.append(f'  <end_effector name="{ee}" parent_link="{parent}" group="{ee}_links" parent_group="{arm}"/>')
    for a, b, reason in disabled:
        lines.append(f'  <disable_collisions link1="{a}" link2="{b}" reason="{reason}"/>')
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- collision sampling (fcl)
class _Collider:
    """python-fcl objects for every shape of the preset, optionally inflated by a margin."""

    def __init__(self, r: Robot, margin: float):
        import fcl

        self.fcl = fcl
        self.objs: dict[str, list[tuple[object, np.ndarray]]] = {}
        for link, shapes in r.links.items():
            objs = []
            for s in shapes:
                if s.kind == "box":
                    g = fcl.Box(*[d + 2 * margin for d in s.dims])
                elif s.kind == "sphere":
                    g = fcl.Sphere(s.dims[0] + margin)
                elif s.kind == "cylinder":
                    g = fcl.Cylinder(s.dims[0] + margin, s.dims[1] + 2 * margin)
                else:
                    g = fcl.Capsule(s.dims[0] + margin, s.dims[1])
                objs.append((fcl.CollisionObject(g, fcl.Transform()), s.origin))
            if objs:
                self.objs[link] = objs

    def place(self, poses: dict[str, np.ndarray]) -> None:
        for link, objs in self.objs.items():
            P = poses[link]
            for o, T in objs:
                W = P @ T
                o.setTransform(self.fcl.Transform(W[:3, :3], W[:3, 3]))

    def collide(self, a: str, b: str) -> bool:
        req = self.fcl.CollisionRequest()
        for oa, _ in self.objs[a]:
            for ob, _ in self.objs[b]:
                if self.fcl.collide(oa, ob, req, self.fcl.CollisionResult()):
                    return True
        return False


def _load_model(r: Robot):
    from humanoid_planner.core.model.robot import RobotModel

    return RobotModel.from_urdf_srdf(urdf_text(r), srdf_text(r, []))


def _link_pose_dicts(model, Q: np.ndarray, links: list[str]):
    P = model.link_poses(Q, links)
    for k in range(len(Q)):
        yield {lk: P[k, i] for i, lk in enumerate(links)}


def find_disabled_pairs(r: Robot, seed: int = 0) -> list[tuple[str, str, str]]:
    """Adjacent, Always and Never pairs (MoveIt setup-assistant categories), deterministic."""
    model = _load_model(r)
    links = [lk for lk in r.links if r.links[lk]]
    adjacent = {frozenset((j.parent, j.child)) for j in r.joints}
    pairs = [(a, b) for i, a in enumerate(links) for b in links[i + 1:] if frozenset((a, b)) not in adjacent]
    rng = np.random.default_rng(seed)

    def sample(n: int) -> np.ndarray:
        return rng.uniform(model.lower, model.upper, size=(n, model.dof))

    exact = _Collider(r, 0.0)
    # Links welded together by fixed joints keep their relative pose: one exact test decides them.
    rigid_root = {lk: lk for lk in r.links}

    def find(lk: str) -> str:
        while rigid_root[lk] != lk:
            lk = rigid_root[lk]
        return lk

    for j in r.joints:
        if j.type == "fixed":
            rigid_root[find(j.child)] = find(j.parent)
    rigid = [p for p in pairs if find(p[0]) == find(p[1])]
    exact.place(next(_link_pose_dicts(model, model.home[None, :], links)))
    always = {p for p in rigid if exact.collide(*p)}
    never = set(rigid) - always
    moving = [p for p in pairs if p not in set(rigid)]
    maybe_always = set(moving)
    for poses in _link_pose_dicts(model, sample(ALWAYS_SAMPLES), links):
        exact.place(poses)
        maybe_always = {p for p in maybe_always if exact.collide(*p)}
    always |= maybe_always
    inflated = _Collider(r, NEVER_MARGIN)
    maybe_never = set(moving) - always
    Q = sample(NEVER_SAMPLES)
    for start in range(0, NEVER_SAMPLES, 500):
        for poses in _link_pose_dicts(model, Q[start:start + 500], links):
            inflated.place(poses)
            maybe_never = {p for p in maybe_never if not inflated.collide(*p)}
    never |= maybe_never
    out = [(a, b, "Adjacent") for j in r.joints for a, b in [(j.parent, j.child)]]
    out += [(a, b, "Always") for a, b in pairs if (a, b) in always]
    out += [(a, b, "Never") for a, b in pairs if (a, b) in never]
    return out


def home_collisions(r: Robot, disabled: list[tuple[str, str, str]], margin: float = HOME_MARGIN) -> list[tuple[str, str]]:
    """Enabled link pairs in contact at the home pose (with every shape inflated by margin)."""
    model = _load_model(r)
    off = {frozenset((a, b)) for a, b, _ in disabled}
    links = [lk for lk in r.links if r.links[lk]]
    col = _Collider(r, margin)
    col.place(next(_link_pose_dicts(model, model.home[None, :], links)))
    return [(a, b) for i, a in enumerate(links) for b in links[i + 1:]
            if frozenset((a, b)) not in off and col.collide(a, b)]


def find_dual_home() -> tuple[np.ndarray, np.ndarray]:
    """Posture fit used once to choose DUAL_HOME_*: upper arm down-forward, forearm forward, wrist mid-range.

    Bounded least squares on elbow and wrist points (+ weak approach and mid-range terms) from 200
    random starts; of the fits that converge, the one farthest from its joint limits wins.
    """
    from scipy.optimize import least_squares

    out = []
    torso = trans(*dh.DUAL_COA)
    for arm, s in ((dh.DUAL_LEFT, -1.0), (dh.DUAL_RIGHT, 1.0)):
        lo = np.array([j.lower for j in arm.joints])
        hi = np.array([j.upper for j in arm.joints])
        mid = (lo + hi) / 2
        shoulder = (torso @ arm.base)[:3, 3]
        elbow_goal = shoulder + np.array([s * 0.06, 0.16, -0.26])
        wrist_goal = elbow_goal + np.array([-s * 0.04, 0.22, 0.08])

        def res(q):
            T = torso @ arm.base
            fr = []
            for i, j in enumerate(arm.joints):
                T = T @ dh.dh_matrix(j.offset + q[i], j.d, j.a, j.alpha)
                fr.append(T)
            approach = (T @ arm.tool)[:3, 3] - T[:3, 3]
            approach /= np.linalg.norm(approach)
            return np.concatenate([fr[3][:3, 3] - elbow_goal, fr[4][:3, 3] - wrist_goal,
                                   0.005 * (approach - np.array([-s * 0.3, 0.95, 0.0])),
                                   0.01 * (q - mid) / (hi - lo)])

        fits = [least_squares(res, np.random.default_rng(k).uniform(lo, hi), bounds=(lo, hi)) for k in range(200)]
        good = [f.x for f in fits if f.cost < 2e-4]
        out.append(max(good, key=lambda q: float(np.min(np.minimum(q - lo, hi - q)))))
    return out[0], out[1]


# ----------------------------------------------------------------------------- main
def generate(name: str, out_dir: Path = OUT_DIR, sample: bool = True) -> tuple[str, str]:
    r = BUILDERS[name]()
    disabled = find_disabled_pairs(r) if sample else _committed_disabled(out_dir / f"{name}.srdf")
    bad = home_collisions(r, disabled)
    if bad:
        raise SystemExit(f"{name}: home pose in collision (margin {HOME_MARGIN} m): {bad}")
    return urdf_text(r), srdf_text(r, disabled)


def _committed_disabled(path: Path) -> list[tuple[str, str, str]]:
    from lxml import etree

    root = etree.parse(str(path)).getroot()
    return [(d.get("link1"), d.get("link2"), d.get("reason")) for d in root.findall("disable_collisions")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", default=list(BUILDERS))
    ap.add_argument("--out", type=Path, default=OUT_DIR)
    ap.add_argument("--check", action="store_true", help="compare the URDFs (and SRDF minus sampling) with --out")
    ap.add_argument("--dual-home", action="store_true", help="print the posture fit behind DUAL_HOME_*")
    args = ap.parse_args(argv)
    if args.dual_home:
        left, right = find_dual_home()
        print("left ", np.round(left, 3).tolist(), "\nright", np.round(right, 3).tolist())
        return 0
    status = 0
    for name in args.names:
        if args.check:
            urdf, srdf = generate(name, args.out, sample=False)
            for ext, text in (("urdf", urdf), ("srdf", srdf)):
                path = args.out / f"{name}.{ext}"
                if not path.is_file() or path.read_text() != text:
                    print(f"{path} is out of date; run scripts/gen_presets.py")
                    status = 1
            continue
        urdf, srdf = generate(name, args.out)
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / f"{name}.urdf").write_text(urdf)
        (args.out / f"{name}.srdf").write_text(srdf)
        n_dis = srdf.count("<disable_collisions")
        print(f"{name}: wrote {name}.urdf, {name}.srdf ({n_dis} disabled pairs)")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
