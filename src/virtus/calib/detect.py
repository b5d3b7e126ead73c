"""Board detection in camera images and sub-pixel refinement of the board's points.

Circle grids
------------

:func:`find_grid` finds and orders the circles with OpenCV's asymmetric circle-grid
detector (a :class:`cv2.SimpleBlobDetector` sized for large circles) and puts them in the
order of :attr:`CircleBoard.object_points`. :func:`refine_centres` replaces each centre by
the centroid of the circle's darkness, ``w = 1 - I / B`` with the local background ``B``
fitted on a ring around the circle: this is the area centroid of the circle's image,
insensitive to smooth illumination gradients and sub-pixel accurate on anti-aliased
images. The refinement windows are placed from the board's homography, refitted to the
centroids until they settle, and :func:`find_grid` first replaces points the grid finder
put far off their circles (:func:`mend_outliers`). The area centroid of an ellipse seen in
perspective is *not* the image of the circle's centre; :mod:`virtus.calib.solve` corrects
that bias with the calibrated model (:func:`virtus.robot.handeye_job.board_pose` with a
camera already calibrated).
White-on-black boards are detected in the inverted image and their centroids weighted by
brightness, ``w = I / B - 1``.

Checkerboards
-------------
:func:`find_grid` runs ``cv2.findChessboardCornersSB`` (its sub-pixel accuracy mode) and
orders the corners as :attr:`CheckerBoard.object_points`: among the grid flips that keep the
board's handedness, the one that puts a dark square beyond corner 0. :func:`refine_points`
refines them to the saddle points of the smoothed image (:func:`refine_corners`; corners
are points, not areas: no perspective bias) or, for the circles, calls
:func:`refine_centres`.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from virtus.calib.arrayspace import NUMPY, ArraySpace, space_of
from virtus.calib.board import Board, CheckerBoard, CircleBoard
from virtus.checks import as_points
from virtus.errors import InputError

#: Darkness window around each circle, as fractions of D_centers in the board plane: the
#: circle plus this margin (its blurred edge: ~3 px at 1 m for the 7x13 default board) ...
_INNER_MARGIN = 0.05
#: ... and the background ring beyond it stops this far short of the neighbouring circle.
_RING_GAP = 0.04
#: Checkerboard corners: smoothing (px) of the image and radius (px) of the saddle fit.
#: Both small, so the fit sees one X-junction and no neighbouring corner (squares of 10 px
#: and more); measured best among sigma 0.5-2 px and radius 2-4 px.
_SADDLE_SIGMA_PX = 0.7
_SADDLE_RADIUS_PX = 2.0
_SADDLE_ITERATIONS = 20
#: Grid points farther than this share of the smallest distance between points from the
#: board's RANSAC homography are replaced by its prediction (:func:`mend_outliers`).
_OUTLIER_SHARE = 0.2
#: Most passes of :func:`refine_centres`: the first places its windows by the homography of
#: the detected points, each further one by that of the previous pass's centroids, until no
#: centroid moves by :data:`_CENTROID_SETTLED_PX`.
_CENTROID_PASSES = 6
_CENTROID_SETTLED_PX = 1e-4
#: Smallest blob area in px^2 (rejects specks) for the blob detector.
_MIN_BLOB_AREA_PX = 12.0
#: ``cv2.findChessboardCornersSB`` flags, tried in turn until the board is found. Its
#: histogram equalisation (``NORMALIZE_IMAGE``) helps dim boards but turns the read noise
#: of a dark background (0-1 DN in 8 bits: a 12-bit imx174 capture) into full-range
#: speckle, where the detector then finds nothing (measured: 5 of 6 poses lost), so
#: detection retries without it.
_CHECKER_FLAGS = (
    cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE,
    cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY,
)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    """8-bit view of an image for OpenCV's detector (floats are scaled by their 99.9th pct)."""
    if image.dtype == np.uint8:
        return image
    image = np.asarray(image, dtype=np.float64)
    top = np.nanpercentile(image, 99.9)
    scale = 255.0 / top if top > 0 else 1.0
    return np.clip(np.nan_to_num(image) * scale, 0, 255).astype(np.uint8)


