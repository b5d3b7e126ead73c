"""Device models: pinhole intrinsics with OpenCV distortion, rigid poses, camera, projector, rig.

Conventions
-----------
* Frames follow OpenCV: x right, y down, z forward (along the optical axis), metres.
* Pixels: the centre of pixel (col=0, row=0) is at (u, v) = (0.0, 0.0); the image spans
  u in [-0.5, width - 0.5]. Coordinates are written (u, v) = (col, row).
* A transform is named by the frames it connects: ``proj2cam`` maps projector-frame points
  into the camera frame, ``X_cam = proj2cam.R @ X_proj + proj2cam.t``; its ``t`` is the
  projector's optical centre in camera coordinates.
* Distortion coefficients follow OpenCV's order ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``.

The projector is modelled as an inverse camera: the same :class:`Intrinsics` map a point in
the projector frame to the projector pixel that lights it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from virtus.checks import as_float_array, as_points, finite, positive, positive_int
from virtus.errors import InputError
from virtus.jsonio import write_json

#: Allowed numbers of distortion coefficients (OpenCV: 4, 5 or 8; 0 = none).
_DIST_LENGTHS = (0, 4, 5, 8)
#: Newton iterations for undistortion; realistic lenses converge in 3-5.
_UNDISTORT_ITERATIONS = 20
#: Convergence threshold of the undistortion, in normalised image units (~1e-10 px).
_UNDISTORT_TOL = 1e-14
#: Orthonormality tolerance for rotation matrices given by users (JSON holds ~15 digits).
_ROTATION_TOL = 1e-6


# --------------------------------------------------------------------------------------------
# Intrinsics
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics with OpenCV lens distortion, for a camera or a projector.

    Parameters
    ----------
    fx, fy : focal lengths in pixels (> 0).
    cx, cy : principal point in pixels, pixel-centre convention ((0, 0) = centre of the
        top-left pixel; the image centre is ``((width - 1) / 2, (height - 1) / 2)``).
    width, height : image size in pixels.
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
        """Build from an OpenCV camera matrix ``K`` (3, 3) and distortion vector (any shape)."""
        K = as_float_array("K", K, (3, 3))  # noqa: N806
        if K[0, 1] != 0.0 or np.any(K[2] != (0.0, 0.0, 1.0)) or K[1, 0] != 0.0:
            raise InputError("K", "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)", K.tolist())
        coeffs = as_float_array("dist", dist).ravel() if dist is not None else np.zeros(0)
        if coeffs.size > 8 and np.any(coeffs[8:] != 0.0):
            raise InputError("dist", "at most 8 coefficients (no thin-prism/tilt terms)", coeffs)
        coeffs = coeffs[:8]
        if coeffs.size not in _DIST_LENGTHS:  # e.g. (k1, k2) or 6 terms: pad with zeros
            coeffs = np.pad(coeffs, (0, (5 if coeffs.size < 5 else 8) - coeffs.size))
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, tuple(coeffs))

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
        """Inverse of :meth:`to_dict`; ``name`` prefixes error messages (e.g. ``camera``)."""
        if not isinstance(data, Mapping):
            raise InputError(name, "an object with width, height, K, dist", data)
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
        k1, k2, p1, p2, k3, k4, k5, k6 = np.pad(self.dist_array, (0, 8 - self.dist_array.size))
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

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


# --------------------------------------------------------------------------------------------
# Pose
# --------------------------------------------------------------------------------------------


def check_rotation(name: str, value: object) -> np.ndarray:
    """Return ``value`` as a (3, 3) float64 proper rotation or raise :class:`InputError`."""
    R = as_float_array(name, value, (3, 3))  # noqa: N806
    error = np.max(np.abs(R.T @ R - np.eye(3)))
    if error > _ROTATION_TOL or np.linalg.det(R) <= 0:
        raise InputError(
            name,
            "an orthonormal rotation matrix with det +1",
            f"max |R^T R - I| = {error:.2e}, det = {np.linalg.det(R):.6f}",
        )
    return R


@dataclass(frozen=True, eq=False)
class Pose:
    """Rigid transform between two named frames: ``X_dst = R @ X_src + t`` (metres).

    Name variables by the frames they connect, e.g. ``proj2cam``, ``board2cam``,
    ``cam2world``; compose as ``a2c = b2c @ a2b``.

    Parameters
    ----------
    R : (3, 3) float rotation matrix (orthonormal, det +1).
    t : (3,) float translation in metres (the source frame's origin in the destination frame).
    """

    R: np.ndarray
    t: np.ndarray

    def __post_init__(self) -> None:
        R = check_rotation("R", self.R)  # noqa: N806
        t = as_float_array("t", self.t).ravel()
        if t.shape != (3,):
            raise InputError("t", "a translation of 3 numbers", f"shape {np.shape(self.t)}")
        R.flags.writeable = False
        t.flags.writeable = False
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", t)

    # -- construction ----------------------------------------------------------------------

    @classmethod
    def identity(cls) -> Pose:
        """The identity transform."""
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_matrix(cls, matrix: object) -> Pose:
        """From a (4, 4) homogeneous matrix ``[[R, t], [0, 0, 0, 1]]``."""
        T = as_float_array("matrix", matrix, (4, 4))  # noqa: N806
        if np.max(np.abs(T[3] - (0.0, 0.0, 0.0, 1.0))) > 1e-12:
            raise InputError("matrix", "last row [0, 0, 0, 1]", T[3].tolist())
        return cls(T[:3, :3], T[:3, 3])

    @classmethod
    def from_euler(
        cls, seq: str, angles: object, degrees: bool = True, t: object = (0.0, 0.0, 0.0)
    ) -> Pose:
        """From Euler angles in scipy's convention (``"xyz"`` extrinsic, ``"XYZ"`` intrinsic)."""
        angles = as_float_array("angles", angles).ravel()
        try:
            rotation = Rotation.from_euler(seq, angles, degrees=degrees)
        except ValueError as error:
            raise InputError(
                "seq", "a scipy Euler sequence matching angles", f"{seq!r}: {error}"
            ) from None
        return cls(rotation.as_matrix(), t)

    @classmethod
    def from_rotvec(cls, rvec: object, t: object = (0.0, 0.0, 0.0)) -> Pose:
        """From a rotation vector in radians (same as OpenCV's Rodrigues ``rvec``) and ``t``."""
        rvec = as_float_array("rvec", rvec).ravel()
        if rvec.shape != (3,):
            raise InputError("rvec", "a rotation vector of 3 numbers", f"shape {rvec.shape}")
        return cls(Rotation.from_rotvec(rvec).as_matrix(), t)

    @classmethod
    def from_quat(cls, quat: object, t: object = (0.0, 0.0, 0.0)) -> Pose:
        """From a quaternion ``(x, y, z, w)`` (scalar last, normalised here) and ``t``."""
        quat = as_float_array("quat", quat).ravel()
        if quat.shape != (4,) or np.linalg.norm(quat) == 0:
            raise InputError("quat", "a non-zero quaternion (x, y, z, w)", quat.tolist())
        return cls(Rotation.from_quat(quat).as_matrix(), t)

    @classmethod
    def look_at(cls, eye: object, target: object, image_down: object = (0.0, 1.0, 0.0)) -> Pose:
        """Device-to-world pose of a device at ``eye`` looking at ``target``.

        Parameters
        ----------
        eye, target : (3,) float, metres, world frame.
        image_down : (3,) float, world direction that should point down in the device's
            image (the device's +y axis is the component of it orthogonal to the view
            direction). In a world that is an upright OpenCV camera frame this is (0, 1, 0).

        Returns
        -------
        ``device2world`` with the device's +z axis along ``target - eye``.
        """
        eye = as_float_array("eye", eye, (3,))
        target = as_float_array("target", target, (3,))
        down = as_float_array("image_down", image_down, (3,))
        z = target - eye
        if np.linalg.norm(z) == 0:
            raise InputError("target", "a point different from eye", target.tolist())
        z = z / np.linalg.norm(z)
        y = down - np.dot(down, z) * z
        if np.linalg.norm(y) < 1e-9:
            raise InputError("image_down", "a direction not parallel to the view", down.tolist())
        y = y / np.linalg.norm(y)
        x = np.cross(y, z)
        return cls(np.stack([x, y, z], axis=1), eye)

    # -- algebra ---------------------------------------------------------------------------

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) float64 homogeneous matrix."""
        T = np.eye(4)  # noqa: N806
        T[:3, :3] = self.R
        T[:3, 3] = self.t
        return T

    def inverse(self) -> Pose:
        """The inverse transform (``dst2src``)."""
        return Pose(self.R.T, -self.R.T @ self.t)

    def __matmul__(self, other: Pose) -> Pose:
        """Composition: ``(b2c @ a2b)`` maps frame a to frame c."""
        if not isinstance(other, Pose):
            return NotImplemented
        return Pose(self.R @ other.R, self.R @ other.t + self.t)

    def apply(self, points: object) -> np.ndarray:
        """Transform points. ``points``: (N, 3) metres, source frame -> (N, 3) destination."""
        points = as_points("points", points, 3, allow_nan=True)
        return points @ self.R.T + self.t

    def apply_direction(self, vectors: object) -> np.ndarray:
        """Rotate direction vectors (no translation). ``vectors``: (N, 3) -> (N, 3)."""
        vectors = as_points("vectors", vectors, 3, allow_nan=True)
        return vectors @ self.R.T

    # -- parameterisations -----------------------------------------------------------------

    @property
    def rotvec(self) -> np.ndarray:
        """(3,) rotation vector in radians (OpenCV Rodrigues compatible)."""
        return Rotation.from_matrix(self.R).as_rotvec()

    def as_euler(self, seq: str, degrees: bool = True) -> np.ndarray:
        """(3,) Euler angles in scipy's convention."""
        return Rotation.from_matrix(self.R).as_euler(seq, degrees=degrees)

    def as_quat(self) -> np.ndarray:
        """(4,) unit quaternion ``(x, y, z, w)``, scalar last."""
        return Rotation.from_matrix(self.R).as_quat()

    @property
    def angle_deg(self) -> float:
        """Rotation angle of ``R`` in degrees (0..180)."""
        return float(np.degrees(np.linalg.norm(self.rotvec)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"R": [[...]], "t": [...]}``."""
        return {"R": self.R.tolist(), "t": self.t.tolist()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], name: str = "pose") -> Pose:
        """Inverse of :meth:`to_dict`; ``name`` prefixes error messages (e.g. ``proj2cam``)."""
        if not isinstance(data, Mapping) or "R" not in data or "t" not in data:
            raise InputError(name, 'an object {"R": 3x3, "t": [x, y, z]}', data)
        try:
            return cls(data["R"], data["t"])
        except InputError as error:
            raise InputError(f"{name}.{error.name}", error.expected, error.got) from None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Pose):
            return NotImplemented
        return bool(np.array_equal(self.R, other.R) and np.array_equal(self.t, other.t))

    def __hash__(self) -> int:
        return hash((self.R.tobytes(), self.t.tobytes()))

    def __repr__(self) -> str:
        euler = np.round(self.as_euler("xyz"), 4).tolist()
        return f"Pose(euler_xyz_deg={euler}, t_m={np.round(self.t, 6).tolist()})"


# --------------------------------------------------------------------------------------------
# Devices and rig
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Device:
    """A device described by its intrinsics (its frame is OpenCV's)."""

    intrinsics: Intrinsics

    @property
    def width(self) -> int:
        """Image width, pixels."""
        return self.intrinsics.width

    @property
    def height(self) -> int:
        """Image height, pixels."""
        return self.intrinsics.height


@dataclass(frozen=True)
class Camera(_Device):
    """A camera: pinhole + distortion intrinsics (its frame is OpenCV's)."""


@dataclass(frozen=True)
class Projector(_Device):
    """A projector, modelled as an inverse camera with the same intrinsics model.

    ``intrinsics.project`` maps a point in the projector frame to the projector pixel
    ``(u_p, v_p)`` that lights it.
    """


@dataclass(frozen=True)
class Rig:
    """A camera-projector pair. The rig's world frame is the camera frame.

    Parameters
    ----------
    camera, projector : the devices.
    proj2cam : maps projector-frame points into the camera frame; ``proj2cam.t`` is the
        projector's optical centre in camera coordinates (metres).
    """

    camera: Camera
    projector: Projector
    proj2cam: Pose

    @property
    def cam2proj(self) -> Pose:
        """Maps camera-frame points into the projector frame."""
        return self.proj2cam.inverse()

    @property
    def baseline_m(self) -> float:
        """Distance between the camera and projector optical centres, metres."""
        return float(np.linalg.norm(self.proj2cam.t))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict in the rig schema: units, camera, projector, proj2cam."""
        return {
            "units": "m",
            "camera": self.camera.intrinsics.to_dict(),
            "projector": self.projector.intrinsics.to_dict(),
            "proj2cam": self.proj2cam.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Rig:
        """Read the rig schema; extra keys (errors, residuals, ...) are ignored."""
        if not isinstance(data, Mapping):
            raise InputError("rig", "a JSON object", type(data).__name__)
        missing = [key for key in ("camera", "projector", "proj2cam") if key not in data]
        if missing:
            raise InputError("rig", "keys camera, projector, proj2cam", f"missing {missing}")
        units = data.get("units", "m")
        if units != "m":
            raise InputError("rig.units", '"m" (translations in metres)', units)
        return cls(
            Camera(Intrinsics.from_dict(data["camera"], "camera")),
            Projector(Intrinsics.from_dict(data["projector"], "projector")),
            Pose.from_dict(data["proj2cam"], "proj2cam"),
        )

    def save_json(self, path: str | Path) -> Path:
        """Write the rig schema to ``path`` (JSON, metres); returns the path."""
        return write_json(path, self.to_dict())

    @classmethod
    def load_json(cls, path: str | Path) -> Rig:
        """Read a rig (or a calibration file using the rig schema) from JSON."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as error:
            raise InputError(str(path), "a JSON file", f"invalid JSON ({error.msg})") from None
        return cls.from_dict(data)


# --------------------------------------------------------------------------------------------
# The paper's system, Isaac Sim parameters and the inverse camera model
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IsaacCameraParams:
    """Isaac Sim (USD) pinhole camera parameters, all in one length unit (Isaac: mm).

    ``horizontal_aperture_offset`` / ``vertical_aperture_offset`` shift the principal point
    from the image centre: offset = (c + 0.5 - size / 2) * pixel_size, positive to the right
    and down in the image.
    """

    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    horizontal_aperture_offset: float = 0.0
    vertical_aperture_offset: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """The five parameters by name, in this object's length unit."""
        return asdict(self)


def isaac_params(intrinsics: Intrinsics, pixel_size: float) -> IsaacCameraParams:
    """Isaac Sim parameters of ``intrinsics`` for a sensor with square pixels of ``pixel_size``.

    The paper's relations: ``f = (fx + fy) / 2 * s``, ``A_h = W * s``, ``A_v = H * s``; the
    result is in the unit of ``pixel_size``. Lens distortion has no Isaac pinhole equivalent
    and is not represented.
    """
    s = positive("pixel_size", pixel_size)
    i = intrinsics
    return IsaacCameraParams(
        focal_length=(i.fx + i.fy) / 2 * s,
        horizontal_aperture=i.width * s,
        vertical_aperture=i.height * s,
        horizontal_aperture_offset=(i.cx + 0.5 - i.width / 2) * s,
        vertical_aperture_offset=(i.cy + 0.5 - i.height / 2) * s,
    )


def intrinsics_from_isaac(
    focal_length: float,
    horizontal_aperture: float,
    width: int,
    height: int,
    vertical_aperture: float | None = None,
    horizontal_aperture_offset: float = 0.0,
    vertical_aperture_offset: float = 0.0,
) -> Intrinsics:
    """Pinhole intrinsics from Isaac Sim parameters (any one length unit).

    ``fx = f * W / A_h``; ``fy = f * H / A_v`` with ``A_v = A_h * H / W`` (square pixels) when
    not given; offsets as in :class:`IsaacCameraParams`.
    """
    f = positive("focal_length", focal_length)
    a_h = positive("horizontal_aperture", horizontal_aperture)
    width = positive_int("width", width)
    height = positive_int("height", height)
    a_v = (
        a_h * height / width
        if vertical_aperture is None
        else positive("vertical_aperture", vertical_aperture)
    )
    s_u, s_v = a_h / width, a_v / height
    return Intrinsics(
        fx=f / s_u,
        fy=f / s_v,
        cx=width / 2 - 0.5 + finite("horizontal_aperture_offset", horizontal_aperture_offset) / s_u,
        cy=height / 2 - 0.5 + finite("vertical_aperture_offset", vertical_aperture_offset) / s_v,
        width=width,
        height=height,
    )


def projected_size(
    intrinsics: Intrinsics,
    distance_m: float,
    R: object | None = None,  # noqa: N803
) -> tuple[float, float]:
    """The paper's inverse camera model: width and height of the projected image at ``Z``.

    The corner pixels ``[0, 0]`` and ``[W, H]`` are back-projected through ``K^-1``, rotated by
    ``R`` (device -> reference frame, identity by default) and scaled to depth ``distance_m``
    along the reference z axis; width and height are the x and y extents between them.
    With ``R = I`` this is exactly ``(W * Z / fx, H * Z / fy)``: linear in Z.

    Returns
    -------
    ``(width_m, height_m)`` in metres.
    """
    z = positive("distance_m", distance_m)
    rotation = np.eye(3) if R is None else check_rotation("R", R)
    corners = np.array([[0.0, 0.0, 1.0], [intrinsics.width, intrinsics.height, 1.0]])
    rays = (np.linalg.inv(intrinsics.K) @ corners.T).T @ rotation.T
    points = rays * (z / rays[:, 2:3])
    return float(abs(points[1, 0] - points[0, 0])), float(abs(points[1, 1] - points[0, 1]))


def rig_info(rig: Rig, pixel_size_mm: float) -> dict[str, Any]:
    """The rig schema of ``rig`` (metres) plus ``isaac``: Isaac Sim camera parameters in mm
    for square pixels of ``pixel_size_mm``; ``projected_size_m``: the projector's footprint
    at 1 m (:func:`projected_size`); and ``baseline_m``."""
    info = rig.to_dict()
    isaac = isaac_params(rig.camera.intrinsics, pixel_size_mm).to_dict()
    info["isaac"] = {"units": "mm", "pixel_size": pixel_size_mm, **isaac}
    width, height = projected_size(rig.projector.intrinsics, 1.0)
    info["projected_size_m"] = {"distance_m": 1.0, "width": width, "height": height}
    info["baseline_m"] = rig.baseline_m
    return info


#: The paper's camera: Isaac focal length 50 and horizontal aperture 20.9995 (same units).
PAPER_CAMERA_FOCAL = 50.0
PAPER_CAMERA_APERTURE = 20.9995
#: Projector footprint at 1 m (DLP LightCrafter 4500 class): 0.5 m wide x 0.625 m tall.
PAPER_PROJECTOR_SIZE_AT_1M = (0.5, 0.625)
#: Projector optical centre in the camera frame: 0.125 m left of and 0.1 m below the camera.
PAPER_PROJECTOR_CENTRE_M = (-0.125, 0.1, 0.0)
#: Working distance (m): the projector is toed in so its optical axis meets the camera's here.
PAPER_WORKING_DISTANCE_M = 1.0


def default_rig() -> Rig:
    """The paper's camera-projector system (DESIGN.md §4).

    * Camera 960 x 960 px, fx = fy = 960 * 50 / 20.9995 = 2285.77 px, centred principal point.
    * Projector 912 x 1140 px, fx = fy = 1824 px (0.5 m x 0.625 m at 1 m), centred.
    * Projector centre 0.125 m left of and 0.1 m below the camera, at (-0.125, 0.1, 0) m in
      the camera frame, with no roll. Toe-in: its optical axis passes through the camera's
      axis at the 1 m working distance, (0, 0, 1) m -- 7.1 deg about the camera's y axis and
      5.7 deg about its x axis. At 1 m the projected field (0.5 x 0.625 m) is centred on the
      camera's field (0.42 x 0.42 m) and covers it with margins of about 4 and 10 cm.
    """
    camera = intrinsics_from_isaac(PAPER_CAMERA_FOCAL, PAPER_CAMERA_APERTURE, 960, 960)
    width_m, height_m = PAPER_PROJECTOR_SIZE_AT_1M
    projector = Intrinsics(
        fx=912 / width_m, fy=1140 / height_m, cx=455.5, cy=569.5, width=912, height=1140
    )
    proj2cam = Pose.look_at(
        PAPER_PROJECTOR_CENTRE_M, (0.0, 0.0, PAPER_WORKING_DISTANCE_M), image_down=(0.0, 1.0, 0.0)
    )
    return Rig(Camera(camera), Projector(projector), proj2cam)
