"""ros/discovery.py: the node's Fast DDS announcement profile, and when it is left alone."""
from __future__ import annotations

import xml.etree.ElementTree as ET

from humanoid_planner.ros.discovery import (CLIENT_HEARTBEAT_PERIOD, PORT_QUEUE_CAPACITY, PROFILE_VARIABLES,
                                            apply_client_profile, apply_node_profile, forget_profile)

NS = {"dds": "http://www.eprosima.com"}


def test_the_profile_announces_at_the_period_and_is_forgotten():
    env: dict[str, str] = {}
    path = apply_node_profile(env, period=0.25)
    assert path is not None and path.is_file()
    assert all(env[v] == str(path) for v in PROFILE_VARIABLES)
    period = ET.parse(path).getroot().find(".//dds:participant/dds:rtps/dds:builtin/dds:discovery_config/"
                                           "dds:leaseAnnouncement", NS)
    assert (period.find("dds:sec", NS).text, period.find("dds:nanosec", NS).text) == ("0", "250000000")
    root = ET.parse(path).getroot()
    shm = [d for d in root.iterfind(".//dds:transport_descriptor", NS) if d.find("dds:type", NS).text == "SHM"]
    assert [int(d.find("dds:port_queue_capacity", NS).text) for d in shm] == [PORT_QUEUE_CAPACITY]
    used = [t.text for t in root.iterfind(".//dds:participant/dds:rtps/dds:userTransports/dds:transport_id", NS)]
    kinds = {d.find("dds:transport_id", NS).text: d.find("dds:type", NS).text
             for d in root.iterfind(".//dds:transport_descriptor", NS)}
    assert sorted(kinds[t] for t in used) == ["SHM", "UDPv4"]  # Fast DDS's built-in pair, nothing less
    forget_profile(path, env)
    assert env == {} and not path.exists()


def test_a_users_profile_or_another_middleware_is_left_alone():
    for env in ({"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}, {"FASTDDS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"},
                {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}):
        before = dict(env)
        assert apply_node_profile(env) is None and apply_client_profile(env) is None
        assert env == before
    env = {"RMW_IMPLEMENTATION": "rmw_fastrtps_dynamic_cpp"}
    path = apply_node_profile(env)
    assert path is not None
    forget_profile(path, env)


def test_the_client_profile_sends_heartbeats_at_the_period():
    env: dict[str, str] = {}
    path = apply_client_profile(env)
    assert path is not None and all(env[v] == str(path) for v in PROFILE_VARIABLES)
    writer = ET.parse(path).getroot().find(".//dds:data_writer", NS)
    assert writer.get("is_default_profile") == "true"
    hb = writer.find("dds:times/dds:heartbeatPeriod", NS)
    assert int(hb.find("dds:sec", NS).text) + int(hb.find("dds:nanosec", NS).text) * 1e-9 == CLIENT_HEARTBEAT_PERIOD
    forget_profile(path, env)
    assert env == {} and not path.exists()
