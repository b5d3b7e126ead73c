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

from virtus.calib.board import CircleBoard
from virtus.calib.detect import apply_homography, circle_pixel_bounds, fit_homography
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


#: Pixels (circles x window box) gathered at once (a window larger than this is a batch
#: of its own). Bounds the memory whatever the image and board size and keeps the batch
#: in cache: measured on the paper's 960 px poses (2 cores), 2^14-2^16 pixels take 70-100
#: ms a pose and 5-24 MB at peak, 2^18 100 ms and 94 MB, 2^20 100 ms and 119 MB (code
#: windows, 4x larger: 250-370 ms at 2^14-2^16, 600-700 ms at 2^20).
_BATCH_PIXELS = 1 << 16
#: Trimming rounds before the final inlier set (each: one batched fit, residuals, new set).
_TRIM_ROUNDS = 8
#: A round keeps residuals up to this multiple of the window's median residual (or the
#: RANSAC threshold when larger), so gross decoding errors leave before the fit is trusted.
_TRIM_MEDIANS = 3.0
#: Gauss-Newton steps on the transfer error after the DLT (as ``cv2.findHomography``'s
#: Levenberg-Marquardt refinement): on rendered 960 px boards the first step moves the
#: projector points by up to 1e-4 px, a second by < 1e-6 px.
_REFINE_STEPS = 1


def local_homographies(
    proj_uv: np.ndarray, board: CircleBoard, cam_centres: np.ndarray, stripe: float | None = None
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

    Returns
    -------
    (N, 3, 3) float64 homographies mapping homogeneous camera pixels (u, v, 1) to projector
    pixels, ``H[2, 2] = 1``; all-NaN for a circle with too few valid decoded pixels around
    it, or with fewer than that many within the threshold of its fit. Keeping the
    homographies (not the maps) lets the caller evaluate them at bias-corrected centres
    later, after the camera is calibrated.

    Notes
    -----
    Every window's pixels are gathered into one padded batch and fitted together (a
    normalised DLT per window from one batched 9 x 9 eigen-decomposition, refined by
    Gauss-Newton on the transfer error): the same least-squares homography as
    :func:`local_homographies_per_circle` (one ``cv2.findHomography`` per circle). Gross
    decoding errors are trimmed instead of found by RANSAC: each round keeps the pixels
    within :data:`_TRIM_MEDIANS` median residuals (at least the threshold) of the last
    fit, affine first (it cannot bend towards gross errors as a DLT can), then projective,
    and the final set is every pixel within the threshold of the last fit. Deterministic
    (batches of :data:`_BATCH_PIXELS` change results by rounding only); on the paper's
    rendered poses the projector points agree with the per-circle path to 1.2e-4 px, also
    with 10-30 % of the pixels off by up to 80 px (``tests/calib/test_projector.py``), at
    1.4-2x its speed on 2 cores (``benchmarks/bench_calibrate.py``).
    """
    uv, anchors, threshold, H = _window_inputs(proj_uv, board, cam_centres, stripe)  # noqa: N806
    radii = projector_window_radii(board, stripe)
    boxes = _window_boxes(H, board.object_points[:, :2], radii, uv.shape[:2])
    out = np.full((len(anchors), 3, 3), np.nan)
    area = np.prod((boxes[:, 1] - boxes[:, 0] + 1).clip(min=0), axis=1).clip(min=1)
    # Batches of windows of similar size (smallest first): less padding to the largest box.
    order = np.argsort(area, kind="stable")
    area = area[order]
    start = 0
    while start < len(anchors):  # batches of circles, at least one each
        stop = start + 1
        while stop < len(anchors) and area[stop] * (stop + 1 - start) <= _BATCH_PIXELS:
            stop += 1
        index = order[start:stop]
        src, dst, valid, inside = _gather_windows(
            uv, H, board.object_points[index, :2], radii[index], boxes[index]
        )
        src -= anchors[index, None, :]  # offsets from the anchor: well conditioned
        out[index] = _fit_windows(src, dst, valid, inside, threshold)
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
    uv: np.ndarray,
    H: np.ndarray,  # noqa: N803
    centres: np.ndarray,
    radii: np.ndarray,
    boxes: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The windows' pixels padded to one box: camera px (n, P, 2), decoded projector px
    (n, P, 2) (0 where invalid), valid (n, P) (inside the window with a finite decode)
    and inside (n, P) (inside the window and the image)."""
    size = (boxes[:, 1] - boxes[:, 0] + 1).clip(min=0)
    box_w, box_h = max(int(size[:, 0].max()), 1), max(int(size[:, 1].max()), 1)
    n = len(centres)
    cols = boxes[:, 0, 0, None] + np.arange(box_w)  # (n, W): what depends on the column
    rows = boxes[:, 0, 1, None] + np.arange(box_h)  # (n, H) or row alone is broadcast
    in_box = (cols <= boxes[:, 1, 0, None])[:, None, :] & (rows <= boxes[:, 1, 1, None])[:, :, None]
    x, y = cols[:, None, :].astype(np.float64), rows[:, :, None].astype(np.float64)
    pix = np.empty((n, box_h, box_w, 2))
    pix[..., 0], pix[..., 1] = x, y
    # Back to the board plane (camera px -> m) to keep the pixels inside the circle.
    g = np.linalg.inv(H)
    den = g[2, 0] * x + g[2, 1] * y + g[2, 2]
    du = (g[0, 0] * x + g[0, 1] * y + g[0, 2]) / den - centres[:, 0, None, None]
    dv = (g[1, 0] * x + g[1, 1] * y + g[1, 2]) / den - centres[:, 1, None, None]
    inside = (in_box & (du * du + dv * dv <= (radii * radii)[:, None, None])).reshape(n, -1)
    height, width = uv.shape[:2]
    row_start = np.minimum(rows, height - 1) * width
    flat = row_start[:, :, None] + np.minimum(cols, width - 1)[:, None, :]
    pix, flat = pix.reshape(n, -1, 2), flat.reshape(n, -1)
    target = np.take(uv.reshape(-1, 2), flat, axis=0)
    valid = inside & np.isfinite(target).all(axis=-1)
    target[~valid] = 0.0
    return pix, target, valid, inside


