"""Frames, lenses and devices: SI units, OpenCV camera frames, transforms named ``a2b``.

* :mod:`~virtus.geometry.transforms` -- rigid transforms named by frames (``Pose``).
* :mod:`~virtus.geometry.optics` -- pinhole intrinsics with OpenCV distortion.
* :mod:`~virtus.geometry.devices` -- Camera, Projector (an inverse camera), Rig and the rig JSON.
* :mod:`~virtus.geometry.isaac` -- Isaac Sim / USD lens conventions <-> OpenCV intrinsics.
* :mod:`~virtus.geometry.trajectories` -- pose trajectories (turntable views).
"""

from virtus.geometry.devices import (
    Camera,
    Projector,
    Rig,
    default_rig,
    projected_size,
    rig_info,
)
from virtus.geometry.isaac import (
    IsaacCameraParams,
    intrinsics_from_isaac,
    isaac_params,
    usd_camera_params,
)
from virtus.geometry.optics import (
    Intrinsics,
    ThinLens,
)
from virtus.geometry.trajectories import (
    turntable_poses,
)
from virtus.geometry.transforms import (
    Pose,
    check_rotation,
)

__all__ = [
    "Camera",
    "Intrinsics",
    "IsaacCameraParams",
    "Pose",
    "Projector",
    "Rig",
    "ThinLens",
    "check_rotation",
    "default_rig",
    "intrinsics_from_isaac",
    "isaac_params",
    "projected_size",
    "rig_info",
    "turntable_poses",
    "usd_camera_params",
]
