"""Smoke test of the benchmark harness (benchmarks/bench_planners.py): a tiny quick-mode run.

One problem per case, 1 s budget, no ROS service part: GIRRT and the OMPL peer on armar3, DAGRRT with
two workers and one on dual_arm, all on the boxes6 family. Checks that the JSON, the markdown table and
the plot are written and well-formed — not how fast or how successful the planners are.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from humanoid_planner.child_env import child_environment

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "benchmarks" / "bench_planners.py"

pytest.importorskip("ompl")


def _finite_or_none(x) -> bool:
    return x is None or (isinstance(x, (int, float)) and math.isfinite(x))


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    env = child_environment()
    p = subprocess.run([sys.executable, str(BENCH), "--quick", "--robots", "armar3,dual_arm", "--families", "boxes6",
                        "--planners", "girrt,ompl,dagrrt", "--problems", "1", "--budget", "1", "--no-service",
                        "--out", str(out)], capture_output=True, text=True, timeout=120, env=env, cwd=str(ROOT))
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return out, p.stdout


def test_quick_run_writes_well_formed_json(quick_run):
    out, _ = quick_run
    res = json.loads((out / "results.json").read_text())
    assert {"meta", "cases", "ratios", "speedups", "targets", "skipped"} <= set(res)
    meta = res["meta"]
    assert meta["budget"] == 1.0 and meta["problems"] == 1 and meta["quick"] is True
    keys = {(c["robot"], c["family"], c["planner"], c["workers"]) for c in res["cases"]}
    assert keys == {("armar3", "boxes6", "girrt", 2), ("armar3", "boxes6", "ompl", 2),
                    ("dual_arm", "boxes6", "dagrrt", 2), ("dual_arm", "boxes6", "dagrrt", 1)}
    for c in res["cases"]:
        assert c["n"] == len(c["problems"]) == 1
        assert 0.0 <= c["success_rate"] <= 1.0 and c["successes"] == sum(r["ok"] for r in c["problems"])
        for k in ("time_median", "time_p95", "time_median_success", "path_length_median", "checks_per_s",
                  "exact_share"):
            assert _finite_or_none(c[k]), (k, c[k])
        assert c["time_median"] > 0 and sum(c["status_counts"].values()) == c["n"]
        for r in c["problems"]:
            assert {"seed", "status", "ok", "time", "wall", "configs_checked", "phases"} <= set(r)
            assert 0 < r["time"] <= r["wall"] + 1e-3 and r["time"] < 1.0 + 2.0  # budget + post-processing slack
            assert r["configs_checked"] > 0, "the request's collision checkers were not recorded"
            if r["ok"]:
                assert r["path_length"] >= 0 and r["waypoints"] >= 2
    (ratio,) = res["ratios"]
    assert (ratio["robot"], ratio["family"], ratio["planner"]) == ("armar3", "boxes6", "girrt")
    assert ratio["ratio"] > 0
    (speedup,) = res["speedups"]
    assert speedup["robot"] == "dual_arm" and _finite_or_none(speedup["speedup"])
    assert any(t["target"].startswith("GIRRT armar3 boxes6") for t in res["targets"])


def test_quick_run_writes_table_and_plot(quick_run):
    out, stdout = quick_run
    table = (out / "table.md").read_text()
    assert "| armar3 | left_arm_torso | boxes6 | girrt |" in table
    assert "### Ours / OMPL peer" in table and "### DAGRRT parallel speed-up" in table
    assert table in stdout  # the same table is printed
    png = (out / "bench.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
