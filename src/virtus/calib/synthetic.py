"""Exact synthetic views of a circle board, independent of the renderer.

They give calibration tests a ground truth built from first principles: camera rays are
intersected with the board plane and every sample is classified as inside or outside a
circle analytically (no texture), and projector coordinates are the rig's own projection of
the hit point. Used to prove detection, centre refinement and calibration on exact data.
"""

from __future__ import annotations

import numpy as np

from virtus.calib.board import CircleBoard
from virtus.checks import positive_int
from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

#: Rows of camera pixels processed at once (bounds memory: rows * width * ss^2 samples).
_CHUNK_ROWS = 64


def _board_xy(intrinsics: Intrinsics, board2cam: Pose, pixels: np.ndarray) -> np.ndarray:
    """Board-frame (x, y) where the rays of ``pixels`` (N, 2) meet the plane; NaN if missed."""
    rays = intrinsics.unproject(pixels)
    normal = board2cam.R[:, 2]
    denom = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (board2cam.t @ normal) / denom
    s = np.where(s > 0, s, np.nan)
    hits = rays * s[:, None]
    return ((hits - board2cam.t) @ board2cam.R)[:, :2]


def _inside_circles(board: CircleBoard, xy: np.ndarray) -> np.ndarray:
    """Boolean (N,): sample (x, y) in metres (board frame) lies inside a circle."""
    points = board.object_points
    half = 0.5 * board.center_distance_m
    x0, y0 = points[0, 0], points[0, 1]
    r2 = (0.5 * board.circle_diameter_m) ** 2
    inside = np.zeros(len(xy), dtype=bool)
    j_near = np.rint((xy[:, 0] - x0) / half)
    for dj in (-1, 0, 1):
        j = j_near + dj
        ok = (j >= 0) & (j < board.cols)
        yj = xy[:, 1] - y0 - np.mod(j, 2) * half
        i = np.clip(np.rint(yj / (2 * half)), 0, board.rows - 1)
        dx = xy[:, 0] - (x0 + j * half)
        dy = yj - i * 2 * half
        inside |= ok & (dx * dx + dy * dy <= r2)
    return inside


def _sample_texture(texture: np.ndarray, board: CircleBoard, xy: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a board texture at board-frame points (N, 2) m; 0 off the plane."""
    height, width = texture.shape
    col = (xy[:, 0] / board.plane_size_m[0] + 0.5) * width - 0.5
    row = (xy[:, 1] / board.plane_size_m[1] + 0.5) * height - 0.5
    ok = np.isfinite(col) & np.isfinite(row)
    col = np.clip(np.where(ok, col, 0.0), 0, width - 1)
    row = np.clip(np.where(ok, row, 0.0), 0, height - 1)
    c0 = np.minimum(np.floor(col).astype(int), width - 2)
    r0 = np.minimum(np.floor(row).astype(int), height - 2)
    fc, fr = col - c0, row - r0
    top = texture[r0, c0] * (1 - fc) + texture[r0, c0 + 1] * fc
    bottom = texture[r0 + 1, c0] * (1 - fc) + texture[r0 + 1, c0 + 1] * fc
    return np.where(ok, top * (1 - fr) + bottom * fr, 0.0)


def board_image(
    intrinsics: Intrinsics,
    board: CircleBoard,
    board2cam: Pose,
    supersample: int = 4,
    shading: np.ndarray | None = None,
    texture: np.ndarray | None = None,
) -> np.ndarray:
    """Exact area-sampled image of the board's albedo seen by a camera.

    Parameters
    ----------
    intrinsics : the camera (distortion honoured).
    board2cam : board frame -> camera frame.
    supersample : ``supersample**2`` samples per pixel on a regular sub-grid (box filter).
    shading : optional (H, W) float multiplier (e.g. an illumination gradient).
    texture : optional (H_t, W_t) board texture (:meth:`CircleBoard.texture`) sampled
        bilinearly instead of the analytic circles.

    Returns
    -------
    (H, W) float64 image: the board's albedo levels where the plane is seen, 0 elsewhere.
    """
    ss = positive_int("supersample", supersample)
    offsets = (np.arange(ss) + 0.5) / ss - 0.5
    width, height = intrinsics.width, intrinsics.height
    image = np.zeros((height, width))
    hw = 0.5 * np.asarray(board.plane_size_m)
    for r0 in range(0, height, _CHUNK_ROWS):
        rows = np.arange(r0, min(r0 + _CHUNK_ROWS, height))
        v = (rows[:, None] + offsets[None, :]).ravel()
        u = (np.arange(width)[:, None] + offsets[None, :]).ravel()
        uu, vv = np.meshgrid(u, v)
        xy = _board_xy(intrinsics, board2cam, np.stack([uu.ravel(), vv.ravel()], axis=1))
        on_plane = np.all(np.abs(xy) <= hw, axis=1)  # NaN compares False
        if texture is None:
            level = np.where(
                _inside_circles(board, np.nan_to_num(xy)),
                board.circle_level,
                board.background_level,
            )
        else:
            level = _sample_texture(texture, board, xy)
        level = np.where(on_plane, level, 0.0)
        image[rows] = level.reshape(len(rows), ss, width, ss).mean(axis=(1, 3))
    if shading is not None:
        image = image * shading
    return image


def projector_map(rig: Rig, board2cam: Pose) -> np.ndarray:
    """Exact projector coordinates seen by every camera pixel centre on the board plane.

    Returns
    -------
    (H, W, 2) float64, projector pixels (u_p, v_p); NaN where the camera ray misses the
    plane (the plane is taken as unbounded: the caller masks by the board if needed).
    """
    cam = rig.camera.intrinsics
    pixels = cam.pixel_grid().reshape(-1, 2)
    xy = _board_xy(cam, board2cam, pixels)
    points = np.column_stack([xy, np.zeros(len(xy))])
    uv = rig.projector.intrinsics.project(
        rig.cam2proj.apply(board2cam.apply(np.nan_to_num(points)))
    )
    uv[~np.isfinite(xy).all(axis=1)] = np.nan
    return uv.reshape(cam.height, cam.width, 2)
