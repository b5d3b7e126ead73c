"""Hand-eye calibration on synthetic board poses: exact, noisy (errors as predicted), and
degenerate motion refused with its reason."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.tolerances import HANDEYE_EXACT_M, HANDEYE_EXACT_RAD, HANDEYE_EXPECTED_RATIO
from virtus.errors import DegenerateData, InputError
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.robot.handeye import solve_handeye

#: the camera 5 cm beside the hand, looking along the hand's z axis, tilted 5 deg
CAM2HAND = Pose.from_euler("xyz", [5.0, -3.0, 90.0], t=[0.05, 0.02, 0.06]).matrix
#: the board on the table 0.5 m in front of the robot, facing up
BOARD2BASE = Pose.from_euler("xyz", [180.0, 0.0, 10.0], t=[0.5, 0.0, 0.0]).matrix
BOARD = np.array([[x, y, 0.0] for x in np.linspace(0, 0.12, 7) for y in np.linspace(0, 0.08, 5)])


def _hand_poses(rng: np.random.Generator, count: int, spread_rad: float = 0.4) -> np.ndarray:
    """Hand poses looking at the board from ~0.45 m, turned by up to ``spread_rad``."""
    out = []
    for _ in range(count):
        eye = np.array([0.55, 0.04, 0.45]) + rng.normal(scale=0.08, size=3)
        cam2base = Pose.look_at(eye, [0.55, 0.04, 0.0], [1.0, 0.0, 0.0]).matrix
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(rng.normal(scale=spread_rad, size=3)).as_matrix()
        out.append(cam2base @ turn @ np.linalg.inv(CAM2HAND))
    return np.array(out)


def _board2cam(hand2base: np.ndarray) -> np.ndarray:
    return np.linalg.inv(CAM2HAND) @ np.linalg.inv(hand2base) @ BOARD2BASE


def _errors(result: Pose, truth: np.ndarray) -> tuple[float, float]:
    delta = Pose.from_matrix(np.linalg.inv(truth) @ result.matrix)
    return float(np.linalg.norm(delta.rotvec)), float(np.linalg.norm(delta.t))


def test_noise_free_poses_give_the_truth_in_both_modes() -> None:
    H = _hand_poses(np.random.default_rng(0), 10)  # noqa: N806
    result = solve_handeye(H, _board2cam(H))
    rot, trans = _errors(result.cam2hand, CAM2HAND)
    assert rot <= HANDEYE_EXACT_RAD and trans <= HANDEYE_EXACT_M
    rot, trans = _errors(result.board2base, BOARD2BASE)
    assert rot <= HANDEYE_EXACT_RAD and trans <= HANDEYE_EXACT_M
    assert result.motion["poses"] == 10 and result.motion["max_relative_rotation_deg"] > 30
    # eye-to-hand: a fixed camera (cam2base) watching a board held by the hand (board2hand)
    cam2base, board2hand = BOARD2BASE, CAM2HAND  # any two poses
    C = np.array([np.linalg.inv(cam2base) @ h @ board2hand for h in H])  # noqa: N806
    fixed = solve_handeye(H, C, mode="eye_to_hand")
    assert max(_errors(fixed.cam2hand, cam2base)) <= HANDEYE_EXACT_M
    assert max(_errors(fixed.board2base, board2hand)) <= HANDEYE_EXACT_M
    assert set(fixed.to_dict()) >= {"cam2base", "board2hand", "expected_rotation_error_deg"}


def test_pixel_refinement_reaches_the_truth_and_predicts_its_errors() -> None:
    rng = np.random.default_rng(1)
    H = _hand_poses(rng, 10)  # noqa: N806
    C = _board2cam(H)  # noqa: N806
    camera = Intrinsics(2285.77, 2285.77, 479.5, 479.5, 960, 960)
    pixels = [camera.project(BOARD @ c[:3, :3].T + c[:3, 3]) for c in C]
    exact = solve_handeye(H, C, board_points=BOARD, image_points=pixels, intrinsics=camera)
    assert max(_errors(exact.cam2hand, CAM2HAND)) <= HANDEYE_EXACT_M
    assert exact.residual_unit == "px" and exact.residual_rms < 1e-6
    seen, predicted = [], []
    for _ in range(20):
        noisy = [p + rng.normal(scale=0.1, size=p.shape) for p in pixels]  # 0.1 px
        r = solve_handeye(H, C, board_points=BOARD, image_points=noisy, intrinsics=camera)
        seen.append(_errors(r.cam2hand, CAM2HAND))
        predicted.append((np.radians(r.rotation_error_deg), r.translation_error_mm / 1e3))
    seen_rms = np.sqrt(np.mean(np.square(seen), axis=0))
    ratio = seen_rms / np.mean(predicted, axis=0)
    assert np.all(ratio < HANDEYE_EXPECTED_RATIO) and np.all(ratio > 1 / HANDEYE_EXPECTED_RATIO)


def test_board_pose_noise_within_the_stated_bound_and_predicted() -> None:
    """0.1 mrad / 0.1 mm board-pose noise at 10 poses of +-23 deg: OpenCV 4.14's methods
    reached 0.012 deg / 0.25 mm (DESIGN 7); ours must do at least as well on average."""
    rng = np.random.default_rng(2)
    H = _hand_poses(rng, 10)  # noqa: N806
    C = _board2cam(H)  # noqa: N806
    seen, predicted = [], []
    for _ in range(20):
        noise = [
            Pose.from_rotvec(rng.normal(scale=1e-4, size=3), rng.normal(scale=1e-4, size=3))
            for _ in C
        ]
        r = solve_handeye(H, [c @ n.matrix for c, n in zip(C, noise, strict=True)])
        seen.append(_errors(r.cam2hand, CAM2HAND))
        predicted.append((np.radians(r.rotation_error_deg), r.translation_error_mm / 1e3))
    seen_rms = np.sqrt(np.mean(np.square(seen), axis=0))
    assert np.degrees(seen_rms[0]) < 0.012 and seen_rms[1] < 0.25e-3
    ratio = seen_rms / np.mean(predicted, axis=0)
    assert np.all(ratio < HANDEYE_EXPECTED_RATIO) and np.all(ratio > 1 / HANDEYE_EXPECTED_RATIO)


def _about_axis(axis: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    base = _hand_poses(np.random.default_rng(3), 1, spread_rad=0.0)[0]
    rng = np.random.default_rng(6)
    out = []
    for angle in angles_deg:
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(np.radians(angle) * axis).as_matrix()
        turn[:3, 3] = rng.normal(scale=0.05, size=3)
        out.append(base @ turn)
    return np.array(out)


def test_degenerate_motion_is_refused_with_its_reason() -> None:
    H = _hand_poses(np.random.default_rng(4), 10)  # noqa: N806
    with pytest.raises(DegenerateData, match=r"at least 3 robot poses .* got 2"):
        solve_handeye(H[:2], _board2cam(H[:2]))
    base = _about_axis(np.array([1.0, 0.0, 0.0]), np.zeros(10))  # translations only
    tilt = np.array(
        [
            p @ Pose.from_rotvec(np.radians(3.0) * np.eye(3)[k % 3]).matrix
            for k, p in enumerate(base)
        ]
    )  # +-3 deg about three axes
    with pytest.raises(DegenerateData, match=r"rotate too little .* need >= 10 deg"):
        solve_handeye(tilt, _board2cam(tilt))
    parallel = _about_axis(np.array([0.0, 0.0, 1.0]), np.linspace(-40, 40, 10))
    with pytest.raises(DegenerateData, match="parallel axes"):
        solve_handeye(parallel, _board2cam(parallel))
    with pytest.raises(InputError, match="one board pose per robot pose"):
        solve_handeye(H, _board2cam(H)[:9])
