"""Messages <-> plain dicts (ros.message_dict), no ROS graph: every example request file round-trips
through YAML unchanged, and a dict that does not fit names the field and what was expected."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from trajectory_msgs.msg import JointTrajectory

from humanoid_planner.ros.message_dict import MessageFieldError, dict_to_msg, msg_to_dict
from humanoid_planner_interfaces.msg import AttachedCollisionObject, CollisionObject
from humanoid_planner_interfaces.srv import PlanDualGrasp, PlanGrasp, PlanPlace, PlanToState

EXAMPLES = Path(__file__).resolve().parents[3] / "config" / "examples"
TYPES = {"plan_grasp.yaml": PlanGrasp.Request, "plan_grasp_object_pose.yaml": PlanGrasp.Request,
         "plan_dual_grasp.yaml": PlanDualGrasp.Request, "target_left.yaml": CollisionObject,
         "plan_grasp_approach_lift.yaml": PlanGrasp.Request, "attach_target.yaml": AttachedCollisionObject,
         "plan_to_state_joints.yaml": PlanToState.Request, "plan_to_state_home.yaml": PlanToState.Request,
         "plan_place_shelf.yaml": PlanPlace.Request, "shelf.yaml": CollisionObject}


def test_the_example_table_lists_every_example():
    assert sorted(TYPES) == sorted(p.name for p in EXAMPLES.glob("*.yaml"))


@pytest.mark.parametrize("name", sorted(TYPES))
def test_example_files_round_trip_through_yaml(name):
    data = yaml.safe_load((EXAMPLES / name).read_text())
    msg = dict_to_msg(TYPES[name], data)
    text = yaml.safe_dump(msg_to_dict(msg))
    assert dict_to_msg(TYPES[name], yaml.safe_load(text)) == msg
    for key, value in data.items():  # what the file gives is what the message holds
        if not isinstance(value, (dict, list)):
            assert getattr(msg, key) == value, key


def test_nested_arrays_of_messages_and_numbers():
    data = {"header": {"frame_id": "base_link"}, "joint_names": ["a", "b"],
            "points": [{"positions": [1, 2.5], "time_from_start": {"sec": 1, "nanosec": 5}}]}
    msg = dict_to_msg(JointTrajectory, data)
    assert list(msg.points[0].positions) == [1.0, 2.5] and msg.points[0].time_from_start.nanosec == 5
    back = msg_to_dict(msg)
    assert back["points"][0]["positions"] == [1.0, 2.5] and type(back["points"][0]["positions"][0]) is float
    assert dict_to_msg(JointTrajectory, None) == JointTrajectory()  # None: every default


@pytest.mark.parametrize("data,words", [
    ({"grup": "x"}, ["grup", "has no field", "group"]),
    ({"timeout": "soon"}, ["timeout", "expected a double"]),
    ({"timeout": True}, ["timeout", "expected a double"]),
    ({"seed": 2**40}, ["seed", "out of the", "range"]),
    ({"seed": 1.5}, ["seed", "expected a"]),
    ({"object_pose": {"pose": {"position": {"x": [1]}}}}, ["object_pose.pose.position.x"]),
    ({"grasps": {"id": "g"}}, ["grasps", "expected a list"]),
    ({"grasps": [{"contacts": [{"q": 1}]}]}, ["grasps[0].contacts[0]", "has no field 'q'"]),
    ({"start_state": 3}, ["start_state", "expected a mapping"]),
])
def test_misfits_name_the_field(data, words):
    with pytest.raises(MessageFieldError) as e:
        dict_to_msg(PlanGrasp.Request, data)
    for w in words:
        assert w in str(e.value)


def test_yaml_special_floats_are_accepted():
    assert dict_to_msg(PlanGrasp.Request, yaml.safe_load("timeout: .inf")).timeout == float("inf")
    assert dict_to_msg(PlanGrasp.Request, {"timeout": "-inf"}).timeout == float("-inf")
    nan = dict_to_msg(PlanGrasp.Request, {"timeout": "nan"}).timeout
    assert nan != nan
