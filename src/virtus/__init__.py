"""virtus: a virtual fringe projection profilometry (FPP) sensor.

The names a user needs, loaded on first use (PEP 562), so ``import virtus`` loads neither
Mitsuba, Dr.Jit, OpenCV nor torch::

    import virtus
    scanner = virtus.Scanner(virtus.default_rig())
    capture = scanner.capture(virtus.default_scene(), rng=0)

Conventions (see README "Conventions"):

* Units are SI inside (metres, radians); human-facing metrics carry the unit in their name.
* Camera and projector frames follow OpenCV: x right, y down, z forward.
* Pixel (col=0, row=0) has its centre at (u, v) = (0.0, 0.0); arrays are ``[row, col]``.
* Transforms are named by frames: ``proj2cam`` maps projector-frame points into the camera
  frame, ``X_cam = R @ X_proj + t``.

The floors below this face, bottom up: ``io``, ``geometry``, ``patterns``/``sensor``/``scene``,
``capture``/``reconstruct``/``metrology``/``calib``/``twin``, ``render``, ``scanner``,
``pipeline`` (jobs) and ``data`` (dataset jobs), ``cli``.
"""

from __future__ import annotations

import importlib
from typing import Any

from virtus.errors import (
    BackendUnavailable,
    DegenerateData,
    InputError,
    MissingDependency,
    RunConflict,
    VirtusError,
)

__version__ = "0.1.0"

#: Public name -> the module that defines it (imported on first use).
_LAZY: dict[str, str] = {
    # the virtual sensor and its parts
    "Scanner": "virtus.scanner",
    "RenderSettings": "virtus.render.settings",
    "Rig": "virtus.geometry",
    "Camera": "virtus.geometry",
    "Projector": "virtus.geometry",
    "default_rig": "virtus.geometry",
    "Pose": "virtus.geometry",
    "Intrinsics": "virtus.geometry",
    "PatternSequence": "virtus.patterns",
    "default_sequence": "virtus.patterns",
    "load_sequence_file": "virtus.patterns",
    "Sensor": "virtus.sensor",
    "ProjectorModel": "virtus.sensor",
    "Scene": "virtus.scene",
    "default_scene": "virtus.scene",
    # the seam and what reads it
    "Capture": "virtus.capture",
    "import_capture": "virtus.capture",
    "triangulate": "virtus.reconstruct",
    "fit_sphere": "virtus.metrology",
    "cloud_to_mesh": "virtus.metrology",
    "load_calibration": "virtus.calib.io",
    # jobs
    "load_scene": "virtus.pipeline.inputs",
    "scan": "virtus.pipeline.scan",
    "calibrate_rig": "virtus.pipeline.calibrate",
    "run_demo": "virtus.pipeline.demo",
}

__all__ = [
    "BackendUnavailable",
    "DegenerateData",
    "InputError",
    "MissingDependency",
    "RunConflict",
    "VirtusError",
    "__version__",
    *sorted(_LAZY),
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'virtus' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
