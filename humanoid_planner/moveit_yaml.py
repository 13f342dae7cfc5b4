"""MoveIt's own YAML files in core terms: a PlanningScene (`moveit_msgs/PlanningScene` as a dict) becomes a
`PlanningScene` of collision objects, a MotionPlanRequest with a joint goal becomes a `StatePlanRequest`.

    scene = planning_scene(yaml.safe_load(open("scene.yaml")), robot)     # -> PlanningScene (.snapshot())
    loaded = motion_plan_request(yaml.safe_load(open("request.yaml")), robot)
    plan = GraspPlanner(robot).plan_to_state(scene.snapshot(), loaded.request)

For scenes and requests saved from MoveIt (or by tools that write its messages), e.g. the public
MotionBenchMaker problem sets (benchmarks/bench_mbm.py); no ROS needed. Both spellings of a message in YAML
are read: vectors and quaternions as lists (`[x, y, z]`, `[x, y, z, w]`) or as maps (`{x:, y:, z:, w:}`),
primitive types as names (`box`) or as SolidPrimitive constants (`1`).

What is read: `world.collision_objects` (id, `header.frame_id`, optional object `pose`, primitives with
`primitive_poses`, meshes with `mesh_poses`; operation ADD, the default); `fixed_frame_transforms` (frames
objects may name); `robot_state.joint_state` (the configuration at which frames that name robot links are
placed); a request's `group_name`, `start_state.joint_state`, `goal_constraints` (one set of joint
constraints, their positions; tolerances are not used: the planner reaches the goal exactly) and
`allowed_planning_time`. What the core cannot represent is refused with MoveItYamlError naming the field
(planes, octomaps, attached objects, a moved virtual joint, position / orientation goals, alternatives
of goals), never dropped silently. The scene's allowed collision matrix is not read: the robot's SRDF says
which of its links may touch. Joint values are kept as given (no clipping, no wrapping): the planner's
request checks decide what is outside the limits.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.plans import StatePlanRequest
from humanoid_planner.core.scene.planning_scene import PlanningScene, SceneUpdateError
from humanoid_planner.core.scene.types import Shape
from humanoid_planner.core.transforms import InvalidQuaternion, checked_unit_quaternion, pose_to_matrix

PRIMITIVE_TYPES = {1: "box", 2: "sphere", 3: "cylinder", 4: "cone"}
"""shape_msgs/SolidPrimitive's type constants."""
ADD = 0
"""moveit_msgs/CollisionObject.ADD, also what an omitted `operation` means."""


class MoveItYamlError(ValueError):
    """A YAML document that is not a MoveIt message this loader reads; the message names the field."""


# ------------------------------------------------------------------------------------------ values
def _field(d: Any, key: str, what: str, default: Any = None, required: bool = False) -> Any:
    if not isinstance(d, Mapping):
        raise MoveItYamlError(f"{what}: expected a map, got {type(d).__name__}")
    if key not in d or d[key] is None:
        if required:
            raise MoveItYamlError(f"{what}: no field {key!r}")
        return default
    return d[key]


def numbers(v: Any, what: str, n: int | None = None) -> np.ndarray:
    """A list of finite numbers (of length n when given)."""
    if not isinstance(v, Sequence) or isinstance(v, str) or (n is not None and len(v) != n):
        raise MoveItYamlError(f"{what}: expected {n if n is not None else 'a list of'} numbers, got {v!r}")
    try:
        out = np.array([float(x) for x in v])
    except (TypeError, ValueError):
        raise MoveItYamlError(f"{what}: expected numbers, got {v!r}") from None
    if not np.all(np.isfinite(out)):
        raise MoveItYamlError(f"{what}: NaN or inf in {v!r}")
    return out


def number(v: Any, what: str) -> float:
    return float(numbers([v], what)[0])


def vector(v: Any, keys: str, what: str) -> np.ndarray:
    """A vector given as a list or as a map of the `keys` (e.g. "xyz", "xyzw"): finite floats."""
    if isinstance(v, Mapping):
        missing = [k for k in keys if k not in v]
        if missing:
            raise MoveItYamlError(f"{what}: no {', '.join(missing)} in {dict(v)}")
        v = [v[k] for k in keys]
    return numbers(v, f"{what} ({', '.join(keys)})", len(keys))


