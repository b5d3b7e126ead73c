"""Projector "images" of the circle centres, read from the decoded projector coordinates.

The projector cannot see, so its image of a circle centre is the projector pixel that lights
that centre: the decoded ``(u_p, v_p)`` at the camera pixel where the centre is imaged.
Reading the map at one pixel would inherit the decoding's local errors (the projector's
pixel staircase, low modulation inside the dark circles), so, as Moreno & Taubin (2012,
"Simple, accurate, and robust projector-camera calibration"), a local homography camera px
-> projector px is fitted to every valid decoded pixel in a neighbourhood of the centre
(the board is planar, so the map is a homography up to lens distortion) and evaluated at
the centre. Hundreds of pixels average the staircase out to a few thousandths of a pixel.
All circles' homographies are fitted together (:func:`local_homographies`: one batched
normalised DLT and Gauss-Newton step); :func:`local_homographies_per_circle` keeps the
one-``cv2.findHomography``-per-circle path as the reference it is tested against.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from virtus.calib.arrayspace import ArraySpace, space_of
from virtus.calib.board import CircleBoard
from virtus.calib.detect import apply_homography, circle_pixel_bounds, fit_homography
from virtus.calib.windowfit import MIN_PIXELS, MIN_VALID_FRACTION, fit_windows
from virtus.checks import as_float_array, as_points, positive
from virtus.errors import InputError

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


#: Pixels (circles x window box) gathered at once on the host (a window larger than this is
#: a batch of its own). Bounds the memory whatever the image and board size and keeps the
#: batch in cache: measured on the paper's 960 px poses (2 cores), 2^14-2^16 pixels take
#: 70-100 ms a pose and 5-24 MB at peak, 2^18 100 ms and 94 MB, 2^20 100 ms and 119 MB (code
#: windows, 4x larger: 250-370 ms at 2^14-2^16, 600-700 ms at 2^20).
_BATCH_PIXELS = 1 << 16
#: The same on a device, where every launch costs the same whatever its size: the paper's
#: poses (~3.5e5 pixels in 91 windows, four times that for code windows) are one batch, at
#: about 30 float64 arrays of that size at peak (~85 MB).
_DEVICE_BATCH_PIXELS = 1 << 21


def local_homographies(
    proj_uv: np.ndarray,
    board: CircleBoard,
    cam_centres: np.ndarray,
    stripe: float | None = None,
    *,
    device: str | None = None,
) -> np.ndarray:
    """Fit one camera px -> projector px homography around every circle, all at once.

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
    device : None to fit with numpy here; else a torch device (``"cuda"``, ``"cpu"``) that
        gathers and fits the windows (torch must be importable: the caller checks, as
        :func:`virtus.calib.observe.observation_device` does).

    Returns
    -------
    (N, 3, 3) float64 homographies mapping homogeneous camera pixels (u, v, 1) to projector
    pixels, ``H[2, 2] = 1``; all-NaN for a circle with too few valid decoded pixels around
    it, or with fewer than that many within the threshold of its fit. Keeping the
    homographies (not the maps) lets the caller evaluate them at bias-corrected centres
    later, after the camera is calibrated.

    Notes
    -----
    Every window's pixels are gathered into one padded batch and fitted together
    (:func:`virtus.calib.windowfit.fit_windows`: a normalised DLT per window refined by
    Gauss-Newton on the transfer error): the same least-squares homography as
    :func:`local_homographies_per_circle` (one ``cv2.findHomography`` per circle), with
    gross decoding errors trimmed instead of found by RANSAC. Deterministic (batches of
    :data:`_BATCH_PIXELS` change results by rounding only, as does fitting on a device);
    on the paper's rendered poses the projector points agree with the per-circle path to
    1.2e-4 px, also with 10-30 % of the pixels off by up to 80 px
    (``tests/calib/test_projector.py``), at 1.4-2x its speed on 2 cores
    (``benchmarks/bench_calibrate.py``).
    """
    uv, anchors, threshold, H = _window_inputs(proj_uv, board, cam_centres, stripe)  # noqa: N806
    space = space_of(device)
    batch_pixels = _BATCH_PIXELS if device is None else _DEVICE_BATCH_PIXELS
    radii = projector_window_radii(board, stripe)
    boxes = _window_boxes(H, board.object_points[:, :2], radii, uv.shape[:2])
    out = np.full((len(anchors), 3, 3), np.nan)
    area = np.prod((boxes[:, 1] - boxes[:, 0] + 1).clip(min=0), axis=1).clip(min=1)
    # Batches of windows of similar size (smallest first): less padding to the largest box.
    order = np.argsort(area, kind="stable")
    area = area[order]
    uv_space = space.asarray(uv)
    start = 0
    while start < len(anchors):  # batches of circles, at least one each
        stop = start + 1
        while stop < len(anchors) and area[stop] * (stop + 1 - start) <= batch_pixels:
            stop += 1
        index = order[start:stop]
        src, dst, valid, inside = _gather_windows(
            space, uv_space, H, board.object_points[index, :2], radii[index], boxes[index]
        )
        src = src - space.asarray(anchors[index, None, :])  # offsets: well conditioned
        out[index] = space.to_host(fit_windows(space, src, dst, valid, inside, threshold))
        start = stop
    shift = np.tile(np.eye(3), (len(anchors), 1, 1))
    shift[:, :2, 2] = -anchors
    out = out @ shift
    return out / out[:, 2:3, 2:3]


def _window_inputs(
    proj_uv: np.ndarray, board: CircleBoard, cam_centres: np.ndarray, stripe: float | None
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Checked inputs of :func:`local_homographies`: the map, the anchors, the RANSAC
    threshold and the board (m) -> camera px homography."""
    uv = as_float_array("proj_uv", proj_uv, (None, None, 2), allow_nan=True)
    anchors = as_points("cam_centres", cam_centres, 2)
    threshold = _RANSAC_PX if stripe is None else max(_RANSAC_PX, positive("stripe", stripe))
    if len(anchors) != board.n_points:
        raise InputError("cam_centres", f"{board.n_points} points (one per circle)", len(anchors))
    H = fit_homography(board.object_points[:, :2], anchors)  # noqa: N806
    if H is None:
        raise InputError("cam_centres", "circle centres of the board's grid", "degenerate points")
    return uv, anchors, threshold, H


