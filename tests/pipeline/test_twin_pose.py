"""``twin --validate`` poses a board the calibration file does not place from both devices
(:func:`virtus.pipeline.twin.stereo_board_pose`): the camera's circle centres and their
decoded projector points. Camera-only PnP puts the board where the camera's focal length
says; a calibration whose focal length is off by 1 % then misplaces it by about 1 % of its
distance, where the stereo pose stays on the surface the rig reconstructs."""

from __future__ import annotations

import numpy as np
import pytest

from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.calib.board import board_from_spec
from virtus.calib.observe import observe_pose
from virtus.calib.poses import pose_set
from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
from virtus.geometry.devices import Camera, Rig
from virtus.pipeline.twin import _pnp, stereo_board_pose, validate_twin
from virtus.reconstruct import points_from_decoded
from virtus.render import RenderSettings
from virtus.scanner import Scanner

RIG = scaled_rig(0.25)
BOARD = board_from_spec("4x7")


@pytest.fixture(scope="module")
def board_captures(tmp_path_factory):
    """Two board poses rendered with the true rig, saved as capture folders."""
    folder = tmp_path_factory.mktemp("boards")
    scanner = Scanner(rig=RIG, render=RenderSettings(spp=1))
    texture = BOARD.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    poses = pose_set("random:2", RIG, BOARD, np.random.default_rng(7))
    for index, pose in enumerate(poses):
        scanner.capture(board_scene(BOARD, pose, texture), rng=50 + index).save(folder / pose.name)
    return folder, poses


def _miscalibrated(rig: Rig, factor: float) -> Rig:
    """The rig with the camera's focal length scaled (a calibration's typical error)."""
    c = rig.camera.intrinsics
    camera = type(c)(c.fx * factor, c.fy * factor, c.cx, c.cy, c.width, c.height, c.dist)
    return Rig(Camera(camera), rig.projector, rig.proj2cam)


def _plane_offset_mm(pose, cloud: np.ndarray) -> float:
    """Median signed distance of a point cloud from the posed board's plane, mm."""
    normal = pose.R[:, 2]
    return float(1e3 * np.median((cloud - pose.t) @ normal))


def test_stereo_pose_is_the_true_pose_and_survives_a_wrong_focal_length(board_captures):
    from virtus.capture.capture import Capture

    folder, poses = board_captures
    capture = Capture.load(folder / poses[0].name)
    obs = observe_pose(capture, BOARD, poses[0].name)
    truth = poses[0].board2cam
    # the true rig: the stereo pose is the rendered one (sub-millimetre, a fraction of a degree)
    pose, errors = stereo_board_pose(RIG, BOARD, obs.cam_centroids, obs.homographies)
    assert np.linalg.norm(pose.t - truth.t) < 5e-4
    assert (pose.inverse() @ truth).angle_deg < 0.2
    assert errors["camera"] < 0.2 and errors["projector"] < 0.2
    # a camera focal length 1 % off: PnP moves the board along the view by ~1 % of its
    # distance, off the surface that rig reconstructs; the stereo pose stays on it
    wrong = _miscalibrated(RIG, 1.01)
    decoded = capture.decode(repair=True)
    cloud = points_from_decoded(wrong, decoded.proj_uv, decoded.mask)[decoded.mask]
    cloud = cloud[np.isfinite(cloud).all(axis=1)]
    stereo, _ = stereo_board_pose(wrong, BOARD, obs.cam_centroids, obs.homographies)
    camera_only = _pnp(wrong, BOARD, obs.cam_centroids)
    on_board = np.abs(
        (cloud - stereo.t) @ stereo.R[:, :2]  # in-plane coordinates within the board
    ).max(axis=1) < 0.5 * min(BOARD.plane_size_m)
    cloud = cloud[on_board]
    pnp_offset = abs(_plane_offset_mm(camera_only, cloud))
    stereo_offset = abs(_plane_offset_mm(stereo, cloud))
    assert pnp_offset > 3.0  # ~1 % of the ~1 m distance
    assert stereo_offset < 0.1 * pnp_offset


def test_validation_without_calibrated_poses_poses_the_board_from_both_devices(
    board_captures, tmp_path
):
    folder, poses = board_captures
    result = validate_twin(RIG, [folder], board="4x7", out=tmp_path / "validation.json")
    assert [row["name"] for row in result.per_pose] == [p.name for p in poses]
    for row in result.per_pose:
        assert row["posed_by"] == "stereo"
        assert row["pose_errors"]["camera"] < 0.2 and row["pose_errors"]["projector"] < 0.2
        for key in ("white_rms", "fringe_rms", "code_rms", "proj_uv_rms_px", "cloud_mae_mm",
                    "cloud_rmse_mm", "point_noise_ratio"):  # fmt: skip
            assert np.isfinite(row[key]), key
    # virtual to virtual with the true rig: the twin's cloud is the capture's
    assert result.overall["cloud_mae_mm"] < 0.05
    assert result.overall["proj_uv_rms_px"] < 0.1
