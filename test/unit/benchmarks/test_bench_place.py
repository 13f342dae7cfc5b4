"""Smoke test of benchmarks/bench_place.py: one proven-solvable place problem, plan_place and the OMPL
peer on it, every success verified; the table and the JSON are written. Not how fast they are."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

pytest.importorskip("ompl")


def test_one_place_problem_both_planners_verified(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_place

    assert bench_place.main(["--problems", "1", "--budget", "3", "--proof", "5", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "place.json").read_text())["rows"]
    assert [r["planner"] for r in rows] == ["ours", "ompl"]
    for r in rows:
        assert r["problems"] == 1 and len(r["records"]) == 1
        rec = r["records"][0]
        if rec["ok"]:
            assert rec["verify_problems"] == [] and 0 <= rec["place_index"] < bench_place.PLACES
    assert rows[0]["solved"] == 1, rows[0]["records"]
    assert "plan_place" in (tmp_path / "place.md").read_text()
    sys.modules.pop("bench_place", None)


def test_the_proof_asks_for_a_set_down_and_a_retreat(monkeypatch):
    """Seed 29: two placements are reachable, but no IK posture of either can set the object down and
    leave it; the proof that stopped at the placements' TCP goals counted it solvable."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_place
    from bench_planners import SPECS, load_robot

    from humanoid_planner.core.pipeline.planner import GraspPlanner

    robot, spec = load_robot(bench_place.ROBOT), SPECS[bench_place.ROBOT]
    gp = GraspPlanner(robot, workers=1)
    problems: list[dict] = []
    why = bench_place._problem(robot, spec.group, spec, 29, 5.0, gp, problems)
    assert not problems and why.startswith("no IK solution of a placement can set the object down and leave it")
    assert "place_poses[0]" in why and "place_poses[4]" in why
    sys.modules.pop("bench_place", None)
