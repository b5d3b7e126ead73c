"""Projector "images" of the circle centres, read from the decoded projector coordinates.

The projector cannot see, so its image of a circle centre is the projector pixel that lights
that centre: the decoded ``(u_p, v_p)`` at the camera pixel where the centre is imaged.
Reading the map at one pixel would inherit the decoding's local errors (the projector's
pixel staircase, low modulation inside the dark circles), so, as Moreno & Taubin (2012,
"Simple, accurate, and robust projector-camera calibration"), a local homography camera px
-> projector px is fitted to every valid decoded pixel in a neighbourhood of the centre
(the board is planar, so the map is a homography up to lens distortion) and evaluated at
the centre. Hundreds of pixels average the staircase out to a few thousandths of a pixel.
"""

from __future__ import annotations

import cv2
import numpy as np

from virtus.calib.board import CircleBoard
from virtus.calib.detect import apply_homography, fit_homography
from virtus.checks import as_float_array, as_points, positive
from virtus.errors import InputError

#: A neighbourhood needs this fraction of valid decoded pixels, else the centre is NaN.
MIN_VALID_FRACTION = 0.5
#: RANSAC threshold (projector px) that rejects gross decoding errors before the LS fit;
#: coordinates decoded from a code alone are stripe centres, off by up to half a stripe
#: plus half a camera pixel's footprint, so there the threshold is the stripe width when
#: that is larger (measured on rendered 4x7 boards: at 1 px, 1.8 px Gray stripes give
#: projector points 0.14 px RMS off and 3.6 px stripes lose every circle; at the stripe
#: width, 0.05 and 0.12 px, 0.09 px for 3.6 px with :data:`CODE_WINDOW_FRACTION`).
_RANSAC_PX = 1.0


#: Radius of the neighbourhood, as a fraction of D_centers (board plane). The phase is
#: valid on and between the circles, so it may reach over the neighbouring circles; larger
#: windows average the projector's pixel staircase better, smaller ones follow lens
#: distortion better (a homography ignores it: <= 0.004 px at 0.42 D with k1 = -0.25);
#: on the paper poses 0.42 D -> 0.48 D lowered the projector RMS from 0.0060 to 0.0052 px.
WINDOW_FRACTION = 0.5


def projector_window_radius(board: CircleBoard) -> float:
    """Neighbourhood radius (m, board plane) of the local homographies, kept on the plane."""
    hw = 0.5 * np.asarray(board.plane_size_m)
    to_edge = float(np.min(hw[None, :] - np.abs(board.object_points[:, :2])))
    return min(WINDOW_FRACTION * board.center_distance_m, 0.95 * to_edge)


#: Codes alone: every board point's neighbourhood reaches this fraction of D_centers, or
#: its own distance to the plane's edge if shorter (not the outermost point's, as for
#: phase): stripe centres are a coarser staircase than a phase map's and more pixels
#: average it out. Measured at 480 x 480 px (imx174, 4 poses), projector points' RMS error
#: 0.0084 -> 0.0045 px on the 7x13 board (0.0058 px with k1 = -0.25), 0.0037 -> 0.0018 px
#: on a 6x9 checkerboard; 1.5 D gains < 10 % more and loses with distortion.
CODE_WINDOW_FRACTION = 1.0


def projector_window_radii(board: CircleBoard, stripe: float | None = None) -> np.ndarray:
    """Neighbourhood radius (m, board plane) of every board point's local homography, kept
    on the plane: :func:`projector_window_radius` for phase (``stripe`` None), else
    :data:`CODE_WINDOW_FRACTION` of D_centers within each point's distance to the edge."""
    if stripe is None:
        return np.full(board.n_points, projector_window_radius(board))
    hw = 0.5 * np.asarray(board.plane_size_m)
    to_edge = np.min(hw[None, :] - np.abs(board.object_points[:, :2]), axis=1)
    return np.minimum(CODE_WINDOW_FRACTION * board.center_distance_m, 0.95 * to_edge)


