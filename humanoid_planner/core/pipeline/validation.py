"""Plan requests checked in core terms: the one place a request's groups, planner, start state,
grasps, approach / retreat and joint-space goal are validated.

A request's own grasps are checked as values (`check_request_grasps`) by the same functions the planning
scene runs on an object's grasps (scene/checks.py: the scene cannot import the pipeline), refused here.

`GraspPlanner` runs these checks before it plans; the node runs the same ones before it queues a request
(so a bad request is answered at once) and maps the refusal's `PlanStatus` to its ErrorCode. Messages
name the request field at fault. What only a message can get wrong (names and positions of different
lengths, unknown frames of a pose, a field's 0 meaning "the node's default") stays in the ROS layer.
"""
from __future__ import annotations

import math
from typing import Collection, Mapping, Sequence

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.planners.baselines import BASELINES
from humanoid_planner.core.planners.cartesian import GripperTranslation
from humanoid_planner.core.planners.common import PlanStatus
from humanoid_planner.core.scene.checks import SceneUpdateError, check_grasp, check_grasp_ids, name_grasps
from humanoid_planner.core.scene.types import GraspSpec

START_LIMIT_SLACK = 1e-4
"""rad (m for a prismatic joint): a start or joint goal this far outside a limit is clipped, not
refused: URDFs round ±π to ±3.14159 and benchmark states sit on ±3.14159265 (2.6e-6 past), rounded
states on ±3.1416 (1e-5 past); further out is a state the robot cannot be in."""
SINGLE_ARM_PLANNERS = ("girrt",) + BASELINES
DUAL_ARM_PLANNERS = ("dagrrt",)
STATE_PLANNERS = ("rrt_connect",) + tuple(p for p in BASELINES if p != "rrt_connect")
"""Joint-goal planners, the default first: RRT-Connect (bidirectional: a tree grows from the goal too)."""


