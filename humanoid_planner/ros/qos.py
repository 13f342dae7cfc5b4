"""QoS profiles of the node's topics."""
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

COLLISION_OBJECT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""Scene diffs must not be lost: reliable, keep all, volatile (late joiners use get_planning_scene, as
with MoveIt). Keep-all on the node's reader: DDS acknowledges every sample it receives (up to its
resource limit, 5000 waiting samples with Fast DDS) whether or not the executor has taken it yet, so a
publisher's keep-last history is not overwritten under a burst; with keep-last 100, 461 of 1000 ADDs
published back to back were lost before the node saw them. Publishers with this profile are
flow-controlled (publish waits while the reader's history is full) and lose nothing."""

JOINT_STATES_QOS = qos_profile_sensor_data
"""Sensor-data QoS (best effort, volatile, keep last 5): only the latest joint state matters."""

PLANNED_TRAJECTORY_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Latched: a late subscriber asking for TRANSIENT_LOCAL gets the last planned trajectory."""

DROPPED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""`~/dropped_scene_updates`: the running count, latched (a client that subscribes later reads it)."""

MARKERS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""RViz markers of the scene and the last plan, latched like planned_trajectory."""

SERVICE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1000,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""The node's services (requests in, responses out). rclpy's default (services default: keep last
10) drops requests beyond the 10th of a burst that arrives before the executor takes them — 10 of
39 simultaneous plan requests were served in our test. A deep queue keeps every request; each is
answered (invalid ones at once, plans as workers free up)."""

POINTCLOUD_QOS = qos_profile_sensor_data
"""Sensor-data QoS, as depth cameras publish (best effort, keep last 5): only the newest cloud matters."""

ROBOT_DESCRIPTION_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""robot_description / robot_description_semantic as robot_state_publisher and move_group publish
them: latched, so a node started later still gets the description."""
