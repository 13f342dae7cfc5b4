"""`grasp_client` (the `ros2 service call` of this package) against planner_node in its own process,
with the example requests shipped in config/examples/."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from humanoid_planner.ros.grasp_client import load_request, summarize
from humanoid_planner.ros.message_dict import MessageFieldError, dict_to_msg, msg_to_dict
from humanoid_planner_interfaces.srv import GetPlanningScene, PlanDualGrasp, PlanGrasp, PlanToState
from humanoid_planner.child_env import child_environment
from humanoid_planner.ros.discovery import PROFILE_VARIABLES

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "config" / "examples"
STARTUP_TIMEOUT = 30.0


def client(*args: str, stdin: str | None = None) -> tuple[int, str, str]:
    exe = Path(sys.executable).parent / "grasp_client"
    assert exe.exists(), f"{exe} missing: run `make setup`"
    env = child_environment()
    for v in PROFILE_VARIABLES:  # as from a user's shell: grasp_client applies its own (ros/discovery.py)
        env.pop(v, None)
    p = subprocess.run([str(exe), *args], capture_output=True, text=True, env=env, input=stdin, timeout=90,
                       cwd=str(REPO))
    return p.returncode, p.stdout, p.stderr


def test_example_requests_parse():
    for name, srv in (("plan_grasp.yaml", PlanGrasp), ("plan_grasp_object_pose.yaml", PlanGrasp),
                      ("plan_dual_grasp.yaml", PlanDualGrasp), ("plan_grasp_approach_lift.yaml", PlanGrasp),
                      ("plan_to_state_joints.yaml", PlanToState)):
        msg = dict_to_msg(srv.Request, load_request(str(EXAMPLES / name)))
        assert msg_to_dict(msg)["timeout"] > 0
    with pytest.raises(MessageFieldError, match="has no field 'grup'"):
        dict_to_msg(PlanGrasp.Request, {"grup": "left_arm"})
    with pytest.raises(MessageFieldError, match=r"start_state.position\[0\]"):
        dict_to_msg(PlanGrasp.Request, {"start_state": {"position": ["a"]}})
    with pytest.raises(MessageFieldError, match="seed"):
        dict_to_msg(PlanGrasp.Request, {"seed": -1})


def test_grasp_client_against_the_node(start_planner_process):
    proc = start_planner_process(params={"robot": "armar3"}, robot=False)
    wait = ["--wait", str(STARTUP_TIMEOUT)]

    code, out, err = client("get_planning_scene", *wait)
    assert code == 0, err + proc.output()
    scene = yaml.safe_load(out)
    assert scene["objects"] == [] and scene["planning_frame"] == "base_link"

    # a request read from stdin (full output): the object given by pose, with its grasps, in the empty scene
    code, out, err = client("plan_grasp", "-", *wait, stdin=(EXAMPLES / "plan_grasp_object_pose.yaml").read_text())
    assert code == 0, out + err
    resp = yaml.safe_load(out)
    assert resp["error_code"]["val"] == 1
    assert resp["trajectory"]["points"][0]["positions"][0] == pytest.approx(0.05)  # torso_yaw from start_state

    # publish the example object, then plan with the example request that names it
    code, out, err = client("collision_object", str(EXAMPLES / "target_left.yaml"), *wait)
    assert code == 0, err
    code, out, err = client("plan_grasp", str(EXAMPLES / "plan_grasp.yaml"), "--brief", *wait)
    assert code == 0, out + err
    assert out.startswith("# error_code: SUCCESS (1)")
    resp = yaml.safe_load(out)
    assert resp["scene_version"] == 1 and resp["grasp"]["id"].startswith("left_arm")
    assert resp["trajectory"]["points"]["count"] >= 2 and resp["trajectory"]["points"]["duration"] > 0

    # the README's pick: approach 10 cm along the hand axis, lift 10 cm; then attach and detach the object
    code, out, err = client("plan_grasp", str(EXAMPLES / "plan_grasp_approach_lift.yaml"), "--brief", *wait)
    assert code == 0, out + err
    resp = yaml.safe_load(out)
    assert resp["approach_distance"] >= 0.05 - 1e-6 and resp["retreat_distance"] >= 0.05 - 1e-6
    assert resp["retreat_trajectory"]["points"]["first"] == resp["trajectory"]["points"]["last"]
    code, out, err = client("attached_collision_object", str(EXAMPLES / "attach_target.yaml"), *wait)
    assert code == 0, err
    scene = {}
    for _ in range(50):  # the topic is applied asynchronously
        scene = yaml.safe_load(client("get_planning_scene", *wait)[1])
        if scene["attached_objects"]:
            break
    assert [a["object"]["id"] for a in scene["attached_objects"]] == ["target"] and scene["objects"] == []
    code, out, err = client("attached_collision_object", "{object: {id: target, operation: 1}}", *wait)
    assert code == 0, err

    # an answered failure exits 2 and shows the code; an invalid request exits 1 without calling
    code, out, err = client("plan_grasp", "{group: left_leg, object_id: target}", *wait)
    assert code == 2 and "INVALID_GROUP_NAME (-15)" in out and "left_leg" in out
    code, out, err = client("plan_grasp", "{group: left_arm, timeout: soon}", *wait)
    assert code == 1 and "timeout" in err
    assert proc.proc.poll() is None


def test_summarize_keeps_first_and_last_point():
    resp = {"trajectory": {"points": [{"positions": [0.0], "time_from_start": {"sec": 0, "nanosec": 0}},
                                      {"positions": [1.0], "time_from_start": {"sec": 1, "nanosec": 500000000}}]}}
    assert summarize(resp)["trajectory"]["points"] == {"count": 2, "duration": 1.5, "first": [0.0], "last": [1.0]}


def readme_examples(heading: str = "### `grasp_client`", end: str = "\n## ") -> list[list[str]]:
    """The grasp_client command lines of the README's section from `heading` to `end`, in their order."""
    import shlex

    text = (REPO / "README.md").read_text()
    section = text[text.index(heading):]
    section = section[:section.index(end)]
    return [shlex.split(line, comments=True)[1:] for line in section.splitlines() if line.startswith("    grasp_client ")]