def _fit_windows(
    src: np.ndarray, dst: np.ndarray, valid: np.ndarray, inside: np.ndarray, threshold: float
) -> np.ndarray:
    """(n, 3, 3) homographies src -> dst of padded windows (:func:`_gather_windows`), NaN
    where fewer than ``max(MIN_VALID_FRACTION * inside, 16)`` pixels are valid or within
    ``threshold`` px of the fit (trimmed as :func:`local_homographies` says).

    Works in Hartley-normalised coordinates fixed by the valid pixels (the transfer error
    there is the projector px error times the similarity's scale), where every round
    reuses the same monomials of the camera pixels."""
    need = np.maximum(MIN_VALID_FRACTION * inside.sum(axis=1), 16)
    usable = valid.sum(axis=1) >= need
    out = np.full((len(need), 3, 3), np.nan)
    if not usable.any():
        return out
    src, dst, valid = src[usable], dst[usable], valid[usable]
    t_src, t_dst = _normalising(src, valid), _normalising(dst, valid)
    s = src @ t_src[:, :2, :2].transpose(0, 2, 1) + t_src[:, None, :2, 2]
    d = dst @ t_dst[:, :2, :2].transpose(0, 2, 1) + t_dst[:, None, :2, 2]
    limit_n = threshold * t_dst[:, 0, 0, None]  # the threshold in normalised units
    x, y, u, v = s[..., 0], s[..., 1], d[..., 0], d[..., 1]
    one = np.ones_like(x)
    monomials = np.stack([x * x, x * y, x, y * y, y, one], axis=1)  # (n, 6, P)
    targets = np.stack([one, u, v, u * u + v * v], axis=1)  # (n, 4, P)
    keep = _trim(_affine, monomials, targets, s, d, valid, limit_n)
    for last in range(_TRIM_ROUNDS, 0, -1):
        hn = _dlt(monomials, targets, keep)
        residual = _transfer_error(hn, s, d)
        with np.errstate(invalid="ignore"):
            within = valid & (residual <= limit_n)
        if np.array_equal(within, keep):
            break  # the fit of exactly its own inliers
        residual[~valid] = np.nan
        median = _row_medians(residual)
        with np.errstate(invalid="ignore"):
            trimmed = valid & (residual <= np.maximum(limit_n, _TRIM_MEDIANS * median))
        if last == 1 or np.array_equal(trimmed, keep):
            keep = within
            hn = _dlt(monomials, targets, keep)
            break
        keep = trimmed
    hn = _gauss_newton(hn, monomials, s, d, keep)
    fitted = np.linalg.solve(t_dst, hn @ t_src)  # denormalised
    with np.errstate(all="ignore"):
        fitted /= fitted[:, 2:3, 2:3]
    bad = (keep.sum(axis=1) < need[usable]) | ~np.isfinite(fitted).all(axis=(1, 2))
    fitted[bad] = np.nan
    out[usable] = fitted
    return out


