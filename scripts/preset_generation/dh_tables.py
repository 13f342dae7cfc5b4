"""The papers' D-H tables, as data: the single source for the preset generator, the closed-form
ARMAR-III IK and the tests that compare the generated URDFs with the tables.

Convention everywhere (all three papers, see config/robots/README.md): standard (distal)
D-H, A_i(q_i) = Rz(offset_i + q_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i), lengths in metres.
Every choice made where a paper is ambiguous or misprinted is written down in config/robots/README.md.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

PI = np.pi
DEG = PI / 180.0


@dataclass(frozen=True)
class DHJoint:
    """One table row plus the limits the preset uses for that joint."""

    name: str              # joint name without side prefix, e.g. "shoulder_1"
    offset: float          # theta offset (rad): theta_i = offset + q_i
    d: float
    a: float
    alpha: float
    lower: float
    upper: float
    velocity: float        # rad/s (URDF <limit velocity>)
    acceleration: float    # rad/s² (our <limit acceleration> extension, read by RobotModel)
    radius: float = 0.04   # collision radius of the link this joint moves (capsule / joint sphere)


@dataclass(frozen=True, eq=False)
class DHArm:
    """A serial arm: Sigma_0 pose in its parent link, the rows, and the TCP in D-H frame n."""

    side: str                  # "left" | "right"
    parent_link: str
    base: np.ndarray           # 4x4: Sigma_0 (frame of joint 1 at q=0) in parent_link
    joints: tuple[DHJoint, ...]
    tool: np.ndarray           # 4x4: TCP in the last D-H frame

    def names(self) -> list[str]:
        return [f"{self.side}_{j.name}_joint" for j in self.joints]


# ----------------------------------------------------------------------------- elementary transforms
def rot_x(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def dh_matrix(theta: np.ndarray | float, d: float, a: float, alpha: float) -> np.ndarray:
    """Formula (1) of seeds 000/001 with its (2,3) sign misprint fixed (-s_alpha c_theta); batched over theta."""
    th = np.asarray(theta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    ca, sa = np.cos(alpha), np.sin(alpha)
    A = np.zeros(th.shape + (4, 4))
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = c, -ca * s, sa * s, a * c
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = s, ca * c, -sa * c, a * s
    A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa, ca, d
    A[..., 3, 3] = 1.0
    return A


def dh_chain(arm: DHArm, q: np.ndarray) -> np.ndarray:
    """Direct D-H product Sigma_0 -> TCP, prod_i A_i(q_i) · tool, for (n,) or (N, n) q (reference FK)."""
    q = np.asarray(q, dtype=float)
    T = np.broadcast_to(np.eye(4), q.shape[:-1] + (4, 4))
    for i, j in enumerate(arm.joints):
        T = T @ dh_matrix(j.offset + q[..., i], j.d, j.a, j.alpha)
    return T @ arm.tool


# ----------------------------------------------------------------------------- mirroring
MIRROR_Y = np.diag([1.0, -1.0, 1.0, 1.0])   # sagittal-plane reflection in a frame with y lateral
_FLIP_Z = np.diag([1.0, 1.0, -1.0, 1.0])    # reflection applied inside every D-H frame
_FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])


def mirror_arm(arm: DHArm, side: str, world_mirror: np.ndarray = MIRROR_Y) -> DHArm:
    """The other arm as the mirror image: same q gives the mirrored pose, same limits.

    With M the reflection of the parent frame and F = diag(1,1,-1) applied in every D-H frame,
    F·A(offset, d, a, alpha)·F = A(offset, -d, a, -alpha), so the mirrored table is
    (offset, -d, a, -alpha), Sigma_0' = M·Sigma_0·F and tool' = F·tool·diag(1,-1,1): the TCP's x and z
    axes are the mirror images of the original ones (y completes a right-handed frame).
    """
    joints = tuple(replace(j, d=-j.d, alpha=-j.alpha) for j in arm.joints)
    return DHArm(side, arm.parent_link, world_mirror @ arm.base @ _FLIP_Z, joints, _FLIP_Z @ arm.tool @ _FLIP_Y)


# ----------------------------------------------------------------------------- armar3 (GIRRT paper)
ARMAR3_L_S = 0.0    # shoulder offset a_1: 0, ARMAR-III's shoulder axes intersect (Simox a=d=0)
ARMAR3_L_U = 0.310  # upper arm (Simox Upperarm d = -310 mm)
ARMAR3_L_F = 0.240  # forearm (Simox Underarm d = -240 mm)
ARMAR3_L_H = 0.130  # wrist -> TCP (Simox Hand -> TCP z = 130 mm)
ARMAR3_HIP_HEIGHT = 0.890           # Simox Hip Pitch z above the platform origin
ARMAR3_COA_FROM_HIP = (-0.035, 0.0, 0.485)  # Simox CoA = hip + (0, -35, 485) mm in its y-forward frame
ARMAR3_SHOULDER_HALF_WIDTH = 0.232  # Simox TrafoToLeftArm / TrafoToRightArm x = -/+232 mm
# Sigma_0 of the right arm in torso_link (x forward, y left, z up): x0 down, y0 forward, z0 to the right.
# At q = 0 the Table-1 arm is straight along x0, so it hangs down; q1 (about z0) swings it forward,
# q2 (about y0) sideways, and the elbow (q4 > 0) bends the forearm forward.
_ARMAR3_R0 = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0, 0, 0, 1.0]])


def _armar3_right() -> DHArm:
    v_arm, v_wrist, acc_arm, acc_wrist = 1.5, 2.0, 3.0, 4.0
    rows = (  # Table 1 of the GIRRT paper (right arm): offset, d, a, alpha, limits
        DHJoint("shoulder_1", 0.0, 0.0, ARMAR3_L_S, -PI / 2, -PI / 2, PI / 2, v_arm, acc_arm, 0.07),
        DHJoint("shoulder_2", -PI / 2, 0.0, 0.0, -PI / 2, -PI / 2, PI / 2, v_arm, acc_arm, 0.06),
        DHJoint("upper_arm", PI / 2, ARMAR3_L_U, 0.0, PI / 2, -23 * PI / 18, PI / 2, v_arm, acc_arm, 0.05),
        DHJoint("elbow", 0.0, 0.0, 0.0, -PI / 2, 0.0, 29 * PI / 36, v_arm, acc_arm, 0.05),
        DHJoint("forearm", 0.0, ARMAR3_L_F, 0.0, PI / 2, 0.0, 35 * PI / 18, v_arm, acc_arm, 0.04),
        DHJoint("wrist_1", PI / 2, 0.0, 0.0, -PI / 2, -PI / 4, PI / 4, v_wrist, acc_wrist, 0.04),
        DHJoint("wrist_2", 0.0, 0.0, ARMAR3_L_H, PI / 2, -PI / 4, PI / 4, v_wrist, acc_wrist, 0.035),
    )
    x, _, z = ARMAR3_COA_FROM_HIP
    base = trans(x, -ARMAR3_SHOULDER_HALF_WIDTH, z) @ _ARMAR3_R0
    return DHArm("right", "torso_link", base, rows, np.eye(4))


ARMAR3_TORSO = (  # the GIRRT paper eq. 15-19: R = Rz(yaw) Ry(pitch) Rx(roll); limits: Simox hip joints +-45 deg
    DHJoint("torso_yaw", 0.0, 0.0, 0.0, 0.0, -PI / 4, PI / 4, 1.0, 2.0, 0.12),
    DHJoint("torso_pitch", 0.0, 0.0, 0.0, 0.0, -PI / 4, PI / 4, 1.0, 2.0, 0.10),
    DHJoint("torso_roll", 0.0, 0.0, 0.0, 0.0, -PI / 4, PI / 4, 1.0, 2.0, 0.10),
)

ARMAR3_RIGHT = _armar3_right()
ARMAR3_LEFT = mirror_arm(ARMAR3_RIGHT, "left")

# ----------------------------------------------------------------------------- dual_arm (DAGRRT paper)
DUAL_COA = (0.0, 0.123, 1.375)  # Simox ARMAR-III "Center of Arms" in the paper's pose frame (x right, y fwd)
DUAL_SHOULDER_HALF_WIDTH = 0.232
DUAL_TCP = 0.130  # Simox hand TCP, z = 130 mm from the last D-H frame (Table 1 has no hand row)


def _dual(side: str, rows_raw) -> DHArm:
    sign = -1.0 if side == "left" else 1.0
    base = trans(sign * DUAL_SHOULDER_HALF_WIDTH, 0.0, 0.0) @ rot_z(-PI / 2) @ rot_x(PI / 2)
    names = ("shoulder_1", "shoulder_2", "upper_arm", "elbow", "forearm", "wrist_1", "wrist_2")
    radii = (0.07, 0.06, 0.05, 0.05, 0.04, 0.04, 0.035)
    lim = ((-PI / 2, PI / 2), (-PI / 2, PI / 2), (-23 * PI / 18, PI / 2), (-23 * PI / 18, PI / 2),
           (-PI, PI), (-PI / 2, PI / 2), (-PI / 2, PI / 2))
    vel = (1.5, 1.5, 1.5, 1.5, 1.5, 2.0, 2.0)
    acc = (3.0, 3.0, 3.0, 3.0, 3.0, 4.0, 4.0)
    joints = tuple(DHJoint(n, o, d_mm / 1000.0, a_mm / 1000.0, al, lo, hi, v, ac, r)
                   for n, (o, al, a_mm, d_mm), (lo, hi), v, ac, r in zip(names, rows_raw, lim, vel, acc, radii))
    return DHArm(side, "torso_link", base, joints, trans(0.0, 0.0, DUAL_TCP))


DUAL_LEFT = _dual("left", (  # Table 1 of the DAGRRT paper, as printed: Theta (offset), Alpha, a (mm), d (mm)
    (PI / 2, PI / 2, 0.0, 0.0), (PI / 2, PI / 2, 0.0, 0.0), (-PI / 2, PI / 2, 20.0, -310.0),
    (0.0, -PI / 2, 0.0, -7.5), (PI / 2, -PI / 2, 0.0, -240.0), (-PI / 2, -PI / 2, 0.0, 0.0),
    (-PI / 2, PI / 2, 0.0, 0.0)))
DUAL_RIGHT = _dual("right", (
    (0.0, -PI / 2, 0.0, 0.0), (-PI / 2, -PI / 2, 0.0, 0.0), (PI / 2, PI / 2, 20.0, -310.0),
    (0.0, -PI / 2, 0.0, 7.5), (0.0, PI / 2, 0.0, -240.0), (PI / 2, -PI / 2, 0.0, 0.0),
    (0.0, PI / 2, 0.0, 0.0)))

# ----------------------------------------------------------------------------- maru1 (Maru-1 thesis)
MARU1_L0 = 0.284    # waist -> shoulder line height (row B-U d)
MARU1_D0 = 0.04     # row B-U a (shoulder line in front of the waist axis)
MARU1_L1, MARU1_L2 = 0.1615, 0.061  # shoulder half-width = l1 + l2 (^B T_S), reading H3
MARU1_D2 = 0.0055   # row L2 d (reading H1)
MARU1_L3, MARU1_L5, MARU1_L6 = 0.224, 0.225, 0.041
MARU1_BASE = dh_matrix(0.0, MARU1_L0, MARU1_D0, PI / 2)  # row B-U at theta_0 = 0: Sigma_0 of both arms

MARU1_TORSO = (DHJoint("waist_yaw", 0.0, 0.0, 0.0, 0.0, -PI / 3, PI / 3, 1.0, 2.0, 0.12),)


def _maru1_left() -> DHArm:
    v, acc = 1.5, 3.0
    rows = (  # thesis Table 1 (the +y arm): offset, d, a, alpha; limits are ours (none survive)
        DHJoint("shoulder_pitch", -PI / 2, -(MARU1_L1 + MARU1_L2), 0.0, -PI / 2, -60 * DEG, 170 * DEG, v, acc, 0.06),
        DHJoint("shoulder_roll", PI / 2, MARU1_D2, 0.0, PI / 2, -20 * DEG, 150 * DEG, v, acc, 0.055),
        DHJoint("upper_arm_yaw", PI / 2, MARU1_L3, 0.0, -PI / 2, -90 * DEG, 90 * DEG, v, acc, 0.045),
        DHJoint("elbow", 0.0, 0.0, 0.0, PI / 2, 0.0, 140 * DEG, v, acc, 0.045),
        DHJoint("forearm_yaw", -PI / 2, MARU1_L5, 0.0, -PI / 2, -90 * DEG, 90 * DEG, 2.0, 4.0, 0.04),
        DHJoint("wrist", -PI / 2, 0.0, MARU1_L6, 0.0, -60 * DEG, 60 * DEG, 2.0, 4.0, 0.035),
    )
    return DHArm("left", "torso_link", MARU1_BASE, rows, np.eye(4))


MARU1_LEFT = _maru1_left()
MARU1_RIGHT = mirror_arm(MARU1_LEFT, "right")

PRESET_ARMS: dict[str, tuple[DHArm, DHArm]] = {
    "armar3": (ARMAR3_LEFT, ARMAR3_RIGHT),
    "dual_arm": (DUAL_LEFT, DUAL_RIGHT),
    "maru1": (MARU1_LEFT, MARU1_RIGHT),
}