def place_cycle() -> list[list[str]]:
    """The README's pick -> place -> home cycle from the shell."""
    return readme_examples("The cycle from the shell", "The same cycle from Python")


def test_every_shipped_example_works_in_the_readme_order(start_planner_process):
    commands = readme_examples()
    used = {Path(a).name for c in commands + place_cycle() for a in c if a.startswith("config/examples/")}
    assert used == {p.name for p in EXAMPLES.glob("*.yaml")}, "every shipped example is in the README"
    proc = start_planner_process(params={"robot": "armar3"}, robot=False)
    wait = ["--wait", str(STARTUP_TIMEOUT)]
    for args in commands:
        code, out, err = client(*args, *wait)
        assert code == 0, f"grasp_client {' '.join(args)} exited {code}:\n{out}{err}\nnode:\n{proc.output()}"


def test_help_names_files_that_exist():
    code, out, err = client("--help")
    assert code == 0
    named = [w for w in out.split() if w.startswith("config/examples/")]
    assert named and all((REPO / w).is_file() for w in named), named


def test_the_readme_place_cycle_from_the_shell(start_planner_process, ros):
    """The README's cycle (pick, lift, place on the shelf, detach, home) command by command against the
    node, this test publishing the joint_states a robot executing each trajectory would: the grasp
    after plan_grasp, the lift's end after the attach, the placement after plan_place, the retreat's
    end after the detach. Every step answers SUCCESS; the object ends on the shelf."""
    import time

    from sensor_msgs.msg import JointState

    from humanoid_planner.ros.qos import JOINT_STATES_QOS
    from plan_helpers import armar3

    commands = place_cycle()
    assert [c[0] for c in commands] == ["collision_object", "collision_object", "plan_grasp", "attached_collision_object",
                                        "plan_place", "attached_collision_object", "plan_to_state"]
    robot = armar3()
    proc = start_planner_process(params={"robot": "armar3"}, robot=False)
    wait = ["--wait", str(STARTUP_TIMEOUT)]
    driver = ros.node("robot")
    scene_cli = driver.create_client(GetPlanningScene, "get_planning_scene")
    pub = driver.create_publisher(JointState, "joint_states", JOINT_STATES_QOS)
    q = robot.home.copy()
    driver.create_timer(0.05, lambda: pub.publish(JointState(name=list(robot.joint_names), position=q.tolist())))

    def execute(names, positions) -> None:
        """The robot now at the end of a trajectory (the driver streams it at 20 Hz)."""
        q[[robot.joint_names.index(n) for n in names]] = positions
        time.sleep(0.3)

    then = None  # what the robot executes after the next attach / detach
    for args in commands:
        code, out, err = client(*args, *wait)
        assert code == 0, f"grasp_client {' '.join(args)} exited {code}:\n{out}{err}\nnode:\n{proc.output()}"
        if args[0] in ("plan_grasp", "plan_place"):
            resp = yaml.safe_load(out)
            names = resp["trajectory"]["joint_names"]
            execute(names, resp["trajectory"]["points"]["last"])
            then = (names, resp["retreat_trajectory"]["points"]["last"])
            if args[0] == "plan_place":
                placed = resp["place_index"]
        elif args[0] == "attached_collision_object":
            # the topic is applied asynchronously: this test's own client waits (the README's
            # get_planning_scene is run as a command at the end)
            attached = "operation: 1" not in args[1]
            ros.wait_until(lambda: bool(ros.call(scene_cli, GetPlanningScene.Request()).attached_objects) == attached,
                           timeout=10.0, what=f"target {'attached' if attached else 'detached'}")
            execute(*then)
    scene = yaml.safe_load(client("get_planning_scene", *wait)[1])
    target = next(o for o in scene["objects"] if o["id"] == "target")
    goal = yaml.safe_load((EXAMPLES / "plan_place_shelf.yaml").read_text())["place_poses"][placed]["pose"]["position"]
    assert [target["pose"]["position"][k] for k in "xyz"] == pytest.approx([goal[k] for k in "xyz"], abs=2e-3)
    assert scene["attached_objects"] == []
