"""End-to-end virtual calibration: render the board with the scanner, calibrate, compare
with the true rig (the issue's numbers: default rig, noise-free, 4 spp)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.calib.board import board_from_spec
from virtus.calib.detect import find_grid
from virtus.calib.poses import BoardPose, paper_poses
from virtus.calib.scene import BOARD_BLUR_M, board_scene
from virtus.errors import VirtusError
from virtus.geometry.devices import Rig, default_rig
from virtus.geometry.transforms import Pose
from virtus.pipeline.calibrate import calibrate_rig, recalibrate
from virtus.render import RenderSettings
from virtus.scanner import Scanner

pytestmark = pytest.mark.slow

RIG = default_rig()
SCANNER = Scanner(rig=RIG)


def _cut_off_pose() -> BoardPose:
    """The board 14 cm right of the axis: its right columns leave the camera image."""
    return BoardPose("cut_off_right", Pose(np.eye(3), (0.14, 0.0, 1.0)))


def test_paper_calibration_meets_the_issue_numbers(tmp_path):
    result = calibrate_rig(SCANNER, out_dir=tmp_path)
    assert result.rms_px["camera"] <= tol.CALIB_RMS_PX
    assert result.rms_px["projector"] <= tol.CALIB_RMS_PX
    error = result.truth_error
    for device in ("camera", "projector"):
        assert abs(error[device]["fx_rel_error"]) <= tol.CALIB_FOCAL_REL
        assert abs(error[device]["fy_rel_error"]) <= tol.CALIB_FOCAL_REL
        assert error[device]["principal_point_error_px"] <= tol.CALIB_PRINCIPAL_POINT_PX
    assert abs(error["proj2cam"]["baseline_error_m"]) <= tol.CALIB_BASELINE_M
    assert error["proj2cam"]["rotation_error_deg"] <= tol.CALIB_ROTATION_DEG
    # Files: the rig schema reads back, finished poses were kept one by one.
    data = json.loads((tmp_path / "calibration.json").read_text())
    assert data["truth_error"]["proj2cam"] == pytest.approx(error["proj2cam"])
    assert len(data["per_pose"]) == 18 and not data["dropped_poses"]
    assert Rig.load_json(tmp_path / "calibration.json").baseline_m == pytest.approx(
        result.rig.baseline_m
    )
    assert len(list((tmp_path / "poses").glob("*.npz"))) == 18
    # Solving again from the saved observations gives the same files, byte for byte (the
    # same float64 inputs, OpenCV on one thread).
    written = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    again = recalibrate(tmp_path)
    assert again.rms_px == result.rms_px
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == written


@pytest.mark.parametrize("spec", ["4x7", "5x9", "7x13"])
def test_rendered_paper_boards_are_detected(spec):
    board = board_from_spec(spec)
    pose = paper_poses(RIG, board)[16]  # 30 deg tilt with a 20 deg roll
    texture = board.texture(blur_m=BOARD_BLUR_M)
    capture = SCANNER.capture(board_scene(board, pose, texture))
    white = capture.frames[capture.sequence.index_of("white")]
    found = find_grid(white, board)
    assert found is not None
    truth = RIG.camera.intrinsics.project(pose.board2cam.apply(board.object_points))
    np.testing.assert_allclose(found, truth, atol=tol.CALIB_DETECT_PX)


def test_cut_off_pose_is_dropped_with_a_warning_naming_it():
    board = board_from_spec("4x7")
    poses = [*paper_poses(RIG, board)[9:12], _cut_off_pose()]
    with pytest.raises(VirtusError, match="cut_off_right"):  # checked by default
        calibrate_rig(SCANNER, board=board, poses=poses)
    with pytest.warns(UserWarning, match="'cut_off_right' dropped: the camera did not detect"):
        result = calibrate_rig(SCANNER, board=board, poses=poses, check_poses=False)
    assert list(result.dropped_poses) == ["cut_off_right"]
    assert [p["name"] for p in result.per_pose] == [p.name for p in poses[:3]]


def test_fewer_than_three_usable_poses_is_a_clear_error(tmp_path):
    board = board_from_spec("4x7")
    poses = [*paper_poses(RIG, board)[9:11], _cut_off_pose()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(VirtusError, match="at least 3 usable poses, got 2"):
            calibrate_rig(SCANNER, board=board, poses=poses, check_poses=False, out_dir=tmp_path)
    # The finished poses were written before the failure, and can be solved again.
    assert len(list((tmp_path / "poses").glob("*.npz"))) == 3
    (tmp_path / "poses" / "cut_off_right.npz").unlink()  # as if the run had stopped there
    with pytest.warns(UserWarning, match="'cut_off_right' left out"):
        with pytest.raises(VirtusError, match="got 2"):
            recalibrate(tmp_path)


def test_cli_calibrates_and_writes_the_files(tmp_path, capsys):
    from virtus.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(
            [
                "calibrate",
                "--board",
                "4x7",
                "--poses",
                "random:4",
                "--seed",
                "5",
                "--out",
                str(tmp_path),
            ]
        )
    assert exit_info.value.code == 0
    printed = capsys.readouterr().out
    assert "projector" in printed and "0.049" in printed  # next to the paper's numbers
    rig = Rig.load_json(tmp_path / "calibration.json")
    assert rig.camera.intrinsics.fx == pytest.approx(
        RIG.camera.intrinsics.fx, rel=tol.CALIB_FOCAL_REL
    )  # measured 3.6e-5 with these 4 poses
    assert (tmp_path / "calibration.yaml").is_file()
    assert (tmp_path / "paper_txt" / "ProjTranslationVector.txt").is_file()


def test_any_sequence_with_both_directions_calibrates(tmp_path):
    """A heterodyne sequence of 4 steps without white or black frames: circles are found and
    refined in the phase background, projector coordinates come from the capture's decode."""
    from tests.pipeline.test_calibrate_resume import quarter_rig
    from virtus.patterns import heterodyne_sequence

    rig = quarter_rig()
    projector = rig.projector.intrinsics
    sequence = heterodyne_sequence(
        projector.width, projector.height, steps=4, white=False, black=False
    )
    scanner = Scanner(rig=rig, sequence=sequence, render=RenderSettings(spp=1))
    result = calibrate_rig(scanner, board="4x7", poses="random:5", rng=3)
    assert not result.dropped_poses
    assert abs(result.truth_error["camera"]["fx_rel_error"]) <= tol.CALIB_JOB_SMALL_FOCAL_REL
    assert abs(result.truth_error["projector"]["fx_rel_error"]) <= tol.CALIB_JOB_SMALL_FOCAL_REL
    assert result.settings["frames_per_pose"] == len(sequence)


def test_a_sequence_with_one_direction_is_refused_before_rendering():
    from virtus.errors import InputError
    from virtus.patterns import build_sequence

    sequence = build_sequence(912, 1140, periods=18.0, steps=4, gray_bits=6, directions=("v",))
    with pytest.raises(InputError, match=r"^sequence: expected phase frames in both directions"):
        calibrate_rig(Scanner(rig=RIG, sequence=sequence), poses="random:3")
