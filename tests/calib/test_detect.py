"""Circle-board detection (:mod:`virtus.calib.detect`) on an exactly drawn board image: a
point the grid finder misplaces moves no centroid."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from virtus.calib import board_from_spec, detect
from virtus.calib.detect import find_grid, mend_outliers, refine_centres
from virtus.calib.solve import centroid_bias
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

#: bench_robot.py's small board: 15 px circles at this focal length and distance.
BOARD = board_from_spec("circles:4x7,spacing_mm=12,diameter_mm=6,border_mm=6")
CAMERA = Intrinsics(2285.77, 2285.77, 119.5, 119.5, 240, 240)
#: The board 0.9 m away, tilted 20 deg about x and 10 about y, turned 15 deg.
BOARD2CAM = Pose.from_euler("xyz", [20.0, -10.0, 15.0], t=(0.0, 0.0, 0.9))
#: Supersampling per axis of the drawn image (coverage error of an edge pixel ~ 1/64).
SUPERSAMPLE = 8
#: Blur of the image (px): a rendered board's edges are soft (texture, pixel, projector);
#: a symmetric blur keeps each circle's darkness centroid.
BLUR_PX = 0.7
#: Grey levels: white board, dark circles, the floor around the board.
WHITE, DARK, FLOOR = 0.9, 0.15, 0.45


def _board_image() -> np.ndarray:
    """(240, 240) float image of BOARD at BOARD2CAM through CAMERA (no distortion), each
    pixel the mean of SUPERSAMPLE^2 samples of the printed board, blurred by BLUR_PX."""
    k = CAMERA.K @ np.column_stack([BOARD2CAM.R[:, 0], BOARD2CAM.R[:, 1], BOARD2CAM.t])
    step = 1.0 / SUPERSAMPLE
    offsets = np.arange(SUPERSAMPLE) * step - 0.5 + step / 2
    u = (np.arange(CAMERA.width)[:, None] + offsets[None]).ravel()
    v = (np.arange(CAMERA.height)[:, None] + offsets[None]).ravel()
    uu, vv = np.meshgrid(u, v)
    plane = np.linalg.solve(k, np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]))
    xy = (plane[:2] / plane[2]).T
    half = 0.5 * np.asarray(BOARD.plane_size_m)
    on_board = (np.abs(xy) <= half).all(axis=1)
    radius = 0.5 * BOARD.circle_diameter_m
    centres = BOARD.object_points[:, :2]
    in_circle = np.zeros(len(xy), dtype=bool)
    for centre in centres:
        in_circle |= np.sum((xy - centre) ** 2, axis=1) <= radius**2
    value = np.where(on_board, np.where(in_circle, DARK, WHITE), FLOOR)
    shape = (CAMERA.height, SUPERSAMPLE, CAMERA.width, SUPERSAMPLE)
    return cv2.GaussianBlur(value.reshape(shape).mean(axis=(1, 3)), (0, 0), BLUR_PX)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return _board_image()


def _truth() -> tuple[np.ndarray, np.ndarray]:
    """The circles' centres as imaged and their area centroids (px)."""
    centres = CAMERA.project(BOARD2CAM.apply(BOARD.object_points))
    return centres, centres + centroid_bias(CAMERA, BOARD, BOARD2CAM)


def test_refined_centroids_are_the_area_centroids(image: np.ndarray) -> None:
    centres, area = _truth()
    found = find_grid(image, BOARD)
    assert found is not None
    assert np.abs(found - centres).max() < 0.5
    # 0.01 px: the drawn image's sampling of each edge (SUPERSAMPLE^2 samples a pixel) and
    # the blur's tails beyond the windows; measured 0.0067 px
    assert np.abs(refine_centres(image, BOARD, found) - area).max() < 0.01


def test_a_point_off_its_circle_moves_no_centroid(image: np.ndarray) -> None:
    # OpenCV's blob detector put a circle's point up to 10 px off (half way to the next
    # circle) on rendered boards of 15 px circles; every refinement window was placed by
    # a homography bent by it, and centroids came out up to 1.2 px off.
    centres, _ = _truth()
    reference = refine_centres(image, BOARD, centres)
    towards = (centres[19] - centres[23]) / np.linalg.norm(centres[19] - centres[23])
    for shift in (2.5, 9.0):
        moved = centres.copy()
        moved[23] += shift * towards
        # measured with one pass and no mending (before): 0.040 px (2.5 px off), 0.30 px
        assert np.abs(refine_centres(image, BOARD, moved) - reference).max() < 1e-3, shift
        mended = mend_outliers(BOARD, moved)
        if shift > 5:  # beyond the outlier threshold: replaced by the grid's prediction
            assert np.abs(mended - centres).max() < 0.05
        else:
            assert np.array_equal(mended, moved)
        assert np.abs(refine_centres(image, BOARD, mended) - reference).max() < 1e-3, shift


