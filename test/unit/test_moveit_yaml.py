"""MoveIt PlanningScene / MotionPlanRequest YAML into core types (humanoid_planner/moveit_yaml.py), on small
documents written here in both spellings MoveIt's YAML comes in (lists and maps)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner
from humanoid_planner.core.pipeline.validation import RequestRefused, check_start
from humanoid_planner.core.transforms import pose_to_matrix
from humanoid_planner.moveit_yaml import MoveItYamlError, motion_plan_request, planning_scene

# Two objects, one per spelling: lists with type names (as MotionBenchMaker writes), and maps with
# SolidPrimitive constants and an object pose (as a moveit_msgs message dumped to YAML).
SCENE = """
name: two objects
fixed_frame_transforms:
  - child_frame_id: world
    transform: {translation: [0, 0, -0.5], rotation: [0, 0, 0, 1]}
robot_state:
  joint_state:
    name: [shoulder, elbow, wrist, finger]
    position: [0.5, 0, 0, 0.01]
world:
  collision_objects:
    - id: shelf
      primitives:
        - {type: box, dimensions: [0.4, 0.6, 0.02]}
        - {type: cylinder, dimensions: [0.3, 0.05]}
      primitive_poses:
        - position: [0.5, 0.1, 0.3]
          orientation: [0, 0, 0.7071067811865476, 0.7071067811865476]
        - {position: [0.5, 0.1, 0.45], orientation: [0, 0, 0, 1]}
    - id: can
      header: {frame_id: world}
      pose:
        position: {x: 0.4, y: -0.2, z: 0.0}
        orientation: {x: 0.0, y: 0.0, z: 0.0, w: 1.0}
      primitives:
        - {type: 2, dimensions: [0.03]}
      primitive_poses:
        - position: {x: 0.0, y: 0.0, z: 0.1}
          orientation: {x: 0.0, y: 0.0, z: 0.0, w: 1.0}
"""

REQUEST = """
group_name: arm
allowed_planning_time: 3
start_state:
  joint_state:
    name: [shoulder, elbow, wrist, finger]
    position: [0.1, 0.2, 0.3, 0.04]
  multi_dof_joint_state:
    joint_names: [virtual_joint]
    transforms: [{rotation: [0, 0, 0, 1], translation: [0, 0, 0]}]
goal_constraints:
  - joint_constraints:
      - {joint_name: shoulder, position: 0.6}
      - {position: -0.4, joint_name: elbow}
      - {joint_name: wrist, position: 1.0, tolerance_above: 0.001, tolerance_below: 0.001}
