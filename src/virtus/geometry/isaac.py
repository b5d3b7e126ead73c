"""Isaac Sim / USD pinhole camera parameters <-> OpenCV intrinsics, and Isaac's frames.

USD's camera (``UsdGeom.Camera``) looks along its local -Z axis with +Y up; its lens and
film values (``focalLength``, ``horizontalAperture``, ``verticalAperture`` and the two
aperture offsets) are in tenths of a scene unit: 25 mm is 0.25 on a metre stage
(``metersPerUnit = 1``) and 25 on a centimetre stage (``metersPerUnit = 0.01``, Isaac's mm).
For a sensor of pixel pitch ``p`` (any length unit) and OpenCV intrinsics (pixel-centre
convention, DESIGN.md section 2)::

    focal = fx p,   A_h = W p,   A_v = H p fx / fy      (non-square pixels through A_v)
    offset_h = -(cx + 0.5 - W / 2) p                    (film x grows to the right, but the
                                                         window moves opposite to the image)
    offset_v = +(cy + 0.5 - H / 2) p fx / fy            (film y grows upwards, rows downwards)

These are the relations of ``UsdGeom.Camera.GetCamera().frustum``: a point seen by a USD
camera with these values lands on the pixel OpenCV gives (``tests/twin/test_usd.py``
projects an
off-axis point both ways); they match the paper code's ``-(cx - W/2) p`` and
``+(cy - H/2) p`` up to the half-pixel of the pixel-centre convention.

Frames: :data:`CV_TO_USD_CAMERA` maps OpenCV camera-frame points to the USD camera's local
frame (and the projector's to its ``RectLight``'s, which emits along its -Z);
:data:`CV_TO_ISAAC_WORLD` is the rotation of a camera at the origin of Isaac's world looking
along +X with +Z up (OpenCV x right -> -Y, y down -> -Z, z forward -> +X).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from virtus.checks import finite, positive, positive_int
from virtus.geometry.optics import Intrinsics

#: OpenCV device frame (x right, y down, z forward) -> USD camera/light frame (x right,
#: y up, looking along -z).
CV_TO_USD_CAMERA = np.diag([1.0, -1.0, -1.0])
#: Rotation of the OpenCV camera frame into Isaac's world for a camera at the origin looking
#: along +X with +Z up: columns are the images of the camera's x, y, z axes.
CV_TO_ISAAC_WORLD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: USD lens and film values are in tenths of a scene unit.
USD_FILM_UNITS_PER_SCENE_UNIT = 10.0


@dataclass(frozen=True)
class IsaacCameraParams:
    """Isaac Sim (USD) pinhole camera parameters, all in one length unit.

    In Isaac's millimetres (a centimetre stage) or in USD's tenths of a scene unit; the
    offsets follow USD (module docstring): ``horizontal_aperture_offset`` is positive when
    the principal point lies *left* of the image centre, ``vertical_aperture_offset`` when
    it lies below it (larger row numbers).
    """

    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    horizontal_aperture_offset: float = 0.0
    vertical_aperture_offset: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """The five parameters by name, in this object's length unit."""
        return asdict(self)

    def scaled(self, factor: float) -> IsaacCameraParams:
        """The same camera in another length unit (every value times ``factor``)."""
        return IsaacCameraParams(*(value * factor for value in asdict(self).values()))


def isaac_params(intrinsics: Intrinsics, pixel_size: float) -> IsaacCameraParams:
    """Isaac Sim parameters of ``intrinsics`` for a sensor with pixels ``pixel_size`` wide.

    ``focal = fx s``, ``A_h = W s``, ``A_v = H s fx / fy`` (non-square pixels), offsets as
    in the module docstring; the result is in the unit of ``pixel_size``. Lens distortion
    has no USD pinhole equivalent (see :mod:`virtus.twin.usd` for Omniverse's OpenCV lens API).
    """
    s = positive("pixel_size", pixel_size)
    i = intrinsics
    s_v = s * i.fx / i.fy
    return IsaacCameraParams(
        focal_length=i.fx * s,
        horizontal_aperture=i.width * s,
        vertical_aperture=i.height * s_v,
        horizontal_aperture_offset=-(i.cx + 0.5 - i.width / 2) * s,
        vertical_aperture_offset=(i.cy + 0.5 - i.height / 2) * s_v,
    )


def usd_camera_params(
    intrinsics: Intrinsics, pixel_size_m: float, meters_per_unit: float = 1.0
) -> IsaacCameraParams:
    """USD camera attributes of ``intrinsics``: tenths of a scene unit of a stage with
    ``meters_per_unit`` metres per unit, for pixels ``pixel_size_m`` metres wide."""
    mpu = positive("meters_per_unit", meters_per_unit)
    pitch = positive("pixel_size_m", pixel_size_m) / mpu * USD_FILM_UNITS_PER_SCENE_UNIT
    return isaac_params(intrinsics, pitch)


def intrinsics_from_isaac(
    focal_length: float,
    horizontal_aperture: float,
    width: int,
    height: int,
    vertical_aperture: float | None = None,
    horizontal_aperture_offset: float = 0.0,
    vertical_aperture_offset: float = 0.0,
    dist: tuple[float, ...] = (),
) -> Intrinsics:
    """Pinhole intrinsics from Isaac Sim / USD parameters (any one length unit).

    ``fx = f W / A_h``; ``fy = f H / A_v`` with ``A_v = A_h H / W`` (square pixels) when
    not given; ``cx = W / 2 - 0.5 - offset_h W / A_h``, ``cy = H / 2 - 0.5 + offset_v H /
    A_v`` (module docstring); ``dist`` in OpenCV order.
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
        cx=width / 2 - 0.5 - finite("horizontal_aperture_offset", horizontal_aperture_offset) / s_u,
        cy=height / 2 - 0.5 + finite("vertical_aperture_offset", vertical_aperture_offset) / s_v,
        width=width,
        height=height,
        dist=tuple(dist),
    )
