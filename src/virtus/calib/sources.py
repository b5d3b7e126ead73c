"""Where a calibration's parameters came from (:class:`CalibrationSources`), and the rig of
a bench imported without a calibration (:func:`uncalibrated_rig`).

A :class:`~virtus.geometry.devices.Rig` holds numbers only: a distortion that no file gave is
five zeros there, exactly as a measured zero distortion. The record says which it was: for
each device the file (and key) of its matrix, distortion and image size, or
:data:`NONE_GIVEN` and why; the extrinsics, the units, and the files or keys that were not
used. :func:`virtus.calib.io.load_calibration_report` returns it beside the rig; ``virtus
import`` prints it and records it in ``capture.json`` (``calibration_source``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virtus.calib.names import side_read_as_camera
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

__all__ = [
    "NONE_GIVEN",
    "PLACEHOLDER_FOCAL_PER_PX",
    "CalibrationSources",
    "record_of",
    "uncalibrated_rig",
]

#: What the record says of a parameter no source gave (the rig holds zeros for it).
NONE_GIVEN = "none given"
#: Focal length of the placeholder rig of an uncalibrated import, in pixels per pixel of the
#: larger image side (f = max(width, height): a ~53 degree field across that side, a usual
#: lens). A placeholder only: its proj2cam has no baseline, so nothing is triangulated with it.
PLACEHOLDER_FOCAL_PER_PX = 1.0
#: The parameters of each device, in the order they are printed.
DEVICE_PARAMETERS = ("K", "dist", "size")
_LABELS = {"K": "matrix", "dist": "distortion", "size": "image size"}


@dataclass(frozen=True)
class CalibrationSources:
    """Where each parameter of a rig read from a calibration came from.

    Attributes
    ----------
    path : the file or folder read ("" for an import without a calibration).
    format : what it was read as (``"rig JSON"``, ``"OpenCV FileStorage"``, ``"text
        folder"``, ``"NumPy .npz"``, ``"mapping file -> <format>"``, ``"none"``).
    camera, projector : ``{"K": ..., "dist": ..., "size": ...}``, each the file (and
        ``": key"``) it came from, an argument (``"given: camera_size"``), or a text
        starting with :data:`NONE_GIVEN` that says why.
    extrinsics : the keys of the extrinsics and their convention.
    units : the unit of the translations and who said so.
    ignored : files (of a folder) or keys (of a file) that were not used.
    calibrated : False for the placeholder rig of an import without a calibration.
    notes : remarks printed with the record.
    files : the files read (a mapping file and the file it maps; a folder's used files).
    """

    path: str
    format: str
    camera: Mapping[str, str]
    projector: Mapping[str, str]
    extrinsics: str
    units: str
    ignored: tuple[str, ...] = ()
    calibrated: bool = True
    notes: tuple[str, ...] = field(default=())
    files: tuple[str, ...] = field(default=())

    def lines(self) -> list[tuple[str, str]]:
        """``(label, text)`` per parameter source, e.g. ``("camera distortion", "none given
        (no distortion in cal/)")``, for a summary table."""
        rows = []
        for device in ("camera", "projector"):
            values = getattr(self, device)
            rows += [(f"{device} {_LABELS[key]}", values[key]) for key in DEVICE_PARAMETERS]
        rows += [("extrinsics", self.extrinsics), ("units", self.units)]
        if self.ignored:
            rows.append(("ignored", ", ".join(self.ignored)))
        rows += [("note", note) for note in self.notes]
        return rows

    def to_dict(self) -> dict[str, Any]:
        """The record as JSON (``capture.json``'s ``calibration_source``)."""
        return {
            "calibrated": self.calibrated,
            "path": self.path,
            "format": self.format,
            "camera": dict(self.camera),
            "projector": dict(self.projector),
            "extrinsics": self.extrinsics,
            "units": self.units,
            "ignored": list(self.ignored),
            "notes": list(self.notes),
            "files": list(self.files),
        }

    def without_distortion(self) -> list[str]:
        """The devices whose distortion no source gave."""
        return [
            device
            for device in ("camera", "projector")
            if getattr(self, device)["dist"].startswith(NONE_GIVEN)
        ]


def record_of(
    path: str | Path,
    fmt: str,
    used: dict[str, Any],
    *,
    label: Callable[[str], str],
    none: str,
    units: str,
    ignored: list[str],
    files: tuple[str | Path, ...] = (),
) -> CalibrationSources:
    """The :class:`CalibrationSources` of a file whose ``used`` keys (``{"camera": {"K",
    "dist", "size"}, "projector": ..., "extrinsics": [keys], "convention": str}``, "" for a
    distortion or size the file lacks) are written by ``label``; ``none``: why a distortion
    was not given; ``files``: the files read (default ``path``)."""
    devices = {}
    for device in ("camera", "projector"):
        keys = used[device]
        devices[device] = {
            "K": label(keys["K"]),
            "dist": label(keys["dist"]) if keys["dist"] else f"{NONE_GIVEN} ({none})",
            "size": label(keys["size"]) if keys["size"] else f"given: {device}_size",
        }
    extrinsics = ", ".join(label(key) for key in used["extrinsics"])
    return CalibrationSources(
        notes=_sides_read_as_camera(used, label),
        path=str(path),
        format=fmt,
        camera=devices["camera"],
        projector=devices["projector"],
        extrinsics=f"{extrinsics} ({used['convention']})",
        units=units,
        ignored=tuple(ignored),
        files=tuple(str(f) for f in (files or (path,))),
    )


def _sides_read_as_camera(used: dict[str, Any], label: Callable[[str], str]) -> tuple[str, ...]:
    """The note of a source whose ``Cam...Right`` (``2``) names were read as the camera's
    because it names the projector ``Proj...`` (:func:`virtus.calib.names.name_roles`)."""

    def side(key: str) -> str:
        return side_read_as_camera(key[: -len(".txt")] if key.lower().endswith(".txt") else key)

    if not any(side(key) for key in used["camera"].values() if key):
        return ()
    keys = [key for key in (*used["camera"].values(), *used["extrinsics"]) if key and side(key)]
    sides = "/".join(sorted({side(key) for key in keys}))
    return (
        f"{sides} read as the camera (the projector's names start with Proj): "
        + ", ".join(label(key) for key in keys),
    )


def uncalibrated_rig(
    camera_size: tuple[int, int], projector_size: tuple[int, int]
) -> tuple[Rig, CalibrationSources]:
    """The placeholder rig of a capture imported without a calibration, and its record.

    Image sizes are the real ones (``(width, height)``: the camera's from the images, the
    projector's from the sequence), so the capture decodes and ``virtus calibrate
    --captures`` calibrates it; K is nominal (f = :data:`PLACEHOLDER_FOCAL_PER_PX` x the
    larger side, principal point at the image centre ``((W - 1) / 2, (H - 1) / 2)``), no
    distortion, and proj2cam the identity: **no baseline**, so any triangulation refuses it
    (:func:`virtus.reconstruct.check_baseline`). The record has ``calibrated`` False.
    """
    devices = []
    for width, height in (camera_size, projector_size):
        focal = PLACEHOLDER_FOCAL_PER_PX * max(width, height)
        devices.append(
            Intrinsics(focal, focal, (width - 1) / 2, (height - 1) / 2, width, height, ())
        )
    rig = Rig(Camera(devices[0]), Projector(devices[1]), Pose.identity())
    placeholder = f"{NONE_GIVEN} (no calibration: a nominal placeholder)"
    cam_wh, proj_wh = (f"{w}x{h}" for w, h in (camera_size, projector_size))
    sources = CalibrationSources(
        path="",
        format="none",
        camera={"K": placeholder, "dist": placeholder, "size": f"the images ({cam_wh})"},
        projector={"K": placeholder, "dist": placeholder,
                   "size": f"the pattern sequence ({proj_wh})"},  # fmt: skip
        extrinsics=f"{NONE_GIVEN} (no calibration: no baseline, nothing can be triangulated)",
        units="m",
        calibrated=False,
        notes=("imported without a calibration: pass --calibration FILE to reconstruct, or "
               "calibrate from such captures with virtus calibrate --captures",),
    )  # fmt: skip
    return rig, sources
