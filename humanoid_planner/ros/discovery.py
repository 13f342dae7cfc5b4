"""The node's Fast DDS profile: how soon a new client finds it, and a receive queue a flood cannot fill.

- Announcement period. A client started after the node learns of the node's DDS participant from the
  node's periodic announcement (Fast DDS: every 3 s by default); until then `wait_for_service` waits.
  Measured here (Jazzy wheels, one host, 10 fresh clients each): with the default, 0.02-2.6 s (half of
  them over 1.5 s); with the server announcing every 0.2 s, 0.02-0.64 s; the client's own setting changes
  nothing. So the node announces itself every ANNOUNCEMENT_PERIOD (one small message twice a second).
- Receive queue. Everything another process on this host sends the node - scene topic messages and
  service requests alike - goes through one shared-memory port, whose queue holds 512 messages by
  default. A client publishing `collision_object` as fast as it can filled it, the requests arriving
  meanwhile were dropped there, and each waited for its client's reliability heartbeat (3 s) to be sent
  again: during a 10 s flood other clients' calls took up to 5 s (p95 names 4.3 s, plan 1.9 s), 8 calls
  got through. With the node's queue at PORT_QUEUE_CAPACITY: names p95 0.14 s, plan p95 0.15 s, 51 calls
  (on a quiet machine 0.11 / 0.09 s, 74 calls), every message still applied or counted as dropped
  (bench_scale.py --only-flood). The queue costs 0.4 MB of shared memory. The transports are otherwise
  Fast DDS's built-in ones (shared memory and UDPv4). With ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST,
  rmw_fastrtps adds its own pair after these; the port is opened by the first, this one (its segment in
  /dev/shm has the larger queue).

- A short-lived client's first sample (grasp_client). Its publisher matches the node's subscription
  before the node has matched the publisher; the sample it publishes in that moment is dropped by the
  node and sent again only at the writer's next heartbeat, 3 s later by default: `grasp_client
  collision_object` took 3.5-4.0 s (3 of 3 runs), with heartbeats every CLIENT_HEARTBEAT_PERIOD
  0.6-1.1 s. So grasp_client's writers announce every CLIENT_HEARTBEAT_PERIOD (apply_client_profile).

Nothing is changed when the user configures Fast DDS with a profile file of their own or runs another
middleware (the settings are Fast DDS's only).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

ANNOUNCEMENT_PERIOD = 0.5  # s
PORT_QUEUE_CAPACITY = 16_384  # messages the node's shared-memory port holds before it drops (Fast DDS: 512)
CLIENT_HEARTBEAT_PERIOD = 0.1  # s between a client's reliable writer's heartbeats (Fast DDS: 3 s)
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
"""Where Fast DDS looks for the user's XML profiles (2.x reads the first, 3.x the second)."""

_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>humanoid_planner_shm</transport_id>
        <type>SHM</type>
        <port_queue_capacity>{port_queue}</port_queue_capacity>
      </transport_descriptor>
      <transport_descriptor>
        <transport_id>humanoid_planner_udp</transport_id>
        <type>UDPv4</type>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="humanoid_planner_node" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>humanoid_planner_shm</transport_id>
          <transport_id>humanoid_planner_udp</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <discovery_config>
            <leaseAnnouncement><sec>{sec}</sec><nanosec>{nanosec}</nanosec></leaseAnnouncement>
          </discovery_config>
        </builtin>
      </rtps>
    </participant>
  </profiles>
</dds>
"""


_CLIENT_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <data_writer profile_name="humanoid_planner_client_writer" is_default_profile="true">
      <times>
        <heartbeatPeriod><sec>{sec}</sec><nanosec>{nanosec}</nanosec></heartbeatPeriod>
      </times>
    </data_writer>
  </profiles>
</dds>
"""


def uses_fast_dds(environ=os.environ) -> bool:
    """Fast DDS is the middleware: RMW_IMPLEMENTATION unset (Jazzy's default) or rmw_fastrtps_*."""
    return environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp").startswith("rmw_fastrtps")


def apply_node_profile(environ=os.environ, period: float = ANNOUNCEMENT_PERIOD,
                       port_queue: int = PORT_QUEUE_CAPACITY) -> Path | None:
    """Before rclpy.init: point Fast DDS at a profile that announces the participant every `period` and
    receives through a shared-memory queue of `port_queue` messages; the profile's path, or None when
    nothing was changed (another middleware, or a profile of the user's). The file is written once per
    process and read by Fast DDS when the participant is made."""
    return _apply_profile(_PROFILE.format(**_seconds(period), port_queue=int(port_queue)), environ)


def apply_client_profile(environ=os.environ, heartbeat: float = CLIENT_HEARTBEAT_PERIOD) -> Path | None:
    """Before rclpy.init in a short-lived client: its reliable writers send a heartbeat every `heartbeat`
    s, so a sample the node dropped while it had not yet matched the writer is sent again at once (the
    module's docstring); the profile's path, or None when nothing was changed (as apply_node_profile)."""
    return _apply_profile(_CLIENT_PROFILE.format(**_seconds(heartbeat)), environ)


def _seconds(period: float) -> dict[str, int]:
    sec = int(period)
    return {"sec": sec, "nanosec": int(round((period - sec) * 1e9))}


def _apply_profile(text: str, environ) -> Path | None:
    """The profile written to a file of its own, which Fast DDS is pointed at; None (nothing written)
    under another middleware or when the user has a profile of their own."""
    if not uses_fast_dds(environ) or any(environ.get(v) for v in PROFILE_VARIABLES):
        return None
    fd, name = tempfile.mkstemp(prefix="humanoid_planner_dds_", suffix=".xml")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    for variable in PROFILE_VARIABLES:
        environ[variable] = name
    return Path(name)


def forget_profile(path: Path | None, environ=os.environ) -> None:
    """Once the participant exists (after rclpy.init and the node): remove the file and the variables
    apply_node_profile or apply_client_profile set, so that no child process inherits a path to a deleted file."""
    if path is None:
        return
    for variable in PROFILE_VARIABLES:
        if environ.get(variable) == str(path):
            del environ[variable]
    path.unlink(missing_ok=True)
