"""The package as users install it, not as `make setup` links it: a built wheel installed with
`pip install --target`, and the `setup.py install` into a prefix that `colcon build` (without
--symlink-install) runs. Each copy lies outside the source tree, imports every module of the package
from itself, reads its presets and config from its own share/ folder, and plans.

The venv's editable install maps `humanoid_planner` to a checkout and would quietly supply any module
a broken install lacks, so the wheel's planning process drops it, and both tests compare the
installed modules with the source's.

Both copies get the checkout's compiled collision kernels (numba's cache; compiling them from nothing
is what `make test` does before pytest, the same code wherever the source lies), so neither spends ~15 s of a
core compiling them again.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from conftest import PlannerProcess

from humanoid_planner.child_env import child_environment

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
BUILD_INPUTS = ("setup.py", "setup.cfg", "package.xml", "resource", "config", "humanoid_planner")
"""What setup.py reads. Built from a copy, because a build writes build/ and *.egg-info next to setup.py."""
STARTUP_TIMEOUT = 90.0
"""s: interpreter start, the ROS wheels' re-exec, loading the preset and, when the checkout has no compiled
collision kernels to copy (seed_kernel_cache), compiling them (~15 s on a quiet 2-core machine, twice that under load)."""
RESULT = "RESULT "

PLAN_FROM_INSTALLED = r"""
import importlib, json, pkgutil, sys
from pathlib import Path

site = Path(sys.argv[1]).resolve()
# nothing but the installed copy may provide the package: not the editable install's finder, not a
# path entry holding another copy (a checkout)
sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, "__module__", "").startswith("__editable__")]
sys.path[:] = [p for p in sys.path
               if Path(p or ".").resolve() == site or not (Path(p or ".") / "humanoid_planner").exists()]

import humanoid_planner
import humanoid_planner.node_main  # the entry point of `planner_node`

modules = sorted(m.name for m in pkgutil.walk_packages(humanoid_planner.__path__, "humanoid_planner."))
for name in modules:
    importlib.import_module(name)

from humanoid_planner.core.model.presets import preset_dir
from humanoid_planner.core.model.robot import RobotModel
from humanoid_planner.core.pipeline.planner import GraspPlanner, GraspPlanRequest
from humanoid_planner.core.verification import verify_plan
from humanoid_planner.scenarios import OBJECT_ID, make_scenario

group = "left_arm_torso"
robot = RobotModel.preset("armar3")
sc = make_scenario(robot, "boxes6", 1, hand="left")
req = GraspPlanRequest(group, robot.home.copy(), sc.object_pose, sc.left_grasps, object_id=OBJECT_ID, seed=1,
                       timeout=10.0)
plan = GraspPlanner(robot, workers=1).plan_grasp(sc.scene, req)
problems = (verify_plan(robot, sc.scene, (group,), robot.home, plan,
                        tuple(sc.object_pose @ g.tcp_in_object for g in plan.grasps), object_id=OBJECT_ID)
            if plan.ok else [plan.message])
files = sorted({m.__file__ for n, m in list(sys.modules.items())
                if n == "humanoid_planner" or n.startswith("humanoid_planner.")})
print("RESULT " + json.dumps({"modules": modules, "files": files, "presets": str(preset_dir("armar3")),
                              "status": plan.status.name, "problems": problems}))
"""


def source_modules() -> list[str]:
    """Dotted names of the package's modules in the source tree (packages included, the top one not)."""
    names = []
    for p in (REPO / "humanoid_planner").rglob("*.py"):
        parts = p.relative_to(REPO).with_suffix("").parts
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(n for n in names if n != "humanoid_planner")


def installed_modules(site: Path) -> list[str]:
    names = []
    for p in (site / "humanoid_planner").rglob("*.py"):
        parts = p.relative_to(site).with_suffix("").parts
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(n for n in names if n != "humanoid_planner")


def child_env(pythonpath: Path, **extra: str) -> dict[str, str]:
    """This environment with the installed copy as the only PYTHONPATH entry (the test run's own may
    name a checkout) and the ROS wheels' bootstrapper free to set up the child's library path."""
    return child_environment({"PYTHONPATH": str(pythonpath), **extra})


def seed_kernel_cache(site: Path) -> None:
    """Copy the checkout's numba cache of the compiled kernels (collision, searches, IK: `make test` compiles
    them first; without one the installed copy compiles) next to the installed kernels.py files. numba keys the
    cache by the source's content, which the install copied unchanged, so the copy loads it (~0.5 s) instead
    of compiling (~15 s)."""
    for part in ("collision", "planners", "ik"):
        src = REPO / "humanoid_planner" / "core" / part / "__pycache__"
        dst = site / "humanoid_planner" / "core" / part / "__pycache__"
        dst.mkdir(exist_ok=True)
        for f in [*src.glob("kernels.*.nbi"), *src.glob("kernels.*.nbc")]:
            shutil.copy2(f, dst / f.name)


def run(args: list[str], cwd: Path, env: dict[str, str] | None = None, timeout: float = 120.0) -> str:
    res = subprocess.run(args, cwd=str(cwd), env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{' '.join(args)}: exit {res.returncode}\n{res.stdout}\n{res.stderr}"
    return res.stdout


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory) -> Path:
    src = tmp_path_factory.mktemp("source") / "humanoid_planner"
    src.mkdir()
    for name in BUILD_INPUTS:
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(REPO / name, src / name)
    return src


