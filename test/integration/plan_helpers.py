"""Shared by the plan-service tests: the armar3 preset, seeded scenarios, a planner graph and requests,
scene publishing, verification."""
from __future__ import annotations

import functools
import time

import numpy as np

from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.scenarios import OBJECT_ID, make_scenario
from humanoid_planner.core.scene.types import SceneObject, SceneSnapshot, Shape
from humanoid_planner.core.postprocess.timing import TimedTrajectory
from humanoid_planner.core.verification import verify_plan
from geometry_msgs.msg import PoseStamped
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from humanoid_planner.ros.conversions import grasp_from_msg, matrix_to_pose_msg, scene_object_to_msg
from humanoid_planner.ros.executors import wait_for_server
from humanoid_planner.ros.qos import COLLISION_OBJECT_QOS, MARKERS_QOS, PLANNED_TRAJECTORY_QOS, SERVICE_QOS
from humanoid_planner_interfaces.msg import CollisionObject
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp

FRAME = "base_link"
SUCCESS = 1
LEFT = "left_arm_torso"
STARTUP_TIMEOUT = 30.0  # interpreter start + re-exec by the ROS wheels' bootstrapper + robot loading, on a busy CI box


def wait_for_services(proc, *clients, timeout: float = STARTUP_TIMEOUT) -> None:
    """Every client's service is up, or the test fails with the planner process's output."""
    for cli in clients:
        if not wait_for_server(cli, timeout):
            raise AssertionError(f"planner_node did not come up; its output:\n{proc.output()}")


@functools.lru_cache(maxsize=None)
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@functools.lru_cache(maxsize=None)
def scenario(family: str, seed: int, hand: str):
    return make_scenario(armar3(), family, seed, hand=hand)


def box_object(oid: str, center, size) -> SceneObject:
    T = np.eye(4)
    T[:3, 3] = center
    return SceneObject(oid, T, (Shape("box", np.eye(4), tuple(float(s) for s in size)),))


def caged(sc) -> SceneSnapshot:
    """The scenario with a solid box around the object: every grasp is reachable (IK ignores
    obstacles) but none can be approached, so GIRRT searches until its deadline."""
    cage = box_object("cage", sc.object_pose[:3, 3], (0.14, 0.14, 0.26))
    return SceneSnapshot(sc.scene.version, sc.scene.frame, sc.scene.objects + (cage,))


def publish_scene(ros, node, objects, scene_version, timeout: float = 10.0, frame: str = FRAME) -> int:
    """Publish ADD messages for core SceneObjects (poses in `frame`, the robot's root link); wait until
    scene_version() reports them all."""
    pub = node.create_publisher(CollisionObject, "collision_object", COLLISION_OBJECT_QOS)
    ros.wait_for_subscribers(pub, timeout=timeout)
    start = scene_version()
    for o in objects:
        pub.publish(scene_object_to_msg(o, frame))
    target = start + len(objects)
    ros.wait_until(lambda: scene_version() >= target, timeout=timeout, what=f"scene version {target}")
    return target


def remote_version(ros, node):
    cli = node.create_client(GetPlanningScene, "get_planning_scene")
    return lambda: ros.call(cli, GetPlanningScene.Request()).version


def trajectory_arrays(traj):
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in traj.points])
    pos = np.array([p.positions for p in traj.points])
    vel = np.array([p.velocities for p in traj.points])
    acc = np.array([p.accelerations for p in traj.points])
    return t, pos, vel, acc


class ResponsePlan:
    """What verify_plan reads from a GraspPlan, rebuilt from a response."""

    def __init__(self, traj):
        t, pos, vel, acc = trajectory_arrays(traj)
        self.trajectory = TimedTrajectory(t, pos, vel, acc)
        self.path = pos


