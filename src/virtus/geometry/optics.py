"""The lens model: pinhole intrinsics with OpenCV distortion, for cameras and projectors.

Conventions
-----------
* Frames follow OpenCV: x right, y down, z forward (along the optical axis), metres.
* Pixels: the centre of pixel (col=0, row=0) is at (u, v) = (0.0, 0.0); the image spans
  u in [-0.5, width - 0.5]. Coordinates are written (u, v) = (col, row).
* Distortion coefficients follow OpenCV's order ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``.

The projector is modelled as an inverse camera: the same :class:`Intrinsics` map a point in
the projector frame to the projector pixel that lights it. Poses live in
:mod:`virtus.geometry.transforms`, devices and rigs in :mod:`virtus.geometry.devices`, Isaac Sim
parameters in
:mod:`virtus.geometry.isaac`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from virtus.checks import as_float_array, as_points, finite, positive, positive_int
from virtus.errors import InputError
from virtus.io.safeio import check_keys

#: Largest image side accepted, pixels: 4x the widest machine-vision sensors (about 8k px);
#: a larger side is a mistake, not a device.
MAX_IMAGE_SIDE_PX = 32768
#: Most pixels accepted (width x height), 2**28 = 268 Mpx (a 16384 x 16384 image): a
#: float64 (H, W, 3) ray map of it takes 6.4 GB, so the bound is checked up front instead
#: of failing with MemoryError after allocating.
MAX_IMAGE_PIXELS = 2**28
#: Keys of an intrinsics object in the rig JSON (DESIGN.md section 3).
_DICT_KEYS = ("width", "height", "K", "dist")
#: Allowed numbers of distortion coefficients (OpenCV: 4, 5 or 8; 0 = none).
_DIST_LENGTHS = (0, 4, 5, 8)
#: Lengths of the distortion vectors read (:meth:`Intrinsics.from_opencv`, the rig's
#: ``dist``): OpenCV's 4, 5, 8, 12 (thin prism) and 14 (tilted sensor), or 0 for none.
#: The model stops at k6: the thin-prism and tilt terms of a 12 or 14 vector must be zero.
#: Other lengths (a 7-vector, say) match no OpenCV model and are refused, not padded.
OPENCV_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
#: Smallest f-number of a lens (numerical aperture 1 in air): a thin lens of aperture A has
#: a focal length of at least ``MIN_F_NUMBER * A``, so it focuses only beyond that distance.
MIN_F_NUMBER = 0.5
#: Newton iterations for undistortion; realistic lenses converge in 3-5.
_UNDISTORT_ITERATIONS = 20
#: Convergence threshold of the undistortion, in normalised image units (~1e-10 px).
_UNDISTORT_TOL = 1e-14


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics with OpenCV lens distortion, for a camera or a projector.

    Parameters
    ----------
    fx, fy : focal lengths in pixels (> 0).
    cx, cy : principal point in pixels, pixel-centre convention ((0, 0) = centre of the
        top-left pixel; the image centre is ``((width - 1) / 2, (height - 1) / 2)``).
    width, height : image size in pixels, each at most :data:`MAX_IMAGE_SIDE_PX` and
        together at most :data:`MAX_IMAGE_PIXELS` pixels.
    dist : distortion coefficients in OpenCV order ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``;
        empty for an ideal pinhole.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "fx", positive("fx", self.fx))
        object.__setattr__(self, "fy", positive("fy", self.fy))
        object.__setattr__(self, "cx", finite("cx", self.cx))
        object.__setattr__(self, "cy", finite("cy", self.cy))
        object.__setattr__(self, "width", positive_int("width", self.width))
        object.__setattr__(self, "height", positive_int("height", self.height))
        for name in ("width", "height"):
            if getattr(self, name) > MAX_IMAGE_SIDE_PX:
                raise InputError(
                    name, f"at most {MAX_IMAGE_SIDE_PX} pixels", f"{getattr(self, name)}"
                )
        if self.width * self.height > MAX_IMAGE_PIXELS:
            raise InputError(
                "width x height",
                f"at most {MAX_IMAGE_PIXELS:,} pixels (2**28)",
                f"{self.width} x {self.height} = {self.width * self.height:,}",
            )
        dist = as_float_array("dist", self.dist).ravel()
        if dist.size not in _DIST_LENGTHS:
            raise InputError("dist", "0, 4, 5 or 8 OpenCV coefficients", f"{dist.size}")
        # all-zero coefficients are the ideal pinhole: store () so equal lenses compare equal
        object.__setattr__(self, "dist", tuple(float(d) for d in dist) if dist.any() else ())

    # -- OpenCV interop ---------------------------------------------------------------------

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the conventional name of the camera matrix
        """(3, 3) float64 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        """Distortion as float64 ``(5,)`` (or ``(8,)`` for the rational model), zero-padded."""
        out = np.zeros(8 if len(self.dist) == 8 else 5)
        out[: len(self.dist)] = self.dist
        return out

    @property
    def has_distortion(self) -> bool:
        """True when any distortion coefficient is non-zero."""
        return any(d != 0.0 for d in self.dist)

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels (OpenCV's ``imageSize`` order)."""
        return (self.width, self.height)

    @classmethod
    def from_opencv(
        cls,
        K: object,
        dist: object,
        width: int,
        height: int,  # noqa: N803
    ) -> Intrinsics:
        """Build from an OpenCV camera matrix ``K`` (3, 3) and distortion vector (any shape)
        of :data:`OPENCV_DIST_LENGTHS` coefficients."""
        K = as_float_array("K", K, (3, 3))  # noqa: N806
        if K[0, 1] != 0.0 or np.any(K[2] != (0.0, 0.0, 1.0)) or K[1, 0] != 0.0:
            raise InputError("K", "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)", K.tolist())
        coeffs = as_float_array("dist", dist).ravel() if dist is not None else np.zeros(0)
        if coeffs.size > 8 and np.any(coeffs[8:] != 0.0):
            raise InputError(
                "dist",
                "at most 8 coefficients (no thin-prism/tilt terms)",
                f"{coeffs.size} with non-zero terms {coeffs[8:].tolist()} beyond k6",
            )
        if coeffs.size not in OPENCV_DIST_LENGTHS:
            raise InputError(
                "dist",
                "0, 4, 5, 8, 12 or 14 coefficients, OpenCV's (k1, k2, p1, p2[, k3[, k4, k5, "
                "k6[, s1, s2, s3, s4[, tx, ty]]]]), those beyond k6 zero",
                f"{coeffs.size} coefficients",
            )
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, tuple(coeffs[:8]))

    def to_opencv(self) -> tuple[np.ndarray, np.ndarray]:
        """``(K (3, 3), dist (5,) or (8,))`` as OpenCV expects them."""
        return self.K, self.dist_array

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict in the rig schema: ``{"width", "height", "K", "dist"}``."""
        return {
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "dist": [float(d) for d in self.dist_array],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], name: str = "intrinsics") -> Intrinsics:
        """Inverse of :meth:`to_dict`; ``name`` prefixes error messages (e.g. ``camera``).

        Keys other than ``width``, ``height``, ``K`` and ``dist`` are refused (a misspelt
        ``distortion`` would otherwise drop the lens model silently).
        """
        if not isinstance(data, Mapping):
            raise InputError(name, "an object with width, height, K, dist", data)
        check_keys(data, _DICT_KEYS, name)
        missing = [key for key in ("width", "height", "K") if key not in data]
        if missing:
            raise InputError(name, "keys width, height, K (optionally dist)", f"missing {missing}")
        try:
            return cls.from_opencv(data["K"], data.get("dist", ()), data["width"], data["height"])
        except InputError as error:
            raise InputError(f"{name}.{error.name}", error.expected, error.got) from None

    def scaled(self, factor: float) -> Intrinsics:
        """The same lens on a sensor resampled by ``factor`` (e.g. 0.25 for quick tests).

        Pixel edges are preserved: ``u' = (u + 0.5) * factor - 0.5``. ``width * factor`` and
        ``height * factor`` must be whole numbers. Distortion (in normalised units) is unchanged.
        """
        factor = positive("factor", factor)
        width, height = self.width * factor, self.height * factor
        if not (float(width).is_integer() and float(height).is_integer()):
            raise InputError("factor", "a factor giving whole image sizes", factor)
        return Intrinsics(
            self.fx * factor,
            self.fy * factor,
            (self.cx + 0.5) * factor - 0.5,
            (self.cy + 0.5) * factor - 0.5,
            int(width),
            int(height),
            self.dist,
        )

    # -- lens distortion on normalised coordinates -----------------------------------------

    def distort_normalized(self, xy: object) -> np.ndarray:
        """Apply lens distortion to ideal normalised coordinates.

        Parameters
        ----------
        xy : (N, 2) float, ideal normalised image coordinates ``(X/Z, Y/Z)``.

        Returns
        -------
        (N, 2) float64 distorted normalised coordinates (OpenCV's model).
        """
        xy = as_points("xy", xy, 2)
        return self._distort(xy)

    def _distort(self, xy: np.ndarray) -> np.ndarray:
        if not self.has_distortion:
            return xy.copy()
        return np.stack(self.distort_xy(xy[:, 0], xy[:, 1]), axis=1)

    def distort_xy(self, x: Any, y: Any) -> tuple[Any, Any]:
        """OpenCV's distortion of ideal normalised coordinates given as two arrays of any
        array type with arithmetic (numpy, or Dr.Jit on the device): ``(x_d, y_d)``."""
        coefficients = np.pad(self.dist_array, (0, 8 - self.dist_array.size))
        k1, k2, p1, p2, k3, k4, k5, k6 = (float(c) for c in coefficients)
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return xd, yd

    def _distort_jacobian(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2, 2) Jacobian d(distorted)/d(ideal) of :meth:`_distort`."""
        k1, k2, p1, p2, k3, k4, k5, k6 = np.pad(self.dist_array, (0, 8 - self.dist_array.size))
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        d_num = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        d_den = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        radial = num / den
        d_radial = (d_num * den - num * d_den) / (den * den)  # d radial / d r2
        jac = np.empty((xy.shape[0], 2, 2))
        jac[:, 0, 0] = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
        jac[:, 0, 1] = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
        jac[:, 1, 0] = jac[:, 0, 1]
        jac[:, 1, 1] = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
        return jac

    def undistort_normalized(self, xy: object) -> np.ndarray:
        """Invert :meth:`distort_normalized` by Newton's method.

        Parameters
        ----------
        xy : (N, 2) float, distorted normalised coordinates.

        Returns
        -------
        (N, 2) float64 ideal normalised coordinates; NaN where the distortion cannot be
        inverted (outside the lens model's monotonic domain). Converged points reproduce
        their input to about 1e-12 normalised units (far below 1e-6 px).
        """
        xy = as_points("xy", xy, 2, allow_nan=True)
        return self._undistort(xy)

    def _undistort(self, distorted: np.ndarray) -> np.ndarray:
        if not self.has_distortion:
            return distorted.copy()
        ideal = distorted.copy()
        active = np.all(np.isfinite(ideal), axis=1)
        for _ in range(_UNDISTORT_ITERATIONS):
            if not active.any():
                break
            idx = np.flatnonzero(active)
            residual = self._distort(ideal[idx]) - distorted[idx]
            step = np.linalg.solve(self._distort_jacobian(ideal[idx]), residual[:, :, None])[..., 0]
            ideal[idx] -= step
            active[idx] = np.max(np.abs(step), axis=1) > _UNDISTORT_TOL
        # Newton can land on a spurious root beyond the lens' fold-over; reject non-reproducing
        # or wandered-off solutions instead of returning them.
        error = np.max(np.abs(self._distort(ideal) - distorted), axis=1)
        bad = ~(error < 1e-10) | active
        ideal[bad] = np.nan
        return ideal

    # -- projection ------------------------------------------------------------------------

    def project(self, points: object) -> np.ndarray:
        """Project device-frame points to pixels (distortion applied).

        Parameters
        ----------
        points : (N, 3) float, metres, in this device's frame (OpenCV axes).

        Returns
        -------
        (N, 2) float64 pixel coordinates ``(u, v)``; NaN rows for points with ``z <= 0``.
        """
        points = as_points("points", points, 3, allow_nan=True)
        z = points[:, 2]
        in_front = z > 0
        xy = np.full((points.shape[0], 2), np.nan)
        xy[in_front] = points[in_front, :2] / z[in_front, None]
        xy[in_front] = self._distort(xy[in_front])
        return np.stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy], axis=1)

    def unproject(self, pixels: object) -> np.ndarray:
        """Back-project pixels to unit ray directions (distortion removed).

        Parameters
        ----------
        pixels : (N, 2) float, pixel coordinates ``(u, v)``.

        Returns
        -------
        (N, 3) float64 unit vectors in the device frame with ``z > 0``; NaN rows where the
        distortion cannot be inverted.
        """
        pixels = as_points("pixels", pixels, 2, allow_nan=True)
        xy = np.stack(
            [(pixels[:, 0] - self.cx) / self.fx, (pixels[:, 1] - self.cy) / self.fy], axis=1
        )
        xy = self._undistort(xy)
        rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def pixel_grid(self) -> np.ndarray:
        """(height, width, 2) float64 pixel-centre coordinates ``(u, v)`` of every pixel."""
        v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
        return np.stack([u, v], axis=-1)


