"""Forward kinematics and the geometric Jacobian of one planning group's TCP, batched in numpy.

The chain root → TCP is precompiled once: every fixed joint, and every active joint that is not in
the group (held at q_ref, e.g. the torso for an arm group), is folded into constant 4x4 transforms,
and each group joint's frame is rotated so that it moves about (or along) its own z axis:

    T(q) = K_0 · M(q_1) · K_1 · M(q_2) ··· M(q_n) · K_n,   M = Rz (revolute) or Tz (prismatic)

Multiplying by Rz(q) only mixes two columns, so the batched path costs one small GEMM per row
((4,4) @ (4,N)) plus a few (3, N) array operations per joint, and never loops over configurations.  A separate
single-configuration path builds all n local transforms at once and chains n small products, which
keeps the per-call overhead low for planners that step one configuration at a time.

Everything is expressed in the URDF root frame (the planning frame); the Jacobian is 6 × n with the
linear rows first: J = [z_i × (p_tcp − o_i); z_i] for revolute joints, [z_i; 0] for prismatic ones.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel, joint_motion


# ε_kab as a (3, 9) matrix: (a × b)_k = Σ ε_kab a_a b_b, i.e. one product with the outer products a ⊗ b
# (entries 0/±1, so each component is the same single rounding of a_a b_b − a_b b_a as the textbook formula).
_LEVI_CIVITA = np.zeros((3, 9))
for _k, _a, _b in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_k, 3 * _a + _b], _LEVI_CIVITA[_k, 3 * _b + _a] = 1.0, -1.0


def _align_z(axis: np.ndarray) -> np.ndarray:
    """A rotation R with R · e_z = axis (so R Rz(q) Rᵀ is the rotation by q about axis)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    z = np.array([0.0, 0.0, 1.0])
    c = float(a @ z)
    if c > 1.0 - 1e-12:
        return np.eye(3)
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])  # Rx(pi)
    v = np.cross(z, a)
    s = np.linalg.norm(v)
    k = v / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _h(R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    return T


class GroupKinematics:
    """FK and Jacobian of a planning group's TCP in the root frame, for (n,) or (N, n) group configurations."""

    def __init__(self, robot: RobotModel, group: str, q_ref: np.ndarray | None = None):
        g = robot.group(group)
        if not g.joint_names or not g.tip_link:
            raise ValueError(f"group {group!r} has no joints or no tip link; it is not a kinematic chain")
        self._setup(robot, g.joint_names, g.tip_link, g.base_link, q_ref, group)

    @classmethod
    def from_chain(cls, robot: RobotModel, base_link: str, tip_link: str,
                   q_ref: np.ndarray | None = None) -> "GroupKinematics":
        """A chain that is not an SRDF group: the active joints from base_link down to tip_link."""
        self = cls.__new__(cls)
        names = tuple(j.name for j in robot.chain_joints(base_link, tip_link) if j.index >= 0)
        if not names:
            raise ValueError(f"no active joint between {base_link} and {tip_link}")
        self._setup(robot, names, tip_link, base_link, q_ref, None)
        return self

    def _setup(self, robot: RobotModel, joint_names: tuple[str, ...], tip_link: str, base_link: str,
               q_ref: np.ndarray | None, group: str | None) -> None:
        self.robot = robot
        self.group = group
        self.tip_link = tip_link
        self.base_link = base_link
        self.joint_names = tuple(joint_names)
        self.joint_indices = np.array([robot.joints[n].index for n in joint_names], dtype=np.int64)
        self.n = len(joint_names)
        self.lower = robot.lower[self.joint_indices].copy()
        self.upper = robot.upper[self.joint_indices].copy()
        self.max_velocity = robot.max_velocity[self.joint_indices].copy()
        self.max_acceleration = robot.max_acceleration[self.joint_indices].copy()
        self.q_ref = np.array(robot.home if q_ref is None else q_ref, dtype=float)
        if self.q_ref.shape != (robot.dof,):
            raise ValueError(f"q_ref must have {robot.dof} values, got shape {self.q_ref.shape}")
        self._compile()

    def with_reference(self, q_ref: np.ndarray) -> "GroupKinematics":
        """Same chain with the joints outside the group held at another full configuration."""
        other = GroupKinematics.__new__(GroupKinematics)
        other._setup(self.robot, self.joint_names, self.tip_link, self.base_link, q_ref, self.group)
        return other

    def _compile(self) -> None:
        chain = self.robot.chain_joints(self.robot.root_link, self.tip_link)
        position = {n: i for i, n in enumerate(self.joint_names)}
        on_chain = [j.name for j in chain if j.name in position]
        if len(on_chain) != self.n:
            missing = sorted(set(self.joint_names) - set(on_chain))
            raise ValueError(f"joints {missing} are not on the chain {self.robot.root_link} -> {self.tip_link}")
        # Column order follows the chain; map the caller's (group) order onto it.
        self._perm = np.array([position[n] for n in on_chain], dtype=np.int64)
        self._identity_perm = bool(np.all(self._perm == np.arange(self.n)))
        consts, prismatic = [], []
        acc = np.eye(4)
        for j in chain:
            if j.name in position:
                if j.type not in ("revolute", "continuous", "prismatic"):
                    raise ValueError(f"joint {j.name} of type {j.type} cannot be a group joint")
                R = _h(_align_z(j.axis))
                consts.append(acc @ j.origin @ R)
                prismatic.append(j.type == "prismatic")
                acc = R.T
            else:
                value = self.q_ref[j.index] if j.index >= 0 else 0.0
                acc = acc @ j.origin @ joint_motion(j.type, j.axis, value)
        consts.append(acc)
        self._K = np.array(consts)                      # (n+1, 4, 4)
        self._KT = np.ascontiguousarray(np.swapaxes(self._K, 1, 2))  # K_iᵀ for the batched GEMMs
        self._prismatic = np.array(prismatic, dtype=bool)
        self._any_prismatic = bool(self._prismatic.any())
        self._revolute_mask = (~self._prismatic).astype(float)
        # single-config path: L_i = K_{i-1}·M(q_i) = u_i·A_i + v_i·B_i + C_i, one batched (16×3)·(3×1) product
        # for all joints: revolute (u, v) = (cos q, sin q) (Rz mixes columns 0 and 1), prismatic (q, 0)
        # (Tz adds q times column 2 to column 3).
        Kj = self._K[:-1]                                # (n, 4, 4)
        A, B, C = np.zeros_like(Kj), np.zeros_like(Kj), np.zeros_like(Kj)
        A[:, :, 0], A[:, :, 1] = Kj[:, :, 0], Kj[:, :, 1]
        B[:, :, 0], B[:, :, 1] = Kj[:, :, 1], -Kj[:, :, 0]
        C[:, :, 2], C[:, :, 3] = Kj[:, :, 2], Kj[:, :, 3]
        pr = self._prismatic
        A[pr], B[pr] = 0.0, 0.0
        A[pr, :, 3] = Kj[pr, :, 2]
        C[pr, :, :2] = Kj[pr, :, :2]
        self._L_basis = np.ascontiguousarray(np.stack([A, B, C], axis=-1).reshape(self.n, 16, 3))
        self._Ktip = self._K[-1]
        self._unperm = np.argsort(self._perm)

    # ------------------------------------------------------------------ public API
    def q_group(self, q_full: np.ndarray) -> np.ndarray:
        """The group's values out of full configurations (..., dof) → (..., n)."""
        return np.asarray(q_full, dtype=float)[..., self.joint_indices]

    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP pose(s) in the root frame: (n,) → (4, 4); (N, n) → (N, 4, 4)."""
        q = self._check(q)
        if q.ndim == 1:
            return self._single(q, jacobian=False)[0]
        if len(q) == 1:
            return self._single(q[0], jacobian=False)[0][None]
        return self._batched(q, jacobian=False)[0]

    def fk_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(TCP pose, 6×n geometric Jacobian, linear rows first), single or batched."""
        q = self._check(q)
        if q.ndim == 1:
            return self._single(q, jacobian=True)
        if len(q) == 1:  # one row: the single path is ~5x cheaper than a batch of one
            T, J = self._single(q[0], jacobian=True)
            return T[None], J[None]
        return self._batched(q, jacobian=True)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return self.fk_jacobian(q)[1]

    # ------------------------------------------------------------------ internals
    def _check(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (self.n,) or q.ndim > 2:
            raise ValueError(f"expected ({self.n},) or (N, {self.n}) group configurations, got {q.shape}")
        return q if self._identity_perm else q[..., self._perm]

    def _single(self, q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        n = self.n
        uv1 = np.empty((n, 3, 1))
        uv1[:, 2, 0] = 1.0
        if self._any_prismatic:
            pr = self._prismatic
            uv1[:, 0, 0] = np.where(pr, q, np.cos(q))
            uv1[:, 1, 0] = np.where(pr, 0.0, np.sin(q))
        else:
            np.cos(q, out=uv1[:, 0, 0])
            np.sin(q, out=uv1[:, 1, 0])
        L = np.matmul(self._L_basis, uv1).reshape(n, 4, 4)   # local transforms L_i = K_{i-1}·M(q_i)
        if not jacobian:
            T = L[0]
            for Li in L[1:]:
                T = T.dot(Li)
            return T.dot(self._Ktip), None
        # prefix products; z_i, o_i are columns 2, 3 of L_0···L_i (Rz(q_i) leaves them unchanged)
        # (ndarray.dot on a 4x4 pair has about half the call overhead of matmul)
        prefix = [L[0]]
        for Li in L[1:]:
            prefix.append(prefix[-1].dot(Li))
        P = np.array(prefix)
        T = prefix[-1].dot(self._Ktip)
        z = P[:, :3, 2].T                                     # (3, n)
        d = T[:3, 3, None] - P[:, :3, 3].T                    # o_i → p_tcp
        J = np.concatenate((_LEVI_CIVITA.dot((z[:, None] * d).reshape(9, n)), z))   # z_i × d_i for all i at once
        if self._any_prismatic:
            pr = self._prismatic
            J[:3, pr] = z[:, pr]
            J[3:, pr] = 0.0
        if not self._identity_perm:
            J = J[:, self._unperm]
        return T, J

    def _batched(self, q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        # Configurations on the last axis: A[r, c] is the (N,) vector of entry (r, c) of the running
        # transform's top 3 rows, so column mixing is contiguous and A·K is one (4,4)@(4,N) GEMM per row.
        N, n = q.shape
        qT = q.T
        cq, sq = np.cos(qT), np.sin(qT)
        A = np.empty((3, 4, N))
        A[:] = self._K[0][:3, :, None]
        if jacobian:
            Z = np.empty((n, 3, N))
            O = np.empty((n, 3, N))
        for i in range(n):
            if i > 0:
                A = np.matmul(self._KT[i], A)
            if self._prismatic[i]:
                A[:, 3] += qT[i] * A[:, 2]
            else:
                c, s = cq[i], sq[i]
                x = A[:, 0].copy()
                A[:, 0] *= c
                A[:, 0] += s * A[:, 1]
                A[:, 1] *= c
                A[:, 1] -= s * x
            if jacobian:
                Z[i] = A[:, 2]
                O[i] = A[:, 3]
        A = np.matmul(self._KT[n], A)
        T = np.zeros((N, 4, 4))
        T[:, :3, :] = A.transpose(2, 0, 1)
        T[:, 3, 3] = 1.0
        if not jacobian:
            return T, None
        D = A[None, :, 3] - O                      # (n, 3, N): o_i → p_tcp
        J = np.empty((N, 6, n))
        Jv = J.transpose(1, 2, 0)                   # (6, n, N) view: writes land in J
        Jv[0] = Z[:, 1] * D[:, 2] - Z[:, 2] * D[:, 1]
        Jv[1] = Z[:, 2] * D[:, 0] - Z[:, 0] * D[:, 2]
        Jv[2] = Z[:, 0] * D[:, 1] - Z[:, 1] * D[:, 0]
        Jv[3:] = Z.transpose(1, 0, 2)
        if self._any_prismatic:
            pr = self._prismatic
            Jv[:3, pr] = Z[pr].transpose(1, 0, 2)
            Jv[3:, pr] = 0.0
        if not self._identity_perm:
            J = J[:, :, self._unperm]
        return T, J
