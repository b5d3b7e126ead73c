"""``virtus twin --validate`` checks its board before rendering anything: a ``--board`` the
captures do not show, or of another geometry than the calibration's, is refused naming
``--board`` (:func:`virtus.pipeline.twin.validate_twin`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.calib.board import board_from_spec
from virtus.calib.poses import pose_set
from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
from virtus.errors import InputError
from virtus.pipeline.twin import _check_board, validate_twin
from virtus.render import RenderSettings
from virtus.scanner import Scanner


@pytest.fixture(scope="module")
def board_capture(tmp_path_factory):
    """One capture of the 4x7 circle board (240 x 240 camera, 1 spp) and its rig."""
    rig, board = scaled_rig(0.25), board_from_spec("4x7")
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    pose = pose_set("paper", rig, board, np.random.default_rng(0))[0]
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    directory = tmp_path_factory.mktemp("twin") / pose.name
    scanner.capture(board_scene(board, pose, texture), rng=1).save(directory)
    return rig, board, directory


def test_a_board_the_captures_do_not_show_is_refused(board_capture, tmp_path, capsys):
    rig, _, directory = board_capture
    with pytest.raises(InputError, match=r"^--board: expected the board the captures show, got "
                       r"'5x9: no 5x9 circle grid found in any of the 1 captures'"):  # fmt: skip
        validate_twin(rig, [directory], board="5x9", out=tmp_path / "v.json")
    assert not (tmp_path / "v.json").exists()
    rig.save_json(tmp_path / "calib.json")
    from virtus.cli import main

    argv = ["twin", str(tmp_path / "calib.json"), "--out", str(tmp_path / "t"), "--validate",
            str(directory), "--board", "5x9"]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and "--board: expected" in err
    assert not (tmp_path / "t").exists() or not any((tmp_path / "t").iterdir())  # no twin


def test_a_board_other_than_the_calibrated_one_is_refused(board_capture, tmp_path):
    rig, board, directory = board_capture
    data = {**rig.to_dict(), "board": board.to_dict()}
    (tmp_path / "calibration.json").write_text(json.dumps(data))
    other = "circles:4x7,spacing_mm=30,diameter_mm=15"
    with pytest.raises(InputError, match=r"^--board: expected the board the calibration used "
                       r"\(4x7 circle grid, .* mm apart\), got '" + other):  # fmt: skip
        validate_twin(tmp_path / "calibration.json", [directory], board=other)


def test_the_board_the_captures_show_passes(board_capture):
    _, board, directory = board_capture
    _check_board(board, board.to_dict(), "4x7", [directory])  # the spec and the file agree
    _check_board(board, board.to_dict(), None, [directory])  # the file's board alone
    with pytest.raises(InputError, match=r"^board \(of the calibration file\): expected the "):
        _check_board(board_from_spec("5x9"), None, None, [directory])
