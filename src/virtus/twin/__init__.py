"""Digital twins: the Isaac Sim parameters of a rig and USD stages (``usd-core`` optional).

* :mod:`~virtus.twin.parameters` -- the Isaac Sim parameters of a calibrated rig.
* :mod:`~virtus.twin.usd` -- USD stages in and out (imported on use: needs ``usd-core``).
"""

from virtus.twin.parameters import (
    camera_world_pose,
    lens_distortion_attributes,
    prim_transform,
    twin_parameters,
)

__all__ = [
    "camera_world_pose",
    "lens_distortion_attributes",
    "prim_transform",
    "twin_parameters",
]
