"""Tests of virtual calibration on exact synthetic data (no renderer): boards, poses,
detection, centre refinement, projector points, solver, truth comparison, files, CLI."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.calib.board import CircleBoard, board_from_spec
from virtus.calib.detect import find_grid, refine_centres
from virtus.calib.io import load_opencv_yaml, load_paper_txt, save_opencv_yaml, save_paper_txt
from virtus.calib.poses import (
    PAPER_POSE_TABLE,
    BoardPose,
    check_pose,
    paper_poses,
    pose_set,
    random_poses,
)
from virtus.calib.projector import apply_homographies, local_homographies
from virtus.calib.solve import PoseObservation, calibrate_observations, centroid_bias
from virtus.calib.synthetic import board_image, projector_map
from virtus.calib.truth import truth_error
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

RIG = default_rig()
CAM = RIG.camera.intrinsics
PROJ = RIG.projector.intrinsics


def _true_centres(board: CircleBoard, board2cam: Pose) -> np.ndarray:
    return CAM.project(board2cam.apply(board.object_points))


def _plane_homography(rig: Rig, board2cam: Pose) -> np.ndarray:
    """Exact camera px -> projector px homography induced by the board plane (no distortion)."""
    normal = board2cam.R[:, 2]
    distance = normal @ board2cam.t  # plane: normal . X_cam = distance
    cam2proj = rig.cam2proj
    H = (
        rig.projector.intrinsics.K
        @ (  # noqa: N806
            cam2proj.R + np.outer(cam2proj.t, normal) / distance
        )
        @ np.linalg.inv(rig.camera.intrinsics.K)
    )
    return H / H[2, 2]


def _exact_observations(board: CircleBoard, poses: list[BoardPose]) -> list[PoseObservation]:
    """Centroids as the camera measures them (area centroids) and exact homographies."""
    return [
        PoseObservation(
            p.name,
            _true_centres(board, p.board2cam) + centroid_bias(CAM, board, p.board2cam),
            np.repeat(_plane_homography(RIG, p.board2cam)[None], board.n_points, axis=0),
        )
        for p in poses
    ]


# -- board ---------------------------------------------------------------------------------


def test_board_scale_equations_follow_the_paper():
    board = CircleBoard(
        rows=4,
        cols=7,
        circle_diameter_mm=15,
        center_distance_mm=30,
        border_mm=10,
        plane_size_m=(0.2, 0.16),
    )
    w_pat = (2 * 10 + 6 * 30 / 2 + 15) * 1e-3
    h_pat = (2 * 10 + 3 * 30 + 15) * 1e-3
    assert board.pattern_size_m == pytest.approx((w_pat, h_pat))
    scale = min(0.2 / w_pat, 0.16 / h_pat)
    assert board.scale == pytest.approx(scale)
    assert board.circle_diameter_m == pytest.approx(15e-3 * scale)
    assert board.center_distance_m == pytest.approx(30e-3 * scale)


def test_board_layout_is_an_asymmetric_grid_centred_on_the_plane():
    board = board_from_spec("5x9")
    points = board.object_points
    assert points.shape == (45, 3) and np.all(points[:, 2] == 0)
    half = board.center_distance_m / 2
    # Column j holds circles j*R .. j*R+R-1, D apart along y; columns D/2 apart along x.
    np.testing.assert_allclose(np.diff(points[:5, 1]), 2 * half)
    np.testing.assert_allclose(points[5, :2] - points[0, :2], (half, half))
    np.testing.assert_allclose(points.min(axis=0)[:2], -points.max(axis=0)[:2])


def test_board_texture_has_the_circles_area_and_their_centroids():
    board = board_from_spec("4x7")
    pixel = 2e-4
    texture = board.texture(pixel_size_m=pixel, blur_m=3e-4)
    darkness = (board.background_level - texture) / (board.background_level - board.circle_level)
    circle_area = np.pi * (board.circle_diameter_m / 2) ** 2
    assert darkness.sum() * pixel**2 == pytest.approx(
        board.n_points * circle_area, rel=tol.CALIB_TEXTURE_AREA_REL
    )
    # Centroid of the first circle's texels (x along columns, y along rows).
    rows, cols = np.mgrid[0 : texture.shape[0], 0 : texture.shape[1]]
    x = (cols + 0.5) * pixel - board.plane_size_m[0] / 2
    y = (rows + 0.5) * pixel - board.plane_size_m[1] / 2
    centre = board.object_points[0]
    near = np.hypot(x - centre[0], y - centre[1]) < 0.4 * board.center_distance_m
    w = darkness * near
    assert (w * x).sum() / w.sum() == pytest.approx(centre[0], abs=tol.CALIB_TEXTURE_CENTROID_M)
    assert (w * y).sum() / w.sum() == pytest.approx(centre[1], abs=tol.CALIB_TEXTURE_CENTROID_M)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"rows": 1}, "rows"),
        ({"cols": 8}, "odd number of columns"),
        ({"circle_diameter_mm": 35}, "circle_diameter_mm"),
        ({"plane_size_m": (0.05, 0.05), "border_mm": 0}, "plane_size_m"),
        ({"circle_level": 1.0}, "circle_level"),
    ],
)
def test_board_rejects_bad_input(kwargs, name):
    with pytest.raises(InputError, match=name):
        CircleBoard(**kwargs)


def test_board_spec_parsing():
    assert board_from_spec("4x7").pattern_shape == (4, 7)
    with pytest.raises(InputError, match="board"):
        board_from_spec("4-7")


# -- poses ---------------------------------------------------------------------------------


def test_paper_poses_are_18_and_inside_both_fields():
    board = board_from_spec("7x13")
    poses = paper_poses(RIG, board)
    assert len(poses) == 18 == len({p.name for p in poses})
    tilts = [np.degrees(np.arccos(p.board2cam.R[2, 2])) for p in poses]
    assert max(tilts) >= 30 - tol.CALIB_POSE_TILT_DEG
    # Every circle projects inside both images.
    for pose in poses:
        cam_uv = _true_centres(board, pose.board2cam)
        proj_uv = PROJ.project(RIG.cam2proj.apply(pose.board2cam.apply(board.object_points)))
        assert np.all((cam_uv > 0) & (cam_uv < 959))
        assert np.all((proj_uv > 0) & (proj_uv < (911, 1139)))


def test_pose_outside_the_field_raises_naming_it():
    board = board_from_spec("7x13")
    name, angles, _ = PAPER_POSE_TABLE[0]
    shifted = BoardPose("too_far_left", Pose.from_euler("xyz", angles, t=(-0.2, 0.0, 1.0)))
    with pytest.raises(VirtusError, match="too_far_left.*camera image"):
        check_pose(RIG, board, shifted)
    backwards = BoardPose("flipped", Pose.from_euler("xyz", (180, 0, 0), t=(0, 0, 1.0)))
    with pytest.raises(VirtusError, match="flipped.*back of the board"):
        check_pose(RIG, board, backwards)


def test_random_poses_are_seeded_and_valid():
    board = board_from_spec("4x7")
    first = pose_set("random:6", RIG, board, rng=7)
    again = random_poses(RIG, board, 6, rng=np.random.default_rng(7))
    assert [p.board2cam for p in first] == [p.board2cam for p in again]
    for pose in first:
        check_pose(RIG, board, pose)
    assert first[0].board2cam != pose_set("random:6", RIG, board, rng=8)[0].board2cam
    with pytest.raises(InputError, match="poses"):
        pose_set("random", RIG, board)


# -- detection and centres -----------------------------------------------------------------


@pytest.mark.parametrize("spec", ["4x7", "5x9", "7x13"])
def test_paper_boards_are_detected_in_order(spec):
    board = board_from_spec(spec)
    pose = paper_poses(RIG, board)[17]  # 30 deg tilt, 15 deg tilt, 45 deg roll
    image = board_image(CAM, board, pose.board2cam, supersample=2)
    found = find_grid(np.round(200 * image).astype(np.uint8), board)
    assert found is not None
    np.testing.assert_allclose(
        found, _true_centres(board, pose.board2cam), atol=tol.CALIB_DETECT_PX
    )


def test_incomplete_board_is_not_detected():
    board = board_from_spec("4x7")
    shifted = Pose.from_euler("xyz", (0, 0, 0), t=(0.14, 0.0, 1.0))  # right columns cut off
    image = board_image(CAM, board, shifted, supersample=1)
    assert find_grid(np.round(200 * image).astype(np.uint8), board) is None


def test_refined_centres_are_area_centroids_despite_shading():
    board = board_from_spec("4x7")
    pose = paper_poses(RIG, board)[8]  # 30 deg tilt about x
    shading = 1.0 + 0.3 * np.linspace(0.0, 1.0, CAM.width)[None, :]
    image = board_image(CAM, board, pose.board2cam, supersample=3, shading=shading)
    found = find_grid(np.round(200 * image).astype(np.uint8), board)
    refined = refine_centres(image, board, found)
    truth = _true_centres(board, pose.board2cam)
    bias = centroid_bias(CAM, board, pose.board2cam)
    assert np.abs(bias).max() > tol.CALIB_MIN_TILT_BIAS_PX  # why the bias is corrected
    np.testing.assert_allclose(refined, truth + bias, atol=tol.CALIB_CENTROID_PX)


def test_centroid_bias_vanishes_for_a_fronto_parallel_centred_circle():
    board = board_from_spec("4x7")
    front = Pose.identity() @ Pose(np.eye(3), (0.0, 0.0, 1.0))
    bias = centroid_bias(Intrinsics(2000, 2000, 0, 0, 960, 960), board, front)
    # An affine view (fronto-parallel) maps centroids to centroids.
    assert np.abs(bias).max() < tol.CALIB_FRONTO_PARALLEL_BIAS_PX


# -- projector points ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("rounded", "limit"),
    [(False, tol.CALIB_HOMOGRAPHY_EXACT_PX), (True, tol.CALIB_HOMOGRAPHY_STAIRCASE_RMS_PX)],
)
def test_local_homographies_give_the_projector_image_of_the_centres(rounded, limit):
    board = board_from_spec("7x13")
    pose = paper_poses(RIG, board)[11]
    uv_map = projector_map(RIG, pose.board2cam)
    if rounded:
        uv_map = np.round(uv_map)
    truth = _true_centres(board, pose.board2cam)
    # Neighbourhoods placed by the biased centroids, evaluated at the true centres.
    anchors = truth + centroid_bias(CAM, board, pose.board2cam)
    homographies = local_homographies(uv_map, board, anchors)
    got = apply_homographies(homographies, truth)
    expected = PROJ.project(RIG.cam2proj.apply(pose.board2cam.apply(board.object_points)))
    error = np.linalg.norm(got - expected, axis=1)
    assert (np.sqrt(np.mean(error**2)) if rounded else error.max()) < limit


def test_invalid_phase_gives_nan_homographies():
    board = board_from_spec("7x13")
    pose = paper_poses(RIG, board)[0]
    uv_map = projector_map(RIG, pose.board2cam)
    truth = _true_centres(board, pose.board2cam)
    rows, cols = np.mgrid[0 : CAM.height, 0 : CAM.width]
    uv_map[np.hypot(cols - truth[0, 0], rows - truth[0, 1]) < 26] = np.nan  # most of circle 0
    homographies = local_homographies(uv_map, board, truth)
    assert np.isnan(homographies[0]).all() and np.isfinite(homographies[1:]).all()


# -- solver --------------------------------------------------------------------------------


def test_calibration_recovers_the_rig_from_exact_observations():
    board = board_from_spec("7x13")
    result = calibrate_observations(
        board, _exact_observations(board, paper_poses(RIG, board)), (960, 960), (912, 1140)
    )
    assert max(result.rms_px.values()) < tol.CALIB_EXACT_RMS_PX
    error = truth_error(result.rig, RIG)
    for device in ("camera", "projector"):
        assert abs(error[device]["fx_rel_error"]) < tol.CALIB_EXACT_FOCAL_REL
        assert abs(error[device]["fy_rel_error"]) < tol.CALIB_EXACT_FOCAL_REL
        assert error[device]["principal_point_error_px"] < tol.CALIB_EXACT_PRINCIPAL_POINT_PX
    assert abs(error["proj2cam"]["baseline_error_m"]) < tol.CALIB_EXACT_BASELINE_M
    assert error["proj2cam"]["rotation_error_deg"] < tol.CALIB_EXACT_ROTATION_DEG


def test_undetected_pose_is_dropped_with_a_warning_naming_it():
    board = board_from_spec("4x7")
    observations = _exact_observations(board, paper_poses(RIG, board)[:5])
    observations[2] = PoseObservation("tilt_x+15", None, None)
    observations[3].homographies[4] = np.nan
    with pytest.warns(UserWarning) as record:
        result = calibrate_observations(board, observations, (960, 960), (912, 1140))
    messages = " ".join(str(w.message) for w in record)
    assert "'tilt_x+15'" in messages and "camera did not detect" in messages
    assert f"'{observations[3].name}'" in messages and "projector did not see" in messages
    assert set(result.dropped_poses) == {"tilt_x+15", observations[3].name}
    assert len(result.used_poses) == 3


def test_outlier_pose_is_dropped():
    board = board_from_spec("4x7")
    observations = _exact_observations(board, paper_poses(RIG, board)[:8])
    rng = np.random.default_rng(1)
    observations[5].cam_centroids += rng.normal(0.0, 2.0, observations[5].cam_centroids.shape)
    with pytest.warns(UserWarning, match="outlier"):
        result = calibrate_observations(board, observations, (960, 960), (912, 1140))
    assert list(result.dropped_poses) == [observations[5].name]


def test_fewer_than_three_usable_poses_is_a_clear_error():
    board = board_from_spec("4x7")
    observations = _exact_observations(board, paper_poses(RIG, board)[:4])
    observations[0] = PoseObservation("front_1000", None, None)
    observations[1] = PoseObservation("front_0900", None, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(VirtusError, match="at least 3 usable poses, got 2"):
            calibrate_observations(board, observations, (960, 960), (912, 1140))


# -- truth comparison ----------------------------------------------------------------------


def test_truth_error_reports_known_perturbations():
    cam = Intrinsics(CAM.fx * 1.001, CAM.fy, CAM.cx + 0.3, CAM.cy - 0.4, 960, 960)
    turn = Pose.from_euler("xyz", (0.0, 0.02, 0.0))
    proj2cam = Pose(RIG.proj2cam.R @ turn.R, RIG.proj2cam.t * (1 + 1e-3))
    error = truth_error(Rig(Camera(cam), RIG.projector, proj2cam), RIG)
    assert error["camera"]["fx_rel_error"] == pytest.approx(1e-3)
    assert error["camera"]["principal_point_error_px"] == pytest.approx(0.5)
    assert error["projector"]["fx_rel_error"] == 0.0
    assert error["proj2cam"]["baseline_error_m"] == pytest.approx(1e-3 * RIG.baseline_m)
    assert error["proj2cam"]["rotation_error_deg"] == pytest.approx(
        0.02, rel=tol.CALIB_TRUTH_ROTATION_REL
    )


# -- files ---------------------------------------------------------------------------------


def _distorted_rig() -> Rig:
    cam = Intrinsics(2280.5, 2281.5, 478.2, 481.7, 960, 960, (-0.1, 0.05, 1e-4, -2e-4, 0.0))
    proj = Intrinsics(1820.0, 1825.0, 450.1, 570.2, 912, 1140, (0.01, -0.02, 0.0, 0.0, 0.0))
    return Rig(Camera(cam), Projector(proj), RIG.proj2cam)


def _assert_same_rig(a: Rig, b: Rig) -> None:
    for da, db in (
        (a.camera.intrinsics, b.camera.intrinsics),
        (a.projector.intrinsics, b.projector.intrinsics),
    ):
        np.testing.assert_allclose(da.K, db.K, rtol=tol.CALIB_FILE_ROUND_TRIP)
        np.testing.assert_allclose(da.dist_array, db.dist_array, atol=tol.CALIB_FILE_ROUND_TRIP)
        assert (da.width, da.height) == (db.width, db.height)
    np.testing.assert_allclose(a.proj2cam.matrix, b.proj2cam.matrix, atol=tol.CALIB_FILE_ROUND_TRIP)


def test_opencv_yaml_round_trip(tmp_path):
    rig = _distorted_rig()
    path = save_opencv_yaml(rig, tmp_path / "cal.yaml", {"rms_stereo_px": 0.01})
    _assert_same_rig(load_opencv_yaml(path), rig)
    import cv2

    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    # OpenCV's stereo convention: X_proj = R X_cam + T (metres).
    np.testing.assert_allclose(storage.getNode("T").mat().ravel(), rig.cam2proj.t)
    storage.release()


def test_paper_txt_round_trip_and_units(tmp_path):
    rig = _distorted_rig()
    save_paper_txt(rig, tmp_path)
    translation = np.loadtxt(tmp_path / "ProjTranslationVector.txt", delimiter="\t")
    np.testing.assert_allclose(translation, rig.cam2proj.t * 1000.0)  # millimetres
    assert np.loadtxt(tmp_path / "CamIntrinsicMatrix.txt", delimiter="\t").shape == (3, 3)
    _assert_same_rig(load_paper_txt(tmp_path), rig)


def test_calibration_json_reads_back_as_a_rig(tmp_path):
    from virtus.calib.result import CalibrationResult

    board = board_from_spec("4x7")
    poses = paper_poses(RIG, board)[:4]
    solved = calibrate_observations(
        board, _exact_observations(board, poses), (960, 960), (912, 1140)
    )
    result = CalibrationResult(
        solved.rig,
        solved.rms_px,
        solved.per_pose,
        truth_error(solved.rig, RIG),
        board,
        poses,
        true_rig=RIG,
    )
    path = result.save(tmp_path)
    data = json.loads(path.read_text())
    assert {
        "units",
        "camera",
        "projector",
        "proj2cam",
        "rms_px",
        "per_pose",
        "board",
        "truth_error",
    } <= set(data)
    assert set(data["rms_px"]) == {"camera", "projector", "stereo"}
    _assert_same_rig(Rig.load_json(path), solved.rig)
    _assert_same_rig(load_opencv_yaml(tmp_path / "calibration.yaml"), solved.rig)


# -- CLI -----------------------------------------------------------------------------------


def test_cli_rejects_a_bad_board(capsys):
    from virtus.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["calibrate", "--board", "7by13", "--out", "unused"])
    assert exit_info.value.code == 2
    assert "board: expected 'ROWSxCOLS'" in capsys.readouterr().err


def test_random_poses_refuse_a_board_larger_than_the_field():
    huge = CircleBoard(rows=4, cols=7, plane_size_m=(0.6, 0.6))
    with pytest.raises(VirtusError, match="no random pose inside the common field"):
        random_poses(RIG, huge, 1, rng=0, max_tries=20)
    with pytest.raises(VirtusError, match="front_1000"):
        paper_poses(RIG, huge)


def test_calibration_file_errors_are_clear(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_paper_txt(tmp_path)
    save_paper_txt(_distorted_rig(), tmp_path)
    (tmp_path / "ProjRotationMatrix.txt").write_text("1\t0\n0\t1\n")
    with pytest.raises(InputError, match="9 numbers"):
        load_paper_txt(tmp_path)
    with pytest.raises(FileNotFoundError):
        load_opencv_yaml(tmp_path / "missing.yaml")