class RequestRefused(ValueError):
    """A request that cannot be planned: the outcome class and a message naming the field at fault."""

    def __init__(self, status: PlanStatus, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


def check_group(robot: RobotModel, name: str, field: str = "group", tcp: bool = True) -> str:
    """A planning group of the robot that has joints and, when tcp, a TCP (RobotModel.group_tcp). A joint
    goal needs no TCP: plan_to_state takes any group with joints, as MoveIt does (Baxter's `both_arms`)."""
    if name in robot.skipped_groups:  # in the SRDF, but naming what the URDF lacks
        raise RequestRefused(PlanStatus.INVALID_GROUP,
                             f"{field}: planning group {name!r} of the SRDF cannot be used: {robot.skipped_groups[name]}")
    if name not in robot.groups:
        raise RequestRefused(PlanStatus.INVALID_GROUP,
                             f"{field}: unknown planning group {name!r}; known: {', '.join(sorted(robot.groups))}")
    if not robot.groups[name].joint_names:
        with_joints = sorted(g for g, v in robot.groups.items() if v.joint_names)
        raise RequestRefused(PlanStatus.INVALID_GROUP,
                             f"{field}: group {name!r} has no joints to plan for; use one of {', '.join(with_joints)}")
    if tcp and not robot.groups[name].tip_link:
        raise RequestRefused(PlanStatus.INVALID_GROUP,
                             f"{field}: group {name!r} has no TCP: {robot.groups[name].tcp_source}; plan one arm's "
                             "group (two arms: plan_dual_grasp with a group per arm)")
    return name


def check_dual_groups(robot: RobotModel, left: str, right: str, fields: tuple[str, str] = ("left_group", "right_group"),
                      tcp: bool = True) -> None:
    """Two planning groups with joints (and TCPs, when tcp) and no joint in common; fields: the request
    fields naming them."""
    check_group(robot, left, fields[0], tcp)
    check_group(robot, right, fields[1], tcp)
    shared = sorted(set(robot.groups[left].joint_names) & set(robot.groups[right].joint_names))
    if shared:
        raise RequestRefused(PlanStatus.INVALID_GROUP,
                             f"{fields[0]} {left!r} and {fields[1]} {right!r} share joint(s) {shared[:5]}; "
                             "they must be disjoint (e.g. left_arm and right_arm)")


def check_planner(name: str, known: tuple[str, ...], field: str = "planner") -> str:
    if name not in known:
        raise RequestRefused(PlanStatus.INVALID_REQUEST, f"{field}: unknown planner {name!r}; known: {', '.join(known)}")
    return name


def check_start(robot: RobotModel, start: Sequence[float] | np.ndarray,
                given: Collection[str] | None = None) -> np.ndarray:
    """The start configuration clipped to the joint limits; refused when malformed or further than
    START_LIMIT_SLACK outside a limit. Continuous joints have no limits: any finite value is kept as
    given (the plan moves within the turn around it, RobotModel.motion_limits). given: the joints the
    request named itself (the others, when given is not None, are reported as coming from joint_states)."""
    q = np.asarray(start, dtype=float)
    if q.shape != (robot.dof,) or not np.all(np.isfinite(q)):
        raise RequestRefused(PlanStatus.INVALID_START, f"start state must be {robot.dof} finite joint values")
    out = ((q < robot.lower - START_LIMIT_SLACK) | (q > robot.upper + START_LIMIT_SLACK)) & ~robot.continuous
    if np.any(out):
        names = robot.joint_names
        parts = [f"{names[i]}={q[i]:.4f} not in [{robot.lower[i]:.4f}, {robot.upper[i]:.4f}]"
                 + ("" if given is None or names[i] in given else " (from joint_states)")
                 for i in np.nonzero(out)[0][:4]]
        raise RequestRefused(PlanStatus.INVALID_START, "start state outside the joint limits: " + "; ".join(parts))
    return robot.clip(q)


def check_grasps(robot: RobotModel, group: str, grasps: Sequence[GraspSpec], field: str = "grasps") -> None:
    """At least one grasp that the group's hand may use (RobotModel.hand_usable_by)."""
    if not grasps:
        raise RequestRefused(PlanStatus.INVALID_GOAL, f"no grasps: {field} is empty")
    if not any(robot.hand_usable_by(g.hand, group) for g in grasps):
        hands = sorted({g.hand for g in grasps})
        raise RequestRefused(PlanStatus.INVALID_GOAL,
                             f"none of the {len(grasps)} grasps may be used by group {group!r} (their hands: {hands}; "
                             f"a grasp's hand must be '', the group, or an end effector of the group)")


def check_request_grasps(grasps: Sequence[GraspSpec], field: str = "grasps") -> tuple[GraspSpec, ...]:
    """A request's own grasps as values: each usable (scene/checks.py), ids given ("#<k>" where empty)
    and unique; returns the checked copies. A bad one refuses the request (INVALID_GOAL)."""
    try:
        out = name_grasps(tuple(check_grasp(g, f"{field}[{i}] ({g.id!r})") for i, g in enumerate(grasps)))
        check_grasp_ids(out, field)
    except SceneUpdateError as e:
        raise RequestRefused(PlanStatus.INVALID_GOAL, str(e)) from None
    return out


def check_translation(robot: RobotModel, planning_frame: str, gt: GripperTranslation | None, field: str) -> None:
    """An approach / retreat: a known frame (empty, the planning frame or a robot link), a usable
    direction and distances."""
    if gt is None:
        return
    if gt.frame not in ("", planning_frame, robot.root_link) and gt.frame not in robot.link_names:
        raise RequestRefused(PlanStatus.INVALID_FRAME,
                             f"{field}: frame {gt.frame!r} is neither the planning frame {planning_frame!r} nor a "
                             "link of the robot (empty: the default frame)")
    why = gt.problem()
    if why is not None:
        raise RequestRefused(PlanStatus.INVALID_GOAL, f"{field}: {why}")


def check_grasp_request(robot: RobotModel, planning_frame: str, req, given: Collection[str] | None = None
                        ) -> np.ndarray:
    """Every check of a GraspPlanRequest, in the order a caller would fix them; the clipped start."""
    check_group(robot, req.group)
    check_planner(req.planner, SINGLE_ARM_PLANNERS)
    start = check_start(robot, req.start, given)
    check_grasps(robot, req.group, req.grasps)
    check_translation(robot, planning_frame, req.approach, "pre_grasp_approach")
    check_translation(robot, planning_frame, req.retreat, "post_grasp_retreat")
    return start


def check_dual_request(robot: RobotModel, planning_frame: str, req, given: Collection[str] | None = None
                       ) -> np.ndarray:
    """Every check of a DualGraspPlanRequest; the clipped start."""
    check_dual_groups(robot, req.left_group, req.right_group)
    check_planner(req.planner, DUAL_ARM_PLANNERS)
    start = check_start(robot, req.start, given)
    check_grasps(robot, req.left_group, req.left_grasps, "left_grasps")
    check_grasps(robot, req.right_group, req.right_grasps, "right_grasps")
    check_translation(robot, planning_frame, req.approach, "pre_grasp_approach")
    check_translation(robot, planning_frame, req.retreat, "post_grasp_retreat")
    return start


def wrap_angle(value: float) -> float:
    """An angle in [-pi, pi): where a continuous joint is planned (its angles wrap)."""
    return (value + math.pi) % (2.0 * math.pi) - math.pi


def state_goal(robot: RobotModel, groups: Sequence[str], named_state: str,
               goal: Mapping[str, float] | None) -> np.ndarray:
    """The goal of a joint-space request: values of the groups' joints (in group order), from an SRDF
    group_state or from `goal` (joint name -> value; every joint of the groups, no other). Refused
    (INVALID_GOAL) naming the joint at fault: unknown, outside the groups, missing, not finite, or
    further than START_LIMIT_SLACK outside its limits (closer: clipped). A continuous joint's value
    wraps into its planning range instead."""
    names = [j for g in groups for j in robot.group(g).joint_names]
    what = " + ".join(repr(g) for g in groups)
    if bool(named_state) == (goal is not None):
        raise RequestRefused(PlanStatus.INVALID_GOAL,
                             "give the goal either as named_state (an SRDF group_state) or as goal_state (joint "
                             "values)" + (", not both" if named_state else ": neither is given"))
    if named_state:
        if named_state not in robot.group_states:
            raise RequestRefused(PlanStatus.INVALID_GOAL,
                                 f"named_state: the SRDF has no group_state {named_state!r}; known: "
                                 f"{', '.join(sorted(robot.group_states)) or 'none'}")
        values = robot.group_states[named_state]
        field = f"named_state {named_state!r}"
        missing = [n for n in names if n not in values]
        if missing:
            raise RequestRefused(PlanStatus.INVALID_GOAL,
                                 f"{field}: the SRDF's group_states of that name give no value for joint(s) "
                                 f"{missing[:5]} of {what}")
    else:
        values = goal
        field = "goal_state"
        unknown = [n for n in values if n not in robot.joints or robot.joints[n].index < 0]
        if unknown:
            raise RequestRefused(PlanStatus.INVALID_GOAL,
                                 f"{field}: unknown joint(s) {unknown[:5]}; the joints of {what} are {', '.join(names)}")
        other = [n for n in values if n not in names]
        if other:
            raise RequestRefused(PlanStatus.INVALID_GOAL,
                                 f"{field}: joint(s) {other[:5]} are not in {what}, whose joints are {', '.join(names)}")
        missing = [n for n in names if n not in values]
        if missing:
            raise RequestRefused(PlanStatus.INVALID_GOAL,
                                 f"{field}: no value for joint(s) {missing[:5]} of {what}; give every joint of the "
                                 "group(s)")
        bad = [f"{n}={values[n]}" for n in names if not math.isfinite(values[n])]
        if bad:
            raise RequestRefused(PlanStatus.INVALID_GOAL, f"{field}: NaN or inf value(s): {', '.join(bad[:5])}")
    q = np.array([wrap_angle(float(values[n])) if robot.joints[n].type == "continuous" else float(values[n])
                  for n in names])
    idx = np.array([robot.joints[n].index for n in names], dtype=np.int64)
    lo, hi = robot.lower[idx], robot.upper[idx]
    out = (q < lo - START_LIMIT_SLACK) | (q > hi + START_LIMIT_SLACK)
    if np.any(out):
        parts = [f"{names[i]}={q[i]:.4f} not in [{lo[i]:.4f}, {hi[i]:.4f}]" for i in np.nonzero(out)[0][:4]]
        raise RequestRefused(PlanStatus.INVALID_GOAL, f"{field} outside the joint limits: " + "; ".join(parts))
    return np.clip(q, lo, hi)


def check_state_request(robot: RobotModel, planning_frame: str, req, given: Collection[str] | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Every check of a StatePlanRequest; (the clipped start, the goal of the groups' joints)."""
    if req.right_group:
        check_dual_groups(robot, req.group, req.right_group, ("group", "right_group"), tcp=False)
    else:
        check_group(robot, req.group, tcp=False)
    check_planner(req.planner, STATE_PLANNERS)
    start = check_start(robot, req.start, given)
    return start, state_goal(robot, req.groups, req.named_state, req.goal)