def _quaternion(q: Any, what: str) -> np.ndarray:
    try:
        return checked_unit_quaternion(vector(q, "xyzw", what))
    except InvalidQuaternion as e:
        raise MoveItYamlError(f"{what}: {e}") from None


def _rigid(m: Any, what: str, shift: str, turn: str) -> np.ndarray:
    """A map {shift: xyz, turn: xyzw} → 4x4 (a missing part is the identity's, as in a message)."""
    if not isinstance(m, Mapping):
        raise MoveItYamlError(f"{what}: expected a map with {shift} and {turn}, got {m!r}")
    pos = vector(m[shift], "xyz", f"{what}.{shift}") if m.get(shift) is not None else np.zeros(3)
    q = _quaternion(m[turn], f"{what}.{turn}") if m.get(turn) is not None else [0, 0, 0, 1]
    return pose_to_matrix(pos, q)


def pose(p: Any, what: str) -> np.ndarray:
    """geometry_msgs/Pose {position, orientation} → 4x4."""
    return _rigid(p, what, "position", "orientation")


def transform(t: Any, what: str) -> np.ndarray:
    """geometry_msgs/Transform {translation, rotation} → 4x4."""
    return _rigid(t, what, "translation", "rotation")


# ------------------------------------------------------------------------------------------ robot state
@dataclass(frozen=True)
class JointValues:
    """A joint_state read against a robot: the full configuration, and the names it gave that are not among the
    robot's active joints (joints the URDF has fixed or as mimics, or unknown), which were not used."""

    q: np.ndarray  # (dof,), RobotModel.joint_names order; joints not named keep the base configuration
    ignored: tuple[str, ...] = ()


def joint_values(robot_state: Any, robot: RobotModel, base: np.ndarray | None = None,
                 what: str = "robot_state") -> JointValues:
    """moveit_msgs/RobotState's joint_state over `base` (default: robot.home). A multi_dof_joint_state is accepted
    only when it leaves the robot where it is (identity transforms): the core has no floating base."""
    q = np.array(robot.home if base is None else base, dtype=float, copy=True)
    if robot_state is None:
        return JointValues(q)
    js = _field(robot_state, "joint_state", what, {}) or {}
    names = list(_field(js, "name", f"{what}.joint_state", []) or [])
    positions = list(_field(js, "position", f"{what}.joint_state", []) or [])
    if len(names) != len(positions):
        raise MoveItYamlError(f"{what}.joint_state: {len(names)} names but {len(positions)} positions")
    index = {n: i for i, n in enumerate(robot.joint_names)}
    ignored = []
    for k, (name, value) in enumerate(zip(names, positions)):
        v = number(value, f"{what}.joint_state.position[{k}] ({name})")
        if name in index:
            q[index[name]] = v
        else:
            ignored.append(str(name))
    multi = _field(robot_state, "multi_dof_joint_state", what, {}) or {}
    for k, t in enumerate(_field(multi, "transforms", f"{what}.multi_dof_joint_state", []) or []):
        T = transform(t, f"{what}.multi_dof_joint_state.transforms[{k}]")
        if not np.allclose(T, np.eye(4), atol=1e-9):
            joint = (multi.get("joint_names") or ["?"] * (k + 1))[k]
            raise MoveItYamlError(f"{what}.multi_dof_joint_state: joint {joint!r} moves the robot's base "
                                  f"({np.round(T[:3, 3], 4).tolist()}); only a base at the planning frame's origin "
                                  "is supported")
    return JointValues(q, tuple(ignored))


