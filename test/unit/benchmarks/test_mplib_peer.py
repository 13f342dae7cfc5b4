"""bench_mbm.py's MPlib plumbing without MPlib: the problem batch survives its JSON round trip (obstacles in the
planning frame, goals within the start slack clipped), the URDF copy MPlib is given, the verification of the
peer's answers and the pairing that counts only MPlib paths that verify (a stand-in peer process answers)."""
from __future__ import annotations

import json
import re
import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_mbm  # noqa: E402
import mplib_peer  # noqa: E402
from mbm_folder import joint_request, mbm_robot_dir  # noqa: E402  (test/mbm_folder.py)

SCENE = {"world": {"collision_objects": [
    {"id": "post", "header": {"frame_id": "base_link"},
     "primitives": [{"type": "box", "dimensions": [0.05, 0.05, 0.6]},
                    {"type": "cylinder", "dimensions": [0.3, 0.02]}],
     "primitive_poses": [{"position": [0.0, 0.35, 0.3], "orientation": [0, 0, 0, 1]},
                         {"position": [0.1, -0.4, 0.2], "orientation": [0, 0.7071068, 0, 0.7071068]}]}]}}
GOAL = (("shoulder", 0.9), ("elbow", 0.6), ("wrist", 3.00005))  # the wrist within the start slack past +3.0


@pytest.fixture
def robot_dir(tmp_path, test_robot_description) -> Path:
    req = joint_request([-0.5, 0.2, 0.0], GOAL)
    return mbm_robot_dir(tmp_path, test_robot_description, SCENE, [req, req])


def problems(robot_dir: Path):
    robot = bench_mbm.load_robot(robot_dir)
    return robot, [bench_mbm.load_problem(robot, robot_dir / "problems" / "box_test_arm", k, 0.0) for k in (1, 2)]


def test_batch_round_trip(robot_dir):
    robot, probs = problems(robot_dir)
    batch = bench_mbm.mplib_batch(robot, Path("/x/a.urdf"), Path("/x/a.srdf"), probs, 7.5)
    back = mplib_peer.batch_from_json(json.loads(json.dumps(mplib_peer.batch_to_json(batch))))
    assert (back.urdf, back.srdf, back.move_group) == ("/x/a.urdf", "/x/a.srdf", "tcp")
    assert back.group_joints == ("shoulder", "elbow", "wrist") and back.joint_names == tuple(robot.joint_names)
    np.testing.assert_allclose(back.max_velocity, [1.5, 1.5, 2.0])
    assert [p.index for p in back.problems] == [1, 2] and all(p.budget == 7.5 for p in back.problems)
    p = back.problems[0]
    np.testing.assert_allclose(p.goal, [0.9, 0.6, 3.0])  # clipped onto the bound, as the planner takes it
    np.testing.assert_allclose(p.start, probs[0].start)
    assert [(o.kind, o.dims) for o in p.obstacles] == [("box", (0.05, 0.05, 0.6)), ("cylinder", (0.3, 0.02))]
    objs = probs[0].scene.objects
    expected = [o.pose @ s.pose for o in objs for s in o.shapes]
    for o, T in zip(p.obstacles, expected):
        np.testing.assert_allclose(o.pose, T, atol=1e-12)
    np.testing.assert_allclose(p.obstacles[1].pose[:3, 3], [0.1, -0.4, 0.2], atol=1e-12)
    with pytest.raises(ValueError, match="format"):
        mplib_peer.batch_from_json({**mplib_peer.batch_to_json(batch), "format": 0})


