"""200 randomized hostile plan requests against planner_node in its own process.

A seeded generator mixes valid and invalid values field by field (NaN, inf, huge and negative
numbers, zero and unnormalized quaternions, unknown names, long and non-ASCII strings, mismatched
array lengths, long lists, wrong frames, overlapping groups). Requests go out four at a time. Every
request must be answered with a known ErrorCode (and a message unless it succeeded) within its
client-side deadline; afterwards the process is still alive and still plans correctly. Valid
requests carry short timeouts, so the whole run stays at a few seconds.
"""
from __future__ import annotations

import collections
import math
import random

import numpy as np
import pytest
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3
from sensor_msgs.msg import JointState

from humanoid_planner.scenarios import OBJECT_ID
from humanoid_planner.ros.conversions import grasp_to_msg, matrix_to_pose_msg
from humanoid_planner.ros.requests import ERROR_NAMES
from humanoid_planner_interfaces.msg import Grasp
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp

from plan_helpers import (FRAME, STARTUP_TIMEOUT, SUCCESS, armar3, publish_scene, scenario, verify_response, wait_all,
                          wait_for_services)

pytestmark = pytest.mark.integration

N_REQUESTS = 200
BATCH = 4
WEIRD_FLOATS = (math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, -0.0, 1e9)
WEIRD_STRINGS = ("", "x" * 2000, "ÄÖÜ-🤖-群", "left_arm ", "LEFT_ARM", "../../etc", "left_hand_links", "torso",
                 "left_hand", "base_link")


class Hostile:
    """Builds one random request at a time (seeded: the same run every time)."""

    def __init__(self, seed: int):
        self.rng = random.Random(seed)
        self.robot = armar3()
        self.sc = scenario("table_shelf", 1, "left")
        self.dual = scenario("empty", 1, "both")

    def chance(self, p: float) -> bool:
        return self.rng.random() < p

    def weird(self) -> float:
        return self.rng.choice(WEIRD_FLOATS)

    def number(self, good: float, p_bad: float = 0.15) -> float:
        return self.weird() if self.chance(p_bad) else good

    def pose(self, T, p_bad=0.15) -> Pose:
        pose = matrix_to_pose_msg(T)
        if self.chance(p_bad):
            kind = self.rng.randrange(4)
            if kind == 0:
                pose.position.x = self.weird()
            elif kind == 1:
                pose.orientation = Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)
            elif kind == 2:
                pose.orientation.w = self.rng.choice((2.0, -3.0, math.nan, 1e-200))
            else:
                pose.position.z = self.rng.uniform(-1e3, 1e3)
        return pose

    def grasps(self, good) -> list[Grasp]:
        roll = self.rng.random()
        if roll < 0.1:
            return []
        if roll < 0.13:  # long list with one broken grasp at the end
            out = [grasp_to_msg(self.rng.choice(good)) for _ in range(300)]
            out[-1].friction = -1.0
            return out
        out = [grasp_to_msg(g) for g in self.rng.sample(list(good), k=min(len(good), self.rng.randint(1, 6)))]
        for g in out:
            if self.chance(0.04):
                g.tcp_in_object = self.pose(np.eye(4), p_bad=1.0)
            if self.chance(0.03):
                g.normals = g.normals[:-1]
            if self.chance(0.03):
                g.contacts = [Point(x=self.weird(), y=0.0, z=0.0)] + list(g.contacts[1:])
            if self.chance(0.03):
                g.normals = [Vector3()] + list(g.normals[1:])
            if self.chance(0.03):
                g.friction = self.rng.choice((-0.5, math.nan, math.inf, 1e6))
            if self.chance(0.03):
                g.hand = self.rng.choice(WEIRD_STRINGS + ("right_arm", "left_arm"))
            if self.chance(0.05):
                g.id = self.rng.choice(WEIRD_STRINGS)
        return out

    def start_state(self) -> JointState:
        roll = self.rng.random()
        names = list(self.robot.joint_names)
        if roll < 0.6:
            return JointState()
        if roll < 0.85:  # a valid partial state (maybe in collision)
            k = self.rng.sample(range(len(names)), self.rng.randint(1, 4))
            return JointState(name=[names[i] for i in k],
                              position=[self.rng.uniform(self.robot.lower[i], self.robot.upper[i]) for i in k])
        kind = self.rng.randrange(6)
        if kind == 0:
            return JointState(name=["no_such_joint"], position=[0.0])
        if kind == 1:
            return JointState(name=[names[0], names[0]], position=[0.0, 0.0])
        if kind == 2:
            return JointState(name=names[:3], position=[0.0])
        if kind == 3:
            return JointState(name=[names[4]], position=[self.weird()])
        if kind == 4:
            return JointState(name=[f"j{i}" for i in range(500)], position=[0.0] * 500)
        return JointState(position=[0.1, 0.2])  # positions without names

    def common(self, req, planners) -> None:
        req.start_state = self.start_state()
        req.planner = (self.rng.choice(("PRM", "girrt ", "ÄÖ", "dagrrt" if len(planners) > 1 else "girrt"))
                       if self.chance(0.08) else self.rng.choice(planners + ("",) * len(planners)))
        req.timeout = (self.rng.choice((-1.0, math.nan, math.inf, -math.inf, -1e-9)) if self.chance(0.06)
                       else self.rng.choice((0.05, 0.1, 0.2)))
        req.max_velocity_scaling = self.number(self.rng.choice((0.0, 0.5, 1.0)), 0.05)
        req.max_acceleration_scaling = self.number(self.rng.choice((0.0, 0.3, 1.0)), 0.05)
        req.seed = self.rng.choice((0, 1, 2**32 - 1, self.rng.randrange(2**32)))

    def object(self, req, object_pose) -> None:
        roll = self.rng.random()
        if roll < 0.75:
            req.object_id = OBJECT_ID
        elif roll < 0.85:
            req.object_id = self.rng.choice(WEIRD_STRINGS + ("table", "shelf"))
        else:
            req.object_id = ""
        req.object_pose = PoseStamped(pose=self.pose(object_pose, p_bad=0.1))
        req.object_pose.header.frame_id = (self.rng.choice(("odom", "world", "x" * 300)) if self.chance(0.1)
                                           else self.rng.choice(("", FRAME)))

    def plan_grasp(self) -> PlanGrasp.Request:
        req = PlanGrasp.Request()
        req.group = (self.rng.choice(("left_arm_torso", "left_arm", "right_arm_torso")) if self.chance(0.88)
                     else self.rng.choice(WEIRD_STRINGS))
        self.object(req, self.sc.object_pose)
        req.grasps = self.grasps(self.sc.left_grasps) if self.chance(0.6) else []
        self.common(req, ("girrt", "rrt", "goal_biased_rrt", "rrt_connect", "rc_rrt"))
        return req

    def plan_dual_grasp(self) -> PlanDualGrasp.Request:
        req = PlanDualGrasp.Request()
        pairs = (("left_arm", "right_arm"),) * 4 + (("left_arm_torso", "right_arm_torso"), ("left_arm", "left_arm"),
                                                   ("right_arm", "left_arm"), ("left_arm_torso", "right_arm"))
        req.left_group, req.right_group = (self.rng.choice(pairs) if self.chance(0.9)
                                           else (self.rng.choice(WEIRD_STRINGS), "right_arm"))
        self.object(req, self.dual.object_pose)
        req.left_grasps = self.grasps(self.dual.left_grasps) if self.chance(0.5) else []
        req.right_grasps = self.grasps(self.dual.right_grasps) if self.chance(0.5) else []
        req.min_grasp_score = self.number(self.rng.choice((0.0, 0.001, -1.0, 10.0)), 0.06)
        self.common(req, ("dagrrt",))
        return req

    def next(self):
        return ("plan_dual_grasp", self.plan_dual_grasp()) if self.chance(0.4) else ("plan_grasp", self.plan_grasp())


