"""The calibration board as a scene: a textured plane in one board pose, and how its
texture is made (the circles' and squares' edge softening, the texel size).

The calibration job (:mod:`virtus.pipeline.calibrate`), the twin validation and the
dataset's calibration mode render the board through :func:`board_scene` with a texture
from ``board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=...)``, :data:`BOARD_BLUR_M` for
circle boards and :data:`CHECKER_BLUR_M` for checkerboards (:func:`board_texture`).
"""

from __future__ import annotations

import functools
import threading
from typing import Any

import numpy as np

from virtus.calib.board import Board, CheckerBoard
from virtus.calib.poses import BoardPose
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

__all__ = [
    "BOARD_BLUR_M",
    "BOARD_TEXEL_M",
    "BOARD_WINDOW_MARGIN_PX",
    "CHECKER_BLUR_M",
    "board_scene",
    "board_texture",
    "board_window",
]

#: Gaussian softening (m, board plane) of the printed circles' edges, like slight lens
#: defocus: with 4 spp the centroid error falls from ~0.005 px to ~0.001 px (measured on
#: exact synthetic images); a symmetric blur leaves every circle's centroid in place.
BOARD_BLUR_M = 2e-4
#: Softening (m) of a checkerboard's square edges: a saddle fit needs the X-junction spread
#: over a few pixels (measured corner error 0.05 px RMS at 2e-4 m, 0.01 px at 1e-3 m with
#: 1.75 mm pixels on the board); corners stay at the crossings (point symmetry).
CHECKER_BLUR_M = 1e-3
#: Texel size (m) of the board texture: about a quarter of a camera pixel at 0.9 m.
BOARD_TEXEL_M = 1e-4


@functools.lru_cache(maxsize=4)
def board_texture(board: Board) -> np.ndarray:
    """The board's printed texture, (H, W) float64 in [0, 1] at :data:`BOARD_TEXEL_M`, its
    edges softened by :data:`CHECKER_BLUR_M` for a checkerboard, else :data:`BOARD_BLUR_M`.

    Read-only and kept for the last few boards (boards are frozen, so equal boards share
    it): drawing the paper's 2000 x 2000 texture took 0.14-0.29 s on 2 CPU cores, a tenth
    of a warm calibration on a GPU, and the same array lets :func:`board_scene` reuse the
    checked plane across calibrations."""
    blur = CHECKER_BLUR_M if isinstance(board, CheckerBoard) else BOARD_BLUR_M
    texture = np.array(board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=blur), dtype=np.float64)
    texture.setflags(write=False)
    return texture


def board_scene(board: Board, pose: BoardPose, texture: np.ndarray) -> Any:
    """The scene of one pose: the board as a textured plane (world = camera frame).

    The poses of one board share its plane: with a read-only float64 texture that owns
    its data (as the calibration's), the texture is checked once, not in every pose
    (a 2000 x 2000 texture's check took 4-7 ms a pose on 2 CPU cores); each pose is
    checked as a plain plane's would be."""
    from virtus.scene.model import PlaneObject, Scene

    plane = _board_plane(board, texture)
    placed = PlaneObject(size_m=board.plane_size_m, pose=pose.board2cam)
    return Scene(objects=[plane.model_copy(update={"pose": placed.pose})])


#: Board planes :func:`board_scene` made, most recent last: ``(board, texture, plane)``.
_PLANES: list[tuple[Board, np.ndarray, Any]] = []
_PLANES_SIZE = 2
_PLANES_LOCK = threading.Lock()


def _board_plane(board: Board, texture: np.ndarray) -> Any:
    """The board's textured plane (identity pose), reused while the same board object and
    the same texture array come back and the plane holds that array itself: the model
    shares only a read-only float64 array owning its data, which nothing can change."""
    from virtus.scene.model import TexturedPlaneObject

    with _PLANES_LOCK:
        for known, image, plane in _PLANES:
            if known is board and image is texture:
                return plane
    plane = TexturedPlaneObject(size_m=board.plane_size_m, texture=texture, pose=Pose.identity())
    if plane.texture is texture:
        with _PLANES_LOCK:
            _PLANES.append((board, texture, plane))
            del _PLANES[:-_PLANES_SIZE]
    return plane


#: Camera pixels around the board's outline that :func:`board_window` keeps.
BOARD_WINDOW_MARGIN_PX = 8
#: Points per edge of the board plane's outline projected by :func:`board_window` (lens
#: distortion bends the edges between the corners).
_OUTLINE_POINTS = 65


def board_window(
    intrinsics: Intrinsics,
    board: Board,
    board2cam: Pose,
    margin_px: int = BOARD_WINDOW_MARGIN_PX,
) -> tuple[slice, slice] | None:
    """Rows and columns of the camera image that hold the board plane's image: its outline
    (densely sampled, lens distortion included) rounded outwards, ``margin_px`` around it,
    clipped to the image. None when a point of the outline is behind the camera.

    Every pixel a calibration observes lies on the board plane (centroid and homography
    windows stay on it), so decoding this window decodes every pixel it reads."""
    half = 0.5 * np.asarray(board.plane_size_m, dtype=np.float64)
    t = np.linspace(-1.0, 1.0, _OUTLINE_POINTS)
    edges = [np.stack([t * half[0], np.full_like(t, s * half[1])], axis=1) for s in (-1, 1)]
    edges += [np.stack([np.full_like(t, s * half[0]), t * half[1]], axis=1) for s in (-1, 1)]
    outline = np.concatenate(edges)
    pixels = intrinsics.project(board2cam.apply(np.column_stack([outline, np.zeros(len(outline))])))
    if not np.isfinite(pixels).all():
        return None
    lo = np.maximum(np.floor(pixels.min(axis=0)).astype(int) - margin_px, 0)
    hi = np.minimum(np.ceil(pixels.max(axis=0)).astype(int) + margin_px + 1, intrinsics.size)
    if (hi <= lo).any():
        return None
    return slice(int(lo[1]), int(hi[1])), slice(int(lo[0]), int(hi[0]))
