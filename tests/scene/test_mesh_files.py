"""Mesh files checked against their own headers before trimesh reads them
(virtus.scene.meshfiles): a truncated or malformed STL, PLY or OBJ is one InputError line
naming the file -- from the scene model, a scene YAML, and ``dataset generate`` before
anything is written -- and every mesh trimesh writes still loads."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from virtus.cli import main
from virtus.errors import InputError
from virtus.scene import meshfiles
from virtus.scene.meshfiles import check_mesh_file, load_mesh_file
from virtus.scene.model import MeshObject, load_scene

#: name -> trimesh export arguments (file type, encoding).
FORMATS = {
    "binary.stl": {},
    "ascii.stl": {"file_type": "stl_ascii"},
    "binary.ply": {},
    "ascii.ply": {"encoding": "ascii"},
    "mesh.obj": {},
}


def write_mesh(folder: Path, name: str) -> Path:
    path = folder / name
    trimesh.creation.icosphere(subdivisions=2, radius=0.05).export(path, **FORMATS[name])
    return path


def cut(path: Path, keep: float = 2 / 3, name: str | None = None) -> Path:
    """A copy of ``path`` cut to ``keep`` of its bytes."""
    data = path.read_bytes()
    out = path.with_name(name or f"cut_{path.name}")
    out.write_bytes(data[: int(len(data) * keep)])
    return out


def one_line(error: pytest.ExceptionInfo, path: Path) -> str:
    text = str(error.value)
    assert "\n" not in text and text.startswith(f"mesh {path}"), text
    return text


@pytest.mark.parametrize("name", sorted(FORMATS))
def test_every_mesh_trimesh_writes_is_accepted(tmp_path, name):
    path = write_mesh(tmp_path, name)
    assert check_mesh_file(path) == path
    vertices, faces, _ = MeshObject(path=path, pose={"t": [0, 0, 1]}).load()
    assert len(faces) == 320 and np.allclose(np.linalg.norm(vertices - [0, 0, 1], axis=1), 0.05)
    assert len(load_mesh_file(path).faces) == 320


@pytest.mark.parametrize(
    ("name", "says"),
    [
        ("binary.stl", r"expected a binary STL of 84 \+ 50 x 320 = 16084 bytes"),
        ("ascii.stl", "expected a complete ASCII STL"),
        ("binary.ply", r"bytes after the header \(its element counts\)"),
        ("ascii.ply", r"element lines after the header|a last face line with all its"),
    ],
)
@pytest.mark.parametrize("keep", [0.2, 2 / 3, 0.999])
def test_a_truncated_stl_or_ply_is_refused_naming_the_file(tmp_path, name, says, keep):
    bad = cut(write_mesh(tmp_path, name), keep)
    with pytest.raises(InputError) as error:
        check_mesh_file(bad)
    assert re.search(says, one_line(error, bad)) and "truncated" in str(error.value)
    with pytest.raises(InputError, match=str(bad)):  # the scene model, at construction
        MeshObject(path=bad)


def test_stl_headers_that_cannot_be_right(tmp_path):
    tiny = tmp_path / "tiny.stl"
    tiny.write_bytes(b"\0" * 40)
    with pytest.raises(InputError, match="at least 84 bytes"):
        check_mesh_file(tiny)
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"\0" * 84)
    with pytest.raises(InputError, match="with triangles"):
        check_mesh_file(empty)
    # a binary STL whose header happens to start with "solid" is still binary
    good = write_mesh(tmp_path, "binary.stl")
    solid = tmp_path / "solid_header.stl"
    solid.write_bytes(b"solid exported" + good.read_bytes()[14:])
    assert check_mesh_file(solid) == solid
    with pytest.raises(InputError, match="complete ASCII STL") as error:
        check_mesh_file(cut(solid, 0.5))
    assert "NUL" in str(error.value)


@pytest.mark.parametrize(
    ("header", "says"),
    [
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n", "no end_header"),
        (b"ply\nformat zip 1.0\nend_header\n", "line 2"),
        (b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", "line 3"),
        (b"ply\nelement vertex 1\nproperty float x\nend_header\n0\n", "format line"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n0\n",
         "line 4"),
        (b"not a ply at all", "a PLY header"),
    ],
)  # fmt: skip
def test_malformed_ply_headers_are_refused(tmp_path, header, says):
    path = tmp_path / "bad.ply"
    path.write_bytes(header)
    with pytest.raises(InputError, match=says) as error:
        check_mesh_file(path)
    one_line(error, path)


def test_a_binary_ply_claiming_more_faces_than_it_holds(tmp_path):
    good = write_mesh(tmp_path, "binary.ply")
    data = good.read_bytes().replace(b"element face 320", b"element face 9999", 1)
    liar = tmp_path / "liar.ply"
    liar.write_bytes(data)
    with pytest.raises(InputError, match=r"at least \d+ bytes after the header"):
        check_mesh_file(liar)


def test_obj_files_are_bounded_text(tmp_path, monkeypatch):
    good = write_mesh(tmp_path, "mesh.obj")
    binary = tmp_path / "binary.obj"
    binary.write_bytes(good.read_bytes()[:200] + b"\0\0\0" + good.read_bytes()[200:])
    with pytest.raises(InputError, match="binary data"):
        check_mesh_file(binary)
    long_line = tmp_path / "long.obj"
    long_line.write_bytes(
        b"# " + b"x" * (meshfiles.MAX_LINE_BYTES + 10) + b"\n" + good.read_bytes()
    )
    with pytest.raises(InputError, match="lines of at most"):
        check_mesh_file(long_line)
    monkeypatch.setattr(meshfiles, "MAX_OBJ_LINES", 100)
    meshfiles._checked.cache_clear()
    with pytest.raises(InputError, match="at most 100 lines"):
        check_mesh_file(good)


def test_a_scene_yaml_with_a_truncated_mesh_is_one_line(tmp_path):
    bad = cut(write_mesh(tmp_path, "binary.stl"), 0.5, "part.stl")
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump({"objects": [{"type": "mesh", "path": "part.stl"}]}))
    with pytest.raises(InputError, match=rf"{bad}.*84 \+ 50 x 320") as error:
        load_scene(scene)
    assert "\n" not in str(error.value)


def test_dataset_generate_refuses_a_truncated_mesh_before_writing(tmp_path, capsys):
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in ("a.stl", "b.ply"):
        trimesh.creation.icosphere(subdivisions=1, radius=0.03).export(folder / name)
    bad = cut(folder / "a.stl", 0.9, "c.stl")
    from virtus.geometry.devices import Camera, Projector, Rig, default_rig
    from virtus.geometry.optics import Intrinsics

    rig = default_rig()
    camera = Intrinsics(152.4, 152.4, 31.5, 23.5, 64, 48)
    Rig(Camera(camera), Projector(rig.projector.intrinsics.scaled(0.25)), rig.proj2cam).save_json(
        tmp_path / "rig.json"
    )
    config = {
        "mode": "training",
        "num_samples": 2,
        "splits": {"train": 1.0},
        "rig": {"file": "rig.json"},
        "fringes": {"codings": ["gray"], "steps": [4], "periods": [16]},
        "objects": {"sources": [{"type": "mesh_folder", "path": "meshes"}]},
    }
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config))
    out = tmp_path / "store"
    with pytest.raises(SystemExit) as exit_info:
        main(["dataset", "generate", "--config", str(tmp_path / "config.yaml"), "--out", str(out)])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and str(bad) in err, err
    assert not out.exists()
