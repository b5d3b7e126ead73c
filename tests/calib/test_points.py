"""Calibration from saved correspondences (:mod:`virtus.calib.points`, the job
:func:`virtus.pipeline.calibrate.calibrate_points`, ``virtus calibrate --from-points``): a
known rig round-trips through every layout; bad files are one-line errors."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from tests import tolerances as tol
from tests.calib.test_solve import _exact_observations
from virtus.calib.board import board_from_spec
from virtus.calib.points import read_points
from virtus.calib.poses import random_poses
from virtus.calib.solve import (
    calibrate_correspondences,
    calibrate_observations,
    opencv_single_thread,
)
from virtus.calib.truth import truth_error
from virtus.cli import main
from virtus.errors import InputError
from virtus.geometry.devices import default_rig
from virtus.pipeline.calibrate import calibrate_points, recalibrate

RIG = default_rig()
BOARD = board_from_spec("7x13")
POSES = random_poses(RIG, BOARD, 8, 2)
SIZES = "960x960,912x1140"
LAYOUTS = ("txt_folders", "txt_suffixes", "csv_ids", "csv_objects", "npz_points")


def _points() -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Exact camera and projector pixels of the board's points in every pose."""
    obj = BOARD.object_points
    cam = [RIG.camera.intrinsics.project(p.board2cam.apply(obj)) for p in POSES]
    proj = [
        RIG.projector.intrinsics.project(RIG.cam2proj.apply(p.board2cam.apply(obj))) for p in POSES
    ]
    return obj, cam, proj


def _lines(points: np.ndarray) -> str:
    return "".join(" ".join(f"{v:.17g}" for v in row) + "\n" for row in points)


def write_layout(layout: str, root: Path) -> Path:
    """Write the exact correspondences in ``layout``; one point the projector missed."""
    obj, cam, proj = _points()
    proj[0] = proj[0].copy()
    proj[0][5] = np.nan  # not seen by the projector: left out of its pose
    names = [p.name for p in POSES]
    if layout == "txt_folders":
        for sub, data in (("cam", cam), ("proj", proj)):
            (root / sub).mkdir(parents=True)
            for name, points in zip(names, data, strict=True):
                header = "# x y (px)\n\n"
                (root / sub / f"{name}.txt").write_text(header + _lines(points))
        return root
    if layout == "txt_suffixes":
        root.mkdir(parents=True)
        for name, c, q in zip(names, cam, proj, strict=True):
            (root / f"{name}_cam.txt").write_text(_lines(c).replace(" ", ","))
            (root / f"{name}_proj.txt").write_text(_lines(q).replace(" ", "\t"))
            (root / f"{name}_obj.txt").write_text(_lines(obj))
        return root
    if layout.startswith("csv"):
        root.mkdir(parents=True)
        with_obj = layout == "csv_objects"
        header = "x_proj,pose,id,y_cam,x_cam,y_proj" + (",z_obj,x_obj,y_obj" if with_obj else "")
        rows = [header]
        for name, c, q in zip(names, cam, proj, strict=True):
            for i in range(len(obj)):
                row = [f"{q[i, 0]:.17g}", name, str(i), f"{c[i, 1]:.17g}", f"{c[i, 0]:.17g}"]
                row.append(f"{q[i, 1]:.17g}")
                if with_obj:
                    row += [f"{obj[i, 2]:.17g}", f"{obj[i, 0]:.17g}", f"{obj[i, 1]:.17g}"]
                rows.append(",".join("" if v == "nan" else v for v in row))
        (root / "points.csv").write_text("\n".join(rows) + "\n")
        return root / "points.csv"
    assert layout == "npz_points"
    root.mkdir(parents=True)
    for name, c, q in zip(names, cam, proj, strict=True):
        np.savez(root / f"{name}.npz", cam_points=c, proj_points=q, object_points=obj)
    return root


def _in_memory() -> dict:
    """The rig calibrated from the same correspondences without files."""
    obj, cam, proj = _points()
    proj[0] = proj[0].copy()
    proj[0][5] = np.nan
    names = [p.name for p in POSES]
    with opencv_single_thread():
        solved = calibrate_correspondences(names, [obj] * 8, cam, proj, (960, 960), (912, 1140))
    return solved.rig.to_dict()


@pytest.mark.parametrize("layout", LAYOUTS)
def test_from_points_round_trips_a_known_rig(layout, tmp_path):
    """Exact correspondences written with 17 digits: the rig of the same solve in memory,
    and the true rig to the exact-calibration tolerances (float32 solver inputs: measured
    7e-8 in fx, 8.5e-4 px in the principal points, 1.2e-8 m in the baseline)."""
    source = write_layout(layout, tmp_path / "points")
    board = "7x13" if layout in ("txt_folders", "csv_ids") else None
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the coverage check may warn: not this test's subject
        result = calibrate_points(source, board=board, sizes=SIZES, out_dir=out)
    assert result.rig.to_dict() == _in_memory()
    error = truth_error(result.rig, RIG)
    for device in ("camera", "projector"):
        assert abs(error[device]["fx_rel_error"]) < tol.CALIB_EXACT_FOCAL_REL
        assert abs(error[device]["fy_rel_error"]) < tol.CALIB_EXACT_FOCAL_REL
        assert error[device]["principal_point_error_px"] < tol.CALIB_EXACT_PRINCIPAL_POINT_PX
    assert abs(error["proj2cam"]["baseline_error_m"]) < tol.CALIB_EXACT_BASELINE_M
    assert error["proj2cam"]["rotation_error_deg"] < tol.CALIB_EXACT_ROTATION_DEG
    assert [p.name for p in result.poses] == [p.name for p in POSES]
    data = json.loads((out / "calibration.json").read_text())
    assert data["settings"]["layout"] == layout.split("_")[0]
    assert data["settings"]["n_poses"] == len(POSES)
    assert data["board"] == (None if board is None else BOARD.to_dict())
    assert set(data["conditioning"]) >= {"tilt_spread_deg", "camera", "projector", "levels"}
    assert data["uncertainty"]["camera"]["fx"] is not None
    for name in ("calibration.yaml", "paper_txt/ProjTranslationVector.txt", "episode.json"):
        assert (out / name).is_file()
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "complete" and record["command"] == "calibrate --from-points"


