"""Robots shared by the core tests: ARMAR-III and dual_arm (presets) and TALOS (meshes, from example-robot-data)."""
from __future__ import annotations

from pathlib import Path

import pytest

from humanoid_planner.core.model.robot import RobotModel

ROOT = Path(__file__).resolve().parents[3]
TALOS = ROOT / ".venv/lib/python3.11/site-packages/cmeel.prefix/share/example-robot-data/robots/talos_data"


@pytest.fixture(scope="module")
def armar3() -> RobotModel:
    return RobotModel.preset("armar3")


@pytest.fixture(scope="module")
def dual_arm() -> RobotModel:
    return RobotModel.preset("dual_arm")


@pytest.fixture(scope="session")
def talos() -> RobotModel:
    """One TALOS for every module: its collision model and the pair tables its checkers build (seconds
    per arm group) are shared; tests that need fresh caches load their own."""
    return RobotModel.from_urdf_srdf(TALOS / "robots/talos_reduced.urdf", TALOS / "srdf/talos.srdf")
