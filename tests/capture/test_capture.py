"""Capture directories (save/load round trip) and the ``virtus capture`` command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.support import small_rig
from virtus.capture.capture import CAPTURE_FORMAT, Capture
from virtus.cli import main
from virtus.errors import VirtusError
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.scanner import Scanner
from virtus.scene.model import Scene, SphereObject, TexturedPlaneObject
from virtus.sensor.camera import SENSOR_PRESETS

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def captured():
    rig, sequence = small_rig(), default_sequence()
    board = TexturedPlaneObject((0.2, 0.1), np.eye(4) * 0.5 + 0.25, Pose(np.eye(3), (0, 0, 1.2)))
    scene = Scene([SphereObject(0.05, (0, 0, 1.0)), board])
    scanner = Scanner(rig=rig, sequence=sequence, sensor=SENSOR_PRESETS["imx174"])
    return scanner, scene, scanner.capture(scene, rng=7, command=["test"])


def test_capture_round_trip(tmp_path, captured) -> None:
    scanner, scene, capture = captured
    manifest = capture.save(tmp_path / "cap")
    data = json.loads(manifest.read_text())
    assert data["format"] == CAPTURE_FORMAT
    assert data["rig"] == scanner.rig.to_dict() and data["units"]["length"] == "m"
    assert data["render"]["spp"] == 4 and data["bit_depth"] == 12 and data["seed"] == 7
    assert data["frames"]["files"][:2] == ["frames/000.png", "frames/001.png"]
    assert data["provenance"]["source"] == "rendered" and data["provenance"]["command"] == ["test"]

    loaded = Capture.load(tmp_path / "cap")
    assert loaded == capture  # frames, rig, pose, bit depth, sensor, sequence, seed
    assert loaded.frames.dtype == np.uint16
    assert loaded.sensor == scanner.sensor and loaded.seed == 7
    np.testing.assert_array_equal(
        loaded.scene.objects[1].texture_image(), scene.objects[1].texture_image()
    )
    for name, array in capture.ground_truth.arrays().items():
        np.testing.assert_array_equal(loaded.ground_truth.arrays()[name], array)
    assert loaded.render["exposure_dn_per_radiance"] == capture.render["exposure_dn_per_radiance"]
    # A different seed is a different capture.
    assert scanner.capture(scene, rng=8) != capture

    # The directory can be moved: paths inside capture.json are relative.
    (tmp_path / "cap").rename(tmp_path / "moved")
    moved = Capture.load(tmp_path / "moved")
    assert moved.scene is not None and moved.has_ground_truth and moved == capture


def test_capture_json_follows_its_schema(tmp_path, captured) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((REPO / "schemas" / "capture.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    data = json.loads(captured[2].save(tmp_path / "cap").read_text())
    jsonschema.validate(data, schema)
    data["format"] = "virtus.capture/9"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, schema)


def test_cam2world_is_recorded(tmp_path, captured) -> None:
    scanner = captured[0]
    cam2world = Pose.from_euler("y", [10.0], (0.05, 0.0, 0.0))
    centre = cam2world.apply(np.array([[0.0, 0.0, 1.0]]))[0]
    capture = scanner.capture(Scene([SphereObject(0.05, tuple(centre))]), cam2world=cam2world)
    assert capture.ground_truth.mask.any()
    loaded = Capture.load(capture.save(tmp_path / "c").parent)
    assert loaded.cam2world == cam2world and loaded == capture


def test_existing_capture_needs_overwrite(tmp_path, captured) -> None:
    capture = captured[2]
    capture.save(tmp_path)
    with pytest.raises(VirtusError, match="already holds a capture"):
        capture.save(tmp_path)
    capture.save(tmp_path, overwrite=True)
    assert Capture.load(tmp_path) == capture


def test_reading_a_capture_never_loads_the_renderer(tmp_path, captured) -> None:
    # DESIGN rule: decoding and reconstructing a capture need neither virtus.render nor
    # Mitsuba; checked in a fresh interpreter.
    import subprocess
    import sys

    directory = tmp_path / "cap"
    captured[2].save(directory)
    code = (
        "import sys\n"
        "from virtus.pipeline.scan import decode_capture, reconstruct_capture\n"
        f"decode_capture({str(directory)!r})\n"
        f"reconstruct_capture({str(directory)!r})\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit')\n"
        "             or m.startswith('virtus.render')))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
    assert (directory / "points.ply").is_file()


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
    loaded = Capture.load(out)
    assert loaded.render["lookup"] == "bilinear"
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


@pytest.mark.parametrize("workers", [0, -1, 2.5])
def test_frame_writer_refuses_a_bad_thread_count(tmp_path, workers):
    from virtus.errors import InputError
    from virtus.io.images import write_frames

    with pytest.raises(InputError, match=r"^workers: expected an integer >= 1"):
        write_frames(tmp_path, np.zeros((1, 4, 4), np.uint8), workers=workers)
    assert not list(tmp_path.glob("*.png"))


def test_a_failed_save_names_the_path_and_leaves_no_partial_capture(
    tmp_path, captured, monkeypatch
) -> None:
    import virtus.capture.capture as capture_module

    def disk_full(directory, frames, **_options):
        (directory / "000.png").write_bytes(b"half a frame")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(capture_module, "write_frames", disk_full)
    with pytest.raises(OSError) as info:
        captured[2].save(tmp_path / "cap")
    assert str(tmp_path / "cap" / "frames") in str(info.value.filename)
    assert not [p for p in (tmp_path / "cap").rglob("*") if p.is_file()]


def test_write_json_is_atomic_and_names_the_path(tmp_path) -> None:
    from virtus.io.jsonio import write_json

    with pytest.raises(OSError) as info:
        write_json(tmp_path / "missing" / "x.json", {"a": 1})
    assert info.value.filename == str(tmp_path / "missing" / "x.json")
    (tmp_path / "x.json").write_text("old")
    with pytest.raises(TypeError):
        write_json(tmp_path / "x.json", {"a": object()})
    assert (tmp_path / "x.json").read_text() == "old"
    write_json(tmp_path / "x.json", {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_cli_capture_owns_its_directory(tmp_path, capsys) -> None:
    rig_path = small_rig().save_json(tmp_path / "rig.json")
    argv = ["capture", "--rig", str(rig_path), "--spp", "1", "--out", str(tmp_path / "o")]
    code, _, _ = run_cli(argv, capsys)
    assert code == 0
    record = json.loads((tmp_path / "o" / "run.json").read_text())
    assert record["command"] == "capture" and record["status"] == "complete"
    assert "frames/000.png" in record["files"] and "points.ply" in record["files"]
    code, _, stderr = run_cli([*argv, "--seed", "3"], capsys)
    assert code == 2 and "with other settings (config.seed: 3 here, 0 in the existing" in stderr
    code, _, _ = run_cli([*argv, "--seed", "3", "--overwrite"], capsys)
    assert code == 0 and Capture.load(tmp_path / "o").seed == 3


@pytest.mark.parametrize(
    ("peak", "dtype", "bits"),
    [
        (0, np.uint8, 8),
        (255, np.uint8, 8),
        (0, np.uint16, 10),
        (255, np.uint16, 10),
        (1023, np.uint16, 10),
        (1024, np.uint16, 12),
        (4095, np.uint16, 12),
        (4096, np.uint16, 16),
        (65535, np.uint16, 16),
    ],
)
def test_bit_depth_is_the_smallest_adc_that_holds_the_peak(peak, dtype, bits) -> None:
    # 2**b - 1 is the largest number of a b-bit ADC: 1023 fits 10 bits, 1024 needs 12.
    from virtus.capture.capture import bit_depth_of

    frames = np.zeros((2, 3, 4), dtype=dtype)
    frames[1, 2, 3] = peak
    assert bit_depth_of(frames) == bits
    assert (1 << bits) - 1 >= peak


def test_a_12_bit_capture_peaking_at_1024_is_accepted_and_decodes() -> None:
    sequence, rig = default_sequence(), small_rig(1 / 12)
    frames = np.full((len(sequence), 80, 80), 300, dtype=np.uint16)
    frames[sequence.index_of("white")] = 1024
    capture = Capture(sequence=sequence, rig=rig, frame_data=frames)
    assert capture.bit_depth == 12 and capture.full_scale == 4095
    # Decoding against that full scale accepts the frames (a 10-bit full scale would not).
    decoded = sequence.decode(capture.frames, full_scale=capture.full_scale)
    assert decoded.mask.shape == (80, 80)
