"""A planning group's TCP pose and 6 × n geometric Jacobian, for (n,) or (N, n) group configurations.

Built on the one FK engine (`fk.KinematicTree`, compiled for the group's joints with the others held at
q_ref, computing only the frames on the chain to the TCP): a frame's z axis is its joint axis and its
column 3 the joint origin, so the Jacobian comes from the same frames as the pose. Everything is in the
URDF root frame (the planning frame); the Jacobian has the linear rows first:
J = [z_i × (p_tcp − o_i); z_i] for revolute joints, [z_i; 0] for prismatic ones.

A single configuration takes the engine's 4x4 chain (`single`), batches its configurations-last path
(`poses_last`), whose (3, N) rows feed the Jacobian without a transpose.
"""
from __future__ import annotations

import numpy as np

from humanoid_planner.core.model.robot import RobotModel


# ε_kab as a (3, 9) matrix: (a × b)_k = Σ ε_kab a_a b_b, i.e. one product with the outer products a ⊗ b
# (entries 0/±1, so each component is the same single rounding of a_a b_b − a_b b_a as the textbook formula).
_LEVI_CIVITA = np.zeros((3, 9))
for _k, _a, _b in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_k, 3 * _a + _b], _LEVI_CIVITA[_k, 3 * _b + _a] = 1.0, -1.0


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
        self._tree = self.robot.kinematic_tree(self.joint_indices, self.q_ref, needed=[self.tip_link])
        if len(self._tree) != self.n:
            on_chain = {self.joint_names[f.column] for f in self._tree.frames}
            missing = sorted(set(self.joint_names) - on_chain)
            raise ValueError(f"joints {missing} are not on the chain {self.robot.root_link} -> {self.tip_link}")
        # the TCP hangs from the chain's last frame; C-contiguous, as the compiled IK reads it (chain_arrays)
        self._Ktip = np.ascontiguousarray(self._tree.anchors[self.tip_link][1], dtype=float)
        self._Ktip_T = np.ascontiguousarray(self._Ktip.T)
        self._prismatic = np.array([f.prismatic for f in self._tree.frames], dtype=bool)
        self._any_prismatic = bool(self._prismatic.any())
        perm = np.array([f.column for f in self._tree.frames], dtype=np.int64)  # frame k moves column perm[k]
        self._identity_perm = bool(np.all(perm == np.arange(self.n)))
        self._unperm = np.argsort(perm)

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

    @property
    def chain_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The chain as the compiled IK (ik/kernels.py) reads it: the tree's kernel arrays (column, parent,
        prismatic flag and local-transform basis of each frame) and the TCP's 4x4 offset from the last frame."""
        return (*self._tree.kernel_arrays, self._Ktip)

    # ------------------------------------------------------------------ internals
    def _check(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (self.n,) or q.ndim > 2:
            raise ValueError(f"expected ({self.n},) or (N, {self.n}) group configurations, got {q.shape}")
        return q

    def _single(self, q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        P = self._tree.single(q)  # the chain's frames, 4x4
        T = P[-1].dot(self._Ktip)
        if not jacobian:
            return T, None
        n = self.n
        Pa = np.array(P)
        z = Pa[:, :3, 2].T                                    # (3, n) joint axes
        d = T[:3, 3, None] - Pa[:, :3, 3].T                   # o_i → p_tcp
        J = np.concatenate((_LEVI_CIVITA.dot((z[:, None] * d).reshape(9, n)), z))   # z_i × d_i for all i at once
        if self._any_prismatic:
            pr = self._prismatic
            J[:3, pr] = z[:, pr]
            J[3:, pr] = 0.0
        if not self._identity_perm:
            J = J[:, self._unperm]
        return T, J

    def _batched(self, q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        N, n = q.shape
        P = self._tree.poses_last(q)                # (n, 3, 4, N)
        A = np.matmul(self._Ktip_T, P[-1])          # TCP rows (3, 4, N)
        T = np.zeros((N, 4, 4))
        T[:, :3, :] = A.transpose(2, 0, 1)
        T[:, 3, 3] = 1.0
        if not jacobian:
            return T, None
        Z = P[:, :, 2]                              # (n, 3, N) joint axes
        D = A[None, :, 3] - P[:, :, 3]              # (n, 3, N): o_i → p_tcp
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
