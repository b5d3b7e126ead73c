"""Rigid transforms named by the frames they connect.

A transform ``a2b`` maps points of frame ``a`` into frame ``b``: ``X_b = R @ X_a + t``
(metres). ``proj2cam`` maps projector-frame points into the camera frame, so its ``t`` is
the projector's optical centre in camera coordinates. Frames follow OpenCV (x right, y down,
z forward).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from virtus.checks import as_float_array, as_points
from virtus.errors import InputError

#: Orthonormality tolerance for rotation matrices given by users (JSON holds ~15 digits).
_ROTATION_TOL = 1e-6


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