def test_resolved_urdf_for_mplib(tmp_path):
    robot_dir = tmp_path / "bot"
    (robot_dir / "meshes").mkdir(parents=True)
    (robot_dir / "meshes" / "a.obj").write_text("mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl 1 2\n")
    (robot_dir / "meshes" / "b.stl").write_text("solid b\nendsolid b\n")
    geom = ('<visual><geometry><mesh filename="package://meshes/missing.dae"/></geometry></visual><collision>'
            '<geometry><mesh filename="package://meshes/{}"/></geometry></collision>')
    (robot_dir / "bot.urdf").write_text(f'<robot name="bot"><link name="l0">{geom.format("a.obj")}</link>'
                                        f'<link name="l1">{geom.format("b.stl")}</link></robot>')
    dest = tmp_path / "out"
    dest.mkdir()
    text = bench_mbm.resolved_urdf(robot_dir, dest).read_text()
    assert "<visual" not in text and "package://" not in text
    files = [(dest / f).resolve() for f in re.findall(r'filename="([^"]+)"', text)]
    assert files[1] == (robot_dir / "meshes" / "b.stl").resolve()
    assert files[0].parent == (dest / "meshes").resolve()  # a copy without the line element
    assert files[0].read_text() == "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


FAKE_PEER = '''#!{python}
"""Answers a batch as mplib_peer does: problem 1 with the straight path to the goal, problem 2 stopping short."""
import json, sys
from pathlib import Path
sys.path.insert(0, str(Path(sys.argv[1]).parent))
import numpy as np
from mplib_peer import batch_from_json
b = batch_from_json(json.loads(Path(sys.argv[2]).read_text()))
idx = [b.joint_names.index(n) for n in b.group_joints]
out = []
for p, t in zip(b.problems, (0.5, 0.25)):
    end = p.goal[idx] if p.index == 1 else 0.5 * (p.start[idx] + p.goal[idx])
    wp = np.array([p.start[idx], end])
    out.append({{"index": p.index, "seed": p.seed, "ok": True, "status": "success", "message": "Success",
                "time": t, "cpu": t, "ompl_time": t, "waypoints": wp.tolist(),
                "trajectory": {{"times": [0.0, 10.0], "positions": wp.tolist(), "velocities": np.zeros_like(wp).tolist(),
                               "accelerations": np.zeros_like(wp).tolist()}}}})
Path(sys.argv[3]).write_text(json.dumps({{"format": 1, "mplib": "fake", "numpy": np.__version__, "import_s": 0,
                                          "load_s": 0, "warm_up_s": None, "results": out}}))
'''


def test_answers_verified_and_only_verified_paths_paired(robot_dir, tmp_path):
    robot, probs = problems(robot_dir)
    fake = tmp_path / "fake_python"
    fake.write_text(FAKE_PEER.format(python=sys.executable))
    fake.chmod(0o755)
    recs, meta = bench_mbm.run_mplib(robot, robot_dir, probs, 5.0, fake)
    assert meta["mplib"] == "fake"
    assert [r["ok"] for r in recs] == [True, True]
    assert recs[0]["verify_problems"] == [] and recs[0]["verify_trajectory"] == []
    assert any("TCP misses" in x for x in recs[1]["verify_problems"])
    mp = bench_mbm.summarize("test_arm", "box", "mplib", recs)
    assert mp["verified"]["valid"] == 1 and mp["verified_trajectory"] == {"checked": 2, "valid": 1}
    girrt = {"problems": [{"seed": k, "ok": True, "time": 0.1} for k in (1, 2)]}
    assert bench_mbm.mplib_pairing(girrt, mp) == (pytest.approx(0.2), 1)  # 0.1 / 0.5; problem 2's path fails
    assert bench_mbm.paired_ratio(girrt, mp) == (pytest.approx(0.3), 2)  # what counting unverified paths gives


def test_missing_venv_says_how_to_make_it(robot_dir, tmp_path, capsys):
    with pytest.raises(SystemExit):
        bench_mbm.main(["--robot-dir", str(robot_dir), "--planners", "girrt,mplib", "--out", str(tmp_path),
                        "--mplib-python", os.fspath(tmp_path / "no" / "python")])
    assert "make mplib-venv" in capsys.readouterr().err