# ------------------------------------------------------------------------------------------ scene
class SceneFrames:
    """Frame name → its pose in the planning frame (the robot's root link): "" and the root itself, the scene's
    fixed_frame_transforms, and the robot's links at configuration q (the names MoveIt resolves). An unknown
    frame is a MoveItYamlError naming the field that used it."""

    def __init__(self, data: Mapping, robot: RobotModel, q: np.ndarray):
        self.robot, self.q = robot, np.asarray(q, dtype=float)
        self.fixed: dict[str, np.ndarray] = {"": np.eye(4), robot.root_link: np.eye(4)}
        for k, t in enumerate(_field(data, "fixed_frame_transforms", "planning scene", []) or []):
            what = f"fixed_frame_transforms[{k}]"
            child = str(_field(t, "child_frame_id", what, required=True))
            parent = str(_field(_field(t, "header", what, {}) or {}, "frame_id", f"{what}.header", ""))
            if parent not in self.fixed:
                raise MoveItYamlError(f"{what}: frame {parent!r} is not known before it (known: {sorted(self.fixed)})")
            self.fixed[child] = self.fixed[parent] @ transform(_field(t, "transform", what, required=True),
                                                               f"{what}.transform")
        self.links: dict[str, np.ndarray] = {}  # filled at the first frame that names a link

    def __call__(self, frame: str, what: str) -> np.ndarray:
        if frame in self.fixed:
            return self.fixed[frame]
        if frame in self.robot.link_names:
            if not self.links:
                self.links.update(zip(self.robot.link_names, self.robot.link_poses(self.q)))
            return self.links[frame]
        raise MoveItYamlError(f"{what}: unknown frame {frame!r}: neither the planning frame {self.robot.root_link!r}, "
                              "a fixed_frame_transforms child nor a link of the robot")


def _shapes(co: Mapping, what: str) -> list[Shape]:
    prims = _field(co, "primitives", what, []) or []
    prim_poses = _field(co, "primitive_poses", what, []) or []
    meshes = _field(co, "meshes", what, []) or []
    mesh_poses = _field(co, "mesh_poses", what, []) or []
    if len(prims) != len(prim_poses):
        raise MoveItYamlError(f"{what}: {len(prims)} primitives but {len(prim_poses)} primitive_poses")
    if len(meshes) != len(mesh_poses):
        raise MoveItYamlError(f"{what}: {len(meshes)} meshes but {len(mesh_poses)} mesh_poses")
    if _field(co, "planes", what, []):
        raise MoveItYamlError(f"{what}: planes are not supported (give a thin box instead)")
    shapes = []
    for i, (p, pp) in enumerate(zip(prims, prim_poses)):
        w = f"{what}.primitives[{i}]"
        kind = _field(p, "type", w, required=True)
        kind = PRIMITIVE_TYPES.get(kind, kind) if isinstance(kind, int) else str(kind).lower()
        if kind not in PRIMITIVE_TYPES.values():
            raise MoveItYamlError(f"{w}: unsupported type {p['type']!r} (box, sphere, cylinder, cone or 1-4)")
        dims = tuple(numbers(_field(p, "dimensions", w, required=True), f"{w}.dimensions"))
        shapes.append(Shape(kind, pose(pp, f"{what}.primitive_poses[{i}]"), dims))
    for i, (m, mp) in enumerate(zip(meshes, mesh_poses)):
        w = f"{what}.meshes[{i}]"
        verts = np.array([vector(v, "xyz", f"{w}.vertices[{j}]")
                          for j, v in enumerate(_field(m, "vertices", w, required=True))]).reshape(-1, 3)
        tris = []
        for j, t in enumerate(_field(m, "triangles", w, required=True)):
            idx = numbers(t.get("vertex_indices") if isinstance(t, Mapping) else t, f"{w}.triangles[{j}]", 3)
            if np.any(idx != np.round(idx)) or np.any(idx < 0):
                raise MoveItYamlError(f"{w}.triangles[{j}]: vertex indices must be whole numbers >= 0, got {t!r}")
            tris.append(idx)
        shapes.append(Shape("mesh", pose(mp, f"{what}.mesh_poses[{i}]"), (), verts,
                            np.array(tris, dtype=np.int64).reshape(-1, 3)))
    return shapes


