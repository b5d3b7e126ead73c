"""Calibration of real rigs from their captures (``virtus calibrate --captures``).

The real path must be the virtual path: rendered calibration captures, exported as plain
image folders (one PNG per frame, as a bench writes them), imported and calibrated from
captures give the calibration the rendered job gives. Checkerboards calibrate too, and bad
inputs end as one clear line.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from virtus.calib.board import CheckerBoard, CircleBoard, board_from_spec
from virtus.calib.poses import pose_set
from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
from virtus.capture.capture import Capture, import_capture
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.transforms import Pose
from virtus.pipeline.calibrate import (
    calibrate_captures,
    calibrate_rig,
    pose_seed,
)
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.scene.model import PlaneObject, Scene


def scaled_rig(factor: float) -> Rig:
    """The paper's rig resampled by ``factor`` (both devices, same footprints)."""
    rig = default_rig()
    return Rig(
        Camera(rig.camera.intrinsics.scaled(factor)),
        Projector(rig.projector.intrinsics.scaled(factor)),
        rig.proj2cam,
    )


def _run_cli(args: list[str]) -> int:
    from virtus.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(args)
    return int(exit_info.value.code)


def _export_png_folder(capture: Capture, folder) -> None:
    """Write a capture's frames as a bench would: one PNG per frame, nothing else."""
    folder.mkdir(parents=True)
    for index, frame in enumerate(capture.frames):
        cv2.imwrite(str(folder / f"img_{index}.png"), frame)


# -- boards and specs (fast) ----------------------------------------------------------------


def test_board_specs():
    paper = board_from_spec("7x13")
    assert isinstance(paper, CircleBoard) and paper.plane_size_m == (0.2, 0.2)
    printed = board_from_spec("circles:4x11,spacing_mm=40,diameter_mm=20,white_on_black")
    assert printed.light_features and printed.scale == pytest.approx(1.0)
    assert printed.center_distance_m == pytest.approx(0.04)
    checker = board_from_spec("checker:6x9,square_mm=25")
    assert isinstance(checker, CheckerBoard) and checker.square_m == pytest.approx(0.025)
    # corner r * cols + c at ((c - 4) s, (r - 2.5) s)
    np.testing.assert_allclose(checker.object_points[10], [-3 * 0.025, -1.5 * 0.025, 0.0])
    for bad, match in (
        ("checker:6x8,square_mm=25", "odd sum"),
        ("checker:6x9", "square size in mm"),
        ("circles:4x11,spacing_mm=40", "diameter_mm"),
        ("circles:4x11,spacing_mm=40,diameter_mm=20,size=3", "options among"),
        ("hexagons", "ROWSxCOLS"),
    ):
        with pytest.raises(InputError, match=match):
            board_from_spec(bad)


def test_checkerboard_texture_is_the_exact_area_fraction():
    board = CheckerBoard(rows=2, cols=3, square_mm=10.0, border_mm=5.0)
    texture = board.texture(pixel_size_m=2.5e-3)  # 4 texels per square, aligned to edges
    levels = texture[2:-2, 2:-2].reshape(3, 4, 4, 4).mean(axis=(1, 3))  # per square
    dark = (np.add.outer(np.arange(3), np.arange(4)) % 2) == 0
    np.testing.assert_allclose(levels[dark], board.dark_level)
    np.testing.assert_allclose(levels[~dark], board.light_level)
    assert (texture[:2] == board.light_level).all()  # the border


# -- the real path is the virtual path ------------------------------------------------------


@pytest.mark.slow
def test_real_path_equals_virtual_path(tmp_path):
    rig = scaled_rig(0.25)
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    board, seed = board_from_spec("4x7"), 5
    virtual = calibrate_rig(
        scanner, board=board, poses="random:4", rng=seed, out_dir=tmp_path / "v"
    )
    # the same renders, through image folders and import_capture
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    poses = pose_set("random:4", rig, board, np.random.default_rng(seed))
    for index, pose in enumerate(poses):
        capture = scanner.capture(board_scene(board, pose, texture), rng=pose_seed(seed, index))
        _export_png_folder(capture, tmp_path / "bench" / pose.name)
        with pytest.raises(InputError, match="px images"):  # the camera size is checked
            import_capture(tmp_path / "bench" / pose.name, scanner.sequence, default_rig())
        imported = import_capture(tmp_path / "bench" / pose.name, scanner.sequence, rig)
        imported.save(tmp_path / "captures" / pose.name)
    out = tmp_path / "real"
    code = _run_cli(
        ["calibrate", "--captures", str(tmp_path / "captures"), "--board", "4x7", "--out", str(out)]
    )
    assert code == 0
    real = Rig.load_json(out / "calibration.json")
    for device in ("camera", "projector"):
        a = getattr(real, device).intrinsics
        b = getattr(virtual.rig, device).intrinsics
        np.testing.assert_allclose(a.K, b.K, rtol=0, atol=tol.REAL_EQUALS_VIRTUAL_PX)
        np.testing.assert_allclose(a.dist_array, b.dist_array, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        real.proj2cam.t, virtual.rig.proj2cam.t, atol=tol.REAL_EQUALS_VIRTUAL_M
    )
    np.testing.assert_allclose(real.proj2cam.R, virtual.rig.proj2cam.R, atol=1e-12)
    data = json.loads((out / "calibration.json").read_text())
    assert [p["name"] for p in data["per_pose"]] == [p.name for p in poses]
    assert data["per_pose"][0]["camera_rms_px"] == virtual.per_pose[0]["camera_rms_px"]
    assert "truth_error" not in data and data["settings"]["source"] == "captures"
    for name in ("calibration.yaml", "paper_txt/ProjTranslationVector.txt", "run.json"):
        assert (out / name).is_file()
    assert len(list((out / "poses").glob("*.npz"))) == 4
    # a second run into the same directory is refused, as for rendered runs
    assert _run_cli(["calibrate", "--captures", str(tmp_path / "captures"), "--out", str(out)]) == 2
    # one more pose without a board: dropped with a warning naming it
    blank = Scene(objects=[PlaneObject(size_m=(1.0, 1.0), pose=Pose(np.eye(3), (0, 0, 1.0)))])
    scanner.capture(blank).save(tmp_path / "captures" / "zz_blank")
    with pytest.warns(UserWarning, match="'zz_blank' dropped: the camera did not detect"):
        again = calibrate_captures([tmp_path / "captures"], board="4x7")
    assert list(again.dropped_poses) == ["zz_blank"]
    np.testing.assert_array_equal(again.rig.camera.intrinsics.K, virtual.rig.camera.intrinsics.K)


