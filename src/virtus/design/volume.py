"""The measuring volume of a camera-projector rig: the box both devices see within the depth
of field, in which a VDI/VDE 2634-2 acceptance test places its artefacts.

A :class:`MeasuringVolume` is an axis-aligned box in the camera frame (metres, OpenCV axes:
x right, y down, z forward). :func:`volume_from_rig` derives it from a rig:

1. **Working distance** ``d_w``: the focus distance of the camera lens if it has one, else
   the depth (camera z) of the closest approach of the two optical axes (the paper's rig
   aims its projector at (0, 0, 1 m)), else -- parallel axes -- :data:`DEFAULT_WORKING_DISTANCE_M`.
2. **Depth range**: with a thin lens on either device, the depths around ``d_w`` where every
   lens's blur circle is at most :data:`MAX_BLUR_PX` of its device's pixels
   (:meth:`virtus.geometry.optics.ThinLens.blur_diameter_px`; for the projector the depth is
   taken along its own axis); pinhole devices are sharp at every depth, so the range is then
   ``d_w (1 +- DEFAULT_DEPTH_FRACTION)``, a typical specification of a fringe scanner.
3. **Lateral extent**: the largest box of the camera image's aspect, centred on the axes'
   crossing point, whose surface (corners and edge points, so lens distortion is respected)
   projects inside both images with a margin of :data:`FIELD_MARGIN` of each image's size.

:func:`check_volume` refuses a given box (``--volume``) that either device does not see
whole; :func:`volume_from_text` parses the option (millimetres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.errors import InputError, VirtusError

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig
    from virtus.geometry.optics import Intrinsics

__all__ = [
    "DEFAULT_DEPTH_FRACTION",
    "DEFAULT_WORKING_DISTANCE_M",
    "FIELD_MARGIN",
    "MAX_BLUR_PX",
    "MeasuringVolume",
    "check_volume",
    "seen_by_both",
    "volume_from_rig",
    "volume_from_text",
    "working_distance",
]

#: Half depth of a pinhole rig's volume, as a fraction of the working distance.
DEFAULT_DEPTH_FRACTION = 0.1
#: Working distance of a rig whose optical axes never cross (parallel axes), metres.
DEFAULT_WORKING_DISTANCE_M = 1.0
#: Largest blur-circle diameter (device pixels) that counts as "in focus": two pixels keep an
#: 18 px fringe period's modulation above 90 % (Gaussian sigma ~ c / 4, DESIGN §9).
MAX_BLUR_PX = 2.0
#: Margin between the derived volume and the image borders, a fraction of the image size.
FIELD_MARGIN = 0.02
#: Axes closer to parallel than this (radians) have no crossing point.
_PARALLEL_RAD = 1e-3
#: Points per box edge checked against the fields (distortion bends the frustum's faces).
_EDGE_POINTS = 9
#: Largest extent of a volume, metres (a typo in millimetres is refused, not rendered).
MAX_EXTENT_M = 100.0


@dataclass(frozen=True)
class MeasuringVolume:
    """An axis-aligned box in the camera frame (metres).

    Attributes
    ----------
    lower_m, upper_m : (3,) corners ``(x, y, z)`` with ``lower < upper``, ``z > 0``.
    source : ``"rig"`` (derived by :func:`volume_from_rig`) or ``"given"``.
    """

    lower_m: tuple[float, float, float]
    upper_m: tuple[float, float, float]
    source: str = "given"

    def __post_init__(self) -> None:
        lower = tuple(float(v) for v in self.lower_m)
        upper = tuple(float(v) for v in self.upper_m)
        if len(lower) != 3 or len(upper) != 3:
            raise InputError("volume", "two corners of 3 coordinates", (lower, upper))
        if not all(math.isfinite(v) for v in (*lower, *upper)):
            raise InputError("volume", "finite coordinates", (lower, upper))
        if not all(lo < hi for lo, hi in zip(lower, upper, strict=True)):
            raise InputError("volume", "lower < upper corner in x, y and z", (lower, upper))
        if lower[2] <= 0:
            raise InputError("volume", "a box in front of the camera (z > 0)", lower[2])
        if max(hi - lo for lo, hi in zip(lower, upper, strict=True)) > MAX_EXTENT_M:
            raise InputError("volume", f"extents of at most {MAX_EXTENT_M:g} m", (lower, upper))
        object.__setattr__(self, "lower_m", lower)
        object.__setattr__(self, "upper_m", upper)

    @property
    def size_m(self) -> np.ndarray:
        """(3,) edge lengths, metres."""
        return np.subtract(self.upper_m, self.lower_m)

    @property
    def centre_m(self) -> np.ndarray:
        """(3,) centre, camera frame, metres."""
        return (np.asarray(self.lower_m) + np.asarray(self.upper_m)) / 2

    @property
    def diagonal_m(self) -> float:
        """Length of the space diagonal, metres (VDI/VDE 2634-2 sizes artefacts by it)."""
        return float(np.linalg.norm(self.size_m))

    def corners(self) -> np.ndarray:
        """(8, 3) corners, camera frame, metres."""
        signs = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=float)
        return np.asarray(self.lower_m) + signs * self.size_m

    def surface_points(self) -> np.ndarray:
        """(M, 3) points on the 12 edges (:data:`_EDGE_POINTS` each), camera frame, metres."""
        corners = self.corners()
        t = np.linspace(0.0, 1.0, _EDGE_POINTS)[:, None]
        edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
        return np.concatenate([corners[a] + t * (corners[b] - corners[a]) for a, b in edges])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description in millimetres."""
        return {
            "frame": "camera",
            "lower_mm": [1e3 * v for v in self.lower_m],
            "upper_mm": [1e3 * v for v in self.upper_m],
            "size_mm": (1e3 * self.size_m).tolist(),
            "diagonal_mm": 1e3 * self.diagonal_m,
            "source": self.source,
        }


