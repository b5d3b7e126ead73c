"""``virtus import`` without a calibration (captures to calibrate a bench from), and what an
import records about its calibration (``calibration_source`` in capture.json, the summary).

Board captures are synthesised without the renderer (:mod:`virtus.calib.synthetic`: exact
board albedo times what the projector shows at each camera pixel's exact projector
coordinate), written as a bench writes them (one PNG per frame), imported by the command
line without ``--calibration``, then calibrated with ``calibrate --captures``; the rig in
between is a placeholder that decodes but never triangulates.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.capture.test_import import run_cli
from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.calib.board import board_from_spec
from virtus.calib.io import save_paper_txt
from virtus.calib.poses import pose_set
from virtus.calib.synthetic import board_image, projector_map
from virtus.capture.capture import Capture
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.patterns import PatternSequence, default_sequence
from virtus.pipeline.calibrate import calibrate_captures
from virtus.pipeline.capture import import_images
from virtus.pipeline.scan import reconstruct_capture

BOARD = "4x7"
#: camera focal length calibrated from the four synthetic captures (1/4 paper rig, 4x7 board,
#: exact albedo, no blur or noise): measured +1.9e-3 (four poses leave the focal length a
#: few 1e-3 uncertain); a solve of garbage, or captures read with the placeholder rig's K,
#: would be off by more than 1e-1.
UNCALIBRATED_FOCAL_REL = 1e-2


def _board_frames(rig: Rig, sequence: PatternSequence, board2cam) -> np.ndarray:
    """(F, H, W) uint8 frames of the board lit by ``sequence`` (ambient 10 DN, white 240)."""
    board = board_from_spec(BOARD)
    albedo = board_image(rig.camera.intrinsics, board, board2cam, supersample=2)
    uv = projector_map(rig, board2cam)
    proj = rig.projector.intrinsics
    lit = np.isfinite(uv).all(axis=-1)
    uv = np.nan_to_num(uv)
    lit &= (np.abs(uv[..., 0] - (proj.width - 1) / 2) <= proj.width / 2) & (
        np.abs(uv[..., 1] - (proj.height - 1) / 2) <= proj.height / 2
    )
    frames = []
    for index, frame in enumerate(sequence.frames):
        axis = {"v": 0, "h": 1}.get(frame.direction, 0)
        shown = sequence.values(index, uv[..., axis]) * lit
        frames.append(np.round(10 + 230 * albedo * shown))
    return np.array(frames, dtype=np.uint8)


@pytest.fixture(scope="module")
def bench(tmp_path_factory) -> dict:
    """A bench's folders: the sequence file and one PNG folder per board pose."""
    root = tmp_path_factory.mktemp("bench")
    rig = scaled_rig(0.25)
    proj = rig.projector.intrinsics
    sequence = default_sequence(proj.width, proj.height)
    (root / "seq.json").write_text(json.dumps(sequence.to_dict()))
    poses = pose_set("random:4", rig, board_from_spec(BOARD), np.random.default_rng(5))
    folders = []
    for pose in poses:
        folder = root / "images" / pose.name
        folder.mkdir(parents=True)
        for index, frame in enumerate(_board_frames(rig, sequence, pose.board2cam)):
            assert cv2.imwrite(str(folder / f"img_{index}.png"), frame)
        folders.append(folder)
    return {"root": root, "rig": rig, "sequence": root / "seq.json", "folders": folders}


