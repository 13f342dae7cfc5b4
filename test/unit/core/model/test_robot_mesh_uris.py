"""Mesh URIs resolve as on a ROS robot: `package://` through the ament index, `file://`,
absolute and relative paths; a mesh that cannot be found is a load error that names its URI."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from humanoid_planner.core.model.robot import RobotModel, RobotModelError

URDF = """<?xml version="1.0"?>
<robot name="one_mesh">
  <link name="base"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="arm"><collision><geometry><mesh filename="{uri}" scale="2 2 2"/></geometry></collision></link>
  <joint name="turn" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
</robot>"""
BOX = (0.3, 0.04, 0.05)


def _ament_prefix(root, pkg: str = "arm_description", marker: bool = True):
    """A minimal ament prefix: share/<pkg>/meshes/arm.stl and (optionally) the index marker."""
    share = root / "share" / pkg
    (share / "meshes").mkdir(parents=True)
    trimesh.creation.box(BOX).export(share / "meshes" / "arm.stl")
    if marker:
        index = root / "share" / "ament_index" / "resource_index" / "packages"
        index.mkdir(parents=True)
        (index / pkg).touch()
    return share / "meshes" / "arm.stl"


def _mesh_extent(robot: RobotModel) -> np.ndarray:
    (g,) = robot.collision_geometry["arm"]
    assert g.kind == "mesh"
    return g.vertices.max(axis=0) - g.vertices.min(axis=0)


def test_package_uri_through_the_ament_index(tmp_path, monkeypatch):
    _ament_prefix(tmp_path / "other", pkg="unrelated")  # an earlier prefix without the package is skipped
    _ament_prefix(tmp_path / "install")
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{tmp_path / 'other'}:{tmp_path / 'install'}")
    robot = RobotModel.from_urdf_srdf(URDF.format(uri="package://arm_description/meshes/arm.stl"))
    np.testing.assert_allclose(_mesh_extent(robot), 2 * np.array(BOX))  # the file, scaled


def test_package_not_in_the_index_names_the_uri(tmp_path, monkeypatch):
    _ament_prefix(tmp_path, marker=False)  # share/<pkg> exists, but the index does not list it
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    uri = "package://arm_description/meshes/arm.stl"
    with pytest.raises(RobotModelError, match=f"mesh not found: {uri}: package 'arm_description' is not in the "
                                              "ament index"):
        RobotModel.from_urdf_srdf(URDF.format(uri=uri))


def test_missing_file_in_a_known_package_names_the_uri(tmp_path, monkeypatch):
    _ament_prefix(tmp_path)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    uri = "package://arm_description/meshes/forearm.stl"
    with pytest.raises(RobotModelError, match=f"mesh not found: {uri}: no file .*forearm.stl"):
        RobotModel.from_urdf_srdf(URDF.format(uri=uri))


def test_package_folder_above_a_urdf_file(tmp_path, monkeypatch):
    """Not in the index (no workspace sourced): the package folder among the URDF file's parents."""
    _ament_prefix(tmp_path, marker=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = tmp_path / "share" / "arm_description" / "urdf" / "robot.urdf"
    urdf.parent.mkdir()
    urdf.write_text(URDF.format(uri="package://arm_description/meshes/arm.stl"))
    np.testing.assert_allclose(_mesh_extent(RobotModel.from_urdf_srdf(urdf)), 2 * np.array(BOX))


def test_file_uri_absolute_and_relative_paths(tmp_path, monkeypatch):
    mesh = _ament_prefix(tmp_path)
    for uri in (f"file://{mesh}", str(mesh)):
        np.testing.assert_allclose(_mesh_extent(RobotModel.from_urdf_srdf(URDF.format(uri=uri))), 2 * np.array(BOX))
    # relative: against the URDF's folder when it is a file ...
    urdf = mesh.parent.parent / "urdf" / "robot.urdf"
    urdf.parent.mkdir()
    urdf.write_text(URDF.format(uri="../meshes/arm.stl"))
    np.testing.assert_allclose(_mesh_extent(RobotModel.from_urdf_srdf(urdf)), 2 * np.array(BOX))
    # ... and against the working directory for URDF text (ROS's resource_retriever does the same)
    monkeypatch.chdir(mesh.parent)
    np.testing.assert_allclose(_mesh_extent(RobotModel.from_urdf_srdf(URDF.format(uri="arm.stl"))), 2 * np.array(BOX))
    with pytest.raises(RobotModelError, match="mesh not found: file:///nowhere/arm.stl: no file /nowhere/arm.stl"):
        RobotModel.from_urdf_srdf(URDF.format(uri="file:///nowhere/arm.stl"))
    with pytest.raises(RobotModelError, match="mesh not found: meshes/hand.stl"):
        RobotModel.from_urdf_srdf(URDF.format(uri="meshes/hand.stl"))


def test_unreadable_mesh_names_the_uri(tmp_path):
    bad = tmp_path / "arm.stl"
    bad.write_text("solid nothing\nendsolid nothing\n")
    with pytest.raises(RobotModelError, match=f"mesh {bad}"):
        RobotModel.from_urdf_srdf(URDF.format(uri=str(bad)))


def test_talos_text_with_package_meshes_through_a_temporary_prefix(example_robot_data, tmp_path, monkeypatch):
    """TALOS handed over as text (as on the robot_description topic): its package://example-robot-data
    meshes resolve only through the ament index."""
    urdf = (example_robot_data / "share/example-robot-data/robots/talos_data/robots/talos_reduced.urdf").read_text()
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    with pytest.raises(RobotModelError, match="mesh not found: package://example-robot-data/robots/talos_data/meshes/"):
        RobotModel.from_urdf_srdf(urdf)
    share = tmp_path / "share"
    (share / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (share / "ament_index" / "resource_index" / "packages" / "example-robot-data").touch()
    (share / "example-robot-data").symlink_to(example_robot_data / "share" / "example-robot-data")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    robot = RobotModel.from_urdf_srdf(urdf)
    meshes = [g for shapes in robot.collision_geometry.values() for g in shapes if g.kind == "mesh"]
    assert len(meshes) > 20


def test_package_uri_in_a_folder_of_packages(tmp_path, monkeypatch):
    """Robot files shipped without a ROS workspace (`package://meshes/...` beside the URDF): the package is
    looked up in the given folders of packages after the ament index, and a worker process reloading the
    robot from `source` finds it the same way."""
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    robot_dir = tmp_path / "robot"
    (robot_dir / "meshes").mkdir(parents=True)
    trimesh.creation.box(BOX).export(robot_dir / "meshes" / "arm.stl")
    urdf = robot_dir / "robot.urdf"
    urdf.write_text(URDF.format(uri="package://meshes/arm.stl"))
    with pytest.raises(RobotModelError, match="mesh not found: package://meshes/arm.stl: .* nor a folder above"):
        RobotModel.from_urdf_srdf(urdf)
    with pytest.raises(RobotModelError, match=f"nor in the package folders {tmp_path}"):
        RobotModel.from_urdf_srdf(urdf, package_dirs=[tmp_path])
    robot = RobotModel.from_urdf_srdf(urdf, package_dirs=[tmp_path / "elsewhere", robot_dir])
    np.testing.assert_allclose(_mesh_extent(robot), 2 * np.array(BOX))
    np.testing.assert_allclose(_mesh_extent(RobotModel.from_urdf_srdf(*robot.source)), 2 * np.array(BOX))


def test_the_ament_index_comes_before_the_package_folders(tmp_path, monkeypatch):
    """A user with a sourced workspace gets the installed package, whatever folders are also given."""
    _ament_prefix(tmp_path / "install", pkg="meshes")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    decoy = tmp_path / "pkgs" / "meshes" / "meshes"  # the same URI in a folder of packages: another mesh
    decoy.mkdir(parents=True)
    trimesh.creation.box((0.1, 0.1, 0.1)).export(decoy / "arm.stl")
    robot = RobotModel.from_urdf_srdf(URDF.format(uri="package://meshes/meshes/arm.stl"), package_dirs=[tmp_path / "pkgs"])
    np.testing.assert_allclose(_mesh_extent(robot), 2 * np.array(BOX))