def working_distance(rig: Rig, camera_lens: Any = None) -> tuple[float, np.ndarray]:
    """The working distance (metres, camera z) and the (3,) point the volume centres on.

    The camera lens's focus distance if ``camera_lens`` is given (on the camera axis); else
    the midpoint of the shortest segment between the optical axes when they cross in front
    of both devices; else :data:`DEFAULT_WORKING_DISTANCE_M` on the camera axis.
    """
    if camera_lens is not None:
        d = float(camera_lens.focus_distance_m)
        return d, np.array([0.0, 0.0, d])
    a = np.array([0.0, 0.0, 1.0])  # camera axis from the origin
    o = np.asarray(rig.proj2cam.t, dtype=np.float64)
    b = rig.proj2cam.apply_direction(np.array([[0.0, 0.0, 1.0]]))[0]
    c = float(a @ b)
    denom = 1.0 - c * c
    if denom > _PARALLEL_RAD**2:
        s = (a @ o - c * (b @ o)) / denom
        r = (c * (a @ o) - b @ o) / denom
        if s > 0 and r > 0:
            point = 0.5 * (s * a + o + r * b)
            return float(point[2]), point
    d = DEFAULT_WORKING_DISTANCE_M
    return d, np.array([0.0, 0.0, d])


def _depth_range(rig: Rig, settings: Any, distance: float) -> tuple[float, float]:
    """``(z_near, z_far)`` in metres: the in-focus depths around ``distance`` (module doc)."""
    camera_lens = getattr(settings, "camera_lens", None)
    projector_lens = getattr(settings, "projector_lens", None)
    if camera_lens is None and projector_lens is None:
        half = DEFAULT_DEPTH_FRACTION * distance
        return distance - half, distance + half
    z = np.linspace(0.2 * distance, 5.0 * distance, 4801)
    sharp = np.ones_like(z, dtype=bool)
    if camera_lens is not None:
        sharp &= camera_lens.blur_diameter_px(z, rig.camera.intrinsics.fx) <= MAX_BLUR_PX
    if projector_lens is not None:
        on_axis = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
        z_proj = rig.cam2proj.apply(on_axis)[:, 2]
        fx = rig.projector.intrinsics.fx
        with np.errstate(all="ignore"):
            sharp &= (z_proj > 0) & (projector_lens.blur_diameter_px(z_proj, fx) <= MAX_BLUR_PX)
    at = int(np.argmin(np.abs(z - distance)))
    if not sharp[at]:
        raise VirtusError(
            f"measuring volume: nothing is in focus at the working distance {distance:g} m "
            f"(blur over {MAX_BLUR_PX:g} px); check the lenses' focus distances"
        )
    lo = at
    while lo > 0 and sharp[lo - 1]:
        lo -= 1
    hi = at
    while hi < z.size - 1 and sharp[hi + 1]:
        hi += 1
    return float(z[lo]), float(z[hi])