def _per_circle(monkeypatch: pytest.MonkeyPatch, function, *arguments):
    """``function(*arguments)`` with the per-circle centroid pass (the reference)."""
    with monkeypatch.context() as patch:
        patch.setattr(detect, "_centroids", detect._centroids_per_circle)
        return function(*arguments)


@pytest.mark.parametrize("batch_pixels", [1 << 16, 1])  # one batch; a circle per batch
def test_batched_centroids_are_the_per_circle_ones(image, monkeypatch, batch_pixels) -> None:
    centres, _ = _truth()
    monkeypatch.setattr(detect, "_CENTROID_BATCH_PIXELS", batch_pixels)
    batched = refine_centres(image, BOARD, centres)
    reference = _per_circle(monkeypatch, refine_centres, image, BOARD, centres)
    assert np.isfinite(reference).all()
    # The same windows and rules; the background fits differ by rounding (normal
    # equations against lstsq): measured 3e-12 px on the paper's rendered poses.
    np.testing.assert_allclose(batched, reference, rtol=0, atol=1e-9)


def test_batched_centroids_reject_the_circles_the_per_circle_pass_rejects(image, monkeypatch):
    centres, _ = _truth()
    # Part of the board beyond the image (its windows leave it), a dark patch that makes
    # a background ring too dark, and a white-on-black board seen inverted.
    cut = image[:, 70:].copy()
    shifted = centres - (70.0, 0.0)
    u, v = np.rint(shifted[17]).astype(int)
    cut[v - 14 : v + 15, u - 14 : u + 15] = 0.0  # no background around circle 17
    light = board_from_spec("circles:4x7,spacing_mm=12,diameter_mm=6,border_mm=6,white_on_black")
    for board, picture in ((BOARD, cut), (light, 1.0 - image)):
        points = shifted if picture is cut else centres
        batched = refine_centres(picture, board, points)
        reference = _per_circle(monkeypatch, refine_centres, picture, board, points)
        np.testing.assert_array_equal(np.isnan(batched), np.isnan(reference))
        np.testing.assert_allclose(batched, reference, rtol=0, atol=1e-9)
    lost = np.isnan(refine_centres(cut, BOARD, shifted)[:, 0])
    assert lost[17] and 5 <= lost.sum() < BOARD.n_points - 4


def test_centroids_on_a_torch_device_are_the_host_ones(image, monkeypatch) -> None:
    # A calibration rendered on a GPU refines its centroids there with this same code;
    # torch on the CPU is its twin. Rejected circles, a light board and the one-by-one
    # least squares of a singular ring must match too.
    pytest.importorskip("torch")
    centres, _ = _truth()
    cut = image[:, 70:].copy()
    shifted = centres - (70.0, 0.0)
    u, v = np.rint(shifted[17]).astype(int)
    cut[v - 14 : v + 15, u - 14 : u + 15] = 0.0
    light = board_from_spec("circles:4x7,spacing_mm=12,diameter_mm=6,border_mm=6,white_on_black")
    cases = ((BOARD, image, centres), (BOARD, cut, shifted), (light, 1.0 - image, centres))
    for board, picture, points in cases:
        host = refine_centres(picture, board, points)
        twin = refine_centres(picture, board, points, device="cpu")
        np.testing.assert_array_equal(np.isnan(twin), np.isnan(host))
        np.testing.assert_allclose(twin, host, rtol=0, atol=1e-9)
    import torch

    solve = torch.linalg.solve

    def singular(*arguments):
        raise torch.linalg.LinAlgError("singular")

    monkeypatch.setattr(torch.linalg, "solve", singular)
    fallback = refine_centres(image, BOARD, centres, device="cpu")
    monkeypatch.setattr(torch.linalg, "solve", solve)
    np.testing.assert_allclose(fallback, refine_centres(image, BOARD, centres), rtol=0, atol=1e-9)


def test_the_per_circle_reference_refuses_a_device() -> None:
    from virtus.calib.arrayspace import torch_space

    pytest.importorskip("torch")
    centres, _ = _truth()
    H = detect.fit_homography(BOARD.object_points[:, :2], centres)  # noqa: N806
    with pytest.raises(ValueError, match="numpy arrays only"):
        detect._centroids_per_circle(_board_image(), BOARD, centres, H, torch_space("cpu"))