@dataclass(frozen=True)
class ThinLens:
    """A thin lens focused at a plane: the aperture that gives a device its depth of field.

    A pinhole device (no ``ThinLens``) is in focus everywhere. With a lens, a point at depth
    ``d`` (metres along the optical axis) is imaged as a blur circle of diameter
    ``c = A f |d - d_f| / (d (d_f - f))`` on the image plane, i.e. ``A fx |d - d_f| /
    (d (d_f - f))`` pixels for a focal length of ``fx`` pixels (thin-lens law).

    Parameters
    ----------
    aperture_m : entrance-pupil diameter ``A`` (metres, > 0); ``A = f / N`` for an f-number N.
    focus_distance_m : depth ``d_f`` of the plane in focus (metres, > ``focal_length_m``;
        without one, > ``A / 2``: no lens is faster than f/0.5, :data:`MIN_F_NUMBER`).
    focal_length_m : focal length ``f`` (metres, >= ``A / 2``), which only enters through
        ``d_f - f``; None treats it as negligible against ``d_f`` (``f << d_f``).
    """

    aperture_m: float
    focus_distance_m: float
    focal_length_m: float | None = None

    def __post_init__(self) -> None:
        aperture = positive("aperture_m", self.aperture_m)
        object.__setattr__(self, "aperture_m", aperture)
        focus = positive("focus_distance_m", self.focus_distance_m)
        object.__setattr__(self, "focus_distance_m", focus)
        # A lens focuses only beyond its focal length, and no lens is faster than f/0.5
        # (numerical aperture 1): the focal length is at least half the aperture.
        shortest = MIN_F_NUMBER * aperture
        if self.focal_length_m is None and focus <= shortest:
            raise InputError(
                "focus_distance_m",
                f"a focus distance beyond the focal length, which is at least {shortest:g} m "
                f"for an aperture of {aperture:g} m (f/{MIN_F_NUMBER:g})",
                self.focus_distance_m,
            )
        if self.focal_length_m is not None:
            focal = positive("focal_length_m", self.focal_length_m)
            if focal >= focus:
                raise InputError(
                    "focal_length_m", f"a focal length < the focus distance {focus}", focal
                )
            if focal < shortest:
                raise InputError(
                    "focal_length_m",
                    f"at least {shortest:g} m for an aperture of {aperture:g} m "
                    f"(f/{MIN_F_NUMBER:g}: no lens is faster)",
                    focal,
                )
            object.__setattr__(self, "focal_length_m", focal)

    @classmethod
    def from_f_number(
        cls, f_number: float, focal_length_m: float, focus_distance_m: float
    ) -> ThinLens:
        """The lens of an f-number ``N`` and focal length ``f``: ``A = f / N``."""
        focal = positive("focal_length_m", focal_length_m)
        return cls(focal / positive("f_number", f_number), focus_distance_m, focal)

    def blur_diameter_px(self, depth_m: object, focal_px: float) -> np.ndarray:
        """Blur-circle diameter (pixels) of points at ``depth_m`` (metres along the axis)
        for a device of focal length ``focal_px`` pixels."""
        d = np.asarray(depth_m, dtype=np.float64)
        f = 0.0 if self.focal_length_m is None else self.focal_length_m
        d_f = self.focus_distance_m
        return self.aperture_m * positive("focal_px", focal_px) * np.abs(d - d_f) / (d * (d_f - f))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (metres)."""
        return {
            "aperture_m": self.aperture_m,
            "focus_distance_m": self.focus_distance_m,
            "focal_length_m": self.focal_length_m,
        }

    @classmethod
    def from_dict(cls, data: object, name: str = "lens") -> ThinLens:
        """Inverse of :meth:`to_dict`; unknown keys are refused."""
        check_keys(data, ("aperture_m", "focus_distance_m", "focal_length_m"), name)
        return cls(**data)  # type: ignore[arg-type]
