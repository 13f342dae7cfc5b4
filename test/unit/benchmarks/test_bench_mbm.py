"""Smoke test of benchmarks/bench_mbm.py on a robot folder laid out as the MotionBenchMaker sets are (URDF + SRDF,
problems/<family>_<robot>/sceneNNNN.yaml + requestNNNN.yaml), written here for the small test arm: GIRRT, plan_to_state and the OMPL peer
solve and verify, a start rounded past a bound is counted as refused-as-given and planned clipped. Not how fast."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from mbm_folder import joint_request, mbm_robot_dir  # test/mbm_folder.py

ROOT = Path(__file__).resolve().parents[3]

pytest.importorskip("ompl")

SCENE = {"world": {"collision_objects": [
    {"id": "post", "header": {"frame_id": "base_link"},
     "primitives": [{"type": "box", "dimensions": [0.05, 0.05, 0.6]}],
     "primitive_poses": [{"position": [0.0, 0.35, 0.3], "orientation": [0, 0, 0, 1]}]}]}}


@pytest.fixture
def robot_dir(tmp_path, test_robot_description) -> Path:
    goal = (("shoulder", 0.9), ("elbow", 0.6), ("wrist", 1.0))
    starts = ([-0.5, 0.2, 0.0], [-0.5, 0.2, -3.0000027])  # 2: the wrist rounded past -3.0
    return mbm_robot_dir(tmp_path, test_robot_description, SCENE, [joint_request(s, goal) for s in starts])


def test_two_problems_both_planners_verified(robot_dir, tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_mbm

    robot = bench_mbm.load_robot(robot_dir)
    p = bench_mbm.load_problem(robot, robot_dir / "problems" / "box_test_arm", 2, bench_mbm.CLIP)
    assert p.clipped == () and p.start[2] == -3.0000027 and p.refused_as_given == ""  # the planner clips it
    np.testing.assert_allclose(p.tcp_goal, robot.link_poses(p.goal, ["tcp"])[0])

    out = tmp_path / "out"
    assert bench_mbm.robot_families(robot_dir) == ["box"]  # the default: every problems/<family>_<robot> folder
    assert bench_mbm.main(["--robot-dir", str(robot_dir), "--planners", "girrt,state,ompl", "--problems", "2",
                           "--budget", "5", "--out", str(out)]) == 0
    res = json.loads((out / "mbm.json").read_text())
    assert res["problem_sets"]["test_arm/box"]["refused_as_given"] == 0
    assert res["problem_sets"]["test_arm/box"]["clipped"] == {}
    rows = {s["planner"]: s for s in res["families"]}
    assert set(rows) == {"girrt", "state", "ompl"}
    for s in rows.values():
        assert s["successes"] == 2, s["problems"]
        assert s["verified"] == {"checked": 2, "valid": 2, "problems": []}
    table = (out / "mbm.md").read_text()
    assert "| test_arm | box | 2/2 |" in table
    assert table.count("| test_arm | box | 2/2 |") == 2  # GIRRT's table and plan_to_state's
    sys.modules.pop("bench_mbm", None)
