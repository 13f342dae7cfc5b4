"""Robot description: one loading path (URDF + SRDF) for presets and users' robots alike.

URDF gives the kinematic tree, limits and collision geometry; SRDF gives planning groups (any form →
its TCP by MoveIt's end-effector rule, `group_tcp`), end effectors, the home pose and the allowed-collision pairs — MoveIt's conventions, so any
robot set up for MoveIt works here unchanged.
"""
from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence
from urllib.parse import unquote

import numpy as np
from lxml import etree

from humanoid_planner.core.model.fk import JointInfo, KinematicTree, joint_motion

DEFAULT_VELOCITY = 1.0  # rad/s (m/s) when a URDF limit has none
DEFAULT_ACCELERATION = 2.0  # rad/s² (m/s²); URDF has no acceleration field
# a continuous joint's lower / upper: ±π (one turn) for sampling without a start; a motion from a start
# is bounded by the turn centred on the start value instead (RobotModel.motion_limits)
CONTINUOUS_RANGE = np.pi


JointLimits = Mapping[str, Mapping[str, object]] | tuple
"""joint -> {key: value} of joint_limits.yaml, or joint_limits_tuple's hashable form of it."""


def joint_limits_tuple(limits: JointLimits) -> tuple:
    """joint_limits as ((joint, ((key, value), ...)), ...), sorted: hashable (RobotModel.source is a cache
    key) and picklable (worker processes load the robot from it)."""
    items = limits.items() if isinstance(limits, Mapping) else limits
    return tuple(sorted((str(j), tuple(sorted((str(k), v) for k, v in (kv.items() if isinstance(kv, Mapping) else kv))))
                        for j, kv in items))


def check_joint_limits(limits: Mapping[str, Mapping[str, object]]
                       ) -> dict[str, tuple[float | None, float | None, tuple[float, float] | None]]:
    """joint_limits.yaml entries checked: joint -> (max velocity, max acceleration, (min, max) position),
    None where the entry's has_*_limits flag is not true. Other keys (jerk, effort, soft limits) have no
    use here and are left alone. A value that is not a finite number, a velocity or acceleration <= 0 or
    a min_position above its max_position is a RobotModelError naming the joint and the key."""
    out = {}
    for joint, spec in limits.items():
        def value(key: str) -> float:
            v = spec.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise RobotModelError(f"joint_limits of {joint}: {key} must be a finite number, got {v!r}")
            return float(v)

        got: list = []
        for flag, key in (("has_velocity_limits", "max_velocity"), ("has_acceleration_limits", "max_acceleration")):
            v = value(key) if spec.get(flag) is True else None
            if v is not None and v <= 0:
                raise RobotModelError(f"joint_limits of {joint}: {key}={v:g} must be > 0")
            got.append(v)
        pos = None
        if spec.get("has_position_limits") is True:
            pos = (value("min_position"), value("max_position"))
            if pos[0] > pos[1]:
                raise RobotModelError(f"joint_limits of {joint}: min_position {pos[0]:g} > max_position {pos[1]:g}")
        out[joint] = (got[0], got[1], pos)
    return out


class RobotModelError(ValueError):
    """The URDF/SRDF could not be loaded or is inconsistent."""


@dataclass(frozen=True)
class LinkGeometry:
    """One collision shape of a link (dims follow URDF: box sizes, sphere (r,), cylinder (r, length))."""

    kind: str
    dims: tuple[float, ...]
    origin: np.ndarray
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None


@dataclass(frozen=True)
class PlanningGroup:
    """An SRDF group resolved to its active joints; tip_link is the TCP (the link grasps are asked of,
    decided by `RobotModel.group_tcp`), tcp_source says by which rule; links is MoveIt's link set of the
    group, in the robot's link order."""

    name: str
    joint_names: tuple[str, ...]
    base_link: str
    tip_link: str
    links: tuple[str, ...] = ()
    tcp_source: str = ""


@dataclass(frozen=True)
class EndEffector:
    """An SRDF end effector: the hand attached at parent_link of parent_group."""

    name: str
    parent_link: str
    parent_group: str
    group: str


def _read_text(src: str | Path) -> tuple[str, Path | None]:
    """XML text and the folder it came from (None for inline text)."""
    if isinstance(src, Path) or "<robot" not in str(src):
        p = Path(src)
        if not p.is_file():
            raise RobotModelError(f"robot description file not found: {p}")
        return p.read_text(), p.resolve().parent
    return str(src), None


