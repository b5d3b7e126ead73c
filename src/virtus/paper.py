"""The paper's system and its published numbers, in one place.

Source: "VIRTUS-FPP: Virtual Sensor Modeling for Fringe Projection Profilometry in NVIDIA
Isaac Sim", IEEE Sensors Journal, 2026 (DESIGN.md section 4). Everything here is a fact of
the paper; virtus's own choices (such as the toe-in of the default rig) live with the code
that makes them.
"""

from __future__ import annotations

__all__ = [
    "C2M_MAE_MM",
    "CAMERA_ISAAC_APERTURE",
    "CAMERA_ISAAC_FOCAL",
    "CAMERA_PIXEL_SIZE_MM",
    "CAMERA_SIZE_PX",
    "DEMO",
    "IMAGES_PER_S",
    "PROJECTOR_CENTRE_M",
    "PROJECTOR_SIZE_AT_1M_M",
    "PROJECTOR_SIZE_PX",
    "RMS_PX",
    "WORKING_DISTANCE_M",
]

#: Camera: Isaac focal length 50 and horizontal aperture 20.9995 (same length unit).
CAMERA_ISAAC_FOCAL = 50.0
CAMERA_ISAAC_APERTURE = 20.9995
#: Camera image size, px (width, height).
CAMERA_SIZE_PX = (960, 960)
#: Camera pixel pitch implied by the aperture, mm (20.9995 mm over 960 px).
CAMERA_PIXEL_SIZE_MM = CAMERA_ISAAC_APERTURE / CAMERA_SIZE_PX[0]
#: Projector image size, px (DLP LightCrafter 4500 class).
PROJECTOR_SIZE_PX = (912, 1140)
#: Projector footprint at 1 m: 0.5 m wide x 0.625 m tall.
PROJECTOR_SIZE_AT_1M_M = (0.5, 0.625)
#: Projector optical centre in the camera frame: 0.125 m left of and 0.1 m below the camera.
PROJECTOR_CENTRE_M = (-0.125, 0.1, 0.0)
#: Working distance (m).
WORKING_DISTANCE_M = 1.0

#: Reported calibration reprojection errors, px.
RMS_PX = {"stereo": 0.056, "projector": 0.049}
#: Reported results of the demo experiment (100 mm-radius sphere).
DEMO = {
    "camera_rms_px": None,
    "projector_rms_px": RMS_PX["projector"],
    "stereo_rms_px": RMS_PX["stereo"],
    "radius_mm": 99.339,
    "radius_error_mm": 0.661,
    "inlier_ratio": 0.986,
}
#: Reported cloud-to-mesh mean absolute error of the virtual free-form scan, mm.
C2M_MAE_MM = 0.37
#: Reported dataset throughput: 16,848 images in 1.5 h on an RTX 5080 laptop GPU.
IMAGES_PER_S = 3.1
