"""Digital twins of calibrated rigs: the Isaac Sim parameters of a rig, in USD's convention.

A twin is the virtual rig of a real calibration (:func:`virtus.calib.io.load_calibration`:
any resolution, off-centre principal points, distortion on both devices). Its Isaac Sim
description (:func:`twin_parameters`) holds

* the stage units: ``metersPerUnit`` (stated; lengths of poses and lights are in scene
  units) and ``upAxis`` Z;
* the camera: USD lens and film values in tenths of a scene unit (:mod:`virtus.geometry.isaac`) for
  a stated pixel pitch, the OpenCV calibration in pixels, and Omniverse's
  ``OmniLensDistortionOpenCvPinholeAPI`` attributes (``omni:lensdistortion:opencvPinhole:*``),
  which render fx != fy and distortion exactly;
* the projector as Isaac models it: a ``UsdLux.RectLight`` whose width and height are the
  projected image's size at 1 m from the inverse camera model
  (:func:`virtus.geometry.devices.projected_size`), with its OpenCV calibration;
* both poses in Isaac's world: the camera at the origin looking along +X with +Z up
  (:data:`virtus.geometry.isaac.CV_TO_ISAAC_WORLD`); a prim's transform maps its USD-local frame
  (looking along -Z, +Y up) to the world, ``prim2world = device2world diag(1, -1, -1)``.
  Quaternions are written ``(w, x, y, z)`` as ``Gf.Quatd``.

This module needs no USD library; :mod:`virtus.twin.usd` writes the same values into a stage.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from virtus import paper
from virtus.checks import positive
from virtus.geometry.devices import Rig, projected_size
from virtus.geometry.isaac import CV_TO_ISAAC_WORLD, CV_TO_USD_CAMERA, usd_camera_params
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

#: Default pixel pitch (m) of the twin's USD camera: the paper's, 20.9995 mm / 960 px, so
#: the paper's camera reads focal length 50 mm and aperture 20.9995 mm as in its Isaac
#: scene. Any pitch gives the same images (only ratios enter the pinhole model).
DEFAULT_PIXEL_SIZE_M = paper.CAMERA_ISAAC_APERTURE / 960 * 1e-3
#: Distance (m) at which the RectLight's size is the projected image's (the paper's 1 m).
PROJECTOR_DISTANCE_M = 1.0
#: Name of the Omniverse lens-distortion model for OpenCV's pinhole + distortion.
OPENCV_PINHOLE = "opencvPinhole"
#: OpenCV coefficient names in order (as the Omniverse attributes name them).
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


def camera_world_pose() -> Pose:
    """``cam2world`` of the twin's camera in Isaac's world: origin, looking along +X, +Z up."""
    return Pose(CV_TO_ISAAC_WORLD, np.zeros(3))


def prim_transform(device2world: Pose) -> Pose:
    """USD prim transform (its local frame -> world, metres) of an OpenCV-frame device pose."""
    return Pose(device2world.R @ CV_TO_USD_CAMERA, device2world.t)


def lens_distortion_attributes(intrinsics: Intrinsics) -> dict[str, Any]:
    """Omniverse ``OmniLensDistortionOpenCvPinholeAPI`` attributes (pixels, OpenCV order)."""
    prefix = f"omni:lensdistortion:{OPENCV_PINHOLE}"
    dist = np.zeros(8)
    dist[: len(intrinsics.dist)] = intrinsics.dist
    attributes: dict[str, Any] = {
        "omni:lensdistortion:model": OPENCV_PINHOLE,
        f"{prefix}:imageSize": [intrinsics.width, intrinsics.height],
        f"{prefix}:fx": intrinsics.fx,
        f"{prefix}:fy": intrinsics.fy,
        f"{prefix}:cx": intrinsics.cx,
        f"{prefix}:cy": intrinsics.cy,
    }
    attributes.update(
        {f"{prefix}:{name}": float(v) for name, v in zip(DIST_NAMES, dist, strict=True)}
    )
    return attributes


def _pose_dict(prim2world: Pose, meters_per_unit: float) -> dict[str, Any]:
    quat = prim2world.as_quat()  # (x, y, z, w)
    return {
        "position": (prim2world.t / meters_per_unit).tolist(),
        "orientation_wxyz": [float(quat[3]), *map(float, quat[:3])],
        "rotation_matrix": prim2world.R.tolist(),
        "euler_xyz_deg": Rotation.from_matrix(prim2world.R).as_euler("xyz", True).tolist(),
    }


def twin_parameters(
    rig: Rig,
    *,
    pixel_size_m: float = DEFAULT_PIXEL_SIZE_M,
    meters_per_unit: float = 1.0,
) -> dict[str, Any]:
    """The Isaac Sim description of ``rig`` (module docstring), JSON-ready.

    Parameters
    ----------
    rig : the calibrated rig (metres, OpenCV frames).
    pixel_size_m : pixel pitch of the USD camera, metres (sets the lens and film values'
        scale, not the images).
    meters_per_unit : the stage's ``metersPerUnit`` (1 for metres, 0.01 for centimetres).

    Returns
    -------
    dict with ``metersPerUnit``, ``upAxis``, ``units`` (what each number is in),
    ``camera`` (``usd``: focalLength, horizontalAperture, verticalAperture,
    horizontalApertureOffset, verticalApertureOffset in tenths of a scene unit;
    ``lens_distortion``; ``opencv``; ``pose``) and ``projector`` (``rect_light``: width and
    height in scene units at :data:`PROJECTOR_DISTANCE_M`; ``opencv``; ``pose``).
    """
    mpu = positive("meters_per_unit", meters_per_unit)
    pitch = positive("pixel_size_m", pixel_size_m)
    cam = rig.camera.intrinsics
    usd = usd_camera_params(cam, pitch, mpu)
    cam2world = camera_world_pose()
    proj2world = cam2world @ rig.proj2cam
    width_m, height_m = projected_size(rig.projector.intrinsics, PROJECTOR_DISTANCE_M)
    return {
        "metersPerUnit": mpu,
        "upAxis": "Z",
        "units": {
            "camera.usd": "tenths of a scene unit (USD lens and film convention)",
            "pose.position": "scene units (metersPerUnit metres each)",
            "rect_light": "scene units",
            "opencv": "pixels; distortion in OpenCV order (k1, k2, p1, p2, k3, k4, k5, k6)",
        },
        "world": "Isaac: camera at the origin looking along +X, +Z up",
        "camera": {
            "pixel_size_m": pitch,
            "usd": {
                "focalLength": usd.focal_length,
                "horizontalAperture": usd.horizontal_aperture,
                "verticalAperture": usd.vertical_aperture,
                "horizontalApertureOffset": usd.horizontal_aperture_offset,
                "verticalApertureOffset": usd.vertical_aperture_offset,
            },
            "lens_distortion": lens_distortion_attributes(cam),
            "opencv": cam.to_dict(),
            "pose": _pose_dict(prim_transform(cam2world), mpu),
        },
        "projector": {
            "rect_light": {
                "width": width_m / mpu,
                "height": height_m / mpu,
                "distance_m": PROJECTOR_DISTANCE_M,
                "isProjector": True,
            },
            "opencv": rig.projector.intrinsics.to_dict(),
            "pose": _pose_dict(prim_transform(proj2world), mpu),
            "proj2cam": rig.proj2cam.to_dict(),
        },
    }
