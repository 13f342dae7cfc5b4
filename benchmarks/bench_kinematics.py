#!/usr/bin/env python3
"""FK + 6×n Jacobian throughput: batched vs one configuration at a time, same run, same chain.

    python benchmarks/bench_kinematics.py                 # armar3 left_arm_torso (10 DoF)
    python benchmarks/bench_kinematics.py --preset maru1 --group left_arm --repeats 9

Prints configs/s (median over repeats, with the min–max spread) for the one-at-a-time path
(`fk_jacobian(q)` with q of shape (n,)) and the batched path (`fk_jacobian(Q)`, Q of shape (N, n)) at
several batch sizes, plus FK alone, and the speed-up per configuration.  Timings are wall-clock
(time.perf_counter) on whatever machine runs it; compare rows of the same run, not across machines.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from humanoid_planner.core.model.kinematics import GroupKinematics  # noqa: E402
from humanoid_planner.core.model.robot import RobotModel  # noqa: E402


def _time(fn, repeats: int, inner: int) -> list[float]:
    """Seconds per call of fn, one value per repeat (each repeat = `inner` calls)."""
    fn()  # warm-up
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        out.append((time.perf_counter() - t0) / inner)
    return out


def run(preset: str, group: str, repeats: int, batches: list[int], seed: int) -> dict:
    robot = RobotModel.preset(preset)
    kin = GroupKinematics(robot, group)
    rng = np.random.default_rng(seed)
    Q = rng.uniform(kin.lower, kin.upper, size=(max(batches), kin.n))
    rows = []

    def add(label: str, per_call: list[float], configs_per_call: int) -> None:
        per_cfg = np.array(per_call) / configs_per_call
        rows.append({"path": label, "batch": configs_per_call,
                     "configs_per_s": float(np.median(1.0 / per_cfg)),
                     "configs_per_s_min": float(np.min(1.0 / per_cfg)),
                     "configs_per_s_max": float(np.max(1.0 / per_cfg)),
                     "us_per_config": float(np.median(per_cfg) * 1e6)})

    singles = Q[:200]
    it = iter(range(10**12))

    def one_fkj():
        kin.fk_jacobian(singles[next(it) % len(singles)])

    def one_fk():
        kin.fk(singles[next(it) % len(singles)])

    add("one at a time, FK + J", _time(one_fkj, repeats, 2000), 1)
    add("one at a time, FK", _time(one_fk, repeats, 2000), 1)
    for N in batches:
        QN = Q[:N]
        inner = max(1, 20000 // N)
        add("batched, FK + J", _time(lambda: kin.fk_jacobian(QN), repeats, inner), N)
    add("batched, FK", _time(lambda: kin.fk(Q[:1000]), repeats, 20), 1000)
    base = rows[0]["configs_per_s"]
    for r in rows:
        r["speedup_vs_one_at_a_time"] = r["configs_per_s"] / base if "FK + J" in r["path"] else None
    return {"preset": preset, "group": group, "dof": kin.n, "repeats": repeats,
            "machine": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__, "rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="armar3")
    ap.add_argument("--group", default="left_arm_torso")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--batches", type=int, nargs="+", default=[10, 100, 1000, 10000])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, help="also write the results here")
    args = ap.parse_args(argv)
    res = run(args.preset, args.group, args.repeats, args.batches, args.seed)
    print(f"{res['preset']} / {res['group']} ({res['dof']} DoF), median of {res['repeats']} repeats "
          f"[min–max]; numpy {res['numpy']}, Python {res['python']}")
    print(f"{'path':<24}{'batch':>7}{'configs/s':>14}{'  [min – max]':<24}{'µs/config':>11}{'speed-up':>10}")
    for r in res["rows"]:
        sp = f"{r['speedup_vs_one_at_a_time']:.1f}x" if r["speedup_vs_one_at_a_time"] else ""
        spread = f"  [{r['configs_per_s_min']:,.0f} – {r['configs_per_s_max']:,.0f}]"
        print(f"{r['path']:<24}{r['batch']:>7}{r['configs_per_s']:>14,.0f}{spread:<24}{r['us_per_config']:>11.2f}{sp:>10}")
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
