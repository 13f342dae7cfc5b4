"""Pictures of plans (matplotlib, no ROS): the scene with the robot along its path, and joint trajectories.

    plot_scene(...)   3-D view, top and side views: scene shapes, the robot as a stick figure (link origins
                      joined along the kinematic tree) at several instants, the TCP path(s), the
                      grasp target(s) with the hand's approach direction (the papers' Fig. 5)
    plot_joints(...)  joint positions and velocities over time (the papers' Fig. 6 / the DAGRRT paper's Fig. 7)
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.scene.types import SceneSnapshot, Shape

PATH_COLORS = ("tab:blue", "tab:orange")
BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))


def _mpl():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def shape_triangles(shape: Shape, T_object: np.ndarray, segments: int = 16) -> list[np.ndarray]:
    """World-frame polygons ((k, 3) arrays) that draw a shape."""
    T = T_object @ shape.pose

    def world(P):
        return P @ T[:3, :3].T + T[:3, 3]

    if shape.kind == "box":
        h = np.asarray(shape.dims) / 2
        C = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        W = world(C)
        return [W[list(f)] for f in BOX_FACES]
    if shape.kind == "mesh":
        W = world(np.asarray(shape.vertices, float))
        return [W[list(t)] for t in np.asarray(shape.triangles)]
    a = np.linspace(0, 2 * np.pi, segments + 1)
    if shape.kind == "sphere":
        r = shape.dims[0]
        polys = []
        for e0, e1 in zip(np.linspace(-np.pi / 2, np.pi / 2, segments // 2 + 1)[:-1],
                          np.linspace(-np.pi / 2, np.pi / 2, segments // 2 + 1)[1:]):
            for a0, a1 in zip(a[:-1], a[1:]):
                P = np.array([[np.cos(e) * np.cos(b), np.cos(e) * np.sin(b), np.sin(e)]
                              for e, b in ((e0, a0), (e0, a1), (e1, a1), (e1, a0))]) * r
                polys.append(world(P))
        return polys
    h, r = shape.dims  # cylinder / cone: height, radius along z
    top_r = r if shape.kind == "cylinder" else 0.0
    polys = []
    for a0, a1 in zip(a[:-1], a[1:]):
        P = np.array([[r * np.cos(a0), r * np.sin(a0), -h / 2], [r * np.cos(a1), r * np.sin(a1), -h / 2],
                      [top_r * np.cos(a1), top_r * np.sin(a1), h / 2], [top_r * np.cos(a0), top_r * np.sin(a0), h / 2]])
        polys.append(world(P))
    return polys


def robot_segments(robot: RobotModel, Q: np.ndarray) -> np.ndarray:
    """(K, J, 2, 3): for each configuration, a segment from each joint's parent link origin to its child's."""
    P = robot.link_poses(np.atleast_2d(Q))[:, :, :3, 3]
    index = {n: i for i, n in enumerate(robot.link_names)}
    pairs = [(index[j.parent], index[j.child]) for j in robot.joints.values()
             if j.parent in index and j.child in index]
    return np.stack([np.stack([P[:, a], P[:, b]], axis=1) for a, b in pairs], axis=1)


def _scene_extent(scene: SceneSnapshot, extra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = [extra.reshape(-1, 3)]
    for o in scene.objects:
        for s in o.shapes:
            pts += [p for p in shape_triangles(s, o.pose)]
    P = np.vstack(pts)
    return P.min(axis=0), P.max(axis=0)


def _clip_z(seg: np.ndarray, z_min: float) -> np.ndarray | None:
    """The part of a segment above z_min (None if nothing is)."""
    a, b = seg
    if a[2] < z_min and b[2] < z_min:
        return None
    if a[2] >= z_min and b[2] >= z_min:
        return seg
    lo, hi = (a, b) if a[2] < b[2] else (b, a)
    t = (z_min - lo[2]) / (hi[2] - lo[2])
    return np.array([lo + t * (hi - lo), hi])


def plot_scene(robot: RobotModel, scene: SceneSnapshot, Q: np.ndarray, tcp_paths: Sequence[np.ndarray],
               targets: Sequence[np.ndarray], approach: Sequence[np.ndarray], labels: Sequence[str], title: str,
               path: str | Path, highlight: str = "", snapshots: int = 5,
               retreat_paths: Sequence[np.ndarray] = ()) -> Path:
    """The scene, the robot at `snapshots` instants of Q (full configurations), TCP paths and grasp targets.
    retreat_paths: per target, the TCP path of the retreat after the grasp (dashed).

    Three panels: a 3-D view from the front left, a top view (x-y) and a side view (x-z); the robot
    below the scene's lowest point minus 0.3 m is cut off. approach: per target, the unit vector
    (world frame) along which the hand points into the object.
    """
    plt = _mpl()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    Q = np.atleast_2d(Q)
    picks = np.unique(np.linspace(0, len(Q) - 1, max(2, snapshots)).round().astype(int))
    segs = robot_segments(robot, Q[picks])
    tcp_paths = list(tcp_paths) + list(retreat_paths)  # (drawn below as their own lines)
    scene_lo, _ = _scene_extent(scene, np.vstack([p.reshape(-1, 3) for p in tcp_paths]))
    z_min = scene_lo[2] - 0.3
    clipped = [[c for c in (_clip_z(seg, z_min) for seg in segs[k]) if c is not None] for k in range(len(picks))]
    robot_pts = np.vstack([np.vstack(c) for c in clipped if c])
    lo, hi = _scene_extent(scene, np.vstack([robot_pts] + [p.reshape(-1, 3) for p in tcp_paths]))
    pad = 0.05
    lo, hi = lo - pad, hi + pad

    fig = plt.figure(figsize=(18, 6.2))
    grid = fig.add_gridspec(1, 3, width_ratios=(1.25, 1, 1), wspace=0.22)
    ax = fig.add_subplot(grid[0], projection="3d")
    top = fig.add_subplot(grid[1])
    side = fig.add_subplot(grid[2])
    views = ((top, 0, 1), (side, 0, 2))
    for o in scene.objects:
        is_target = o.id == highlight
        face = (0.2, 0.75, 0.3, 0.85) if is_target else (0.6, 0.65, 0.75, 0.35)
        for s in o.shapes:
            polys = shape_triangles(s, o.pose)
            ax.add_collection3d(Poly3DCollection(polys, facecolor=face, edgecolor=(0.3, 0.3, 0.35, 0.6),
                                                 linewidth=0.5))
            for view, i, j in views:  # projections: the faces, overlapping
                for poly in polys:
                    view.fill(poly[:, i], poly[:, j], color=face, ec=(0.3, 0.3, 0.35, 0.3), lw=0.3,
                              zorder=5 if is_target else 1)
    n = len(picks)
    for k in range(n):
        last = k == n - 1
        alpha = 0.25 + 0.75 * k / max(1, n - 1)
        color = (0.1, 0.1, 0.1, alpha) if last else (0.35, 0.35, 0.45, alpha * 0.8)
        lw = 3.0 if last else 1.5
        for seg in clipped[k]:
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=color, lw=lw, solid_capstyle="round")
            for view, i, j in views:
                view.plot(seg[:, i], seg[:, j], color=color, lw=lw * 0.8, zorder=3, solid_capstyle="round")
    for m, (tcp, T, d, label) in enumerate(zip(tcp_paths, targets, approach, labels)):
        c = PATH_COLORS[m % 2]
        p, q = T[:3, 3] - 0.1 * d, T[:3, 3]
        ax.plot(tcp[:, 0], tcp[:, 1], tcp[:, 2], color=c, lw=2.5, label=f"TCP path {label}")
        ax.scatter(*tcp[0], color=c, marker="o", s=30)
        ax.quiver(*p, *(q - p), color="red", lw=2, arrow_length_ratio=0.3)
        ax.scatter(*q, color="red", marker="x", s=50, label="grasp target (arrow: approach)" if m == 0 else None)
        for view, i, j in views:
            view.plot(tcp[:, i], tcp[:, j], color=c, lw=2.5, zorder=6, label=f"TCP path {label}")
            view.scatter(tcp[0, i], tcp[0, j], color=c, marker="o", s=25, zorder=7,
                         label="TCP at start" if m == 0 else None)
            view.annotate("", xy=(q[i], q[j]), xytext=(p[i], p[j]),
                          arrowprops=dict(arrowstyle="->", color="red", lw=2), zorder=8)
            view.scatter(q[i], q[j], color="red", marker="x", s=50, zorder=8,
                         label="grasp target (arrow: approach)" if m == 0 else None)
    for m, back in enumerate(retreat_paths):
        c = PATH_COLORS[m % 2]
        ax.plot(back[:, 0], back[:, 1], back[:, 2], color=c, lw=2.5, ls="--",
                label="retreat (object in hand)" if m == 0 else None)
        for view, i, j in views:
            view.plot(back[:, i], back[:, j], color=c, lw=2.5, ls="--", zorder=6,
                      label="retreat (object in hand)" if m == 0 else None)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo)
    ax.set_xlabel("x forward [m]")
    ax.set_ylabel("y left [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=28, azim=150)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"3-D view over the left shoulder (robot at {n} instants, darker = later)", fontsize=10)
    for view, i, j in views:
        view.set_aspect("equal")
        view.set_xlim(lo[i], hi[i])
        view.set_ylim(lo[j], hi[j])
        view.set_xlabel("x forward [m]")
        view.set_ylabel("y left [m]" if j == 1 else "z up [m]")
        view.grid(alpha=0.3)
    top.set_title("top view", fontsize=10)
    side.set_title("side view (from the right)", fontsize=10)
    side.legend(loc="lower right", fontsize=8, framealpha=0.9)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.02, right=0.98, top=0.88, bottom=0.1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_joints(times: np.ndarray, positions: np.ndarray, velocities: np.ndarray, joint_names: Sequence[str],
                title: str, path: str | Path, velocity_limits: np.ndarray | None = None) -> Path:
    """Joint positions and velocities over time, one line per joint. Joints are grouped by name prefix
    (`left_…`, `right_…`, `torso_…`): the first group solid, the others dashed, the k-th joint of each
    group in the same colour."""
    plt = _mpl()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    cmap = plt.get_cmap("tab10")
    prefixes = list(dict.fromkeys(n.split("_")[0] for n in joint_names))
    seen: dict[str, int] = {}
    for j, name in enumerate(joint_names):
        prefix = name.split("_")[0]
        style = "-" if prefix == prefixes[0] else "--"
        k = seen.get(prefix, 0)  # the k-th joint of each arm gets the same colour (solid / dashed)
        seen[prefix] = k + 1
        c = cmap(k % 10)
        ax1.plot(times, positions[:, j], style, color=c, lw=1.6, label=name)
        ax2.plot(times, velocities[:, j], style, color=c, lw=1.6)
    if velocity_limits is not None:
        limits = sorted({round(float(v), 6) for v in velocity_limits})
        for v in limits:
            ax2.axhline(v, color="k", lw=0.7, ls=":")
            ax2.axhline(-v, color="k", lw=0.7, ls=":")
        ax2.plot([], [], color="k", lw=0.7, ls=":", label="velocity limits (" + ", ".join(f"{v:g}" for v in limits)
                 + " rad/s)")
        ax2.legend(loc="lower right", fontsize=8)
    ax1.set_ylabel("position [rad]")
    ax2.set_ylabel("velocity [rad/s]")
    ax2.set_xlabel("time [s]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    ax1.legend(loc="center left", bbox_to_anchor=(1.01, 0.0), fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