def blob_detector(image_shape: tuple[int, int]) -> cv2.SimpleBlobDetector:
    """Blob detector for dark circles from a dozen px^2 up to 5 % of the image area.

    OpenCV's default ``maxArea`` (5000 px^2) misses circles wider than about 80 px, a common
    failure with boards close to the camera.
    """
    params = cv2.SimpleBlobDetector_Params()
    params.filterByColor = True
    params.blobColor = 0
    params.filterByArea = True
    params.minArea = _MIN_BLOB_AREA_PX
    params.maxArea = 0.05 * float(image_shape[0] * image_shape[1])
    params.minThreshold = 10
    params.maxThreshold = 240
    params.thresholdStep = 10
    params.minDistBetweenBlobs = 3.0
    # Ellipses of boards tilted by up to ~60 deg stay well above these.
    params.filterByCircularity = True
    params.minCircularity = 0.6
    params.filterByInertia = True
    params.minInertiaRatio = 0.2
    params.filterByConvexity = True
    params.minConvexity = 0.9
    return cv2.SimpleBlobDetector_create(params)


def _order_candidates(board: Board) -> list[np.ndarray]:
    """Index permutations mapping OpenCV's ordering onto ours (grid flips)."""
    shape = (
        (board.rows, board.cols) if isinstance(board, CheckerBoard) else (board.cols, board.rows)
    )
    idx = np.arange(board.n_points).reshape(shape)
    return [
        idx,
        idx[::-1, :],
        idx[:, ::-1],
        idx[::-1, ::-1],
    ]


def fit_homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """Least-squares homography (3, 3) mapping points src (N, 2) to dst (N, 2), N >= 4.

    ``cv2.findHomography`` without RANSAC (DLT + Levenberg-Marquardt on the transfer
    error); ``None`` if it fails (degenerate points).
    """
    H, _ = cv2.findHomography(src.astype(np.float64), dst.astype(np.float64), 0)
    return H


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:  # noqa: N803
    """Map points (N, 2) through a homography H (3, 3) -> (N, 2)."""
    p = np.column_stack([points, np.ones(len(points))]) @ H.T
    return p[:, :2] / p[:, 2:3]