def planning_scene(data: Any, robot: RobotModel, q: np.ndarray | None = None) -> PlanningScene:
    """The collision objects of a moveit_msgs/PlanningScene dict, in a new PlanningScene whose frame is the robot's
    root link. q: the configuration at which frames naming robot links are placed (default: the scene's own
    robot_state over robot.home). Shapes are checked by PlanningScene's own rules (SceneUpdateError there is
    re-raised as MoveItYamlError naming the object)."""
    if not isinstance(data, Mapping):
        raise MoveItYamlError(f"planning scene: expected a map, got {type(data).__name__}")
    state = _field(data, "robot_state", "planning scene", {}) or {}
    if _field(state, "attached_collision_objects", "robot_state", []):
        raise MoveItYamlError("robot_state.attached_collision_objects: attached objects are not supported")
    if q is None:
        q = joint_values(state, robot).q
    resolve = SceneFrames(data, robot, q)
    world = _field(data, "world", "planning scene", {}) or {}
    octomap = _field(world, "octomap", "world", {}) or {}
    if (_field(octomap, "octomap", "world.octomap", {}) or {}).get("data"):
        raise MoveItYamlError("world.octomap: octomaps are not supported (send a point cloud to the node instead)")
    scene = PlanningScene(robot.root_link)
    for k, co in enumerate(_field(world, "collision_objects", "world", []) or []):
        what = f"world.collision_objects[{k}]"
        oid = str(_field(co, "id", what, required=True))
        what += f" ({oid!r})"
        op = _field(co, "operation", what, ADD)
        if op not in (ADD, "ADD", "add"):
            raise MoveItYamlError(f"{what}: operation {op!r}: a planning scene lists objects to ADD")
        frame = str(_field(_field(co, "header", what, {}) or {}, "frame_id", f"{what}.header", ""))
        T = resolve(frame, f"{what}.header.frame_id")
        if co.get("pose") is not None:
            T = T @ pose(co["pose"], f"{what}.pose")
        try:
            scene.add(oid, T, _shapes(co, what))
        except SceneUpdateError as e:
            raise MoveItYamlError(f"{what}: {e}") from None
    return scene


# ------------------------------------------------------------------------------------------ request
@dataclass(frozen=True)
class LoadedRequest:
    """A MotionPlanRequest in core terms: the joint-goal request, the goal as a full configuration (the start's
    values for the joints outside the group), and the start-state names that were not used."""

    request: StatePlanRequest
    goal: np.ndarray  # (dof,)
    ignored_joints: tuple[str, ...] = ()


def motion_plan_request(data: Any, robot: RobotModel, base: np.ndarray | None = None) -> LoadedRequest:
    """A moveit_msgs/MotionPlanRequest dict with one set of joint constraints as its goal → a StatePlanRequest
    (group, start over `base` (default robot.home), every goal joint; timeout = allowed_planning_time, else
    StatePlanRequest's). Which joints the goal must give is checked by the planner (validation.state_goal)."""
    if not isinstance(data, Mapping):
        raise MoveItYamlError(f"motion plan request: expected a map, got {type(data).__name__}")
    group = str(_field(data, "group_name", "motion plan request", required=True))
    start = joint_values(_field(data, "start_state", "motion plan request", {}), robot, base, "start_state")
    alternatives = _field(data, "goal_constraints", "motion plan request", []) or []
    if len(alternatives) != 1:
        raise MoveItYamlError(f"goal_constraints: {len(alternatives)} sets of constraints; exactly one is supported")
    (c,) = alternatives
    for kind in ("position_constraints", "orientation_constraints", "visibility_constraints"):
        if _field(c, kind, "goal_constraints[0]", []):
            raise MoveItYamlError(f"goal_constraints[0].{kind}: only joint constraints are supported")
    goal: dict[str, float] = {}
    for k, jc in enumerate(_field(c, "joint_constraints", "goal_constraints[0]", required=True)):
        what = f"goal_constraints[0].joint_constraints[{k}]"
        name = str(_field(jc, "joint_name", what, required=True))
        goal[name] = number(_field(jc, "position", what, required=True), f"{what}.position")
    q_goal = start.q.copy()
    index = {n: i for i, n in enumerate(robot.joint_names)}
    for name, v in goal.items():
        if name in index:
            q_goal[index[name]] = v
    timeout = _field(data, "allowed_planning_time", "motion plan request", None)
    extra = {"timeout": float(timeout)} if timeout else {}
    return LoadedRequest(StatePlanRequest(group, start.q, goal=goal, **extra), q_goal, start.ignored)