def local_homographies(
    proj_uv: np.ndarray, board: CircleBoard, cam_centres: np.ndarray, stripe: float | None = None
) -> np.ndarray:
    """Fit one camera px -> projector px homography around every circle.

    Parameters
    ----------
    proj_uv : (H, W, 2) float, decoded projector coordinates (u_p, v_p) per camera pixel,
        NaN where invalid.
    board : the board (sets the neighbourhood: the circle and the ring around it, as
        :func:`virtus.calib.detect.refine_centres`).
    cam_centres : (N, 2) float64 approximate camera pixels (u, v) of the circle centres,
        board order; they place the neighbourhoods.
    stripe : width (projector px) of the stripes that ``proj_uv`` holds the centres of,
        for coordinates decoded from a code alone (``DecodeResult.stripe_v``/``_h``; 1 for
        OpenCV's Gray code, whose integer columns and rows the fit averages to sub-pixel
        points like a phase map's staircase; it sets the RANSAC threshold and the wider
        neighbourhoods of :func:`projector_window_radii`); None for phase.

    Returns
    -------
    (N, 3, 3) float64 homographies mapping homogeneous camera pixels (u, v, 1) to projector
    pixels; all-NaN for a circle with too few valid decoded pixels around it. Keeping the
    homographies (not the maps) lets the caller evaluate them at bias-corrected centres
    later, after the camera is calibrated.
    """
    uv = as_float_array("proj_uv", proj_uv, (None, None, 2), allow_nan=True)
    anchors = as_points("cam_centres", cam_centres, 2)
    threshold = _RANSAC_PX if stripe is None else max(_RANSAC_PX, positive("stripe", stripe))
    if len(anchors) != board.n_points:
        raise InputError("cam_centres", f"{board.n_points} points (one per circle)", len(anchors))
    obj = board.object_points[:, :2]
    H = fit_homography(obj, anchors)  # noqa: N806  board (m) -> camera px
    if H is None:
        raise InputError("cam_centres", "circle centres of the board's grid", "degenerate points")
    H_inv = np.linalg.inv(H)  # noqa: N806
    radii = projector_window_radii(board, stripe)
    ring = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    circle = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    height, width = uv.shape[:2]
    out = np.full((len(anchors), 3, 3), np.nan)
    for k, centre in enumerate(obj):
        r_out = radii[k]
        outline = apply_homography(H, centre + r_out * circle)
        lo = np.maximum(np.floor(outline.min(axis=0)).astype(int), 0)
        hi = np.minimum(np.ceil(outline.max(axis=0)).astype(int), (width - 1, height - 1))
        if (hi < lo).any():
            continue
        vv, uu = np.mgrid[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
        pix = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        inside = np.linalg.norm(apply_homography(H_inv, pix) - centre, axis=1) <= r_out
        target = uv[vv.ravel(), uu.ravel()]
        valid = inside & np.isfinite(target).all(axis=1)
        need = max(MIN_VALID_FRACTION * inside.sum(), 16)
        if valid.sum() < need:
            continue
        # Offsets from the anchor keep the fit well conditioned.
        src = pix[valid] - anchors[k]
        dst = target[valid]
        local, mask = cv2.findHomography(src, dst, cv2.RANSAC, threshold)
        if local is None:
            continue
        keep = mask.ravel().astype(bool)
        if keep.sum() < need:
            continue
        local = fit_homography(src[keep], dst[keep])
        if local is None:
            continue
        shift = np.array([[1.0, 0.0, -anchors[k, 0]], [0.0, 1.0, -anchors[k, 1]], [0, 0, 1]])
        out[k] = local @ shift
    return out


def apply_homographies(homographies: np.ndarray, cam_points: np.ndarray) -> np.ndarray:
    """Evaluate per-circle homographies (N, 3, 3) at camera pixels (N, 2) -> (N, 2) projector px.

    NaN homographies give NaN rows.
    """
    hs = as_float_array("homographies", homographies, (None, 3, 3), allow_nan=True)
    points = as_points("cam_points", cam_points, 2)
    if len(hs) != len(points):
        raise InputError("cam_points", f"{len(hs)} points (one per homography)", len(points))
    p = np.einsum("nij,nj->ni", hs, np.column_stack([points, np.ones(len(points))]))
    return p[:, :2] / p[:, 2:3]
