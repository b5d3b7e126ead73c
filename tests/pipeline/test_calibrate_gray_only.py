"""Benches that project Gray code only (OpenCV's ``GrayCodePattern``) or a plain binary code,
no phase frames, calibrate from their captures (``virtus calibrate --captures``).

Each bench is rendered as a real one: a 12-bit camera with the imx174's noise, a
LightCrafter-class projector (blurred pixels, gamma, 1000:1, fall-off), 4 samples per
pixel; its frames are written as a plain folder of PNGs, imported with the sequence the
bench describes (one line: ``preset: opencv_graycode``) and calibrated back; the result is
compared with the rig that rendered it.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from tests.pipeline.test_calibrate_captures import _export_png_folder, _run_cli, scaled_rig
from virtus.calib.board import Board, board_from_spec
from virtus.calib.poses import pose_set
from virtus.calib.scene import (
    board_scene,
    board_texture,
)
from virtus.calib.truth import truth_error
from virtus.capture.capture import import_capture
from virtus.geometry.devices import Rig
from virtus.patterns import PatternSequence, opencv_graycode_sequence
from virtus.pipeline.calibrate import calibrate_captures, pose_seed
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.sensor.camera import SENSOR_PRESETS
from virtus.sensor.projector import PROJECTOR_PRESETS

#: 480 x 480 camera, 456 x 570 projector: 9 + 10 bits, 40 frames per pose.
RIG = scaled_rig(0.5)
BOARDS = {"circles": "7x13", "checker": "checker:6x9,square_mm=20"}
POSES = 6
SEED = 1


def described(code: str) -> PatternSequence:
    """The sequence as the bench's file describes it."""
    projector = RIG.projector.intrinsics
    size = {"width": projector.width, "height": projector.height}
    if code == "gray":
        return PatternSequence.from_dict({**size, "preset": "opencv_graycode"})
    blocks = [
        {"kind": "binary", "direction": direction, "bits": (span - 1).bit_length()}
        | {"inverted": True}
        for direction, span in (("v", size["width"]), ("h", size["height"]))
    ]
    return PatternSequence.from_dict({**size, "blocks": [*blocks, *_uniform()]})


def _uniform() -> list[dict[str, str]]:
    return [{"kind": "white"}, {"kind": "black"}]


def bench(tmp_path: Path, sequence: PatternSequence, board: Board) -> Path:
    """Capture directories of ``POSES`` board poses (PNG folders imported as a bench's)."""
    texture = board_texture(board)
    scanner = Scanner(
        rig=RIG,
        sequence=sequence,
        sensor=SENSOR_PRESETS["imx174"],
        projector=PROJECTOR_PRESETS["lightcrafter"],
        render=RenderSettings(spp=4),
    )
    for index, pose in enumerate(pose_set(f"random:{POSES}", RIG, board, SEED)):
        capture = scanner.capture(board_scene(board, pose, texture), rng=pose_seed(SEED, index))
        folder = tmp_path / "bench" / pose.name
        _export_png_folder(capture, folder)
        imported = import_capture(folder, sequence, RIG)
        assert imported.bit_depth == 12
        imported.save(tmp_path / "captures" / pose.name)
    return tmp_path / "captures"


@pytest.mark.slow
@pytest.mark.parametrize("board_name", sorted(BOARDS))
@pytest.mark.parametrize("code", ["gray", "binary"])
def test_code_only_bench_recovers_the_rig(tmp_path, code, board_name):
    sequence = described(code)
    assert len(sequence) == 2 * (9 + 10) + 2
    if code == "gray":
        assert sequence == opencv_graycode_sequence(456, 570)
    board = board_from_spec(BOARDS[board_name])
    captures = bench(tmp_path, sequence, board)
    if code == "gray":  # the command line, as a bench runs it
        out = tmp_path / "out"
        args = ["calibrate", "--captures", str(captures), "--board", BOARDS[board_name]]
        assert _run_cli([*args, "--out", str(out)]) == 0
        rig = Rig.load_json(out / "calibration.json")
    else:
        result = calibrate_captures([captures], board=board, processes=0)
        assert not result.dropped_poses
        rig = result.rig
    error = truth_error(rig, RIG)
    for device in ("camera", "projector"):
        assert abs(error[device]["fx_rel_error"]) <= tol.CODE_ONLY_CALIB_FOCAL_REL
        assert abs(error[device]["fy_rel_error"]) <= tol.CODE_ONLY_CALIB_FOCAL_REL
        limit = tol.CODE_ONLY_CALIB_PRINCIPAL_POINT_PX[board_name]
        assert error[device]["principal_point_error_px"] <= limit
    assert abs(error["proj2cam"]["baseline_error_m"]) <= tol.CODE_ONLY_CALIB_BASELINE_M
    assert error["proj2cam"]["rotation_error_deg"] <= tol.CODE_ONLY_CALIB_ROTATION_DEG


def test_code_in_one_direction_is_a_one_line_error(tmp_path, capsys):
    projector, camera = RIG.projector.intrinsics, RIG.camera.intrinsics
    blocks = [{"kind": "gray", "direction": "v", "bits": 9}, *_uniform()]
    one = PatternSequence.from_dict(
        {"width": projector.width, "height": projector.height, "blocks": blocks}
    )
    frame = np.zeros((camera.height, camera.width), dtype=np.uint8)
    for name in ("a", "b", "c"):
        folder = tmp_path / "bench" / name
        folder.mkdir(parents=True)
        for index in range(len(one)):
            cv2.imwrite(str(folder / f"img_{index}.png"), frame)
        import_capture(folder, one, RIG).save(tmp_path / "captures" / name)
    args = ["calibrate", "--captures", str(tmp_path / "captures"), "--out", str(tmp_path / "o")]
    assert _run_cli(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "phase frames in both directions (v and h), or a Gray or binary code alone" in err
    assert not (tmp_path / "o").exists()
