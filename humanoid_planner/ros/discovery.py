"""How soon a new client finds the node: Fast DDS's participant announcement period.

A client started after the node learns of the node's DDS participant from the node's periodic
announcement (Fast DDS: every 3 s by default); until then `wait_for_service` waits. Measured here
(Jazzy wheels, one host, 10 fresh clients each): with the default, 0.02-2.6 s (half of them over
1.5 s); with the server announcing every 0.2 s, 0.02-0.64 s; the client's own setting changes nothing.
So the node announces itself every ANNOUNCEMENT_PERIOD, unless the user configures Fast DDS with a
profile file of their own (then nothing is changed) or runs another middleware (the setting is Fast
DDS's only). An announcement is one small discovery message: twice a second costs nothing measurable.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

ANNOUNCEMENT_PERIOD = 0.5  # s
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
"""Where Fast DDS looks for the user's XML profiles (2.x reads the first, 3.x the second)."""

_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <participant profile_name="humanoid_planner_discovery" is_default_profile="true">
      <rtps>
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


def uses_fast_dds(environ=os.environ) -> bool:
    """Fast DDS is the middleware: RMW_IMPLEMENTATION unset (Jazzy's default) or rmw_fastrtps_*."""
    return environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp").startswith("rmw_fastrtps")


def announce_often(environ=os.environ, period: float = ANNOUNCEMENT_PERIOD) -> Path | None:
    """Before rclpy.init: point Fast DDS at a profile that announces the participant every `period`;
    the profile's path, or None when nothing was changed (another middleware, or a profile of the
    user's). The file is written once per process and read by Fast DDS when the participant is made."""
    if not uses_fast_dds(environ) or any(environ.get(v) for v in PROFILE_VARIABLES):
        return None
    sec = int(period)
    text = _PROFILE.format(sec=sec, nanosec=int(round((period - sec) * 1e9)))
    fd, name = tempfile.mkstemp(prefix="humanoid_planner_dds_", suffix=".xml")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    for variable in PROFILE_VARIABLES:
        environ[variable] = name
    return Path(name)


def forget_profile(path: Path | None, environ=os.environ) -> None:
    """Once the participant exists (after rclpy.init and the node): remove the file and the variables
    announce_often set, so that no child process inherits a path to a deleted file."""
    if path is None:
        return
    for variable in PROFILE_VARIABLES:
        if environ.get(variable) == str(path):
            del environ[variable]
    path.unlink(missing_ok=True)