def _inside(intrinsics: Intrinsics, points_dev: np.ndarray, margin: float) -> bool:
    """Whether every point lies in front of the device and inside its image, ``margin``
    (a fraction of the size) from the borders."""
    if not (points_dev[:, 2] > 0).all():
        return False
    uv = intrinsics.project(points_dev)
    mx, my = margin * intrinsics.width, margin * intrinsics.height
    u, v = uv[:, 0], uv[:, 1]
    ok = (u >= -0.5 + mx) & (u <= intrinsics.width - 0.5 - mx)
    ok &= (v >= -0.5 + my) & (v <= intrinsics.height - 0.5 - my)
    return bool(np.isfinite(uv).all() and ok.all())


def seen_by_both(rig: Rig, points_cam: np.ndarray, margin: float = 0.0) -> bool:
    """Whether camera and projector both see every point (``(N, 3)`` camera frame, metres),
    ``margin`` (a fraction of each image's size) inside their borders."""
    return _inside(rig.camera.intrinsics, points_cam, margin) and _inside(
        rig.projector.intrinsics, rig.cam2proj.apply(points_cam), margin
    )


def volume_from_rig(rig: Rig, settings: Any = None) -> MeasuringVolume:
    """The rig's measuring volume (module docstring).

    Parameters
    ----------
    rig : the camera-projector rig (camera frame = world).
    settings : the scanner's :class:`~virtus.render.settings.RenderSettings` (its lenses set
        the depth of field), or None for pinhole devices.

    Raises
    ------
    VirtusError : the fields do not overlap at the working distance, or nothing is in focus.
    """
    camera_lens = getattr(settings, "camera_lens", None)
    distance, centre = working_distance(rig, camera_lens)
    z_near, z_far = _depth_range(rig, settings, distance)
    cam = rig.camera.intrinsics
    # Half extents per unit scale: the camera's field at the near depth (its narrowest).
    half = np.array([cam.width / cam.fx, cam.height / cam.fy]) * z_near / 2

    def box(scale: float) -> MeasuringVolume:
        lo = (centre[0] - scale * half[0], centre[1] - scale * half[1], z_near)
        hi = (centre[0] + scale * half[0], centre[1] + scale * half[1], z_far)
        return MeasuringVolume(lo, hi, "rig")

    low, high = 0.0, 1.0
    if not seen_by_both(rig, box(1e-3).surface_points(), FIELD_MARGIN):
        raise VirtusError(
            f"measuring volume: camera and projector do not both see the depths "
            f"{z_near:.3g}-{z_far:.3g} m around {distance:.3g} m (do the fields overlap?)"
        )
    for _ in range(40):  # bisection on the lateral scale: 1e-12 of the camera's field
        mid = (low + high) / 2
        low, high = (
            (mid, high)
            if seen_by_both(rig, box(mid).surface_points(), FIELD_MARGIN)
            else (
                low,
                mid,
            )
        )
    return box(low)


def check_volume(volume: MeasuringVolume, rig: Rig, name: str = "--volume") -> MeasuringVolume:
    """``volume`` if both devices see all of it (edges sampled), else :class:`InputError`
    naming ``name``."""
    points = volume.surface_points()
    for device, intrinsics, pts in (
        ("camera", rig.camera.intrinsics, points),
        ("projector", rig.projector.intrinsics, rig.cam2proj.apply(points)),
    ):
        if not _inside(intrinsics, pts, 0.0):
            raise InputError(
                name,
                f"a box inside the {device}'s field (both devices must see all of it)",
                _text(volume),
            )
    return volume


def _text(volume: MeasuringVolume) -> str:
    return ",".join(f"{1e3 * v:g}" for v in (*volume.lower_m, *volume.upper_m)) + " mm"


def volume_from_text(text: str, name: str = "--volume") -> MeasuringVolume:
    """A volume from ``'X0,Y0,Z0,X1,Y1,Z1'``: two opposite corners in millimetres, camera
    frame (x right, y down, z forward)."""
    parts = str(text).split(",")
    expected = "'X0,Y0,Z0,X1,Y1,Z1' (two corners in mm, camera frame, z > 0)"
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(name, expected, text) from None
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise InputError(name, expected, text)
    lower = tuple(min(a, b) / 1e3 for a, b in zip(values[:3], values[3:], strict=True))
    upper = tuple(max(a, b) / 1e3 for a, b in zip(values[:3], values[3:], strict=True))
    try:
        return MeasuringVolume(lower, upper, "given")  # type: ignore[arg-type]
    except InputError as error:
        raise InputError(name, error.expected, text) from None
