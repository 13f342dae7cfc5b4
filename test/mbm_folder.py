"""Shared by the benchmark tests: the test arm as a MotionBenchMaker robot folder."""
from __future__ import annotations

from pathlib import Path

import yaml


def mbm_robot_dir(root: Path, description: tuple[str, str], scene: dict, requests: list[dict]) -> Path:
    """`root`/test_arm laid out as the MotionBenchMaker sets are: test_arm.urdf + .srdf and
    problems/box_test_arm/sceneNNNN.yaml + requestNNNN.yaml, problem k (1-based) = requests[k - 1] in `scene`."""
    d = root / "test_arm"
    problems = d / "problems" / "box_test_arm"
    problems.mkdir(parents=True)
    urdf, srdf = description
    (d / "test_arm.urdf").write_text(urdf)
    (d / "test_arm.srdf").write_text(srdf)
    for k, req in enumerate(requests, start=1):
        (problems / f"scene{k:04d}.yaml").write_text(yaml.safe_dump(scene))
        (problems / f"request{k:04d}.yaml").write_text(yaml.safe_dump(req))
    return d


def joint_request(start: list[float], goal: tuple[tuple[str, float], ...]) -> dict:
    """A MotionPlanRequest of the test arm's group from `start` to the joint goal `goal` ((name, value)...)."""
    return {"group_name": "arm",
            "start_state": {"joint_state": {"name": ["shoulder", "elbow", "wrist"], "position": list(start)}},
            "goal_constraints": [{"joint_constraints": [{"joint_name": n, "position": v} for n, v in goal]}]}
