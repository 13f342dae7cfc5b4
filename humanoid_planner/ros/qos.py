"""QoS profiles of the node's topics (DESIGN §4)."""
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

COLLISION_OBJECT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=100,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""Scene diffs must not be dropped: reliable, volatile, keep last 100 (late joiners use
get_planning_scene, as with MoveIt)."""

JOINT_STATES_QOS = qos_profile_sensor_data
"""Sensor-data QoS (best effort, volatile, keep last 5): only the latest joint state matters."""

PLANNED_TRAJECTORY_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Latched: a late subscriber asking for TRANSIENT_LOCAL gets the last planned trajectory."""

MARKERS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""RViz markers of the scene and the last plan, latched like planned_trajectory."""