class MeshResolver:
    """Mesh URI → file, as a ROS robot resolves it (resource_retriever's rules):

    - `package://PKG/rel`: `<share of PKG>/rel`, PKG looked up in the ament index (`AMENT_PREFIX_PATH`,
      through `ament_index_python`); when the index has no PKG: `<dir>/PKG` for the first of
      `package_dirs` that holds it (folders of packages, as ROS 1's ROS_PACKAGE_PATH: robot files
      shipped without a ROS workspace), then, when the URDF is a file, a folder named PKG among the
      URDF's folder and its parents (a source checkout or an install tree that is not sourced);
    - `file:///abs/path` and absolute paths: as given;
    - relative paths: against the URDF's folder when the URDF is a file, else the working directory.

    A mesh that cannot be found raises RobotModelError naming the URI and where it was looked for.
    """

    def __init__(self, urdf_dir: Path | None, package_dirs: Sequence[str | Path] = ()):
        self.urdf_dir = urdf_dir
        self.package_dirs = tuple(Path(d) for d in package_dirs)

    def package_share(self, pkg: str) -> tuple[Path | None, str]:
        """(PKG's folder or None, how it was looked for)."""
        prefixes = os.environ.get("AMENT_PREFIX_PATH", "")
        how = f"package {pkg!r} is not in the ament index (AMENT_PREFIX_PATH={prefixes or 'unset'})"
        try:
            from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        except ImportError:  # no ROS 2 install / wheels: only the URDF's folders can hold the package
            how = f"ament_index_python is not installed, so package {pkg!r} cannot be looked up in the ament index"
        else:
            try:
                return Path(get_package_share_directory(pkg, print_warning=False)), ""
            except (PackageNotFoundError, ValueError, OSError):  # OSError: AMENT_PREFIX_PATH unset
                pass
        for d in self.package_dirs:
            if (d / pkg).is_dir():
                return d / pkg, ""
        if self.package_dirs:
            how += f" nor in the package folders {', '.join(str(d) for d in self.package_dirs)}"
        if self.urdf_dir is not None:
            for d in (self.urdf_dir, *self.urdf_dir.parents):
                if d.name == pkg:
                    return d, ""
            how += f" nor a folder above the URDF ({self.urdf_dir})"
        return None, how

    def __call__(self, uri: str) -> Path:
        if uri.startswith("package://"):
            pkg, _, rel = uri[len("package://"):].partition("/")
            share, why = self.package_share(pkg)
            if share is None:
                raise RobotModelError(f"mesh not found: {uri}: {why}")
            path = share / rel
            if not path.is_file():
                raise RobotModelError(f"mesh not found: {uri}: no file {path} (package {pkg!r} is at {share})")
            return path
        if uri.startswith("file://"):
            path = Path(unquote(uri[len("file://"):]))
        else:
            path = Path(uri)
            if not path.is_absolute():
                path = (self.urdf_dir or Path.cwd()) / path
        if not path.is_file():
            raise RobotModelError(f"mesh not found: {uri}: no file {path}")
        return path