def test_virtus_pose_files_solve_as_the_job_solves_them(tmp_path):
    """A run's poses/*.npz (centroids and homographies) with its episode.json: the same
    solve as calibrate_observations, bias correction included."""
    board = board_from_spec("4x7")
    poses = random_poses(RIG, board, 6, 4)
    observations = _exact_observations(board, poses)
    run = tmp_path / "run"
    (run / "poses").mkdir(parents=True)
    episode = {"board": board.to_dict(), "camera_size": [960, 960], "projector_size": [912, 1140]}
    episode["names"] = [p.name for p in reversed(poses)]  # the recorded order wins
    (run / "episode.json").write_text(json.dumps(episode))
    for obs in observations:
        np.savez(run / "poses" / f"{obs.name}.npz", cam_centroids=obs.cam_centroids,
                 homographies=obs.homographies)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate_points(run)
        with opencv_single_thread():
            direct = calibrate_observations(board, observations[::-1], (960, 960), (912, 1140))
    assert result.rig.to_dict() == direct.rig.to_dict()
    assert result.settings["layout"] == "npz" and result.board == board
    with pytest.raises(InputError, match="out_dir: expected a folder that does not hold"):
        calibrate_points(run / "poses", out_dir=run)


def test_recalibrate_takes_a_lens_model(tmp_path):
    """recalibrate(distortion=...) solves a run's pose files with another lens model and
    records it; the default records nothing (earlier runs' settings stay as they were)."""
    board = board_from_spec("4x7")
    poses = random_poses(RIG, board, 6, 4)
    run = tmp_path / "run"
    (run / "poses").mkdir(parents=True)
    settings = {"fix_intrinsics": False}
    episode = {"true_rig": RIG.to_dict(), "board": board.to_dict(), "settings": settings}
    episode["poses"] = [p.to_dict() for p in poses]
    (run / "episode.json").write_text(json.dumps(episode))
    for pose, obs in zip(poses, _exact_observations(board, poses), strict=True):
        np.savez(run / "poses" / f"{pose.name}.npz", board2cam=pose.board2cam.matrix,
                 cam_centroids=obs.cam_centroids, homographies=obs.homographies)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = recalibrate(run)
        from_points = calibrate_points(run)  # the same pose files, read as points
        rational = recalibrate(run, distortion="rational")
    assert from_points.rig.to_dict() == default.rig.to_dict()
    assert "distortion" not in default.settings and len(default.rig.camera.intrinsics.dist) <= 5
    assert rational.settings["distortion"] == "rational"
    assert json.loads((run / "calibration.json").read_text())["settings"]["distortion"] == (
        "rational"
    )
    assert len(rational.uncertainty["camera"]["dist"]) == 8


@pytest.mark.parametrize(
    ("files", "message"),
    [
        ({"a_cam.txt": "1 2\n3\n", "a_proj.txt": "1 2\n3 4\n"}, "line 2: expected 2 numbers"),
        ({"a_cam.txt": "1 2\n", "a_proj.txt": "1 2\n3 4\n"}, "as many camera, projector"),
        ({"a_cam.txt": "1 2\n"}, "pose 'a': expected a projector file"),
        ({"notes.md": "nothing"}, "points: expected a .csv file or a folder"),
        ({"p.csv": "pose,x_cam\n"}, "expected columns pose, id, x_cam"),
    ],
)
def test_bad_points_are_one_line_errors(files, message, tmp_path):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    source = tmp_path / "p.csv" if "p.csv" in files else tmp_path
    with pytest.raises(InputError, match=message) as info:
        read_points(source, board="4x7", sizes=SIZES)
    assert "\n" not in str(info.value)


def test_sizes_and_board_are_required_where_the_files_lack_them(tmp_path):
    source = write_layout("txt_folders", tmp_path / "points")
    with pytest.raises(InputError, match="sizes: expected the camera and projector"):
        read_points(source, board="7x13")
    with pytest.raises(InputError, match="board: expected a board"):
        read_points(source, sizes=SIZES)
    with pytest.raises(InputError, match="sizes: expected camera and projector image sizes"):
        read_points(source, board="7x13", sizes="960x960")


def test_cli_calibrates_from_a_csv_with_the_k3_model(tmp_path, capsys):
    source = write_layout("csv_ids", tmp_path / "points")
    out = tmp_path / "out"
    argv = ["calibrate", "--from-points", str(source), "--sizes", SIZES, "--board", "7x13"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--distortion", "k3", "--out", str(out)])
    assert exit_info.value.code == 0
    printed = capsys.readouterr().out
    assert "conditioning" in printed and "wrote" in printed
    data = json.loads((out / "calibration.json").read_text())
    assert data["settings"]["distortion"] == "k3"
    assert data["uncertainty"]["camera"]["dist"][4] is not None  # k3 estimated


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--sizes", SIZES], "--sizes: expected --from-points"),
        (["--from-points", "missing.csv", "--sizes", SIZES], "points: expected a .csv file"),
        (["--from-points", ".", "--resume"], "--from-points: expected no --captures"),
    ],
)
def test_cli_from_points_errors_are_one_line(extra, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(["calibrate", *extra, "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "out").exists()