def _trim(
    fit: Any,
    monomials: np.ndarray,
    targets: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    valid: np.ndarray,
    limit: np.ndarray,
) -> np.ndarray:
    """(n, P) pixels kept by trimming rounds of ``fit`` (:func:`_affine`): each keeps the
    valid pixels within ``max(limit, _TRIM_MEDIANS * median residual)`` of the last fit,
    until the set stops changing (at most :data:`_TRIM_ROUNDS`). An affine map cannot bend
    to gross errors as a DLT of them can, so it trims them first."""
    keep = valid
    for _ in range(_TRIM_ROUNDS):
        residual = _transfer_error(fit(monomials, targets, keep), src, dst)
        with np.errstate(invalid="ignore"):
            if not (valid & ~(residual <= limit)).any():
                return valid  # every pixel within the threshold: nothing to trim
        residual[~valid] = np.nan
        median = _row_medians(residual)
        with np.errstate(invalid="ignore"):
            trimmed = valid & (residual <= np.maximum(limit, _TRIM_MEDIANS * median))
        if np.array_equal(trimmed, keep):
            break
        keep = trimmed
    return keep


def _row_medians(residual: np.ndarray) -> np.ndarray:
    """(n, 1) medians of the non-NaN residuals of each row of (n, P), NaN for a row of NaN
    only (an all-NaN, degenerate fit). Without ``np.nanmedian``'s warning for such rows,
    whose silencing (``warnings.catch_warnings``) is not thread-safe: windows are fitted
    in observer threads (:mod:`virtus.calib.observers`)."""
    median = np.full((len(residual), 1), np.nan)
    some = ~np.isnan(residual).all(axis=1)
    if some.any():
        median[some, 0] = np.nanmedian(residual[some], axis=1)
    return median


def _affine(monomials: np.ndarray, targets: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n, 3, 3) least-squares affine maps (NaN where singular) of the point sets of
    :func:`_dlt`'s arguments."""
    w = weights.astype(np.float64)
    blocks = _outer_blocks(targets[:, :3] * w[:, None], monomials)  # sums m m^T, u m, v m
    rhs = np.stack([blocks[:, 1, :, 2], blocks[:, 2, :, 2]], axis=-1)  # (n, 3, 2)
    out = np.full((len(w), 3, 3), np.nan)
    out[:, 2] = (0.0, 0.0, 1.0)
    normal = blocks[:, 0]
    solvable = np.linalg.cond(normal) < 1e12
    out[solvable, :2] = np.linalg.solve(normal[solvable], rhs[solvable]).transpose(0, 2, 1)
    return out


