"""Batched forward kinematics of the frames a collision checker needs, and nothing else.

RobotModel.link_poses is generic (every link, 4x4 matmuls, ~49 µs/config for TALOS at N=1000);
a collision check needs one frame per *group joint*: every link is a constant offset from the
nearest group joint above it (fixed joints and joints outside the group, at q_ref, fold into that
constant). Rotations use Rodrigues with the constant parts premultiplied (A, A·K, A·K²): a joint's
local transform is linear in (1, sin q, 1 - cos q, q).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from humanoid_planner.core.model.robot import RobotModel, axis_rotation_generators, joint_motion


@dataclass(frozen=True)
class Frame:
    """One group joint: its frame = parent frame @ [A | t] @ motion(q) (A, t fold every constant
    transform since the parent group joint)."""

    parent: int  # index of the parent frame, -1 = root (world)
    column: int  # column in the group configuration
    prismatic: bool
    A: np.ndarray  # 3x3: rotation from parent frame to this joint's frame at q = 0
    AK: np.ndarray  # A @ K
    AK2: np.ndarray  # A @ K²
    t: np.ndarray  # (3,) joint origin in the parent frame
    Aaxis: np.ndarray  # A @ axis (prismatic)


class FrameKinematics:
    """Batched FK of the frames of the group joints; every link is (frame, constant 4x4 offset).

    anchors[link] = (frame index, T): the link's pose is frame_pose @ T, or T itself (root frame)
    when frame is -1. Only frames that some link in `needed` hangs from (and their ancestors) are
    computed.
    """

    def __init__(self, robot: RobotModel, joint_index: np.ndarray, q_ref: np.ndarray,
                 needed: Iterable[str] | None = None):
        column = {int(j): c for c, j in enumerate(joint_index)}
        anchors: dict[str, tuple[int, np.ndarray]] = {robot.root_link: (-1, np.eye(4))}
        raw: list[tuple[int, np.ndarray, str, np.ndarray, int]] = []
        joint_of = {j.child: j for j in robot.joints.values()}
        for link in robot.link_names[1:]:
            j = joint_of[link]
            f, Tp = anchors[j.parent]
            C = Tp @ j.origin
            if j.index in column:
                raw.append((f, C, j.type, j.axis, column[j.index]))
                anchors[link] = (len(raw) - 1, np.eye(4))
            else:
                value = q_ref[j.index] if j.index >= 0 else 0.0
                anchors[link] = (f, C @ joint_motion(j.type, j.axis, value))
        keep = np.zeros(len(raw), dtype=bool)
        for link in (robot.link_names if needed is None else needed):
            f = anchors[link][0]
            while f >= 0 and not keep[f]:
                keep[f] = True
                f = raw[f][0]
        renum = np.cumsum(keep) - 1
        self.anchors = {l: (int(renum[f]) if f >= 0 and keep[f] else -1 if f < 0 else -2, T)
                        for l, (f, T) in anchors.items()}  # -2: a frame nobody needs
        frames = []
        for (parent, C, jtype, axis, col), k in zip(raw, keep):
            if not k:
                continue
            K, K2 = axis_rotation_generators(axis)
            A = C[:3, :3]
            frames.append(Frame(int(renum[parent]) if parent >= 0 else -1, col, jtype == "prismatic", A.copy(),
                                A @ K, A @ K2, C[:3, 3].copy(), A @ axis))
        self.frames = frames
        # A joint's local 4x4 is linear in (1, sin q, 1 - cos q, q): one (F, N, 4) @ (F, 4, 16)
        # matmul makes all of them (Rodrigues; a prismatic frame has zero sin/cos rows, a revolute
        # one a zero q row). Much cheaper than broadcasting over 3x3 blocks.
        self._cols = np.array([f.column for f in frames], dtype=np.int64)
        G = np.zeros((len(frames), 4, 4, 4))
        for k, f in enumerate(frames):
            G[k, 0, :3, :3], G[k, 0, :3, 3], G[k, 0, 3, 3] = f.A, f.t, 1.0
            if f.prismatic:
                G[k, 3, :3, 3] = f.Aaxis
            else:
                G[k, 1, :3, :3], G[k, 2, :3, :3] = f.AK, f.AK2
        self._G = G.reshape(len(frames), 4, 16)
        self._roots = np.array([k for k, f in enumerate(frames) if f.parent < 0], dtype=np.int64)
        self._chain = [(k, f.parent) for k, f in enumerate(frames) if f.parent >= 0]

    def __len__(self) -> int:
        return len(self.frames)

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, n) group configurations → rotations (N, F, 3, 3) and translations (N, F, 3).

        One matmul makes every joint's local transform, then one (N, 3, 4) @ (N, 4, 4) matmul per
        frame walks the tree: few numpy calls, so small batches stay cheap too."""
        N, F = len(q), len(self.frames)
        if F == 0:
            return np.empty((N, 0, 3, 3)), np.empty((N, 0, 3))
        v = q[:, self._cols].T  # (F, N)
        X = np.empty((F, N, 4))
        X[:, :, 0] = 1.0
        X[:, :, 1] = np.sin(v)
        X[:, :, 2] = 1.0 - np.cos(v)
        X[:, :, 3] = v
        local = np.matmul(X, self._G).reshape(F, N, 4, 4)
        W = np.empty((F, N, 3, 4))
        W[self._roots] = local[self._roots, :, :3, :]
        for k, p in self._chain:
            np.matmul(W[p], local[k], out=W[k])
        W = W.transpose(1, 0, 2, 3)
        return W[..., :3], W[..., 3]
