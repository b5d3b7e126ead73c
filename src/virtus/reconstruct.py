"""Triangulation: camera pixels + projector coordinates -> 3D points in the camera frame.

A camera pixel ``(u, v)`` defines a ray from the camera centre; the decoded projector
coordinates define either a second ray (both ``u_p`` and ``v_p`` known) or a surface of
projector rays (one coordinate known). The point is where they meet:

* ``use="uv"``: least-squares ray-ray intersection, i.e. the midpoint of the shortest
  segment between the camera ray and the projector ray.
* ``use="u"`` or ``use="v"``: intersection of the camera ray with the set of projector rays
  whose ``u_p`` (or ``v_p``) equals the decoded value. Without projector distortion that set
  is a plane through the projector centre (closed form); with distortion it is a curved
  ruled surface, and the plane solution is refined along the camera ray by Newton's method
  on the projected coordinate until it matches to ``1e-9`` px.

Lens distortion of the camera is handled by :meth:`Intrinsics.unproject` (exact iterative
undistortion), that of the projector by ``unproject`` / ``project`` likewise.

Conventions: metres, OpenCV frames (x right, y down, z forward), pixel (col 0, row 0)
centred at (u, v) = (0, 0), maps indexed ``[row, col]``; ``rig.proj2cam`` maps projector-frame
points into the camera frame (``X_cam = R @ X_proj + t``), so ``t`` is the projector centre
in the camera frame. Points that cannot be triangulated (invalid input, parallel rays,
intersection behind either device) come back as NaN; nothing is clamped.

:func:`reconstruct` triangulates a whole decoded image into a :class:`Reconstruction` and
drops pixels next to depth discontinuities (mixed pixels at silhouettes:
:func:`depth_edge_mask`); a rig whose baseline is below :data:`MIN_BASELINE_M` is refused
(:func:`check_baseline`). :meth:`Reconstruction.save` writes a scan directory's
reconstruction files (:mod:`virtus.capture.scandir`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.capture.scandir import save_reconstruction
from virtus.checks import as_float_array, as_member, as_points
from virtus.errors import InputError, VirtusError

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig
    from virtus.geometry.optics import Intrinsics

__all__ = [
    "DEFAULT_MIN_MODULATION",
    "EDGE_MAX_STEP",
    "MIN_BASELINE_M",
    "Reconstruction",
    "Use",
    "as_use",
    "check_baseline",
    "depth_edge_mask",
    "depth_map",
    "normals_from_points",
    "points_from_decoded",
    "reconstruct",
    "triangulate",
    "valid_points",
]

#: Default fringe modulation threshold of decoding, a fraction of full scale.
DEFAULT_MIN_MODULATION = 0.02
#: Depth-discontinuity filter default, in pixel footprints (see ``depth_edge_mask``).
EDGE_MAX_STEP = 20.0
#: Shortest camera-projector baseline (m) triangulation accepts: below 1 um every depth is
#: undetermined (the rays are parallel); real rigs have 50-300 mm.
MIN_BASELINE_M = 1e-6


class Use(StrEnum):
    """Which decoded projector coordinates constrain a triangulated point: ``uv`` (both:
    ray-ray least squares), ``u`` or ``v`` (one: ray-surface intersection)."""

    uv = "uv"
    u = "u"
    v = "v"


def as_use(value: object) -> Use:
    """``value`` as a :class:`Use`, or :class:`InputError` naming ``use``."""
    return as_member(Use, "use", value)


#: Rays closer to parallel than this (sine of the angle between them) are not intersected:
#: at 1e-9 rad the depth is undetermined far beyond any working volume.
_MIN_SINE = 1e-9
#: Newton refinement on the projector coordinate for distorted projectors (``use="u"|"v"``).
_NEWTON_TOL_PX = 1e-9
_NEWTON_MAX_ITER = 30


def triangulate(
    rig: Rig,
    cam_px: object,
    proj_uv: object,
    use: Use = Use.uv,
) -> np.ndarray:
    """Triangulate camera pixels against decoded projector coordinates.

    Parameters
    ----------
    rig : the calibrated (or true) camera-projector rig.
    cam_px : (N, 2) float, camera pixel coordinates ``(u, v)``; must be finite.
    proj_uv : (N, 2) float, projector coordinates ``(u_p, v_p)`` in projector pixels; NaN
        marks an undecoded coordinate. With ``use="u"`` only column 0 is read, with
        ``use="v"`` only column 1.
    use : which projector coordinates constrain the point: ``"uv"`` (ray-ray least
        squares), ``"u"`` or ``"v"`` (ray-surface intersection).

    Returns
    -------
    (N, 3) float64, points in the camera frame in metres; NaN rows where the needed
    projector coordinates are NaN, the rays are parallel, or the point is not in front of
    both devices: ``z <= 0`` in the camera frame or in the projector frame (a wrong
    correspondence or calibration, never a surface either device can see).
    """
    cam = as_points("cam_px", cam_px, 2)
    proj = as_points("proj_uv", proj_uv, 2, allow_nan=True)
    if proj.shape[0] != cam.shape[0]:
        raise InputError("proj_uv", f"{cam.shape[0]} rows like cam_px", f"{proj.shape[0]} rows")
    use = as_use(use)

    needed = proj if use == "uv" else proj[:, :1] if use == "u" else proj[:, 1:]
    valid = np.isfinite(needed).all(axis=1)
    points = np.full((cam.shape[0], 3), np.nan)
    if not valid.any():
        return points

    rays_cam = rig.camera.intrinsics.unproject(cam[valid])
    if use == "uv":
        out = _ray_ray(rig, rays_cam, proj[valid])
    else:
        axis = 0 if use == "u" else 1
        out = _ray_surface(rig, rays_cam, proj[valid, axis], axis)
    points[valid] = out
    points[~_in_front(rig, points)] = np.nan
    return points


def points_from_decoded(
    rig: Rig,
    proj_uv: object,
    mask: object | None = None,
    use: Use = Use.uv,
) -> np.ndarray:
    """Triangulate a whole decoded image.

    Parameters
    ----------
    rig : camera-projector rig; the camera's image size must match ``proj_uv``.
    proj_uv : (H, W, 2) float, projector coordinates ``(u_p, v_p)`` per camera pixel,
        NaN where not decoded.
    mask : (H, W) bool, optional; pixels to triangulate (default: all with finite input).
    use : see :func:`triangulate`.

    Returns
    -------
    (H, W, 3) float64 point map in the camera frame, metres; NaN where invalid, including
    points behind the camera or the projector (``z <= 0`` in either frame; see
    :func:`triangulate`).
    """
    intr = rig.camera.intrinsics
    uv = as_float_array("proj_uv", proj_uv, (intr.height, intr.width, 2), allow_nan=True)
    keep = np.ones(uv.shape[:2], dtype=bool) if mask is None else _as_mask(mask, uv.shape[:2])
    grid = intr.pixel_grid()
    points = np.full(uv.shape[:2] + (3,), np.nan)
    points[keep] = triangulate(rig, grid[keep], uv[keep], use=use)
    return points


def depth_map(
    rig: Rig,
    proj_uv: object,
    mask: object | None = None,
    use: Use = Use.uv,
) -> np.ndarray:
    """Depth (camera-frame z, metres) per camera pixel; NaN where invalid.

    Same arguments as :func:`points_from_decoded`; returns an (H, W) float64 array.
    """
    return points_from_decoded(rig, proj_uv, mask, use)[..., 2]


def valid_points(point_map: object) -> tuple[np.ndarray, np.ndarray]:
    """Flatten a point map to its valid points.

    Parameters
    ----------
    point_map : (H, W, 3) float, NaN where invalid.

    Returns
    -------
    points : (N, 3) float64, the finite points in row-major pixel order.
    pixels : (N, 2) int64, their ``(row, col)`` indices.
    """
    pts = as_float_array("point_map", point_map, (None, None, 3), allow_nan=True)
    ok = np.isfinite(pts).all(axis=-1)
    rows, cols = np.nonzero(ok)
    return pts[ok], np.stack([rows, cols], axis=1).astype(np.int64)


def normals_from_points(point_map: object) -> np.ndarray:
    """Unit surface normals of an organised point map, oriented towards the camera.

    Central differences along rows and columns (one-sided at borders and next to invalid
    pixels) give two tangents; their cross product is the normal.

    Parameters
    ----------
    point_map : (H, W, 3) float, camera frame, NaN where invalid.

    Returns
    -------
    (H, W, 3) float64 unit normals (n . X <= 0, i.e. facing the camera at the origin);
    NaN where the point or both neighbours along a direction are invalid.
    """
    pts = as_float_array("point_map", point_map, (None, None, 3), allow_nan=True)
    d_col = _central_difference(pts, axis=1)
    d_row = _central_difference(pts, axis=0)
    normals = np.cross(d_col, d_row)
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = np.where(norm > 0, normals / norm, np.nan)
    flip = np.einsum("...k,...k->...", normals, pts) > 0
    normals[flip] *= -1.0
    return normals


def depth_edge_mask(point_map: object, focal_px: float, max_step: float = 20.0) -> np.ndarray:
    """Pixels next to a depth discontinuity (mixed pixels at silhouettes).

    A camera pixel at depth ``z`` covers ``z / f`` metres of a fronto-parallel surface; a
    surface seen at angle ``theta`` stretches that by ``1 / cos(theta)``. A step to a
    4-neighbour larger than ``max_step`` footprints (20 -> surfaces up to ~87 deg from
    the view direction pass) is a jump between two surfaces, where a pixel sees a mixture of
    both and decodes to a point between them.

    Parameters
    ----------
    point_map : (H, W, 3) float, camera frame, metres, NaN where invalid.
    focal_px : camera focal length in pixels (e.g. ``rig.camera.intrinsics.fx``).
    max_step : allowed 3D step between neighbours, in pixel footprints.

    Returns
    -------
    (H, W) bool, True for valid pixels with at least one valid 4-neighbour farther than the
    allowed step (pixels both sides of the jump are flagged).
    """
    pts = as_float_array("point_map", point_map, (None, None, 3), allow_nan=True)
    focal = float(focal_px)
    if not np.isfinite(focal) or focal <= 0:
        raise InputError("focal_px", "a positive number", focal_px)
    if not np.isfinite(max_step) or max_step <= 0:
        raise InputError("max_step", "a positive number", max_step)
    footprint = pts[..., 2] / focal
    edge = np.zeros(pts.shape[:2], dtype=bool)
    for axis in (0, 1):
        step = np.linalg.norm(np.diff(pts, axis=axis), axis=-1)
        low = np.minimum(
            footprint.take(range(footprint.shape[axis] - 1), axis=axis),
            footprint.take(range(1, footprint.shape[axis]), axis=axis),
        )
        with np.errstate(invalid="ignore"):
            jump = step > max_step * low  # NaN (a neighbour invalid) compares False
        if axis == 0:
            edge[:-1] |= jump
            edge[1:] |= jump
        else:
            edge[:, :-1] |= jump
            edge[:, 1:] |= jump
    return edge


# --- a decoded image, triangulated -----------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """A triangulated camera image.

    Attributes
    ----------
    points : (H, W, 3) float64, camera frame, metres; NaN where there is no point.
    edges : (H, W) bool, pixels dropped by the depth-discontinuity filter.
    rig : the rig the points were triangulated with.
    """

    points: np.ndarray
    edges: np.ndarray
    rig: Rig

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool, pixels with a point."""
        return np.isfinite(self.points).all(axis=-1)

    @property
    def depth(self) -> np.ndarray:
        """(H, W) float64 camera-frame z, metres, NaN where there is no point."""
        return self.points[..., 2]

    def cloud(self) -> np.ndarray:
        """(N, 3) float64 valid points in row-major pixel order, camera frame, metres."""
        return valid_points(self.points)[0]

    def save(
        self,
        directory: str | Path,
        ply_path: str | Path | None = None,
        source: dict[str, Any] | None = None,
    ) -> Path:
        """Write the PLY and, for the directory's own ``points.ply``, ``reconstruction/``;
        returns the PLY path.

        ``ply_path`` defaults to ``directory/points.ply``, which is written with
        ``reconstruction/*.npy`` as a pair: ``reconstruction/source.json`` (``source`` plus
        the rig's and the PLY's SHA-256) is removed first and written last, so a partly
        replaced pair is stale, and a changed ``points.ply`` removes an ``evaluation.json``
        of another cloud. Another ``ply_path`` gets only that PLY (the directory's pair is
        left as it is). Every file is written atomically
        (:func:`virtus.capture.scandir.save_reconstruction`).
        """
        normals = normals_from_points(self.points)
        return save_reconstruction(directory, self.points, normals, self.rig, ply_path, source)