def test_import_without_calibration_then_calibrate_and_reconstruct(bench, tmp_path, capsys):
    rig, captures = bench["rig"], tmp_path / "captures"
    for folder in bench["folders"]:
        out = captures / folder.name
        args = ["import", folder, "--sequence", bench["sequence"], "--out", out,
                "--pixel-size-um", "5.86"]  # fmt: skip
        code, stdout, stderr = run_cli(args, capsys)
        assert code == 0, stderr
        assert "placeholder" in stdout and "camera distortion: none given" in stdout
    data = json.loads((captures / bench["folders"][0].name / "capture.json").read_text())
    source = data["calibration_source"]
    assert source["calibrated"] is False and source["camera"]["dist"].startswith("none given")
    assert data["camera_pixel_size_m"] == pytest.approx(5.86e-6, rel=1e-12)
    capture = Capture.load(captures / bench["folders"][0].name)
    assert not capture.calibrated
    assert (capture.rig.camera.width, capture.rig.camera.height) == (
        rig.camera.width,
        rig.camera.height,
    )
    # Decoding works on the placeholder rig ...
    first = captures / bench["folders"][0].name
    code, _, stderr = run_cli(["decode", first], capsys)
    assert code == 0, stderr
    # ... reconstructing asks for a calibration, in one line ...
    code, _, stderr = run_cli(["reconstruct", first], capsys)
    assert code == 2 and len(stderr.splitlines()) == 1 and "--calibration" in stderr
    assert "imported without one" in stderr and not (first / "points.ply").exists()
    # ... and works with one.
    rig.save_json(tmp_path / "rig.json")
    recon = reconstruct_capture(first, tmp_path / "rig.json")
    assert np.isfinite(recon.points).all(axis=-1).sum() > 100
    # The captures calibrate the bench (their placeholder rigs are not used).
    result = calibrate_captures([captures], board=BOARD, processes=0)
    assert not result.dropped_poses
    assert result.rig.camera.intrinsics.size == rig.camera.intrinsics.size
    fx_rel = result.rig.camera.intrinsics.fx / rig.camera.intrinsics.fx - 1
    assert abs(fx_rel) < UNCALIBRATED_FOCAL_REL, fx_rel


def test_units_without_a_calibration_are_refused(bench, tmp_path) -> None:
    with pytest.raises(InputError, match="--units"):
        import_images(bench["folders"][0], bench["sequence"], None, tmp_path / "out", units="mm")
    with pytest.raises(InputError, match=r"--camera-size: expected the images' size 240,240"):
        import_images(
            bench["folders"][0], bench["sequence"], None, tmp_path / "out", camera_size=(240, 200)
        )
    with pytest.raises(InputError, match="--pixel-size-um"):
        import_images(
            bench["folders"][0], bench["sequence"], None, tmp_path / "out", pixel_size_um=-1.0
        )
    assert not (tmp_path / "out").exists()


def test_a_folder_without_distortion_is_recorded_as_none_given(bench, tmp_path, capsys):
    folder = save_paper_txt(bench["rig"], tmp_path / "cal")
    (folder / "CamDistortion.txt").unlink()
    (folder / "ProjDistortion.txt").rename(folder / "ProjLensModel.txt")  # unrecognised
    out = tmp_path / "cap"
    args = ["import", bench["folders"][0], "--sequence", bench["sequence"],
            "--calibration", folder, "--out", out, "--camera-size", "240,240"]  # fmt: skip
    code, stdout, stderr = run_cli(args, capsys)
    assert code == 0, stderr
    # The unused file is named in one warning line; both distortions say "none given".
    warning = [line for line in stderr.splitlines() if "ProjLensModel.txt" in line]
    assert len(warning) == 1 and warning[0].startswith("virtus: warning: ")
    assert f"camera distortion: none given (no distortion file in {folder})" in stdout
    assert f"projector distortion: none given (no distortion file in {folder})" in stdout
    assert "camera image size: --camera-size (240x240)" in stdout
    source = json.loads((out / "capture.json").read_text())["calibration_source"]
    assert source["calibrated"] is True and source["format"] == "text folder"
    assert source["camera"]["dist"].startswith("none given")
    assert source["projector"]["dist"].startswith("none given")
    assert source["camera"]["K"] == "CamIntrinsicMatrix.txt"
    assert source["ignored"] == ["ProjLensModel.txt"]
    assert Capture.load(out).calibrated


def test_capture_json_with_a_source_follows_its_schema(bench, tmp_path) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    schema_path = Path(__file__).resolve().parents[2] / "schemas" / "capture.schema.json"
    schema = json.loads(schema_path.read_text())
    import_images(bench["folders"][1], bench["sequence"], None, tmp_path / "c", pixel_size_um=3.45)
    data = json.loads((tmp_path / "c" / "capture.json").read_text())
    jsonschema.validate(data, schema)
    data["calibration_source"]["camera"].pop("dist")
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, schema)
