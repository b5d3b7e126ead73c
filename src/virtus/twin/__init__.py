"""Digital twins: the Isaac Sim parameters of a rig and USD stages (``usd-core`` optional).

* :mod:`~virtus.twin.parameters` -- the Isaac Sim parameters of a calibrated rig.
* :mod:`~virtus.twin.photometric` -- the twin's light fitted to real captures: projector
  gamma and blur, vignetting and fall-off, exposure, ambient level, camera gain and noise.
* :mod:`~virtus.twin.usd` -- USD stages in and out (imported on use: needs ``usd-core``).
"""

from virtus.twin.parameters import (
    camera_world_pose,
    lens_distortion_attributes,
    prim_transform,
    twin_parameters,
)
from virtus.twin.photometric import (
    PhotometricFit,
    fit_photometry,
    frame_differences,
    response_harmonics,
)

__all__ = [
    "PhotometricFit",
    "camera_world_pose",
    "fit_photometry",
    "frame_differences",
    "lens_distortion_attributes",
    "prim_transform",
    "response_harmonics",
    "twin_parameters",
]