def test_captures_observed_in_worker_processes_give_the_same_files(tmp_path):
    rig = scaled_rig(0.25)
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    board, seed = board_from_spec("4x7"), 2
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    poses = pose_set("random:5", rig, board, np.random.default_rng(seed))
    for index, pose in enumerate(poses):
        capture = scanner.capture(board_scene(board, pose, texture), rng=pose_seed(seed, index))
        capture.save(tmp_path / "captures" / pose.name)
    results = {}
    for processes in (0, 2):
        out = tmp_path / f"out_{processes}"
        results[processes] = calibrate_captures(
            [tmp_path / "captures"], board=board, out_dir=out, processes=processes
        )
    assert results[0].rms_px == results[2].rms_px
    with pytest.raises(InputError, match="processes"):
        calibrate_captures([tmp_path / "captures"], board=board, processes=-1)
    for name in ["calibration.json", *(f"poses/{pose.name}.npz" for pose in poses)]:
        assert (tmp_path / "out_0" / name).read_bytes() == (tmp_path / "out_2" / name).read_bytes()


@pytest.mark.slow
def test_checkerboard_calibration_recovers_the_rig():
    rig = scaled_rig(0.5)
    board = board_from_spec("checker:6x9,square_mm=20")
    result = calibrate_rig(
        Scanner(rig=rig, render=RenderSettings(spp=1)), board=board, poses="random:10", rng=3
    )
    error = result.truth_error
    for device in ("camera", "projector"):
        assert abs(error[device]["fx_rel_error"]) <= tol.CHECKER_FOCAL_REL
        assert abs(error[device]["fy_rel_error"]) <= tol.CHECKER_FOCAL_REL
        assert error[device]["principal_point_error_px"] <= tol.CHECKER_PRINCIPAL_POINT_PX
    assert abs(error["proj2cam"]["baseline_error_m"]) <= tol.CHECKER_BASELINE_M
    assert result.rms_px["camera"] <= tol.CHECKER_RMS_PX


# -- bad inputs: one clear line, non-zero exit -----------------------------------------------


def test_bad_captures_are_one_line_errors(tmp_path, capsys):
    out = ["--out", str(tmp_path / "out")]
    assert (
        _run_cli(["calibrate", "--captures", str(tmp_path / "none"), "--board", "4x7", *out]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "captures: expected capture directories" in err
    (tmp_path / "empty").mkdir()
    assert _run_cli(["calibrate", "--captures", str(tmp_path / "empty"), *out]) == 2
    assert _run_cli(["calibrate", "--captures", str(tmp_path), "--board", "checker:6x9", *out]) == 2
    assert "square size" in capsys.readouterr().err


@pytest.mark.slow
def test_too_few_poses_and_no_board_are_clear_errors(tmp_path, capsys):
    rig = scaled_rig(0.25)
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    blank = Scene(objects=[PlaneObject(size_m=(1.0, 1.0), pose=Pose(np.eye(3), (0, 0, 1.0)))])
    capture = scanner.capture(blank)
    for name in ("a", "b", "c"):
        capture.save(tmp_path / name)
    with pytest.warns(UserWarning):
        with pytest.raises(VirtusError, match=r"at least 3 usable poses, got 0 \(dropped: a, b, c"):
            calibrate_captures([tmp_path / n for n in "abc"], board="4x7")
    dirs = [str(tmp_path / n) for n in "abc"]
    code = _run_cli(["calibrate", "--captures", *dirs, "--out", str(tmp_path / "out")])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("virtus: error: calibration needs at least 3 usable poses")