def circle_pixel_bounds(
    H: np.ndarray,  # noqa: N803
    centres: np.ndarray,
    radii: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and highest camera pixels ``(u, v)`` ((N, 2) int each, floor and ceiling,
    not clipped to any image) of the board circles of ``radii`` (m, one or (N,)) around
    ``centres`` (N, 2) m, mapped by ``H`` (board -> camera px): 32 outline points each."""
    ring = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    circle = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(centres),))
    outline = centres[:, None, :] + radii[:, None, None] * circle[None]  # (N, 32, 2)
    mapped = outline @ H[:2, :2].T + H[:2, 2]
    mapped = mapped / (outline @ H[2, :2] + H[2, 2])[..., None]
    return np.floor(mapped.min(axis=1)).astype(int), np.ceil(mapped.max(axis=1)).astype(int)


def order_to_board(
    board: Board, centres: np.ndarray, image: np.ndarray | None = None
) -> np.ndarray | None:
    """Reorder detected points (OpenCV's order) into ``board.object_points`` order.

    Among the grid flips, keep the one whose board-to-image homography fits best and keeps
    the board's handedness (the printed face seen from the front: positive Jacobian); for a
    checkerboard the (8-bit) ``image`` then tells a half turn apart by the dark square
    beyond corner 0. Returns ``None`` if none fits (a detection that is not this board).
    """
    obj = board.object_points[:, :2]
    best, best_rms = None, np.inf
    for candidate in _order_candidates(board):
        ordered = np.empty_like(centres)
        ordered[candidate.ravel()] = centres
        H = fit_homography(obj, ordered)  # noqa: N806
        if H is None:
            continue
        rms = np.sqrt(np.mean(np.sum((apply_homography(H, obj) - ordered) ** 2, axis=1)))
        # Jacobian determinant of the homography at the board centre.
        h = H / H[2, 2]
        jac = np.linalg.det(h[:2, :2] - np.outer(h[:2, 2], h[2, :2]))
        if isinstance(board, CheckerBoard) and (image is None or not _dark_first(board, H, image)):
            continue
        if jac > 0 and rms < best_rms:
            best, best_rms = ordered, rms
    # A wrong order misses by about a grid spacing; lens distortion bends a right one by
    # far less than a quarter of it.
    spacing_px = np.median(np.linalg.norm(np.diff(centres, axis=0), axis=1))
    if best is None or best_rms > 0.25 * spacing_px:
        return None
    return best


def _dark_first(board: CheckerBoard, H: np.ndarray, image: np.ndarray) -> bool:  # noqa: N803
    """True when, through the board-to-image homography ``H``, the dark squares of the board
    look darker in ``image`` than the light ones (mean over every square's centre)."""
    centres, dark = board.square_centres()
    uv = np.rint(apply_homography(H, centres)).astype(int)
    inside = (uv >= 0).all(axis=1) & (uv[:, 0] < image.shape[1]) & (uv[:, 1] < image.shape[0])
    if not (inside & dark).any() or not (inside & ~dark).any():
        return False
    values = image[uv[inside, 1], uv[inside, 0]].astype(np.float64)
    return bool(values[dark[inside]].mean() < values[~dark[inside]].mean())


def find_grid(image: np.ndarray, board: Board) -> np.ndarray | None:
    """Detect the board's circles (or checkerboard corners) in a camera image.

    Parameters
    ----------
    image : (H, W) uint8 or float image of the board under uniform light.
    board : the board (its ``pattern_shape`` and geometry).

    Returns
    -------
    (N, 2) float64 pixel positions (u, v) in ``board.object_points`` order, or ``None`` if
    the whole grid was not found.
    """
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype.kind not in "uif":
        raise InputError("image", "a (H, W) grey image", f"{image.dtype} of shape {image.shape}")
    gray = _to_uint8(image)
    if isinstance(board, CheckerBoard):
        found, corners = False, None
        for flags in _CHECKER_FLAGS:
            found, corners = cv2.findChessboardCornersSB(gray, board.pattern_shape, flags=flags)
            if found:
                break
        if not found or corners is None or len(corners) != board.n_points:
            return None
        return order_to_board(board, corners.reshape(-1, 2).astype(np.float64), gray)
    if board.light_features:
        gray = 255 - gray
    detector = blob_detector(gray.shape)
    found, centres = cv2.findCirclesGrid(
        gray, board.pattern_shape, flags=cv2.CALIB_CB_ASYMMETRIC_GRID, blobDetector=detector
    )
    if not found or centres is None or len(centres) != board.n_points:
        return None
    ordered = order_to_board(board, centres.reshape(-1, 2).astype(np.float64))
    return None if ordered is None else mend_outliers(board, ordered)


def mend_outliers(board: CircleBoard, centres: np.ndarray) -> np.ndarray:
    """The grid points of ``cv2.findCirclesGrid`` with gross misplacements replaced.

    OpenCV's blob detector can place a circle's blob off the circle (it averages blob
    centres over its thresholds): seen on 4x7 boards of 15 px circles near the board's edge
    (bench_robot.py's small board in the 960 px camera), in 7 of 10 poses one point 2-10 px
    off, up to between two circles. Each such point bent the homography that places every
    refinement window (:func:`refine_centres`), and centroids came out up to 1.2 px off. A
    homography from the board to the points is fitted with RANSAC (threshold
    :data:`_OUTLIER_SHARE` of the smallest distance between points) and a point farther
    than that from it is replaced by the homography's prediction (a starting point for the
    refinement, which places its windows from all points and then from its own centroids).

    Parameters
    ----------
    board : the circle board.
    centres : (N, 2) float64 grid points (u, v) px in ``board.object_points`` order.

    Returns
    -------
    (N, 2) float64 points, same order.
    """
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    np.fill_diagonal(gaps, np.inf)
    threshold = _OUTLIER_SHARE * float(gaps.min())
    obj = board.object_points[:, :2]
    H, _ = cv2.findHomography(obj, centres, cv2.RANSAC, threshold)  # noqa: N806
    if H is None:
        return centres
    predicted = apply_homography(H, obj)
    far = np.linalg.norm(predicted - centres, axis=1) > threshold
    out = centres.copy()
    out[far] = predicted[far]
    return out


def _window_radii(board: CircleBoard) -> tuple[float, float]:
    """Inner (circle) and outer (background ring) radii in the board plane, metres."""
    d = board.center_distance_m
    r_circle = 0.5 * board.circle_diameter_m
    r_in = r_circle + _INNER_MARGIN * d
    r_out = d / np.sqrt(2.0) - r_circle - _RING_GAP * d
    # Stay on the plane for the outer circles.
    hw = 0.5 * np.asarray(board.plane_size_m)
    to_edge = np.min(hw[None, :] - np.abs(board.object_points[:, :2]))
    r_out = min(r_out, to_edge - _RING_GAP * d)
    return r_in, r_out


def refine_points(
    image: np.ndarray, board: Board, points: np.ndarray, *, device: str | None = None
) -> np.ndarray:
    """Sub-pixel positions of the board's points found by :func:`find_grid`.

    Circle boards: :func:`refine_centres` (area centroids on ``image``; ``device`` is
    its). Checkerboards: :func:`refine_corners` (saddle points, on the host).

    Returns
    -------
    (N, 2) float64 (u, v) px in board order; NaN where a circle could not be refined.
    """
    if isinstance(board, CheckerBoard):
        return refine_corners(image, points)
    return refine_centres(image, board, points, device=device)


def refine_corners(image: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Sub-pixel checkerboard corners: saddle points of the Gaussian-smoothed image.

    Two straight edges crossing make a point-symmetric X-junction, so any symmetric blur
    keeps its saddle at the crossing, whatever the perspective. The image is smoothed by
    :data:`_SADDLE_SIGMA_PX`; around each corner a quadratic is fitted (Gaussian weights of
    :data:`_SADDLE_RADIUS_PX` / 2 centred on the current estimate) and the estimate moved to
    its stationary point, until it moves less than 1e-6 px. Measured on rendered 6x9 boards
    (11 px squares, 4 spp): 0.01 px RMS against 0.2 px for ``findChessboardCornersSB`` alone
    and 0.03 px for ``cv2.cornerSubPix``.

    Parameters
    ----------
    image : (H, W) float or integer image of the board under uniform light.
    corners : (N, 2) float64 approximate corners (u, v) px.

    Returns
    -------
    (N, 2) float64 corners (u, v) px; NaN where the window leaves the image or the fit is
    not a saddle.
    """
    import cv2

    points = as_points("corners", corners, 2)
    smooth = cv2.GaussianBlur(np.asarray(image, dtype=np.float64), (0, 0), _SADDLE_SIGMA_PX)
    height, width = smooth.shape
    reach = int(np.ceil(_SADDLE_RADIUS_PX))
    out = np.full_like(points, np.nan)
    for k, start in enumerate(points):
        centre = start.copy()
        for _ in range(_SADDLE_ITERATIONS):
            u0, v0 = np.rint(centre).astype(int)
            if not (reach <= u0 < width - reach and reach <= v0 < height - reach):
                centre[:] = np.nan
                break
            vv, uu = np.mgrid[v0 - reach : v0 + reach + 1, u0 - reach : u0 + reach + 1]
            du, dv = (uu - centre[0]).ravel(), (vv - centre[1]).ravel()
            weight = np.exp(-(du**2 + dv**2) / (2 * (0.5 * _SADDLE_RADIUS_PX) ** 2))
            design = np.stack([np.ones_like(du), du, dv, du * du, du * dv, dv * dv], axis=1)
            values = smooth[vv.ravel(), uu.ravel()]
            coef, *_ = np.linalg.lstsq(design * weight[:, None], values * weight, rcond=None)
            hessian = np.array([[2 * coef[3], coef[4]], [coef[4], 2 * coef[5]]])
            if np.linalg.det(hessian) >= 0:  # not a saddle
                centre[:] = np.nan
                break
            step = -np.linalg.solve(hessian, coef[1:3])
            centre += step
            if np.abs(step).max() < 1e-6:
                break
        if np.isfinite(centre).all() and np.linalg.norm(centre - start) <= _SADDLE_RADIUS_PX:
            out[k] = centre
    return out


def refine_centres(
    image: np.ndarray, board: CircleBoard, centres: np.ndarray, *, device: str | None = None
) -> np.ndarray:
    """Sub-pixel area centroids of the circles' images.

    Parameters
    ----------
    image : (H, W) uint8 or float camera image under uniform illumination.
    board : the board.
    centres : (R*C, 2) float64 approximate centres (u, v) px in board order.
    device : None to work with numpy here; else a torch device (``"cuda"``, ``"cpu"``)
        that gathers and reduces the windows (:mod:`virtus.calib.arrayspace`: the same
        centroids to rounding; the homographies between passes stay on the host).

    Returns
    -------
    (R*C, 2) float64 centroids (u, v) px; NaN for a circle whose window leaves the image or
    whose background ring is too dark to normalise by.

    Notes
    -----
    The windows are placed by a board-to-image homography: first that of ``centres``, then
    that of the previous pass's centroids until they settle (:data:`_CENTROID_PASSES`), so a
    detected point a few pixels off its circle moves no window. Measured on
    bench_robot.py's small board (15 px circles in the 960 px camera, 10 rendered poses,
    three with a detected point 2.2-2.4 px off): centroids up to 0.009 px off the exact
    area centroids with one pass, 0.002 px with passes until settled.
    """
    space = space_of(device)
    img = space.asarray(np.asarray(image, dtype=np.float64))
    centres = as_points("centres", centres, 2)
    if len(centres) != board.n_points:
        raise InputError("centres", f"{board.n_points} points (one per circle)", len(centres))
    obj = board.object_points[:, :2]
    H = fit_homography(obj, centres)  # noqa: N806  board (m) -> image (px)
    if H is None:
        raise InputError("centres", "circle centres of the board's grid", "degenerate points")
    out = _centroids(img, board, centres, H, space)
    for _ in range(_CENTROID_PASSES - 1):
        found = np.isfinite(out).all(axis=1)
        if found.sum() < 4:
            break
        H = fit_homography(obj[found], out[found])  # noqa: N806
        if H is None:
            break
        placed = np.where(found[:, None], out, centres)
        previous, out = out, _centroids(img, board, placed, H, space)
        if np.nanmax(np.abs(out - previous), initial=0.0) < _CENTROID_SETTLED_PX:
            break
    return out


#: Pixels (circles x window box) of :func:`_centroids` gathered at once: bounds the memory
#: whatever the image and board size (a window larger than this is a batch of its own).
_CENTROID_BATCH_PIXELS = 1 << 16
#: The same on a torch device, where launches cost alike whatever their size: a pose's
#: circles (~1.4e5 padded pixels at the paper's 960 px) are one batch.
_DEVICE_CENTROID_BATCH_PIXELS = 1 << 21


def _centroids(
    img: Any,
    board: CircleBoard,
    centres: np.ndarray,
    H: np.ndarray,  # noqa: N803
    space: ArraySpace = NUMPY,
) -> np.ndarray:
    """One pass of :func:`refine_centres` with windows placed by the homography ``H``: every
    circle's window gathered into padded batches and solved together (the background fits
    from batched 6 x 6 normal equations), as :func:`_centroids_per_circle` does circle by
    circle (the same windows and rules; centroids equal to rounding, ~1e-10 px). ``img``
    (H, W) float64 is in ``space``, the rest and the (N, 2) result on the host."""
    obj = board.object_points[:, :2]
    r_in, r_out = _window_radii(board)
    lo, hi = circle_pixel_bounds(H, obj, r_out)
    lo, hi = lo - 1, hi + 1
    height, width = img.shape
    fits = (lo.min(axis=1) >= 0) & (hi[:, 0] < width) & (hi[:, 1] < height)
    out = np.full_like(centres, np.nan)
    index = np.flatnonzero(fits)
    area = np.prod(hi[index] - lo[index] + 1, axis=1)
    limit = _CENTROID_BATCH_PIXELS if space is NUMPY else _DEVICE_CENTROID_BATCH_PIXELS
    start = 0
    while start < len(index):  # batches of circles, at least one each
        stop = start + 1
        while stop < len(index) and area[start : stop + 1].max() * (stop + 1 - start) <= limit:
            stop += 1
        batch = index[start:stop]
        found = _centroid_batch(
            space, img, board, centres[batch], obj[batch], H, lo[batch], hi[batch], (r_in, r_out)
        )
        out[batch] = space.to_host(found)
        start = stop
    return out


def _centroid_batch(
    space: ArraySpace,
    img: Any,
    board: CircleBoard,
    centres: np.ndarray,
    obj: np.ndarray,
    H: np.ndarray,  # noqa: N803
    lo: np.ndarray,
    hi: np.ndarray,
    radii: tuple[float, float],
) -> Any:
    """Centroids (n, 2) of the circles ``obj`` (n, 2) m whose windows are the pixel boxes
    ``lo``..``hi`` (n, 2) inclusive (inside the image), NaN where a rule of
    :func:`_centroids_per_circle` rejects the circle, in ``space`` (as ``img``; the other
    arguments are on the host). The boxes are padded to one (n, rows, columns) block; what
    depends on a pixel's column or row alone is computed per column or row and broadcast."""
    xp = space.xp
    n = len(obj)
    box_w, box_h = (int(size) for size in (hi - lo + 1).max(axis=0))
    shape = (n, box_h, box_w)
    cols = space.asarray(lo[:, 0, None] + np.arange(box_w))  # (n, W) pixel columns of a box
    rows = space.asarray(lo[:, 1, None] + np.arange(box_h))  # (n, H)
    last = space.asarray(hi)
    in_box = (cols <= last[:, 0, None])[:, None, :] & (rows <= last[:, 1, None])[:, :, None]
    rho = _plane_distance(space, np.linalg.inv(H), cols, rows, obj)  # (n, H, W) board m
    inner = (in_box & (rho <= radii[0])).reshape(n, -1)
    ring = (in_box & (rho > radii[0]) & (rho <= radii[1])).reshape(n, -1)
    rows_in, cols_in = rows.clip(max=img.shape[0] - 1), cols.clip(max=img.shape[1] - 1)
    values = img[rows_in[:, :, None], cols_in[:, None, :]].reshape(n, -1)
    # Quadratic background in pixel offsets from the centre, scaled by the window's size
    # (the same fit, better conditioned normal equations): 1, du, dv, du^2, dv^2, du dv.
    scale = space.asarray(1.0 / np.maximum(hi - lo, 1).max(axis=1).astype(np.float64))
    centre = space.asarray(centres)
    du = ((space.float64(cols) - centre[:, 0, None]) * scale[:, None])[:, None, :]
    dv = ((space.float64(rows) - centre[:, 1, None]) * scale[:, None])[:, :, None]
    terms = (space.full(shape, 1.0), du, dv, du * du, dv * dv, du * dv)
    design = xp.stack([xp.broadcast_to(term, shape) for term in terms], axis=1).reshape(n, 6, -1)
    weighted = design * ring[:, None, :]
    usable = ring.sum(axis=1) >= 12
    coef = space.full((n, 6), 0.0)
    normal, rhs = weighted @ design.swapaxes(1, 2), (weighted @ values[..., None])[..., 0]
    try:
        coef[usable] = xp.linalg.solve(normal[usable], rhs[usable][..., None])[..., 0]
    except space.singular_error:  # a singular ring (never seen): least squares, one by one
        host = [space.to_host(a) for a in (design, ring, values)]
        for k in np.flatnonzero(space.to_host(usable)):
            d, r, v = (a[k] for a in host)
            coef[k] = space.asarray(np.linalg.lstsq(d[:, r].T, v[r], rcond=None)[0])
    background = (coef[:, None, :] @ design)[:, 0]
    with space.quiet():
        top = space.row_max(xp.where(inner, background, -math.inf))
        dim = (inner & (background <= 0.05 * top[:, None])).any(axis=1)
        weight = xp.where(inner, 1.0 - values / background, 0.0).reshape(shape)
    if board.light_features:
        weight = -weight
    total = weight.sum(axis=(1, 2))
    good = usable & ~dim & (total > 0) & inner.any(axis=1)
    out = space.full((n, 2), math.nan)
    with space.quiet():
        u = (weight.sum(axis=1) * cols).sum(axis=1) / total
        v = (weight.sum(axis=2) * rows).sum(axis=1) / total
    out[good] = xp.stack([u, v], axis=1)[good]
    return out


def _plane_distance(space: ArraySpace, g: np.ndarray, cols: Any, rows: Any, obj: np.ndarray) -> Any:
    """(n, H, W) board-plane distances (m) from the points ``obj`` (n, 2) of the pixels
    ``(cols[i, w], rows[i, h])`` (in ``space``) mapped by the camera px -> board
    homography ``g`` (3, 3)."""
    g = g.tolist()
    x = space.float64(cols)[:, None, :]
    y = space.float64(rows)[:, :, None]
    centre = space.asarray(obj)
    den = (g[2][0] * x + g[2][2]) + g[2][1] * y
    bx = ((g[0][0] * x + g[0][2]) + g[0][1] * y) / den - centre[:, 0, None, None]
    by = ((g[1][0] * x + g[1][2]) + g[1][1] * y) / den - centre[:, 1, None, None]
    return space.xp.sqrt(bx * bx + by * by)


def _centroids_per_circle(
    img: np.ndarray,
    board: CircleBoard,
    centres: np.ndarray,
    H: np.ndarray,  # noqa: N803
    space: ArraySpace = NUMPY,
) -> np.ndarray:
    """One pass of :func:`refine_centres` with windows placed by the homography ``H``, one
    circle at a time (a least-squares background per circle): the reference that the
    batched :func:`_centroids` is tested and benchmarked against, on the host alone
    (``space`` is :func:`_centroids`'s, for a stand-in, and must be numpy's)."""
    if space is not NUMPY:
        raise ValueError("the per-circle centroids run on numpy arrays only")
    obj = board.object_points[:, :2]
    H_inv = np.linalg.inv(H)  # noqa: N806
    r_in, r_out = _window_radii(board)
    ring = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    circle = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    out = np.full_like(centres, np.nan)
    height, width = img.shape
    for k, centre in enumerate(obj):
        outline = apply_homography(H, centre + r_out * circle)
        lo = np.floor(outline.min(axis=0)).astype(int) - 1
        hi = np.ceil(outline.max(axis=0)).astype(int) + 1
        if lo.min() < 0 or hi[0] >= width or hi[1] >= height:
            continue
        vv, uu = np.mgrid[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
        pix = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        rho = np.linalg.norm(apply_homography(H_inv, pix) - centre, axis=1)
        values = img[vv.ravel(), uu.ravel()]
        inner = rho <= r_in
        bg = (rho > r_in) & (rho <= r_out)
        if bg.sum() < 12:
            continue
        # Quadratic background model in pixel offsets from the centre.
        d = pix - centres[k]
        design = np.column_stack([np.ones(len(d)), d, d * d, d[:, :1] * d[:, 1:]])
        coef, *_ = np.linalg.lstsq(design[bg], values[bg], rcond=None)
        background = design[inner] @ coef
        if np.any(background <= 0.05 * np.max(background)):
            continue
        weight = 1.0 - values[inner] / background
        if board.light_features:
            weight = -weight
        total = weight.sum()
        if total <= 0:
            continue
        out[k] = (weight[:, None] * pix[inner]).sum(axis=0) / total
    return out
