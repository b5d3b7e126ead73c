"""Loading scenes into Mitsuba (:func:`virtus.render.mitsuba_scene.load_scene`): reused from
pose to pose, and never stale when a file it reads changes."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
import trimesh

from tests.support import small_rig
from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.render import trace
from virtus.render.mitsuba_scene import _RECENT_S, load_scene
from virtus.scene.model import MeshObject, Scene, default_scene

VARIANT = "llvm_ad_rgb"


def box_file(path, depth_m: float, age_s: float) -> Scene:  # noqa: ANN001
    """A scene of one 0.2 m box mesh whose front face is at ``depth_m`` from the camera,
    read from ``path``, the file's times set ``age_s`` seconds in the past."""
    trimesh.creation.box((0.2, 0.2, 0.2)).export(path)
    past = time.time() - age_s
    os.utime(path, (past, past))
    return Scene([MeshObject(path=path, pose=Pose(np.eye(3), (0.0, 0.0, depth_m + 0.1)))])


def centre_depth(scene: Scene) -> float:
    rig = small_rig()
    depth = trace(rig, scene, spp=1, variant=VARIANT).gt.depth
    return float(depth[rig.camera.height // 2, rig.camera.width // 2])


def test_a_scene_without_files_is_loaded_once() -> None:
    assert load_scene(VARIANT, default_scene()) is load_scene(VARIANT, default_scene())


def test_an_unchanged_mesh_file_is_loaded_once(tmp_path) -> None:
    scene = box_file(tmp_path / "box.stl", 1.0, age_s=60.0)
    assert load_scene(VARIANT, scene) is load_scene(VARIANT, scene)


def test_an_edited_mesh_file_is_loaded_again(tmp_path) -> None:
    path = tmp_path / "box.stl"
    scene = box_file(path, 1.0, age_s=60.0)
    first = load_scene(VARIANT, scene)
    assert abs(centre_depth(scene) - 1.0) < 1e-5
    # Another mesh in the same file (same size: only the vertices move), older times.
    trimesh.creation.box((0.2, 0.2, 0.2)).apply_translation((0.0, 0.0, 0.05)).export(path)
    past = time.time() - 30.0
    os.utime(path, (past, past))
    assert load_scene(VARIANT, scene) is not first
    assert abs(centre_depth(scene) - 1.05) < 1e-5


def test_a_file_modified_just_now_is_not_cached(tmp_path) -> None:
    scene = box_file(tmp_path / "box.stl", 1.0, age_s=-1.0)  # a time stamp ahead of now
    assert _RECENT_S > 0
    assert load_scene(VARIANT, scene) is not load_scene(VARIANT, scene)


def test_a_mesh_edited_to_lie_behind_the_camera_is_refused(tmp_path) -> None:
    path = tmp_path / "box.stl"
    scene = box_file(path, 1.0, age_s=60.0)
    centre_depth(scene)  # in front: rendered (and its bounds kept)
    trimesh.creation.box((0.2, 0.2, 0.2)).apply_translation((0.0, 0.0, -3.0)).export(path)
    past = time.time() - 30.0
    os.utime(path, (past, past))
    with pytest.raises(InputError, match="in front of the camera"):
        centre_depth(scene)


def _reflectance(image: np.ndarray):  # noqa: ANN202
    """The Mitsuba texture the renderer makes for an albedo image."""
    from virtus.render.backend import mitsuba
    from virtus.render.mitsuba_scene import bsdf_dict
    from virtus.scene.model import Material

    mi, _, _ = mitsuba(VARIANT)
    return bsdf_dict(mi, Material(specular=0.0), albedo=image)["bsdf"]["reflectance"]


def test_a_read_only_image_keeps_its_texture_until_it_can_change() -> None:
    image = np.full((8, 8), 0.5)
    image.setflags(write=False)  # owns its data: nothing can change it now
    texture = _reflectance(image)
    assert _reflectance(image) is texture
    image.setflags(write=True)
    image[2, 3] = 0.25
    changed = _reflectance(image)
    assert changed is not texture
    assert _reflectance(image) is changed  # writeable: reused while its contents are equal
    image[2, 3] = 0.75
    assert _reflectance(image) is not changed


def test_a_read_only_view_of_a_writeable_array_is_compared_by_contents() -> None:
    base = np.full((8, 8), 0.5)
    view = base[:, :]
    view.setflags(write=False)  # read-only, but its base can still change it
    texture = _reflectance(view)
    assert _reflectance(view) is texture
    base[0, 0] = 0.0
    assert _reflectance(view) is not texture
