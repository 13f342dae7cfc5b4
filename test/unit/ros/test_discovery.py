"""ros/discovery.py: the node's Fast DDS announcement profile, and when it is left alone."""
from __future__ import annotations

import xml.etree.ElementTree as ET

from humanoid_planner.ros.discovery import PROFILE_VARIABLES, announce_often, forget_profile

NS = {"dds": "http://www.eprosima.com"}


def test_the_profile_announces_at_the_period_and_is_forgotten():
    env: dict[str, str] = {}
    path = announce_often(env, period=0.25)
    assert path is not None and path.is_file()
    assert all(env[v] == str(path) for v in PROFILE_VARIABLES)
    period = ET.parse(path).getroot().find(".//dds:participant/dds:rtps/dds:builtin/dds:discovery_config/"
                                           "dds:leaseAnnouncement", NS)
    assert (period.find("dds:sec", NS).text, period.find("dds:nanosec", NS).text) == ("0", "250000000")
    forget_profile(path, env)
    assert env == {} and not path.exists()


def test_a_users_profile_or_another_middleware_is_left_alone():
    for env in ({"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}, {"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"},
                {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}):
        before = dict(env)
        assert announce_often(env) is None
        assert env == before
    env = {"RMW_IMPLEMENTATION": "rmw_fastrtps_dynamic_cpp"}
    path = announce_often(env)
    assert path is not None
    forget_profile(path, env)