def _window_boxes(
    H: np.ndarray,  # noqa: N803
    centres: np.ndarray,
    radii: np.ndarray,
    shape: tuple[int, int],
) -> np.ndarray:
    """(N, 2, 2) int pixel boxes ``[[u_lo, v_lo], [u_hi, v_hi]]`` (inclusive, clipped to the
    image; ``hi < lo`` when off it) of the windows: the board circles of ``radii`` (m)
    around ``centres`` (N, 2) m, mapped by ``H`` (board -> camera px)."""
    lo, hi = circle_pixel_bounds(H, centres, radii)
    height, width = shape
    return np.stack([np.maximum(lo, 0), np.minimum(hi, (width - 1, height - 1))], axis=1)


def _gather_windows(
    space: ArraySpace,
    uv: Any,
    H: np.ndarray,  # noqa: N803
    centres: np.ndarray,
    radii: np.ndarray,
    boxes: np.ndarray,
) -> tuple[Any, Any, Any, Any]:
    """The windows' pixels padded to one box, in ``space`` (``uv``, the (H, W, 2) map, is
    there already; the rest is on the host): camera px (n, P, 2), decoded projector px
    (n, P, 2) (0 where invalid), valid (n, P) (inside the window with a finite decode) and
    inside (n, P) (inside the window and the image)."""
    xp = space.xp
    size = (boxes[:, 1] - boxes[:, 0] + 1).clip(min=0)
    box_w, box_h = max(int(size[:, 0].max()), 1), max(int(size[:, 1].max()), 1)
    n = len(centres)
    height, width = uv.shape[:2]
    # (n, W) what depends on the column, (n, H) on the row: broadcast, not tiled.
    cols = space.asarray(boxes[:, 0, 0, None] + np.arange(box_w))
    rows = space.asarray(boxes[:, 0, 1, None] + np.arange(box_h))
    hi = space.asarray(boxes[:, 1])
    in_box = (cols <= hi[:, 0, None])[:, None, :] & (rows <= hi[:, 1, None])[:, :, None]
    x, y = space.float64(cols)[:, None, :], space.float64(rows)[:, :, None]
    shape = (n, box_h, box_w)
    pix = xp.stack([xp.broadcast_to(x, shape), xp.broadcast_to(y, shape)], axis=-1)
    # Back to the board plane (camera px -> m) to keep the pixels inside the circle.
    g = np.linalg.inv(H).tolist()
    c = space.asarray(centres)
    den = g[2][0] * x + g[2][1] * y + g[2][2]
    du = (g[0][0] * x + g[0][1] * y + g[0][2]) / den - c[:, 0, None, None]
    dv = (g[1][0] * x + g[1][1] * y + g[1][2]) / den - c[:, 1, None, None]
    r2 = space.asarray(radii * radii)[:, None, None]
    inside = (in_box & (du * du + dv * dv <= r2)).reshape(n, -1)
    flat = rows.clip(max=height - 1)[:, :, None] * width + cols.clip(max=width - 1)[:, None, :]
    target = uv.reshape(-1, 2)[flat.reshape(-1)].reshape(n, -1, 2)
    valid = inside & xp.isfinite(target).all(axis=-1)
    target[~valid] = 0.0
    return pix.reshape(n, -1, 2), target, valid, inside


def local_homographies_per_circle(
    proj_uv: np.ndarray, board: CircleBoard, cam_centres: np.ndarray, stripe: float | None = None
) -> np.ndarray:
    """:func:`local_homographies` one circle at a time, with ``cv2.findHomography`` (RANSAC,
    then a least-squares fit of its inliers): the reference that the batched fit is tested
    and benchmarked against (``benchmarks/bench_calibrate.py``).

    Parameters and the result are those of :func:`local_homographies` (the same
    neighbourhoods, threshold and minimum counts of valid pixels and of inliers).
    """
    uv, anchors, threshold, H = _window_inputs(proj_uv, board, cam_centres, stripe)  # noqa: N806
    obj = board.object_points[:, :2]
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
        need = max(MIN_VALID_FRACTION * inside.sum(), MIN_PIXELS)
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