def _load_mesh(path: Path, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    m = trimesh.load(str(path), force="mesh", process=False)
    if isinstance(m, trimesh.Scene):  # pragma: no cover - force="mesh" normally concatenates
        m = m.dump(concatenate=True)
    v = np.asarray(m.vertices, dtype=float) * scale
    f = np.asarray(m.faces, dtype=np.int64)
    if len(f) == 0:
        raise RobotModelError(f"mesh has no triangles: {path}")
    return v, f


class RobotModel:
    """Kinematic tree, limits, groups and collision geometry of one robot (see docs/ROBOT_MODEL_API.md)."""

    def __init__(self) -> None:  # use from_urdf_srdf / preset
        self.name = ""
        self.source: tuple = ("", None, (), ())  # from_urdf_srdf's arguments (urdf, srdf, package_dirs, joint_limits)
        self.root_link = ""
        self.link_names: tuple[str, ...] = ()
        self.joint_names: tuple[str, ...] = ()
        self.joints: dict[str, JointInfo] = {}
        self.lower = self.upper = self.max_velocity = self.max_acceleration = self.home = np.zeros(0)
        self.continuous = np.zeros(0, dtype=bool)  # (dof,): URDF continuous joints (unbounded, angles wrap)
        self.groups: dict[str, PlanningGroup] = {}
        self.end_effectors: dict[str, EndEffector] = {}
        self.skipped_groups: dict[str, str] = {}  # SRDF groups that name what the URDF lacks -> why
        self.ignored_joint_limits: tuple[str, ...] = ()  # joint_limits entries of joints this URDF does not move
        self.virtual_frames: tuple[str, ...] = ()  # SRDF virtual joints' parent frames (e.g. world) over the root
        self.group_states: dict[str, dict[str, float]] = {}  # SRDF <group_state>s merged by name
        self.ignored_state_values: tuple[str, ...] = ()  # "state: joint='value'" not a finite number: left out
        self.disabled_collision_pairs: frozenset[frozenset[str]] = frozenset()
        self.adjacent_link_pairs: frozenset[frozenset[str]] = frozenset()
        self.collision_geometry: dict[str, tuple[LinkGeometry, ...]] = {}
        self._parent_joint: dict[str, JointInfo] = {}
        self._children: dict[str, list[JointInfo]] = {}
        self._tree: KinematicTree | None = None  # all joints free: link_poses

    # ------------------------------------------------------------------ loading
    @classmethod
    def preset(cls, name: str, joint_limits: JointLimits = ()) -> "RobotModel":
        """A built-in robot from config/robots/ ('armar3', 'dual_arm', 'maru1')."""
        from humanoid_planner.core.model.presets import preset_paths

        urdf, srdf = preset_paths(name)
        return cls.from_urdf_srdf(urdf, srdf, joint_limits=joint_limits)

    @classmethod
    def from_urdf_srdf(cls, urdf: str | Path, srdf: str | Path | None = None,
                       package_dirs: Sequence[str | Path] = (), joint_limits: JointLimits = ()) -> "RobotModel":
        """Load from URDF (+ optional SRDF): XML text or file paths. Mesh URIs resolve as on a ROS
        robot (MeshResolver; `package_dirs`: folders of packages tried after the ament index); a mesh
        that cannot be found is a RobotModelError naming its URI. joint_limits: a MoveIt configuration's
        joint_limits.yaml entries (joint -> {has_velocity_limits, max_velocity, ...}; apply_joint_limits)."""
        import yourdfpy

        urdf_text, urdf_dir = _read_text(urdf)
        try:
            u = yourdfpy.URDF.load(io.BytesIO(urdf_text.encode()), build_scene_graph=False,
                                   build_collision_scene_graph=False, load_meshes=False,
                                   load_collision_meshes=False)
        except KeyError as e:  # an element without an attribute the URDF spec requires
            raise RobotModelError(f"invalid URDF: a required attribute is missing: {e}") from e
        except Exception as e:  # yourdfpy raises many kinds
            raise RobotModelError(f"invalid URDF: {e}") from e
        accel = cls._acceleration_attrs(urdf_text)
        self = cls()
        self.name = u.robot.name
        # how to load this robot again (e.g. in a worker process): the arguments as given
        limits = joint_limits_tuple(joint_limits)
        self.source = (str(urdf) if isinstance(urdf, Path) else urdf, str(srdf) if isinstance(srdf, Path) else srdf,
                       tuple(str(d) for d in package_dirs), limits)
        self._build_tree(u, accel)
        self.ignored_joint_limits = self._apply_joint_limits(dict((j, dict(kv)) for j, kv in limits))
        self._load_geometry(u, MeshResolver(urdf_dir, package_dirs))
        self.home = np.clip(np.zeros(len(self.joint_names)), self.lower, self.upper)
        if srdf is not None:
            srdf_text, _ = _read_text(srdf)
            self._apply_srdf(srdf_text)
        return self

    def _apply_joint_limits(self, limits: Mapping[str, Mapping[str, object]]) -> tuple[str, ...]:
        """MoveIt's joint_limits.yaml over the URDF's limits, as MoveIt reads it: a joint's max_velocity,
        max_acceleration and min_position / max_position replace the URDF's where their has_*_limits flag
        is true (URDF has no acceleration at all: there DEFAULT_ACCELERATION stands in; a continuous
        joint keeps its turn). Returns the joints named that are not active joints of this URDF (a MoveIt
        configuration lists its grippers' joints, fixed or mimic ones here): left out, not an error."""
        index = {n: i for i, n in enumerate(self.joint_names)}
        ignored = []
        for joint, (vel, acc, pos) in check_joint_limits(limits).items():
            i = index.get(joint)
            if i is None:
                ignored.append(joint)
                continue
            if vel is not None:
                self.max_velocity[i] = vel
            if acc is not None:
                self.max_acceleration[i] = acc
            if pos is not None and not self.continuous[i]:
                self.lower[i], self.upper[i] = pos
        return tuple(ignored)

    @staticmethod
    def _acceleration_attrs(urdf_text: str) -> dict[str, float]:
        """Non-standard <limit acceleration="..."> values, which some robot descriptions carry."""
        out = {}
        try:
            root = etree.fromstring(urdf_text.encode())
        except etree.XMLSyntaxError as e:
            raise RobotModelError(f"invalid URDF XML: {e}") from e
        for j in root.iter("joint"):
            lim = j.find("limit")
            if lim is not None and lim.get("acceleration"):
                out[j.get("name")] = float(lim.get("acceleration"))
        return out

    def _build_tree(self, u, accel: dict[str, float]) -> None:
        children = {j.child for j in u.robot.joints}
        roots = [l.name for l in u.robot.links if l.name not in children]
        if len(roots) != 1:
            raise RobotModelError(f"URDF must have exactly one root link, found {roots}")
        self.root_link = roots[0]
        by_parent: dict[str, list] = {}
        for j in u.robot.joints:
            by_parent.setdefault(j.parent, []).append(j)
        # Active joints in URDF order (the configuration vector order users see in joint_states).
        active = [j for j in u.robot.joints if j.type in ("revolute", "continuous", "prismatic") and j.mimic is None]
        self.joint_names = tuple(j.name for j in active)
        index = {n: i for i, n in enumerate(self.joint_names)}
        lo, hi, vel, acc = [], [], [], []
        for j in active:
            lim = j.limit
            if j.type == "continuous":
                lo.append(-CONTINUOUS_RANGE)
                hi.append(CONTINUOUS_RANGE)
            else:
                if lim is None:
                    raise RobotModelError(f"joint {j.name}: a {j.type} joint needs a <limit> element (URDF spec)")
                # urdfdom reads a missing lower / upper as 0 (Centauro's wheels: "actually continuous" revolute
                # joints with only effort and velocity): such a joint stays at 0, as under ROS
                lo.append(float(lim.lower) if lim.lower is not None else 0.0)
                hi.append(float(lim.upper) if lim.upper is not None else 0.0)
                if not (math.isfinite(lo[-1]) and math.isfinite(hi[-1])):
                    raise RobotModelError(f"joint {j.name}: limit lower={lo[-1]} upper={hi[-1]} must be finite "
                                          "(an unbounded revolute joint is a continuous one)")
            v = float(lim.velocity) if lim is not None and lim.velocity else 0.0
            vel.append(v if v > 0 else DEFAULT_VELOCITY)
            acc.append(accel.get(j.name, DEFAULT_ACCELERATION))
        self.lower, self.upper = np.array(lo), np.array(hi)
        self.continuous = np.array([j.type == "continuous" for j in active], dtype=bool)
        if np.any(self.lower > self.upper):
            raise RobotModelError("a joint has lower limit > upper limit")
        self.max_velocity, self.max_acceleration = np.array(vel), np.array(acc)
        # Breadth-first over the tree: parents before children.
        order, queue = [], [self.root_link]
        mimic_home: dict[str, tuple[str, float, float]] = {}
        while queue:
            link = queue.pop(0)
            order.append(link)
            for j in by_parent.get(link, []):
                origin = np.array(j.origin, dtype=float) if j.origin is not None else np.eye(4)
                axis = np.array(j.axis if j.axis is not None else [1.0, 0.0, 0.0], dtype=float)
                if not (np.all(np.isfinite(origin)) and np.all(np.isfinite(axis))):
                    raise RobotModelError(f"joint {j.name}: its origin or axis is not finite")
                n = np.linalg.norm(axis)
                axis = axis / n if n > 0 else np.array([1.0, 0.0, 0.0])
                jtype = j.type if j.type in ("revolute", "continuous", "prismatic") else "fixed"
                if j.mimic is not None:
                    mimic_home[j.name] = (j.mimic.joint, float(j.mimic.multiplier or 1.0), float(j.mimic.offset or 0.0))
                    jtype = "fixed"
                    origin = origin @ joint_motion(j.type, axis, float(j.mimic.offset or 0.0))
                info = JointInfo(j.name, jtype, j.parent, j.child, origin, axis, index.get(j.name, -1) if jtype != "fixed" else -1)
                self.joints[j.name] = info
                self._parent_joint[j.child] = info
                self._children.setdefault(link, []).append(info)
                queue.append(j.child)
        self.link_names = tuple(order)
        self._link_index = {n: i for i, n in enumerate(order)}
        self.adjacent_link_pairs = frozenset(frozenset((j.parent, j.child)) for j in self.joints.values())

    def _load_geometry(self, u, resolve: MeshResolver) -> None:
        geo: dict[str, tuple[LinkGeometry, ...]] = {}
        for link in u.robot.links:
            shapes = []
            for c in link.collisions:
                origin = np.array(c.origin, dtype=float) if c.origin is not None else np.eye(4)
                g = c.geometry
                if not np.all(np.isfinite(origin)):
                    raise RobotModelError(f"link {link.name}: a collision origin is not finite")
                if g.box is not None:
                    dims = _dims(link.name, "box size", g.box.size, None)
                    if len(dims) != 3 or min(dims) <= 0:
                        raise RobotModelError(f"link {link.name}: bad box size {dims}")
                    shapes.append(LinkGeometry("box", dims, origin))
                elif g.sphere is not None:
                    shapes.append(LinkGeometry("sphere", _dims(link.name, "sphere radius", (g.sphere.radius,)), origin))
                elif g.cylinder is not None:
                    dims = _dims(link.name, "cylinder radius and length", (g.cylinder.radius, g.cylinder.length))
                    shapes.append(LinkGeometry("cylinder", dims, origin))
                elif g.mesh is not None:
                    scale = np.ones(3) if g.mesh.scale is None else np.broadcast_to(
                        np.asarray(_dims(link.name, "mesh scale", np.ravel(g.mesh.scale), None), float), (3,))
                    path = resolve(g.mesh.filename)
                    try:
                        v, f = _load_mesh(path, scale)
                    except Exception as e:  # trimesh raises many kinds on unreadable files
                        raise RobotModelError(f"cannot load mesh {g.mesh.filename} ({path}): {e}") from e
                    shapes.append(LinkGeometry("mesh", (), origin, v, f))
            if shapes:
                geo[link.name] = tuple(shapes)
        self.collision_geometry = geo

    def _apply_srdf(self, text: str) -> None:
        try:
            root = etree.fromstring(text.encode())
        except etree.XMLSyntaxError as e:
            raise RobotModelError(f"invalid SRDF XML: {e}") from e
        # MoveIt's model frame: the parent of a virtual joint into the URDF root (`world`), which coincides
        # with the root until something moves the joint (a fixed one never; a floating or planar one by
        # multi-DOF joint states, which this planner does not take: the base stays where the root is)
        self.virtual_frames = tuple(dict.fromkeys(
            vj.get("parent_frame") for vj in root.findall("virtual_joint")
            if vj.get("child_link") == self.root_link and vj.get("parent_frame")
            and vj.get("parent_frame") not in self.link_names))
        # end effectors first: they decide the TCP of the groups they are attached to
        for ee in root.findall("end_effector"):
            self.end_effectors[ee.get("name")] = EndEffector(
                ee.get("name"), ee.get("parent_link", ""), ee.get("parent_group", ""), ee.get("group", ""))
        elems = {g.get("name"): g for g in root.findall("group") if g.get("name")}
        resolved: dict[str, PlanningGroup] = {}

        def resolve(name: str, stack: tuple[str, ...] = ()) -> PlanningGroup:
            if name in resolved:
                return resolved[name]
            if name not in elems or name in stack:
                raise RobotModelError(f"SRDF group {name!r} is undefined or recursive")
            joints: list[str] = []
            links: list[str] = []  # MoveIt's link set of the group: the child link of each of its joints
            base = ""
            for child in elems[name]:
                if child.tag == "chain":
                    b, t = child.get("base_link"), child.get("tip_link")
                    for lk in (b, t):
                        if lk not in self._link_index:
                            raise RobotModelError(f"SRDF group {name}: unknown link {lk}")
                    path = self.chain_joints(b, t)
                    joints += [j.name for j in path if j.index >= 0]
                    links += [j.child for j in path]
                    base = base or b
                elif child.tag == "joint":
                    jn = child.get("name")
                    if jn not in self.joints:
                        raise RobotModelError(f"SRDF group {name}: unknown joint {jn}")
                    if self.joints[jn].index >= 0:
                        joints.append(jn)
                    links.append(self.joints[jn].child)
                    base = base or self.joints[jn].parent
                elif child.tag == "link":
                    ln = child.get("name")
                    if ln not in self._link_index:
                        raise RobotModelError(f"SRDF group {name}: unknown link {ln}")
                    links.append(ln)
                    pj = self._parent_joint.get(ln)
                    if pj is not None and pj.index >= 0:  # as in MoveIt, a listed link brings its joint
                        joints.append(pj.name)
                elif child.tag == "group":
                    sub = resolve(child.get("name"), stack + (name,))
                    joints += list(sub.joint_names)
                    # a subgroup's TCP counts as one of the group's links: arm + torso keeps the arm's hand
                    links += list(sub.links) + ([sub.tip_link] if sub.tip_link else [])
                    base = base or sub.base_link
                    if sub.base_link and base in self.subtree_links(sub.base_link) and base != sub.base_link:
                        base = sub.base_link
            joint_names = tuple(dict.fromkeys(joints))
            group_links = tuple(sorted(set(links), key=self._link_index.__getitem__))
            tcp, source = self.group_tcp(name, joint_names, group_links)
            g = PlanningGroup(name, joint_names, base, tcp, group_links, source)
            resolved[name] = g
            return g

        # as MoveIt's srdfdom does, a group naming what the URDF lacks (an SRDF written for a fuller model
        # of the robot: TALOS, iCub reduced, PR2, Baxter) is skipped, not fatal; group() says why it is missing
        for name in elems:
            try:
                resolve(name)
            except RobotModelError as e:
                self.skipped_groups[name] = str(e)
        self.groups = resolved
        ignored = []
        for gs in root.findall("group_state"):
            values = self.group_states.setdefault(gs.get("name"), {})
            for j in gs.findall("joint"):
                if j.get("name") in self.joints and j.get("value"):
                    words = j.get("value").split()
                    value = _finite(words[0]) if words else None
                    if value is None:  # as srdfdom: the value is left out with a warning, the SRDF loads
                        ignored.append(f"{gs.get('name')}: {j.get('name')}={j.get('value')!r}")
                    else:
                        values[j.get("name")] = value
        self.ignored_state_values = tuple(ignored)
        if "home" in self.group_states:
            self.home = self.state("home")
        self.disabled_collision_pairs = _allowed_collisions(root, self.link_names)

    def group_tcp(self, group: str, joint_names: Sequence[str], links: Sequence[str]) -> tuple[str, str]:
        """(TCP link, the rule that chose it) of a group with these active joints and MoveIt link set; the
        one rule for chains, joint lists, link lists and subgroups alike, MoveIt's end-effector convention:

        1. the parent_link of an end effector whose parent_group is the group;
        2. else the parent_link of an end effector without parent_group whose parent_link is a group link;
        3. else the group's last link: the deepest of its links (a chain's tip, the child link of a joint
           list's last joint, the TCP of its deepest subgroup).

        A candidate must lie below every joint of the group (FK and the Jacobian run from the root to the
        TCP), which rules out end effectors that name a link elsewhere; the first fitting end effector in
        SRDF order wins. A group whose joints lie on several branches (both arms) has no TCP ("").
        """
        below = [l for l in links if self._below_all(l, joint_names)]
        for ee in self.end_effectors.values():
            if ee.parent_group == group and ee.parent_link in self._link_index \
                    and self._below_all(ee.parent_link, joint_names):
                return ee.parent_link, f"end effector {ee.name!r} (its parent_group)"
        for ee in self.end_effectors.values():
            if not ee.parent_group and ee.parent_link in below:
                return ee.parent_link, f"end effector {ee.name!r} (its parent_link is a group link)"
        if below:
            depth = {l: len(self.ancestors(l)) for l in below}
            return max(below, key=lambda l: (depth[l], self._link_index[l])), "the group's last link"
        return "", "its joints lie on several branches" if links else "it has no links"

    def _below_all(self, link: str, joint_names: Iterable[str]) -> bool:
        """Does every one of these joints lie on the tree path from the root to `link`?"""
        above: set[str] = set()
        while link in self._parent_joint:
            j = self._parent_joint[link]
            above.add(j.name)
            link = j.parent
        return set(joint_names) <= above

    # ------------------------------------------------------------------ queries
    def state(self, name: str) -> np.ndarray:
        """Full configuration of an SRDF group state (joints it does not name keep their home value)."""
        if name not in self.group_states:
            raise KeyError(f"no SRDF group_state {name!r}; known: {sorted(self.group_states)}")
        q = self.home.copy()
        idx = {n: i for i, n in enumerate(self.joint_names)}
        for joint, value in self.group_states[name].items():
            if joint in idx:
                q[idx[joint]] = value
        return self.clip(q)

    def clip(self, q: np.ndarray) -> np.ndarray:
        """Configurations (..., dof) clipped to the joint limits; continuous joints keep their values (they
        have no limits: clipping one would move it, as FK is periodic in it)."""
        q = np.asarray(q, dtype=float)
        return np.where(self.continuous, q, np.clip(q, self.lower, self.upper))

    def motion_limits(self, idx: np.ndarray, q_start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of joints `idx` for a motion that starts at q_start (their values): the URDF limits;
        for a continuous joint the turn centred on its start value, [q - π, q + π]. A continuous joint is
        unbounded (MoveIt: angles wrap); planning in this window keeps the trajectory's first point equal to
        the start as given (a controller expects the value it reports, not that value wrapped), reaches every
        angle by its shortest rotation, and samples each angle once."""
        idx = np.asarray(idx, dtype=np.int64)
        q = np.asarray(q_start, dtype=float)
        c = self.continuous[idx]
        return (np.where(c, q - CONTINUOUS_RANGE, self.lower[idx]),
                np.where(c, q + CONTINUOUS_RANGE, self.upper[idx]))

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def group(self, name: str) -> PlanningGroup:
        try:
            return self.groups[name]
        except KeyError:
            if name in self.skipped_groups:
                raise KeyError(f"planning group {name!r} of the SRDF cannot be used: "
                               f"{self.skipped_groups[name]}") from None
            raise KeyError(f"unknown planning group {name!r}; known: {sorted(self.groups)}") from None

    def group_joint_indices(self, group: str) -> np.ndarray:
        idx = {n: i for i, n in enumerate(self.joint_names)}
        return np.array([idx[j] for j in self.group(group).joint_names], dtype=np.int64)

    def expand(self, group: str, q_group: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
        """Group configurations written into copies of a full reference configuration."""
        q_group = np.asarray(q_group, dtype=float)
        idx = self.group_joint_indices(group)
        if q_group.ndim == 1:
            out = np.array(q_ref, dtype=float, copy=True)
            out[idx] = q_group
            return out
        out = np.repeat(np.asarray(q_ref, dtype=float)[None, :], len(q_group), axis=0)
        out[:, idx] = q_group
        return out

    def chain_joints(self, base_link: str, tip_link: str) -> list[JointInfo]:
        """Joints from base_link down to tip_link (tip must be a descendant of base)."""
        out: list[JointInfo] = []
        link = tip_link
        while link != base_link:
            j = self._parent_joint.get(link)
            if j is None:
                raise RobotModelError(f"{tip_link} is not below {base_link}")
            out.append(j)
            link = j.parent
        return out[::-1]

    def parent_joint(self, link: str) -> JointInfo | None:
        """The joint whose child is `link` (None for the root)."""
        return self._parent_joint.get(link)

    def child_joints(self, link: str) -> tuple[JointInfo, ...]:
        """The joints whose parent is `link`, in URDF order."""
        return tuple(self._children.get(link, ()))

    def ancestors(self, link: str) -> set[str]:
        """Every link above `link` up to the root."""
        out = set()
        while link in self._parent_joint:
            link = self._parent_joint[link].parent
            out.add(link)
        return out

    def subtree_links(self, link: str) -> tuple[str, ...]:
        out, stack = [], [link]
        while stack:
            l = stack.pop()
            out.append(l)
            stack.extend(j.child for j in self._children.get(l, []))
        return tuple(out)

    def moving_links(self, group: str) -> tuple[str, ...]:
        moving: set[str] = set()
        for jn in self.group(group).joint_names:
            moving.update(self.subtree_links(self.joints[jn].child))
        return tuple(l for l in self.link_names if l in moving)

    def hand_usable_by(self, hand: str, group: str) -> bool:
        """May a grasp meant for `hand` be executed by planning group `group`? The one rule for every
        hand filter (request checks and the planner's grasp targets).

        `hand` is "" (any hand), the group itself, an SRDF end effector, or a group. An end effector
        wins over a group of the same name: MoveIt setups usually name a hand's link group and its end
        effector alike (Panda's "hand"), and that link group has no chain, so matching it as a group
        would refuse every grasp. An end effector fits when its parent group has the group's TCP, or
        it is attached at the TCP or to the group's hand links; a group fits when its TCP is the same.
        """
        if hand in ("", group):
            return True
        tip = self.group(group).tip_link
        ee = self.end_effectors.get(hand)
        if ee is not None:
            parent = self.groups.get(ee.parent_group)
            if parent is not None and parent.tip_link == tip:
                return True
            return ee.parent_link == tip or ee.parent_link in self.hand_links(group)
        g = self.groups.get(hand)
        return g is not None and bool(g.tip_link) and g.tip_link == tip

    def hand_links(self, group: str) -> tuple[str, ...]:
        """Links of the hand of a group: the subtree below the group joint nearest to its TCP.

        Found along the tree path from the TCP up, not as "the last joint listed": groups such as
        TALOS's r_arm_torso list the arm before the torso.
        """
        g = self.group(group)
        own = set(g.joint_names)
        link = g.tip_link
        while link in self._parent_joint:
            j = self._parent_joint[link]
            if j.name in own:
                return self.subtree_links(j.child)
            link = j.parent
        return ()

    def kinematic_tree(self, joint_index: Sequence[int] | np.ndarray, q_ref: np.ndarray | None = None,
                       needed: Iterable[str] | None = None) -> KinematicTree:
        """The FK engine compiled for these free joints (full-configuration indices, in the caller's
        column order), the others held at q_ref (default: home), computing only what `needed` links
        hang from (default: every link)."""
        q_ref = self.home if q_ref is None else np.asarray(q_ref, dtype=float)
        return KinematicTree(self.root_link, [self._parent_joint[link] for link in self.link_names[1:]],
                             joint_index, q_ref, needed)

    def link_poses(self, q_full: np.ndarray, links: Sequence[str] | None = None) -> np.ndarray:
        """Root-frame poses of links for (N, dof) or (dof,) configurations (all links by default)."""
        q = np.asarray(q_full, dtype=float)
        if q.shape[-1:] != (self.dof,) or q.ndim > 2:
            raise ValueError(f"expected {self.dof} joint values, got shape {q.shape}")
        if self._tree is None:  # compiled once; immutable, so threads may share it (a race builds two equal ones)
            self._tree = self.kinematic_tree(np.arange(self.dof))
        return self._tree.link_poses(q, self.link_names if links is None else links)


def _dims(link: str, what: str, values, least: float | None = 0.0) -> tuple[float, ...]:
    """A shape's numbers as URDF gives them; RobotModelError naming the link unless all are finite and (least
    given) at least `least`: a sphere or cylinder of size 0 is a point, harmless; a mesh scale may be
    negative (a mirrored mesh)."""
    dims = tuple(float(x) for x in values)
    if not dims or not all(math.isfinite(d) and (least is None or d >= least) for d in dims):
        bound = "" if least is None else f" and at least {least:g}"
        raise RobotModelError(f"link {link}: {what} {dims} must be finite{bound}")
    return dims


def _finite(text: str) -> float | None:
    """A number an SRDF gives as text; None when it is not a finite number."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _pair(a: str | None, b: str | None) -> frozenset[str] | None:
    return frozenset((a, b)) if a and b else None


def _allowed_collisions(root, link_names: Sequence[str]) -> frozenset[frozenset[str]]:
    """The link pairs the SRDF lets touch, as MoveIt's allowed collision matrix reads them (srdfdom 2):
    `disable_collisions` pairs; every pair of a `disable_default_collisions` link, but for the pairs of
    `enable_collisions` (an explicit entry wins over a default one, and a disabled pair over an enabled one)."""
    disabled = {p for d in root.findall("disable_collisions") if (p := _pair(d.get("link1"), d.get("link2")))}
    enabled = {p for e in root.findall("enable_collisions") if (p := _pair(e.get("link1"), e.get("link2")))}
    for d in root.findall("disable_default_collisions"):
        link = d.get("link")
        if link in link_names:
            disabled.update(p for other in link_names if other != link
                            and (p := frozenset((link, other))) not in enabled)
    return frozenset(disabled)
