"""``virtus twin`` as an owned run (:func:`virtus.pipeline.twin.run_twin`): its ``run.json``
(complete, failed, or refusing another command's directory) and the per-pose difference maps
``--validate`` stores beside ``validation.json`` (:func:`~virtus.pipeline.twin.difference_maps`),
which must agree with the per-pose numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.calib.board import board_from_spec
from virtus.calib.poses import pose_set
from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
from virtus.errors import VirtusError
from virtus.io.runs import file_digest
from virtus.pipeline import twin as twin_module
from virtus.pipeline.twin import MAP_LAYERS, _binned, validate_twin
from virtus.render import RenderSettings
from virtus.scanner import Scanner

RIG = scaled_rig(0.25)  # 240 x 240 px camera
#: float32 maps against the float64 numbers of the table
MAP_RTOL = 1e-5


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """One 4x7 board pose rendered with the true rig, and the rig as a calibration file."""
    folder = tmp_path_factory.mktemp("twin-run")
    board = board_from_spec("4x7")
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    pose = pose_set("random:1", RIG, board, np.random.default_rng(7))[0]
    capture = Scanner(rig=RIG, render=RenderSettings(spp=1)).capture(
        board_scene(board, pose, texture), rng=50
    )
    capture.save(folder / "captures" / pose.name)
    RIG.save_json(folder / "calib.json")
    return folder


def _cli(argv: list[str], capsys) -> tuple[int, str]:
    from virtus.cli import main

    with pytest.raises(SystemExit) as done:
        main([str(a) for a in argv])
    return int(done.value.code), capsys.readouterr().err


def test_binning_averages_blocks_and_keeps_empty_blocks_nan() -> None:
    values = np.arange(20, dtype=np.float64).reshape(1, 4, 5)
    values[0, 0, 0] = np.nan  # ignored in its block
    values[0, 2:, 4] = np.nan  # the whole (padded) block of the last column, rows 2-3
    binned = _binned(values, 2)
    assert binned.shape == (1, 2, 3) and binned.dtype == np.float32
    assert binned[0, 0, 0] == pytest.approx((1 + 5 + 6) / 3)
    assert binned[0, 0, 2] == pytest.approx((4 + 9) / 2)
    assert np.isnan(binned[0, 1, 2])


def test_the_maps_agree_with_the_per_pose_numbers(captures, tmp_path) -> None:
    result = validate_twin(RIG, [captures / "captures"], board="4x7",
                           out=tmp_path / "validation.json")  # fmt: skip
    (row,) = result.per_pose
    table = json.loads((tmp_path / "validation.json").read_text())
    entry = table["maps"]["files"][row["name"]]
    assert table["maps"]["layers"] == list(MAP_LAYERS) and entry["bin"] == 1
    file = tmp_path / entry["file"]
    assert file_digest(file) == entry["sha256"]
    maps = np.load(file)
    assert maps.shape == (4, 240, 240) and maps.dtype == np.float32
    white, _, _, proj = maps
    assert int(np.isfinite(proj).sum()) == row["pixels"]  # the compared pixels, no others
    assert np.sqrt(np.nanmean(white.astype(np.float64) ** 2)) == pytest.approx(
        row["white_rms"], rel=MAP_RTOL
    )
    assert np.sqrt(np.nanmean(proj.astype(np.float64) ** 2)) == pytest.approx(
        row["proj_uv_rms_px"], rel=MAP_RTOL
    )
    assert "maps" not in validate_twin(RIG, [captures / "captures"], board="4x7").to_dict()


def test_a_twin_run_keeps_a_record_and_bins_large_maps(captures, tmp_path, capsys,
                                                        monkeypatch) -> None:  # fmt: skip
    monkeypatch.setattr(twin_module, "MAP_MAX_SIDE", 100)  # 240 px -> bins of 3 px
    out = tmp_path / "twin"
    argv = ["twin", captures / "calib.json", "--out", out, "--validate",
            captures / "captures", "--board", "4x7", "--quiet"]  # fmt: skip
    assert _cli(argv, capsys)[0] == 0
    record = json.loads((out / "run.json").read_text())
    assert record["command"] == "twin" and record["status"] == "complete"
    assert {"rig.json", "isaac.json", "validation.json", "validation_maps/pose_001.npy"} <= set(
        record["files"]
    )
    table = json.loads((out / "validation.json").read_text())
    (entry,) = table["maps"]["files"].values()
    assert entry["bin"] == 3 and entry["shape"] == [4, 80, 80]
    assert _cli(argv, capsys)[0] == 0  # a new twin replaces the old one's files
    assert json.loads((out / "run.json").read_text())["status"] == "complete"


def test_a_failed_validation_leaves_a_failed_record(captures, tmp_path, capsys,
                                                    monkeypatch) -> None:  # fmt: skip
    from virtus.report import check_run

    def broken(*args, **kwargs):
        raise VirtusError("twin validation: rendering stopped")

    monkeypatch.setattr(twin_module, "validate_twin", broken)
    out = tmp_path / "twin"
    code, err = _cli(["twin", captures / "calib.json", "--out", out, "--validate",
                      captures / "captures", "--board", "4x7"], capsys)  # fmt: skip
    assert code == 2 and "rendering stopped" in err
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed" and "rendering stopped" in record["error"]
    assert "rig.json" in record["files"]  # what it wrote before failing is the run's
    with pytest.raises(VirtusError, match="half-finished `virtus twin` run"):
        check_run(out)


def test_another_commands_directory_is_refused(captures, tmp_path, capsys) -> None:
    out = tmp_path / "scan"
    out.mkdir()
    record = {"format": "virtus.run/1", "command": "scan", "status": "complete", "files": []}
    (out / "run.json").write_text(json.dumps(record))
    code, err = _cli(["twin", captures / "calib.json", "--out", out], capsys)
    assert code == 2 and "holds a `virtus scan` run" in err and err.count("\n") == 1
    assert sorted(p.name for p in out.iterdir()) == ["run.json"]