def _normalising(points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n, 3, 3) similarities moving each padded set's (n, P, 2) weighted centroid to 0 and
    its RMS distance from it to sqrt(2) (Hartley's normalisation)."""
    w = weights.astype(np.float64)
    count = np.maximum(w.sum(axis=1), 1.0)
    mean = np.einsum("np,npk->nk", w, points) / count[:, None]
    spread = np.einsum("np,npk,npk->n", w, points, points) / count - np.sum(mean * mean, axis=1)
    scale = np.sqrt(2.0) / np.where(spread > 0, np.sqrt(np.maximum(spread, 0.0)), 1.0)
    T = np.zeros((len(points), 3, 3))  # noqa: N806
    T[:, 0, 0] = T[:, 1, 1] = scale
    T[:, :2, 2] = -scale[:, None] * mean
    T[:, 2, 2] = 1.0
    return T


def _outer_blocks(q: np.ndarray, monomials: np.ndarray) -> np.ndarray:
    """(n, Q, 3, 3) weighted sums ``sum_p q[n, k, p] m m^T``, ``m = (x, y, 1)``, from the
    monomials (n, 6, P) ``(x^2, xy, x, y^2, y, 1)`` by one batched product: the blocks of
    the DLT and Gauss-Newton normal equations, without their (n, 2P, 9) design matrices."""
    sums = q @ monomials.transpose(0, 2, 1)  # (n, Q, 6)
    xx, xy, x1, yy, y1, one = np.moveaxis(sums, -1, 0)
    rows = [np.stack(row, axis=-1) for row in ((xx, xy, x1), (xy, yy, y1), (x1, y1, one))]
    return np.stack(rows, axis=-2)


def _normal_matrix(blocks: np.ndarray) -> np.ndarray:
    """(n, 9, 9) normal matrix of the rows ``(m, 0, -u m)`` and ``(0, m, -v m)`` from
    :func:`_outer_blocks` of the weights ``(w, w u, w v, w (u^2 + v^2))``."""
    plain, by_u, by_v, by_uv = (blocks[:, k] for k in range(4))
    zero = np.zeros_like(plain)
    return np.block([[plain, zero, -by_u], [zero, plain, -by_v], [-by_u, -by_v, by_uv]])


def _dlt(monomials: np.ndarray, targets: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(n, 3, 3) DLT homographies (``H[2, 2] = 1``; NaN where degenerate or < 4 points) of
    normalised point sets given by their monomials (n, 6, P) and targets (n, 4, P)
    ``(1, u, v, u^2 + v^2)``, each point weighted by ``weights`` (n, P): the eigenvector
    of the smallest eigenvalue of the 9 x 9 normal matrix."""
    w = weights.astype(np.float64)
    values, vectors = np.linalg.eigh(_normal_matrix(_outer_blocks(targets * w[:, None], monomials)))
    H = vectors[..., 0].reshape(-1, 3, 3)  # noqa: N806
    with np.errstate(all="ignore"):
        H = H / H[:, 2:3, 2:3]  # noqa: N806
    degenerate = (w.sum(axis=1) < 4) | (values[:, 1] <= 1e-12 * values[:, -1])
    H[degenerate | ~np.isfinite(H).all(axis=(1, 2))] = np.nan
    return H


def _transfer_error(H: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:  # noqa: N803
    """(n, P) distances between ``H`` (n, 3, 3) applied to src (n, P, 2) and dst."""
    h = H.reshape(len(H), 9, 1)
    x, y = src[..., 0], src[..., 1]
    with np.errstate(all="ignore"):
        inv = 1.0 / (h[:, 6] * x + h[:, 7] * y + h[:, 8])
        du = (h[:, 0] * x + h[:, 1] * y + h[:, 2]) * inv - dst[..., 0]
        dv = (h[:, 3] * x + h[:, 4] * y + h[:, 5]) * inv - dst[..., 1]
        return np.sqrt(du * du + dv * dv)


def _gauss_newton(
    H: np.ndarray,  # noqa: N803
    monomials: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    weights: np.ndarray,
) -> np.ndarray:
    """:data:`_REFINE_STEPS` Gauss-Newton steps on the transfer error ``sum w |H(src) -
    dst|^2`` over the 8 entries of each ``H`` (n, 3, 3) with ``H[2, 2] = 1`` (what
    ``cv2.findHomography``'s Levenberg-Marquardt refinement minimises); NaN stays NaN."""
    w = weights.astype(np.float64)
    h = H.reshape(len(H), 9)[:, :8].copy()
    ok = np.isfinite(h).all(axis=1)
    h[~ok] = 0.0
    x, y = src[..., 0], src[..., 1]
    for _ in range(_REFINE_STEPS):
        with np.errstate(all="ignore"):
            inv = np.where(ok[:, None], 1.0 / (h[:, None, 6] * x + h[:, None, 7] * y + 1.0), 0.0)
        u = (h[:, None, 0] * x + h[:, None, 1] * y + h[:, None, 2]) * inv
        v = (h[:, None, 3] * x + h[:, None, 4] * y + h[:, None, 5]) * inv
        r_u, r_v = u - dst[..., 0], v - dst[..., 1]
        # Jacobian rows (m, 0, -u m) / den and (0, m, -v m) / den, m = (x, y, 1), without
        # the fixed H[2, 2]: J^T J from w m m^T / den^2, J^T r from w r m / den.
        w2, w1 = w * inv * inv, w * inv
        q = np.stack(
            [
                w2,
                w2 * u,
                w2 * v,
                w2 * (u * u + v * v),
                w1 * r_u,
                w1 * r_v,
                w1 * (u * r_u + v * r_v),
            ],
            axis=1,
        )
        blocks = _outer_blocks(q, monomials)  # m m^T summed; its last column sums m
        jtj = _normal_matrix(blocks[:, :4])[:, :8, :8]
        jtr = np.concatenate([blocks[:, 4, :, 2], blocks[:, 5, :, 2], -blocks[:, 6, :2, 2]], 1)
        jtj[~ok] = np.eye(8)
        try:
            h -= np.linalg.solve(jtj, jtr[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break  # a singular system: keep the last estimate
    out = np.concatenate([h, np.ones((len(h), 1))], axis=1).reshape(-1, 3, 3)
    out[~ok] = np.nan
    return out


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