@dataclass
class WheelPlan:
    """The wheel installed with `pip install --target` into `site`, and the planning process started from it."""

    site: Path
    proc: subprocess.Popen
    log: Path

    def output(self, timeout: float) -> str:
        """The process's stdout once it has exited 0 (the test fails with its output otherwise)."""
        code = self.proc.wait(timeout=timeout)
        text = self.log.read_text()
        assert code == 0, f"planning from the installed wheel: exit {code}\n{text}"
        return text


@pytest.fixture(scope="module")
def wheel_plan(source_copy, tmp_path_factory) -> WheelPlan:
    """Build and install the wheel, then start planning from it in the background, on the other core
    while the colcon test below runs."""
    tmp = tmp_path_factory.mktemp("wheel")
    dist, site, cwd = tmp / "dist", tmp / "site", tmp / "cwd"
    cwd.mkdir()
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check"]
    run([*pip, "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(dist), str(source_copy)], cwd)
    (wheel,) = dist.glob("humanoid_planner-*.whl")
    run([*pip, "install", "-q", "--no-deps", "--target", str(site), str(wheel)], cwd)
    seed_kernel_cache(site)
    log = tmp / "plan.log"
    # AMENT_PREFIX_PATH = the dev venv: where `make setup` links share/humanoid_planner/config to a
    # checkout; the installed copy must still read its own share/
    with log.open("w") as out:
        proc = subprocess.Popen([sys.executable, "-c", PLAN_FROM_INSTALLED, str(site)], cwd=str(cwd),
                                env=child_env(site, AMENT_PREFIX_PATH=sys.prefix), stdout=out,
                                stderr=subprocess.STDOUT, text=True)
    try:
        yield WheelPlan(site, proc, log)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.usefixtures("wheel_plan")  # the wheel plans on the other core meanwhile
def test_colcon_style_install_runs_the_node_which_plans(source_copy, tmp_path, ros_domain_id):
    """What `colcon build` does for an ament_python package without --symlink-install, then
    `ros2 run humanoid_planner planner_node` and `grasp_client` from that install, as a sourced
    workspace would run them (PYTHONPATH and AMENT_PREFIX_PATH naming the install prefix)."""
    build, prefix, cwd = tmp_path / "build", tmp_path / "install", tmp_path / "cwd"
    build.mkdir()
    cwd.mkdir()
    site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    site.mkdir(parents=True)  # colcon creates it and puts it on PYTHONPATH before `setup.py install`
    run([sys.executable, "setup.py", "egg_info", "--egg-base", os.path.relpath(build, source_copy),
         "build", "--build-base", str(build / "build"),
         "install", "--prefix", str(prefix), "--record", str(build / "install.log"),
         "--single-version-externally-managed"], source_copy, child_env(site))
    assert installed_modules(site) == source_modules()
    share = prefix / "share" / "humanoid_planner"
    for f in ("package.xml", "config/planner.yaml", "config/robots/armar3.urdf", "config/robots/armar3.srdf",
              "config/examples/plan_grasp_object_pose.yaml"):
        assert (share / f).is_file(), f
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "humanoid_planner").is_file()
    libexec = prefix / "lib" / "humanoid_planner"  # where `ros2 run` looks (setup.cfg's install_scripts)
    for exe in ("planner_node", "grasp_client", "planner_demo", "planner_setup"):
        assert os.access(libexec / exe, os.X_OK), exe

    seed_kernel_cache(site)
    amend = os.pathsep.join(p for p in (str(prefix), os.environ.get("AMENT_PREFIX_PATH", "")) if p)
    env = child_env(site, AMENT_PREFIX_PATH=amend)
    log_dir = tmp_path / "node"
    log_dir.mkdir()
    proc = PlannerProcess(libexec / "planner_node", [share / "config" / "planner.yaml"], log_dir,
                          ["-p", "robot:=armar3"], env, cwd=cwd)
    try:
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while "ready" not in proc.output():
            assert proc.proc.poll() is None and time.monotonic() < deadline, f"no 'ready':\n{proc.output()}"
            time.sleep(0.1)
        assert "from preset 'armar3'" in proc.output()
        # the shipped example request, from the installed share/, answered SUCCESS (exit 0)
        example = share / "config" / "examples" / "plan_grasp_object_pose.yaml"
        out = run([str(libexec / "grasp_client"), "plan_grasp", str(example), "--wait", str(STARTUP_TIMEOUT),
                   "--brief"], cwd, env)
        assert yaml.safe_load(out)["error_code"]["val"] == 1, out
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=15) == 0, proc.output()
        assert "Traceback" not in proc.output(), proc.output()
    finally:
        proc.stop()


def test_wheel_installed_elsewhere_imports_finds_its_presets_and_plans(wheel_plan):
    site = wheel_plan.site
    assert installed_modules(site) == source_modules()
    out = wheel_plan.output(timeout=STARTUP_TIMEOUT + 60.0)
    result = json.loads(next(line for line in out.splitlines() if line.startswith(RESULT))[len(RESULT):])
    assert result["modules"] == source_modules()  # every module imported from the installed copy
    outside = [f for f in result["files"] if not Path(f).is_relative_to(site)]
    assert not outside, f"modules not from the installed copy: {outside}"
    assert Path(result["presets"]) == site / "share" / "humanoid_planner" / "config" / "robots"
    assert result["status"] == "SUCCESS" and result["problems"] == [], result
