"""Capture directories (save/load round trip) and the ``virtus capture`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from tests.test_render_support import small_rig
from virtus.capture import GT_NAMES, load_capture, save_capture
from virtus.cli import main
from virtus.errors import VirtusError
from virtus.patterns import default_sequence
from virtus.render import render
from virtus.scene import Scene, SphereObject, TexturedPlaneObject
from virtus.transforms import Pose


@pytest.fixture(scope="module")
def captured():
    rig, sequence = small_rig(), default_sequence()
    board = TexturedPlaneObject((0.2, 0.1), np.eye(4) * 0.5 + 0.25, Pose(np.eye(3), (0, 0, 1.2)))
    scene = Scene([SphereObject(0.05, (0, 0, 1.0)), board])
    return rig, sequence, scene, render(rig, scene, sequence, bit_depth=16)


def test_capture_round_trip(tmp_path, captured) -> None:
    rig, sequence, scene, rendering = captured
    manifest = save_capture(tmp_path / "cap", rendering, rig=rig, sequence=sequence, scene=scene)
    data = json.loads(manifest.read_text())
    assert data["rig"] == rig.to_dict() and data["units"]["length"] == "m"
    assert data["render"]["spp"] == 4 and data["render"]["bit_depth"] == 16
    assert data["frames"]["files"][:2] == ["frames/000.png", "frames/001.png"]

    loaded = load_capture(tmp_path / "cap")
    np.testing.assert_array_equal(loaded.frames, rendering.frames)
    assert loaded.frames.dtype == np.uint16
    assert loaded.rig.to_dict() == rig.to_dict()
    assert loaded.sequence == sequence
    np.testing.assert_array_equal(
        loaded.scene.objects[1].texture_image(), scene.objects[1].texture_image()
    )
    assert set(loaded.gt) == set(GT_NAMES)
    for name, array in rendering.gt.arrays().items():
        np.testing.assert_array_equal(loaded.gt[name], array)
    np.testing.assert_array_equal(loaded.ground_truth.mask, rendering.gt.mask)
    assert loaded.metadata["render"]["exposure_dn_per_radiance"] == rendering.exposure

    # The directory can be moved: paths inside capture.json are relative.
    (tmp_path / "cap").rename(tmp_path / "moved")
    moved = load_capture(tmp_path / "moved", load_gt=False)
    assert moved.gt == {} and moved.scene is not None


def test_existing_capture_needs_overwrite(tmp_path, captured) -> None:
    rig, sequence, scene, rendering = captured
    save_capture(tmp_path, rendering, rig=rig, sequence=sequence)
    with pytest.raises(VirtusError, match="already holds a capture"):
        save_capture(tmp_path, rendering, rig=rig, sequence=sequence)
    save_capture(tmp_path, rendering, rig=rig, sequence=sequence, overwrite=True)
    assert load_capture(tmp_path).scene is None


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    captured = capsys.readouterr()
    return exit_info.value.code, captured.out, captured.err


def test_cli_capture_writes_the_layout(tmp_path, capsys) -> None:
    rig_path = small_rig().save_json(tmp_path / "rig.json")
    out = tmp_path / "cap"
    code, stdout, stderr = run_cli(
        ["capture", "--rig", str(rig_path), "--out", str(out), "--lookup", "bilinear"], capsys
    )
    assert code == 0, stderr
    assert "52 x 160 x 160" in stdout
    assert len(list((out / "frames").glob("*.png"))) == 52
    for name in ("depth", "points", "normals", "proj_uv", "mask"):
        assert (out / "gt" / f"{name}.npy").is_file()
    loaded = load_capture(out)
    assert loaded.metadata["render"]["lookup"] == "bilinear"
    assert loaded.scene.objects[0].radius_m == 0.1  # the default scene


@pytest.mark.parametrize(
    ("scene", "message"),
    [
        ({"objects": [{"type": "mesh", "path": "missing.stl"}]}, "expected an existing mesh"),
        ({"objects": []}, "expected at least one object"),
        ({"objects": [{"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, -1]}]},
         "expected an object in front of the camera"),
        ({"objects": [{"type": "sphere", "radius_m": 0.1, "center_m": [0, 0, 1], "size": 2}]},
         "scene.objects.0.size: expected no such key"),
    ],
)  # fmt: skip
def test_cli_capture_bad_scene_is_one_line(tmp_path, capsys, scene, message) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    rig_path = small_rig().save_json(tmp_path / "rig.json")
    code, _, stderr = run_cli(
        ["capture", "--scene", str(path), "--rig", str(rig_path), "--out", str(tmp_path / "o")],
        capsys,
    )
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("virtus: error: ") and message in lines[0]
    assert not (tmp_path / "o").exists()


def test_cli_capture_missing_scene_file(tmp_path, capsys) -> None:
    code, _, stderr = run_cli(["capture", "--scene", str(tmp_path / "none.yaml")], capsys)
    assert code == 2 and "expected an existing YAML file" in stderr
    assert len(stderr.strip().splitlines()) == 1


def test_capture_module_does_not_load_mitsuba():
    # DESIGN rule: only virtus.render knows Mitsuba exists, and only when it renders.
    import subprocess
    import sys

    code = (
        "import sys, virtus.capture; "
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'mitsuba', 'drjit'}))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize("workers", [0, -1, 2.5])
def test_frame_writer_refuses_a_bad_thread_count(tmp_path, workers):
    from virtus.capture import write_frames
    from virtus.errors import InputError

    with pytest.raises(InputError, match=r"^workers: expected an integer >= 1"):
        write_frames(tmp_path, np.zeros((1, 4, 4), np.uint8), workers=workers)
    assert not list(tmp_path.glob("*.png"))
