"""Where the node's robot comes from, and waiting for it on the `robot_description` topics.

Precedence (README "Loading a robot"):
1. the `robot_description` parameter, when non-empty (with `robot_description_semantic`, which may be
   empty: a robot without groups);
2. else the preset named by `robot`, when non-empty;
3. else the `robot_description` topic and, unless the `robot_description_semantic` parameter gives the
   SRDF, the `robot_description_semantic` topic: std_msgs/String, reliable + transient local, as
   robot_state_publisher (URDF) and move_group (SRDF) publish them. The node waits for both, logging
   what it waits for, and starts serving once the robot is loaded.

A description from parameters or a preset that cannot be loaded stops the node (exit 1: a fixed
configuration will not fix itself). One from the topics is logged with the reason (a missing mesh
names its URI) and the node keeps waiting for a new message on either topic: the publisher may be
restarted with a corrected description.
"""
from __future__ import annotations

import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String

from humanoid_planner.core.model.robot import JointLimits, RobotModel, RobotModelError, check_joint_limits
from humanoid_planner.ros.parameters import JOINT_LIMITS_PREFIX, StartParameters, StartupError, joint_limit_parameters
from humanoid_planner.ros.qos import ROBOT_DESCRIPTION_QOS

URDF_TOPIC = "robot_description"
SRDF_TOPIC = "robot_description_semantic"
WAIT_LOG_PERIOD = 10.0  # s between "still waiting" lines
SPIN_PERIOD = 0.2  # s: the wait loop looks at the context (shutdown, signals) this often


class RobotLoadError(StartupError):
    """The robot description could not be loaded; the node cannot start."""


def tcp_lines(robot: RobotModel) -> list[str]:
    """One line per planning group (a group with joints): the link its grasps are asked of and the rule that
    chose it (RobotModel.group_tcp). No message field carries a group's TCP, so the node logs these at
    startup."""
    out = []
    for name in sorted(robot.groups):
        g = robot.groups[name]
        if not g.joint_names:
            continue
        what = f"TCP link {g.tip_link!r}, from {g.tcp_source}" if g.tip_link else f"no TCP: {g.tcp_source}"
        out.append(f"group {name!r} ({len(g.joint_names)} joints): {what}")
    return out


def load_robot(node: Node, start: StartParameters) -> tuple[RobotModel, str]:
    """(robot, where it came from) by the precedence above; raises RobotLoadError (parameters, preset)
    or ExternalShutdownException (shut down while waiting for the topics)."""
    urdf, srdf, preset = start.robot_description, start.robot_description_semantic, start.robot
    limits = joint_limit_parameters(node)
    if limits:  # a bad value fails here, named, not once per description received
        try:
            check_joint_limits(limits)
        except RobotModelError as e:
            raise RobotLoadError(f"parameters {JOINT_LIMITS_PREFIX}*: {e}") from e
    if not urdf.strip() and not preset:
        robot = robot_from_topics(node, srdf if srdf.strip() else "", limits)
        source = "the robot_description topic"
    else:
        source = "the robot_description parameter" if urdf.strip() else f"preset {preset!r}"
        try:
            robot = (RobotModel.from_urdf_srdf(urdf, srdf if srdf.strip() else None, joint_limits=limits)
                     if urdf.strip() else RobotModel.preset(preset, limits))
        except Exception as e:  # file, XML, model and mesh errors of every kind
            raise RobotLoadError(f"cannot load the robot from {source}: {e}") from e
    for name, why in robot.skipped_groups.items():  # as MoveIt warns about them
        node.get_logger().warning(f"SRDF group {name!r} skipped: {why}")
    for what in robot.ignored_state_values:
        node.get_logger().warning(f"SRDF group_state value left out (not a finite number): {what}")
    if limits:
        used = sorted(set(limits) - set(robot.ignored_joint_limits))
        node.get_logger().info(f"joint limits of {len(used)} joint(s) from {JOINT_LIMITS_PREFIX}*: {', '.join(used)}")
    if robot.ignored_joint_limits:
        node.get_logger().warning(f"{JOINT_LIMITS_PREFIX}* name joint(s) this URDF does not move, left out: "
                                  f"{', '.join(robot.ignored_joint_limits)}")
    return robot, source


def robot_from_topics(node: Node, srdf_parameter: str = "", joint_limits: JointLimits = ()) -> RobotModel:
    """Spin `node` on the two description topics (only the URDF one when `srdf_parameter` gives the
    SRDF) until a description loads; returns the robot. The node's other entities are not created
    yet, so nothing else is served meanwhile. Raises ExternalShutdownException when the context is
    shut down first (SIGINT / SIGTERM while waiting)."""
    texts: dict[str, str | None] = {URDF_TOPIC: None, SRDF_TOPIC: srdf_parameter or None}

    def keep(topic: str):
        def on_message(msg: String) -> None:
            texts[topic] = msg.data
        return on_message

    topics = (URDF_TOPIC,) if srdf_parameter else (URDF_TOPIC, SRDF_TOPIC)
    subs = [node.create_subscription(String, t, keep(t), ROBOT_DESCRIPTION_QOS) for t in topics]
    names = ", ".join(s.topic_name for s in subs)
    log = node.get_logger()
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    tried: tuple[str | None, str | None] | None = None
    logged = 0.0
    try:
        while rclpy.ok(context=node.context):
            pair = (texts[URDF_TOPIC], texts[SRDF_TOPIC])
            if None not in pair and pair != tried:
                tried = pair
                try:
                    robot = RobotModel.from_urdf_srdf(pair[0], pair[1] if pair[1].strip() else None,
                                                      joint_limits=joint_limits)
                except Exception as e:  # noqa: BLE001 - XML, model and mesh errors of every kind
                    log.error(f"cannot load the robot from the {' and '.join(topics)} topic(s): {e}; "
                              "waiting for a new description")
                else:
                    log.info(f"robot description received on {names}")
                    return robot
            elif None in pair and time.monotonic() - logged >= WAIT_LOG_PERIOD:
                missing = [s.topic_name for s, t in zip(subs, topics) if texts[t] is None]
                log.info(f"waiting for the robot description on {', '.join(missing)} (std_msgs/String, "
                         "transient local, as robot_state_publisher publishes it); the `robot` and "
                         "`robot_description` parameters are empty")
                logged = time.monotonic()
            executor.spin_once(timeout_sec=SPIN_PERIOD)
        raise ExternalShutdownException()
    finally:
        executor.remove_node(node)
        executor.shutdown()
        for s in subs:
            node.destroy_subscription(s)
