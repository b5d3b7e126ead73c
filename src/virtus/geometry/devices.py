"""Devices and the rig: camera, projector (an inverse camera), ``proj2cam``, the rig JSON,
the paper's default system and the inverse camera model.

The rig's world frame is the camera frame. ``proj2cam`` maps projector-frame points into
the camera frame: ``X_cam = R X_proj + t``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus import paper
from virtus.checks import positive
from virtus.errors import InputError
from virtus.geometry.isaac import intrinsics_from_isaac, isaac_params
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose, check_rotation
from virtus.io.jsonio import write_json
from virtus.io.safeio import check_keys, closest_key, read_json

#: Keys the rig schema requires at its top level (DESIGN.md section 3).
_RIG_KEYS = ("camera", "projector", "proj2cam")
#: Keys of the ``proj2cam`` object.
_POSE_KEYS = ("R", "t")


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
        """Read the rig schema (DESIGN.md section 3).

        Extra keys at the top level are accepted and ignored: calibration results and
        captures add their own fields (errors, residuals, sequence, ...) beside the rig's.
        Inside ``camera``, ``projector`` and ``proj2cam`` only the schema's keys are
        accepted, so a misspelt key (``distortion`` for ``dist``) is an error naming it
        rather than a silently ignored lens model.
        """
        if not isinstance(data, Mapping):
            raise InputError("rig", "a JSON object", type(data).__name__)
        missing = [key for key in _RIG_KEYS if key not in data]
        if missing:
            found = [str(key) for key in data]
            hints = [
                f"{key!r}"
                + (f" (is {near!r} misspelt?)" if (near := closest_key(key, found)) else "")
                for key in missing
            ]
            raise InputError(
                "rig", "keys camera, projector, proj2cam", f"missing {', '.join(hints)}"
            )
        units = data.get("units", "m")
        if units != "m":
            raise InputError("rig.units", '"m" (translations in metres)', units)
        check_keys(data["proj2cam"], _POSE_KEYS, "proj2cam")
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
        """Read a rig (or a calibration file using the rig schema) from JSON.

        The file is read through :func:`virtus.io.safeio.read_json` (size, UTF-8, depth and
        syntax checked; NaN refused) and must hold a JSON object; see :meth:`from_dict`.
        """
        return cls.from_dict(read_json(path, "rig", expect=dict))


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
    camera = intrinsics_from_isaac(paper.CAMERA_ISAAC_FOCAL, paper.CAMERA_ISAAC_APERTURE, 960, 960)
    width_m, height_m = paper.PROJECTOR_SIZE_AT_1M_M
    projector = Intrinsics(
        fx=912 / width_m, fy=1140 / height_m, cx=455.5, cy=569.5, width=912, height=1140
    )
    proj2cam = Pose.look_at(
        paper.PROJECTOR_CENTRE_M, (0.0, 0.0, paper.WORKING_DISTANCE_M), image_down=(0.0, 1.0, 0.0)
    )
    return Rig(Camera(camera), Projector(projector), proj2cam)
