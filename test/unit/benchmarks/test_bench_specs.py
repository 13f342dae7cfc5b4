"""The benchmark's robot specs (benchmarks/bench_planners.py): a robot's arm + torso groups are a spec of
their own, loaded as that robot and run on the one-hand pick families only."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
pytest.importorskip("ompl")


def test_torso_specs_load_their_robot_and_run_the_pick_families_only(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_planners as bp
    from humanoid_planner.scenarios import ARMS, FAMILIES, HUMANOIDS, PICK_FAMILIES

    with_torso = [h for h in (*HUMANOIDS.values(), *ARMS.values()) if h.torso]
    assert {"g1", "tiago"} <= {h.name for h in with_torso}
    for h in with_torso:
        spec = bp.SPECS[f"{h.name}_torso"]
        assert (spec.group, spec.left, spec.right, spec.model) == (h.torso[0], *h.torso, h.name)
    loaded = []
    monkeypatch.setattr(bp, "load_humanoid", lambda name: loaded.append(name) or name)
    assert bp.load_robot("g1_torso") == "g1" and bp.load_robot("tiago") == "tiago" and loaded == ["g1", "tiago"]
    cases = bp.build_matrix("default", ("g1_torso", "tiago_torso", "tiago"), FAMILIES + PICK_FAMILIES,
                            ("girrt", "ompl", "dagrrt"))
    torso = {(c.family, c.planner) for c in cases if c.robot.endswith("_torso")}
    assert torso == {(f, p) for f in PICK_FAMILIES for p in ("girrt", "ompl")}
    assert {c.family for c in cases if c.robot == "tiago"} == set(FAMILIES + PICK_FAMILIES)
    assert not any(c.dual for c in cases)