def check_baseline(rig: Rig, what: str = "rig") -> Rig:
    """``rig``, or :class:`VirtusError` when its baseline is below :data:`MIN_BASELINE_M`
    (camera and projector at one point: no depth can be triangulated)."""
    baseline = float(np.linalg.norm(rig.proj2cam.t))
    if not baseline >= MIN_BASELINE_M:
        raise VirtusError(
            f"{what}: the camera-projector baseline is {baseline * 1e6:.3g} um, below "
            f"{MIN_BASELINE_M * 1e6:g} um: nothing can be triangulated (proj2cam.t is the "
            "projector's centre in camera coordinates, metres)"
        )
    return rig


def reconstruct(
    rig: Rig,
    proj_uv: object,
    mask: object | None = None,
    *,
    use: Use = "uv",
    edge_max_step: float | None = EDGE_MAX_STEP,
) -> Reconstruction:
    """Triangulate a decoded image and drop depth-discontinuity pixels.

    Parameters
    ----------
    rig : rig to triangulate with (true or calibrated); its baseline must be at least
        :data:`MIN_BASELINE_M` (:func:`check_baseline`).
    proj_uv : (H, W, 2) float, decoded projector coordinates, NaN where invalid.
    mask : (H, W) bool, optional decode mask.
    use : see :func:`triangulate`.
    edge_max_step : see :func:`depth_edge_mask`; None disables the filter.
    """
    check_baseline(rig)
    points = points_from_decoded(rig, proj_uv, mask, use=use)
    edges = np.zeros(points.shape[:2], dtype=bool)
    if edge_max_step is not None:
        edges = depth_edge_mask(points, rig.camera.intrinsics.fx, edge_max_step)
        points[edges] = np.nan
    return Reconstruction(points, edges, rig)


