"""Isaac Sim (USD) pinhole camera parameters <-> OpenCV intrinsics."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from virtus.checks import finite, positive, positive_int
from virtus.optics import Intrinsics


@dataclass(frozen=True)
class IsaacCameraParams:
    """Isaac Sim (USD) pinhole camera parameters, all in one length unit (Isaac: mm).

    ``horizontal_aperture_offset`` / ``vertical_aperture_offset`` shift the principal point
    from the image centre: offset = (c + 0.5 - size / 2) * pixel_size, positive to the right
    and down in the image.
    """

    focal_length: float
    horizontal_aperture: float
    vertical_aperture: float
    horizontal_aperture_offset: float = 0.0
    vertical_aperture_offset: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """The five parameters by name, in this object's length unit."""
        return asdict(self)


def isaac_params(intrinsics: Intrinsics, pixel_size: float) -> IsaacCameraParams:
    """Isaac Sim parameters of ``intrinsics`` for a sensor with square pixels of ``pixel_size``.

    The paper's relations: ``f = (fx + fy) / 2 * s``, ``A_h = W * s``, ``A_v = H * s``; the
    result is in the unit of ``pixel_size``. Lens distortion has no Isaac pinhole equivalent
    and is not represented.
    """
    s = positive("pixel_size", pixel_size)
    i = intrinsics
    return IsaacCameraParams(
        focal_length=(i.fx + i.fy) / 2 * s,
        horizontal_aperture=i.width * s,
        vertical_aperture=i.height * s,
        horizontal_aperture_offset=(i.cx + 0.5 - i.width / 2) * s,
        vertical_aperture_offset=(i.cy + 0.5 - i.height / 2) * s,
    )


def intrinsics_from_isaac(
    focal_length: float,
    horizontal_aperture: float,
    width: int,
    height: int,
    vertical_aperture: float | None = None,
    horizontal_aperture_offset: float = 0.0,
    vertical_aperture_offset: float = 0.0,
) -> Intrinsics:
    """Pinhole intrinsics from Isaac Sim parameters (any one length unit).

    ``fx = f * W / A_h``; ``fy = f * H / A_v`` with ``A_v = A_h * H / W`` (square pixels) when
    not given; offsets as in :class:`IsaacCameraParams`.
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
        cx=width / 2 - 0.5 + finite("horizontal_aperture_offset", horizontal_aperture_offset) / s_u,
        cy=height / 2 - 0.5 + finite("vertical_aperture_offset", vertical_aperture_offset) / s_v,
        width=width,
        height=height,
    )