def test_node_survives_200_hostile_requests(ros, start_planner_process):
    proc = start_planner_process(params={"robot": "armar3", "num_workers": 2}, robot=False)
    node = ros.node("hostile_client")
    scene_cli = node.create_client(GetPlanningScene, "get_planning_scene")
    clients = {"plan_grasp": node.create_client(PlanGrasp, "plan_grasp"),
               "plan_dual_grasp": node.create_client(PlanDualGrasp, "plan_dual_grasp")}
    wait_for_services(proc, scene_cli, *clients.values())

    def version():
        return ros.call(scene_cli, GetPlanningScene.Request()).version

    gen = Hostile(seed=20240601)
    publish_scene(ros, node, gen.sc.scene.objects, version, timeout=STARTUP_TIMEOUT)
    codes = collections.Counter()
    for start in range(0, N_REQUESTS, BATCH):
        batch = [gen.next() for _ in range(BATCH)]
        futures = [clients[kind].call_async(req) for kind, req in batch]
        # valid requests plan for at most 0.2 s; 4 of them share 2 workers
        responses = wait_all(futures, 20.0)
        for (kind, req), resp in zip(batch, responses):
            code = resp.error_code.val
            assert code in ERROR_NAMES, f"request {start}: unknown code {code}"
            codes[f"{kind} {ERROR_NAMES[code]}"] += 1
            if code != SUCCESS:
                assert resp.message, f"{kind} {ERROR_NAMES[code]} without a message"
                assert len(resp.trajectory.points) == 0
            else:
                assert len(resp.trajectory.points) >= 2
        assert proc.proc.poll() is None, f"planner_node died after request {start}:\n{proc.output()}"
    print("\n" + "\n".join(f"{n:4d}  {k}" for k, n in sorted(codes.items())))
    assert sum(codes.values()) == N_REQUESTS
    assert "Traceback" not in proc.output()

    # still alive, and still plans correctly
    sc = gen.sc
    resp = ros.call(clients["plan_grasp"], PlanGrasp.Request(group="left_arm_torso", object_id=OBJECT_ID,
                                                             timeout=5.0, seed=3), timeout=30.0)
    assert resp.error_code.val == SUCCESS, resp.message
    assert verify_response(resp, sc.scene, ("left_arm_torso",), armar3().home, sc.object_pose) == []
