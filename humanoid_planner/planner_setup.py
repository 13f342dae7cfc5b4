"""`planner_setup`: write a MoveIt SRDF (groups, end effectors, home, disabled collision pairs) for a
robot that ships none, or whose SRDF has no groups — as MoveIt Setup Assistant would
(core/model/srdf_setup.py says how). No ROS needed.

    planner_setup ROBOT.urdf [--srdf INPUT.srdf] -o OUT.srdf [--params OUT.yaml]
                  [--left-shoulder LINK --left-hand LINK --right-shoulder LINK --right-hand LINK]
                  [--samples 10000] [--seed 0] [--home-state NAME]

--params writes a planner_node parameter file holding the URDF and the new SRDF
(`robot_description`, `robot_description_semantic`), for `planner_node --ros-args --params-file`.
Exit status: 0 written, 1 the robot cannot be loaded or its arms not found (one line says why).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from humanoid_planner.core.model.robot import RobotModelError
from humanoid_planner.core.model.srdf_setup import DEFAULT_SAMPLES, SIDES, SetupError, generate_srdf


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="planner_setup", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("urdf", type=Path, help="the robot's URDF file")
    ap.add_argument("--srdf", type=Path, help="the robot's own SRDF, if any: its disabled pairs, reference "
                    "pose and other elements are merged into the output")
    ap.add_argument("-o", "--output", type=Path, required=True, help="where to write the SRDF")
    ap.add_argument("--params", type=Path, help="also write a planner_node parameter file (URDF + this SRDF)")
    for side in SIDES:
        ap.add_argument(f"--{side}-shoulder", metavar="LINK", help=f"first link of the {side} arm (child of its "
                        "first joint); default: detected")
        ap.add_argument(f"--{side}-hand", metavar="LINK", help=f"the {side} arm's TCP link; default: detected "
                        "(a tool frame at the hand, else the hand link)")
    ap.add_argument("--samples", type=int, default=DEFAULT_SAMPLES, help="random configurations for the never / "
                    f"always colliding pairs (default {DEFAULT_SAMPLES}, Setup Assistant's)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the sampled configurations")
    ap.add_argument("--home-state", metavar="NAME", help="the input SRDF's group_state to use as home (default: "
                    "its 'home', else 'half_sitting', else its first)")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    if a.samples < 0:
        print("planner_setup: --samples must be >= 0", file=sys.stderr)
        return 1
    shoulders = {s: v for s in SIDES if (v := getattr(a, f"{s}_shoulder"))}
    hands = {s: v for s in SIDES if (v := getattr(a, f"{s}_hand"))}
    t0 = time.perf_counter()
    try:
        res = generate_srdf(a.urdf, a.srdf, shoulders=shoulders, hands=hands, samples=a.samples, seed=a.seed,
                            home_state=a.home_state)
    except (RobotModelError, SetupError, OSError) as e:
        print(f"planner_setup: {e}", file=sys.stderr)
        return 1
    a.output.parent.mkdir(parents=True, exist_ok=True)
    a.output.write_text(res.srdf)
    for arm in res.arms:
        print(f"{arm.side + '_' if arm.side else ''}arm: {arm.base_link} -> {arm.tcp_link} (shoulder {arm.shoulder_link})")
    print(f"torso: {'from ' + res.waist_base if res.waist_base else 'none (no joint between the root and the arms)'}")
    print(f"home: {res.home_source}")
    print("disabled collision pairs: " + ", ".join(f"{n} {r}" for r, n in sorted(res.disabled.items()))
          + f" ({a.samples} samples, {time.perf_counter() - t0:.1f} s)")
    print(f"wrote {a.output}")
    if a.params is not None:
        import yaml

        a.params.parent.mkdir(parents=True, exist_ok=True)
        a.params.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
            "robot_description": a.urdf.read_text(), "robot_description_semantic": res.srdf}}}, width=1 << 30))
        print(f"wrote {a.params}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
