"""The board's window in the camera image (:func:`virtus.calib.scene.board_window`): it
holds the board plane's whole image, lens distortion included, and no more than a margin
around it."""

from __future__ import annotations

import numpy as np

from virtus.calib.board import board_from_spec
from virtus.calib.scene import board_window
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

BOARD = board_from_spec("7x13")
#: A 960 px camera with strong barrel distortion: edges bow out between the corners.
CAMERA = Intrinsics(1500.0, 1500.0, 479.5, 479.5, 960, 960, dist=(-0.4, 0.1, 0.0, 0.0))


def _plane_pixels(board2cam: Pose) -> np.ndarray:
    """Camera pixels of a dense grid over the whole board plane."""
    half = 0.5 * np.asarray(BOARD.plane_size_m)
    x, y = np.meshgrid(*(np.linspace(-h, h, 201) for h in half))
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    return CAMERA.project(board2cam.apply(points))


def test_the_window_holds_the_whole_board_image_and_a_margin():
    board2cam = Pose.from_euler("xyz", [25.0, -20.0, 10.0], t=(0.05, -0.03, 0.8))
    rows, cols = board_window(CAMERA, BOARD, board2cam, margin_px=8)
    pixels = _plane_pixels(board2cam)
    assert np.isfinite(pixels).all()
    lo, hi = pixels.min(axis=0), pixels.max(axis=0)
    assert cols.start <= lo[0] - 8 + 1 and hi[0] + 8 - 1 <= cols.stop - 1
    assert rows.start <= lo[1] - 8 + 1 and hi[1] + 8 - 1 <= rows.stop - 1
    assert cols.stop - cols.start <= hi[0] - lo[0] + 2 * 8 + 3  # no more than the margin
    # Near the image's edge the window is clipped to the image.
    side = Pose.from_euler("xyz", [0.0, 30.0, 0.0], t=(0.35, 0.0, 0.8))
    rows, cols = board_window(CAMERA, BOARD, side)
    assert cols.stop == CAMERA.width and rows.start > 0


def test_a_board_behind_the_camera_has_no_window():
    behind = Pose.from_euler("xyz", [0.0, 0.0, 0.0], t=(0.0, 0.0, -0.5))
    assert board_window(CAMERA, BOARD, behind) is None
    crossing = Pose.from_euler("xyz", [0.0, 89.0, 0.0], t=(0.0, 0.0, 0.05))
    assert board_window(CAMERA, BOARD, crossing) is None