def verify_response(resp, scene: SceneSnapshot, groups: tuple[str, ...], start: np.ndarray, object_pose: np.ndarray,
                    object_id: str = OBJECT_ID, robot: RobotModel | None = None) -> list[str]:
    """verify_plan on a PlanGrasp / PlanDualGrasp response (start, limits, grasp reached, collisions, time);
    robot: the client's copy of the node's robot (default armar3)."""
    robot = robot or armar3()
    grasps = [resp.grasp] if len(groups) == 1 else [resp.left_grasp, resp.right_grasp]
    targets = tuple(object_pose @ grasp_from_msg(g, "grasp").tcp_in_object for g in grasps)
    expected = [n for g in groups for n in robot.group(g).joint_names]
    problems = []
    if list(resp.trajectory.joint_names) != expected:
        problems.append(f"joint_names {list(resp.trajectory.joint_names)} != {expected}")
    if resp.trajectory.header.frame_id != robot.root_link:  # the planning frame: the root link by default
        problems.append(f"trajectory frame {resp.trajectory.header.frame_id!r}")
    return problems + verify_plan(robot, scene, groups, start, ResponsePlan(resp.trajectory), targets, object_id=object_id)


def wait_all(futures, timeout: float):
    """Results of several rclpy futures (TimeoutError naming how many are missing)."""
    deadline = time.monotonic() + timeout
    while not all(f.done() for f in futures):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{sum(not f.done() for f in futures)} of {len(futures)} requests unanswered")
        time.sleep(0.01)
    return [f.result() for f in futures]


class Graph:
    """An armar3 PlannerNode plus a client node with clients, a trajectory and a marker subscriber."""

    def __init__(self, ros, **params):
        self.ros = ros
        self.planner = ros.planner(urdf="", srdf="", robot="armar3", **params)
        self.node = ros.node("plan_client")
        # a burst of requests gets a burst of answers: the clients' response queues are as deep as the
        # services' (rclpy's default of 10 can drop answers of a 39-request burst)
        self.plan = self.node.create_client(PlanGrasp, "plan_grasp", qos_profile=SERVICE_QOS)
        self.dual = self.node.create_client(PlanDualGrasp, "plan_dual_grasp", qos_profile=SERVICE_QOS)
        self.scene_cli = self.node.create_client(GetPlanningScene, "get_planning_scene", qos_profile=SERVICE_QOS)
        self.trajectories: list[JointTrajectory] = []
        self.markers: list[MarkerArray] = []
        self.node.create_subscription(JointTrajectory, "planned_trajectory", self.trajectories.append,
                                      PLANNED_TRAJECTORY_QOS)
        self.node.create_subscription(MarkerArray, "humanoid_planner/markers", self.markers.append, MARKERS_QOS)
        for cli in (self.plan, self.dual, self.scene_cli):  # requests sent before discovery would be lost
            assert wait_for_server(cli, 10.0), f"{cli.srv_name} not available"

    def load(self, objects) -> int:
        return publish_scene(self.ros, self.node, objects, lambda: self.planner.scene.version)

    def call(self, client, request, timeout: float = 30.0):
        return self.ros.call(client, request, timeout=timeout)


def single_request(**kw) -> PlanGrasp.Request:
    kw.setdefault("group", LEFT)
    kw.setdefault("object_id", OBJECT_ID)
    kw.setdefault("timeout", 5.0)
    kw.setdefault("seed", 1)
    return PlanGrasp.Request(**kw)


def dual_request(**kw) -> PlanDualGrasp.Request:
    kw.setdefault("left_group", "left_arm")
    kw.setdefault("right_group", "right_arm")
    kw.setdefault("object_id", OBJECT_ID)
    kw.setdefault("timeout", 10.0)
    kw.setdefault("seed", 1)
    return PlanDualGrasp.Request(**kw)


def pose_stamped(T, frame=FRAME) -> PoseStamped:
    msg = PoseStamped(pose=matrix_to_pose_msg(T))
    msg.header.frame_id = frame
    return msg