"""


@pytest.fixture(scope="module")
def robot(test_robot_description) -> RobotModel:
    return RobotModel.from_urdf_srdf(*test_robot_description)


def test_scene_objects_in_both_spellings(robot):
    scene = planning_scene(yaml.safe_load(SCENE), robot)
    assert scene.frame == "base_link"
    shelf, can = scene.snapshot().objects
    assert (shelf.id, [s.kind for s in shelf.shapes]) == ("shelf", ["box", "cylinder"])
    np.testing.assert_allclose(shelf.pose, np.eye(4))  # no header, no pose: the planning frame
    np.testing.assert_allclose(shelf.shapes[0].pose, pose_to_matrix([0.5, 0.1, 0.3], [0, 0, 0.7071068, 0.7071068]),
                               atol=1e-7)
    assert shelf.shapes[0].dims == (0.4, 0.6, 0.02) and shelf.shapes[1].dims == (0.3, 0.05)
    # the can's frame is the fixed frame "world", half a metre under the robot's root
    np.testing.assert_allclose(can.pose[:3, 3], [0.4, -0.2, -0.5])
    assert can.shapes[0].kind == "sphere" and can.shapes[0].dims == (0.03,)
    np.testing.assert_allclose(can.shapes[0].pose[:3, 3], [0, 0, 0.1])


def test_objects_on_a_robot_link_are_placed_at_the_scenes_robot_state(robot):
    data = yaml.safe_load(SCENE)
    data["world"]["collision_objects"][1]["header"]["frame_id"] = "tcp"
    q = np.array([0.5, 0.0, 0.0])  # the scene's robot_state
    T_tcp = robot.link_poses(q, ["tcp"])[0]
    (_, can) = planning_scene(data, robot).snapshot().objects
    np.testing.assert_allclose(can.pose, T_tcp @ pose_to_matrix([0.4, -0.2, 0.0], [0, 0, 0, 1]), atol=1e-12)
    (_, can) = planning_scene(data, robot, q=np.zeros(3)).snapshot().objects  # an explicit configuration wins
    np.testing.assert_allclose(can.pose, robot.link_poses(np.zeros(3), ["tcp"])[0]
                               @ pose_to_matrix([0.4, -0.2, 0.0], [0, 0, 0, 1]), atol=1e-12)


def test_mesh_objects(robot):
    data = {"world": {"collision_objects": [{
        "id": "wedge", "meshes": [{"vertices": [[0, 0, 0], {"x": 0.1, "y": 0, "z": 0}, [0, 0.1, 0], [0, 0, 0.1]],
                                   "triangles": [{"vertex_indices": [0, 1, 2]}, [0, 1, 3], [0, 2, 3], [1, 2, 3]]}],
        "mesh_poses": [{"position": [0.3, 0, 0.2], "orientation": [0, 0, 0, 1]}]}]}}
    (wedge,) = planning_scene(data, robot).snapshot().objects
    (mesh,) = wedge.shapes
    assert mesh.kind == "mesh" and mesh.vertices.shape == (4, 3) and mesh.triangles.tolist()[0] == [0, 1, 2]
    np.testing.assert_allclose(mesh.pose[:3, 3], [0.3, 0, 0.2])
    data["world"]["collision_objects"][0]["meshes"][0]["triangles"][1] = [0, 1.5, 3]
    with pytest.raises(MoveItYamlError, match=r"triangles\[1\]: vertex indices must be whole numbers"):
        planning_scene(data, robot)
    data["world"]["collision_objects"][0]["meshes"][0]["triangles"][1] = [0, 1, 7]
    with pytest.raises(MoveItYamlError, match=r"\('wedge'\).*triangle index out of range"):
        planning_scene(data, robot)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["world"]["collision_objects"][1]["header"].update(frame_id="map"), r"\('can'\).*unknown frame 'map'"),
    (lambda d: d["world"]["collision_objects"][0]["primitive_poses"].pop(), "2 primitives but 1 primitive_poses"),
    (lambda d: d["world"]["collision_objects"][0]["primitives"][0].update(type="torus"), "unsupported type 'torus'"),
    (lambda d: d["world"]["collision_objects"][0]["primitives"][0].update(dimensions=[0.4, 0.6]),
     r"\('shelf'\).*box needs 3"),
    (lambda d: d["world"]["collision_objects"][0]["primitive_poses"][0].update(orientation=[0, 0, 0, 2]),
     r"primitive_poses\[0\].orientation: quaternion norm is 2"),
    (lambda d: d["world"]["collision_objects"][1]["pose"]["position"].pop("z"), r"pose.position: no z"),
    (lambda d: d["world"]["collision_objects"][0].update(operation=1), "operation 1"),
    (lambda d: d["world"]["collision_objects"][0].update(planes=[{"coef": [0, 0, 1, 0]}]), "planes are not supported"),
    (lambda d: d["robot_state"].update(attached_collision_objects=[{"link_name": "hand"}]), "attached objects"),
])
def test_scene_errors_name_the_field(robot, edit, message):
    data = yaml.safe_load(SCENE)
    edit(data)
    with pytest.raises(MoveItYamlError, match=message):
        planning_scene(data, robot)


def test_request_into_a_state_request(robot):
    loaded = motion_plan_request(yaml.safe_load(REQUEST), robot)
    req = loaded.request
    assert req.group == "arm" and req.timeout == 3.0
    np.testing.assert_allclose(req.start, [0.1, 0.2, 0.3])
    assert dict(req.goal) == {"shoulder": 0.6, "elbow": -0.4, "wrist": 1.0}
    np.testing.assert_allclose(loaded.goal, [0.6, -0.4, 1.0])
    assert loaded.ignored_joints == ("finger",)  # not a joint of this robot: reported, not used


def test_request_plans_to_its_goal_in_its_scene(robot):
    """The two loaded halves are what GraspPlanner.plan_to_state takes."""
    scene = planning_scene({"world": {"collision_objects": []}}, robot).snapshot()
    loaded = motion_plan_request(yaml.safe_load(REQUEST), robot)
    plan = GraspPlanner(robot).plan_to_state(scene, loaded.request)
    assert plan.ok, plan.message
    np.testing.assert_allclose(plan.path[-1], loaded.goal, atol=1e-9)


def test_values_past_a_bound_are_kept_as_given(robot):
    """The loader does not clip: a start rounded past a bound reaches the planner's own check as written."""
    data = yaml.safe_load(REQUEST)
    data["start_state"]["joint_state"]["position"][2] = -3.0000027
    loaded = motion_plan_request(data, robot)
    assert loaded.request.start[2] == -3.0000027
    assert check_start(robot, loaded.request.start)[2] == -3.0  # a rounding past the bound: the planner clips
    data["start_state"]["joint_state"]["position"][2] = -3.001
    with pytest.raises(RequestRefused, match="wrist=-3.0010 not in"):
        check_start(robot, motion_plan_request(data, robot).request.start)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("group_name"), "no field 'group_name'"),
    (lambda d: d["start_state"]["joint_state"]["position"].pop(), "4 names but 3 positions"),
    (lambda d: d["start_state"]["joint_state"]["position"].__setitem__(0, ".nan"), r"position\[0\] \(shoulder\)"),
    (lambda d: d["start_state"]["multi_dof_joint_state"]["transforms"][0].update(translation=[1, 0, 0]),
     "'virtual_joint' moves the robot's base"),
    (lambda d: d["goal_constraints"].append(d["goal_constraints"][0]), "2 sets of constraints"),
    (lambda d: d["goal_constraints"][0].update(position_constraints=[{"link_name": "tcp"}]),
     "only joint constraints"),
    (lambda d: d["goal_constraints"][0]["joint_constraints"][1].pop("position"),
     r"joint_constraints\[1\]: no field 'position'"),
])
def test_request_errors_name_the_field(robot, edit, message):
    data = yaml.safe_load(REQUEST)
    edit(data)
    with pytest.raises(MoveItYamlError, match=message):
        motion_plan_request(data, robot)
