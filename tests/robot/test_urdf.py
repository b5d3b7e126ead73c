"""Robots from URDF: package paths, missing meshes refused, kinematics as yourdfpy's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import FK_AGREEMENT_M
from virtus.errors import InputError

pytest.importorskip("yourdfpy")

from virtus.robot.panda import panda_tree  # noqa: E402
from virtus.robot.urdf import load_urdf, parse_package_paths, resolve_mesh_path  # noqa: E402

PANDA_URDF = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda.urdf"

ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"><visual><geometry><mesh filename="{mesh}"/></geometry></visual>
    <collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="tool"><collision><geometry><cylinder radius="0.03" length="0.3"/></geometry>
    </collision></link>
  <joint name="j1" type="{kind}"><parent link="base"/><child link="tool"/>
    <origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


def _arm(folder: Path, mesh: str, kind: str = "revolute") -> Path:
    path = folder / "arm.urdf"
    path.write_text(ARM.format(mesh=mesh, kind=kind))
    return path


def _box_stl(path: Path) -> None:
    import trimesh

    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(path)


def test_package_paths_resolve_and_meshes_load(tmp_path: Path) -> None:
    _box_stl(tmp_path / "pkgs" / "arm_description" / "meshes" / "base.stl")
    urdf = _arm(tmp_path, "package://arm_description/meshes/base.stl")
    packages = parse_package_paths([f"arm_description={tmp_path / 'pkgs' / 'arm_description'}"])
    robot = load_urdf(urdf, packages)
    assert robot.tree.joint_names == ("j1",)
    meshes = robot.meshes([0.5])
    assert len(meshes) == 2  # the STL base, the tool's collision cylinder as its visual
    np.testing.assert_allclose(meshes[0].extents, (0.1, 0.1, 0.1))
    assert robot.source["package_paths"] == {"arm_description": str(packages["arm_description"])}


def test_missing_mesh_and_unknown_package_are_errors(tmp_path: Path) -> None:
    urdf = _arm(tmp_path, "package://arm_description/meshes/base.stl")
    with pytest.raises(InputError, match=r"package path for 'arm_description'"):
        load_urdf(urdf)
    (tmp_path / "pkg").mkdir()
    with pytest.raises(InputError, match=r"link base mesh .*: expected an existing mesh file"):
        load_urdf(urdf, {"arm_description": tmp_path / "pkg"})
    with pytest.raises(InputError, match="an existing mesh file"):
        resolve_mesh_path("meshes/none.stl", tmp_path, {})
    with pytest.raises(InputError, match="NAME=DIR"):
        parse_package_paths(["arm_description"])
    with pytest.raises(InputError, match="type"):
        _box_stl(tmp_path / "b.stl")
        load_urdf(_arm(tmp_path, "b.stl", kind="floating"))


def test_urdf_panda_matches_the_builtin_panda() -> None:
    robot = load_urdf(PANDA_URDF)
    builtin = panda_tree()
    assert robot.tree.joint_names == builtin.joint_names
    q = builtin.random_q(np.random.default_rng(5), 200)
    ours, theirs = robot.tree.fk(q), builtin.fk(q)
    for link in builtin.link_names:
        np.testing.assert_allclose(ours[link], theirs[link], atol=FK_AGREEMENT_M)
    assert len(robot.capsules) == 9  # links with collision shapes
    assert robot.clearance(np.array([0.0, 0.85, 0.0, -1.7, 0.0, 2.55, 0.785])) > 0