# --- internals -----------------------------------------------------------------------------


def _in_front(rig: Rig, points_cam: np.ndarray) -> np.ndarray:
    """(N,) bool: finite points with ``z > 0`` in both the camera and the projector frame."""
    cam2proj = rig.cam2proj
    z_proj = points_cam @ cam2proj.R[2] + cam2proj.t[2]
    with np.errstate(invalid="ignore"):
        return (points_cam[:, 2] > 0) & (z_proj > 0)


def _as_mask(mask: object, shape: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(mask)
    if array.dtype != bool or array.shape != shape:
        raise InputError("mask", f"a bool array of shape {shape}", f"{array.dtype} {array.shape}")
    return array


def _ray_ray(rig: Rig, rays_cam: np.ndarray, proj_uv: np.ndarray) -> np.ndarray:
    """Midpoints of the shortest segments between camera rays and projector rays."""
    pose = rig.proj2cam
    origin = np.asarray(pose.t, dtype=np.float64)
    rays_proj = pose.apply_direction(rig.projector.intrinsics.unproject(proj_uv))
    # Camera ray s*a (origin 0), projector ray o + r*b, |a| = |b| = 1. Normal equations of
    # min |s a - o - r b|^2:  s - c r = a.o,  c s - r = b.o  with c = a.b.
    a, b = rays_cam, rays_proj
    c = np.einsum("ij,ij->i", a, b)
    ao = a @ origin
    bo = b @ origin
    denom = 1.0 - c * c
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (ao - c * bo) / denom
        r = (c * ao - bo) / denom
    bad = (denom < _MIN_SINE**2) | (s <= 0) | (r <= 0)
    points = 0.5 * (s[:, None] * a + origin + r[:, None] * b)
    points[bad] = np.nan
    return points


def _ray_surface(rig: Rig, rays_cam: np.ndarray, coord: np.ndarray, axis: int) -> np.ndarray:
    """Intersect camera rays with the projector's constant-``u_p`` (axis 0) or ``v_p`` surface."""
    proj_intr = rig.projector.intrinsics
    cam2proj = rig.proj2cam.inverse()
    pose = rig.proj2cam
    origin = np.asarray(pose.t, dtype=np.float64)
    R = np.asarray(pose.R, dtype=np.float64)
    K = proj_intr.K
    # Pinhole plane in the projector frame: x_n = (u_p - cx) / fx, i.e. n = (1, 0, -x_n) for
    # u_p (and (0, 1, -y_n) for v_p); skew is zero in this model.
    f = K[axis, axis]
    c0 = K[axis, 2]
    normal_proj = np.zeros((coord.shape[0], 3))
    normal_proj[:, axis] = 1.0
    normal_proj[:, 2] = -(coord - c0) / f
    if proj_intr.has_distortion:
        # Undistort at the decoded coordinate and the principal point's other coordinate:
        # a good start for Newton's method below.
        start = np.empty((coord.shape[0], 2))
        start[:, axis] = coord
        start[:, 1 - axis] = K[1 - axis, 2]
        xy = proj_intr.undistort_normalized((start - K[:2, 2]) / np.diag(K)[:2])
        normal_proj[:, 2] = -xy[:, axis]
    normal_cam = normal_proj @ R.T
    # Camera ray X = s * a meets the plane n.(X - o) = 0 at s = n.o / n.a.
    na = np.einsum("ij,ij->i", normal_cam, rays_cam)
    no = normal_cam @ origin
    sine = np.abs(na) / np.linalg.norm(normal_cam, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = no / na
    bad = ~(sine >= _MIN_SINE) | ~(s > 0)
    if proj_intr.has_distortion:
        s = _newton_depth(proj_intr, cam2proj, rays_cam, coord, axis, np.where(bad, np.nan, s))
        bad |= ~(s > 0)
    points = s[:, None] * rays_cam
    points[bad] = np.nan
    return points


def _newton_depth(
    proj_intr: Intrinsics,
    cam2proj: object,
    rays_cam: np.ndarray,
    coord: np.ndarray,
    axis: int,
    s: np.ndarray,
) -> np.ndarray:
    """Refine ray parameters ``s`` so that projecting ``s * ray`` gives ``coord`` exactly."""
    s = s.copy()
    active = np.isfinite(s)
    for _ in range(_NEWTON_MAX_ITER):
        if not active.any():
            break
        idx = np.nonzero(active)[0]
        si = s[idx]
        h = 1e-7 * si  # relative step: the projected coordinate is smooth in s
        f0 = _projected(proj_intr, cam2proj, si[:, None] * rays_cam[idx], axis) - coord[idx]
        f1 = _projected(proj_intr, cam2proj, (si + h)[:, None] * rays_cam[idx], axis) - coord[idx]
        with np.errstate(invalid="ignore", divide="ignore"):
            step = f0 * h / (f1 - f0)
        new = si - step
        # A step that leaves the working side (s <= 0) or fails to be finite is divergence.
        diverged = ~np.isfinite(new) | (new <= 0)
        new[diverged] = np.nan
        s[idx] = new
        converged = np.abs(f0) < _NEWTON_TOL_PX
        active[idx[converged | diverged]] = False
    s[active] = np.nan  # not converged within the iteration budget
    return s


def _projected(proj_intr: Intrinsics, cam2proj: object, points_cam: np.ndarray, axis: int):
    return proj_intr.project(cam2proj.apply(points_cam))[:, axis]  # type: ignore[attr-defined]


def _central_difference(points: np.ndarray, axis: int) -> np.ndarray:
    forward = np.roll(points, -1, axis=axis) - points
    backward = points - np.roll(points, 1, axis=axis)
    # np.roll wraps around: invalidate the wrapped borders.
    index = [slice(None)] * 3
    index[axis] = -1
    forward[tuple(index)] = np.nan
    index[axis] = 0
    backward[tuple(index)] = np.nan
    ok_f = np.isfinite(forward).all(axis=-1, keepdims=True)
    ok_b = np.isfinite(backward).all(axis=-1, keepdims=True)
    both = ok_f & ok_b
    out = np.where(both, 0.5 * (forward + backward), np.where(ok_f, forward, backward))
    return np.where(ok_f | ok_b, out, np.nan)
