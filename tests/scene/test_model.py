"""Scene description: defaults, YAML round trips, textures, meshes and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import yaml

from virtus.errors import InputError, VirtusError
from virtus.geometry.transforms import Pose
from virtus.scene.model import (
    BoxObject,
    Material,
    MeshObject,
    PlaneObject,
    Scene,
    SphereObject,
    TexturedPlaneObject,
    default_scene,
    load_scene,
    load_texture,
)


def write_yaml(path, data) -> str:
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_default_scene_is_the_issues_sphere_and_wall() -> None:
    scene = default_scene()
    (sphere,) = scene.objects
    assert isinstance(sphere, SphereObject)
    assert sphere.radius_m == 0.1 and sphere.center_m == (0.0, 0.0, 1.0)
    assert sphere.material.roughness == 0.95 and sphere.material.specular == 0.15
    assert scene.background is not None and scene.background.pose.t[2] == 1.3
    assert scene.ambient == 0.0


def test_yaml_round_trip_with_every_object_kind(tmp_path) -> None:
    mesh_path = tmp_path / "part.stl"
    trimesh.creation.icosphere(subdivisions=1, radius=20.0).export(mesh_path)
    texture = np.linspace(0, 1, 12).reshape(3, 4)
    scene = Scene(
        objects=[
            SphereObject(0.1, (0.0, 0.0, 1.0), Material(0.5, 0.4, 0.6, True)),
            BoxObject((0.1, 0.2, 0.3), {"euler_deg": [10, 20, 30], "t": [0, 0, 1.1]}),
            MeshObject(mesh_path, 0.001, Pose.from_euler("xyz", [0, 45, 0], t=(0, 0, 0.9))),
            TexturedPlaneObject((0.3, 0.2), texture, {"R": np.eye(3).tolist(), "t": [0, 0, 1]}),
        ],
        background=PlaneObject((2, 2), {"t": [0, 0, 1.3]}, Material(albedo=texture)),
        ambient=0.05,
    )
    path = scene.to_yaml(tmp_path / "scene.yaml")
    loaded = load_scene(path)
    assert loaded.ambient == 0.05
    a, b = scene.objects, loaded.objects
    assert b[0].material.metal and b[0].material.albedo == 0.5
    assert b[1].pose == a[1].pose
    assert b[2].path.resolve() == mesh_path.resolve() and b[2].scale_to_m == 0.001
    np.testing.assert_array_equal(b[3].texture_image(), texture)
    np.testing.assert_array_equal(loaded.background.material.albedo_image(), texture)
    # In-memory arrays went to an asset folder next to the YAML, referenced relatively.
    text = path.read_text()
    assert "scene_assets/texture_0.npy" in text and str(tmp_path) not in text


def test_texture_files_are_read_as_albedo(tmp_path) -> None:
    import cv2

    image = np.array([[0, 128, 255]], dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "t8.png"), image)
    cv2.imwrite(str(tmp_path / "t16.png"), (image.astype(np.uint16) * 257))
    np.testing.assert_allclose(load_texture(tmp_path / "t8.png"), [[0, 128 / 255, 1]])
    np.testing.assert_allclose(load_texture(tmp_path / "t16.png"), [[0, 128 / 255, 1]])
    board = TexturedPlaneObject((0.3, 0.1), tmp_path / "t8.png", material=Material(albedo=0.5))
    np.testing.assert_allclose(board.texture_image(), [[0, 64 / 255, 0.5]])


def test_mesh_loads_in_world_coordinates(tmp_path) -> None:
    path = tmp_path / "cube.obj"
    trimesh.creation.box(extents=(10.0, 20.0, 30.0)).export(path)
    pose = Pose(np.eye(3), (0.0, 0.0, 1.0))
    vertices, faces, _ = MeshObject(path, scale_to_m=0.01, pose=pose).load()
    np.testing.assert_allclose(vertices.min(axis=0), (-0.05, -0.1, 0.85))
    np.testing.assert_allclose(vertices.max(axis=0), (0.05, 0.1, 1.15))
    assert faces.shape == (12, 3)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"objects": []}, r"^scene\.objects: expected at least one object"),
        ({"ambient": 0.1}, r"^scene\.objects: expected at least one object"),
        ({"objects": [], "lamps": 1}, r"^scene\.lamps: expected no such key"),
        (
            {"objects": [{"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, 1], "colour": 1}]},
            r"^scene\.objects\.0\.colour: expected no such key",
        ),
        (
            {"objects": [{"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, 1],
                          "material": {"albedo": 0.5, "shininess": 3}}]},
            r"^scene\.objects\.0\.material\.shininess: expected no such key",
        ),
        (
            {"objects": [{"type": "plane", "size_m": [1, 1], "pose": {"R": 1}}]},
            r"^scene\.objects\.0\.pose\.R: expected an array of shape \(3, 3\)",
        ),
        (
            {"objects": [{"type": "sphere", "radius_m": -1, "center_m": [0, 0, 1]}]},
            r"^scene\.objects\.0\.radius_m: expected greater than 0",
        ),
        (
            {"objects": [{"type": "cone"}]},
            r"^scene\.objects\.0\.type: expected an object type",
        ),
        (
            {"objects": [{"type": "mesh", "path": "missing.stl"}]},
            r"^scene\.objects\.0\.path: expected an existing mesh file, got '.*missing\.stl'",
        ),
        (
            {"objects": [{"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, 1],
                          "material": {"albedo": 1.5}}]},
            r"^scene\.objects\.0\.material\.albedo: expected a number in \[0, 1\]",
        ),
    ],
)  # fmt: skip
def test_bad_scene_files_give_one_line_errors(tmp_path, data, message) -> None:
    with pytest.raises(InputError, match=message) as error:
        load_scene(write_yaml(tmp_path / "bad.yaml", data))
    assert "\n" not in str(error.value)


def test_bad_python_arguments() -> None:
    with pytest.raises(InputError, match="^SphereObject.center_m: expected 3 finite numbers"):
        SphereObject(0.1, (0, 0))
    with pytest.raises(InputError, match="^TexturedPlaneObject.texture: expected values in"):
        TexturedPlaneObject((0.1, 0.1), np.full((2, 2), 2.0))
    with pytest.raises(InputError, match="material.albedo: expected a constant"):
        TexturedPlaneObject((0.1, 0.1), np.ones((2, 2)), material=Material(np.ones((2, 2))))
    with pytest.raises(InputError, match="texture: expected an existing texture file"):
        TexturedPlaneObject((0.1, 0.1), "nope.png")
    with pytest.raises(InputError, match="scene: expected an existing YAML file"):
        load_scene("nope.yaml")
    with pytest.raises(VirtusError, match="asset folder"):
        Scene([TexturedPlaneObject((0.1, 0.1), np.ones((2, 2)))]).to_dict()


# -- garbage refused --------------------------------------------------------------------------

_SPHERE = {"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, 1]}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"objects": [{**_SPHERE, "radius_m": 1e300}]},
         r"^scene\.objects\.0\.radius_m: expected less than or equal to 1000"),
        ({"objects": [{**_SPHERE, "center_m": [0, 0, 1e9]}]},
         r"^scene\.objects\.0\.center_m: expected lengths within 1000 m"),
        ({"objects": [{"type": "box", "size_m": [0.1, 0.1, 5000]}]},
         r"^scene\.objects\.0\.size_m: expected lengths within 1000 m"),
        ({"objects": [{"type": "plane", "size_m": [1, 1], "pose": {"t": [0, 0, 1e6]}}]},
         r"^scene\.objects\.0\.pose\.t: expected coordinates within \+-1000 m"),
        ({"objects": [_SPHERE], "ambient": 1e6}, r"^scene\.ambient: expected less than or equal"),
        ({"objects": [{"type": "mesh", "path": "part.obj", "scale_to_m": 0}]},
         r"^scene\.objects\.0\.scale_to_m: expected greater than 0"),
    ],
    ids=["huge-radius", "far-centre", "huge-box", "far-pose", "ambient", "zero-scale"],
)  # fmt: skip
def test_values_out_of_bounds_are_refused(tmp_path, data, message) -> None:
    (tmp_path / "part.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=message) as error:
        load_scene(write_yaml(tmp_path / "bad.yaml", data))
    assert "\n" not in str(error.value)


def test_non_finite_numbers_are_refused_in_yaml_and_python(tmp_path) -> None:
    path = tmp_path / "nan.yaml"
    path.write_text("objects:\n  - {type: sphere, radius_m: .inf, center_m: [0, 0, 1]}\n")
    with pytest.raises(InputError, match=r"^scene .*nan\.yaml: expected finite numbers"):
        load_scene(path)
    with pytest.raises(InputError, match=r"^SphereObject\.radius_m: expected a finite number"):
        SphereObject(float("inf"), (0, 0, 1))
    with pytest.raises(InputError, match=r"^scene\.ambient: expected a finite number"):
        Scene([SphereObject(0.1, (0, 0, 1))], ambient=float("nan"))
    with pytest.raises(InputError, match=r"center_m: expected 3 finite numbers"):
        SphereObject(0.1, (0, float("nan"), 1))


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"objects:\n  - {type: sphere, radius_m: 0.1, center_m: [0, 0, 1]}\n\xff\xfe",
         r"expected UTF-8 text, got 'not UTF-8 text"),
        (b"\x00\x01binary", r"binary file"),
        (b"- type: sphere\n", r"expected a YAML mapping, got 'a YAML sequence'"),
        (b"", r"expected a YAML mapping, got 'an empty YAML document'"),
        (b"objects: [\n", r"expected valid YAML, got .* line 2, column 1"),
        (b"ambient: 0.1\nambient: 0.2\nobjects: []\n", r"expected each key once per mapping"),
    ],
    ids=["latin", "binary", "list", "empty", "syntax", "duplicate"],
)  # fmt: skip
def test_malformed_scene_files_are_refused(tmp_path, content, message) -> None:
    path = tmp_path / "bad.yaml"
    path.write_bytes(content)
    with pytest.raises(InputError, match=rf"^scene .*bad\.yaml: .*{message}") as error:
        load_scene(path)
    assert "\n" not in str(error.value)


def test_alias_bomb_scene_fails_fast(tmp_path) -> None:
    lines = ["a0: &a0 [" + ", ".join(["x"] * 9) + "]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join(lines) + "\nobjects: []\n")
    with pytest.raises(InputError, match=r"YAML nodes with aliases expanded"):
        load_scene(path)


_TRIANGLE = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\n"


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        ("v 0 0 0\nv 0.1 0 0\nv nan 0.1 0\nf 1 2 3\n",
         r"expected finite vertex coordinates, got '1 non-finite \(first #2\)'"),
        ("v 0 0 0\nv 0.1 0 0\nv 0.2 0 0\nf 1 2 3\n", r"expected a surface with area"),
        (_TRIANGLE + "f 1 2 3\nf 1 1 2\n", r"got '1 of 2 faces with zero area \(first #1\)'"),
        (_TRIANGLE + "v 0.3 0 0\nf 1 2 3\nf 1 2 4\n", r"expected no degenerate faces"),
        (_TRIANGLE + "f 1 2 9\n", r"expected a readable triangle mesh"),
        ("solid nothing\nendsolid\n", r"expected a mesh with triangles, got 'an empty mesh'"),
    ],
    ids=["nan", "zero-area", "repeated-index", "collinear", "bad-index", "empty"],
)  # fmt: skip
def test_broken_meshes_are_refused_naming_the_file(tmp_path, obj, message) -> None:
    path = tmp_path / "part.obj"
    path.write_text(obj)
    with pytest.raises(InputError, match=rf"^mesh .*part\.obj: .*{message}") as error:
        MeshObject(path).load()
    assert "\n" not in str(error.value)


def test_mesh_size_and_extent_are_bounded(tmp_path, monkeypatch) -> None:
    path = tmp_path / "part.obj"
    path.write_text(_TRIANGLE + "f 1 2 3\n")
    with pytest.raises(InputError, match=r"^mesh .*: expected vertices within \+-1000 m .*scale"):
        MeshObject(path, scale_to_m=1e6).load()
    monkeypatch.setattr("virtus.scene.model.MAX_MESH_BYTES", 10)
    with pytest.raises(
        InputError,
        match=r"^MeshObject\.path: expected a mesh file of at most 10 bytes, got '.*part\.obj \(36",
    ):
        MeshObject(path)


def test_textures_refuse_pickles_and_wrong_shapes(tmp_path) -> None:
    np.save(tmp_path / "obj.npy", np.array([None, 1], dtype=object), allow_pickle=True)
    with pytest.raises(InputError, match=r"^texture .*obj\.npy: .*pickled arrays are refused"):
        load_texture(tmp_path / "obj.npy")
    np.save(tmp_path / "flat.npy", np.zeros(4))
    with pytest.raises(InputError, match=r"expected an array of shape \(N, N\)"):
        load_texture(tmp_path / "flat.npy")
