"""The artefacts of a VDI/VDE 2634-2 acceptance test and where they go in a measuring volume.

Sizes follow the guideline, from the volume's space diagonal ``D``
(:attr:`~virtus.design.volume.MeasuringVolume.diagonal_m`):

* **sphere** (probing errors P_F, P_S): diameter :data:`SPHERE_DIAMETER_FRACTION` ``x D``
  (the guideline asks for 0.1-0.2 D);
* **ball bar** (sphere-spacing error SD): two spheres of the same diameter whose centres are
  :data:`BAR_LENGTH_FRACTION` ``x D`` apart (the guideline: at least 2/3 D); no rod is
  modelled (it is not measured);
* **plane** (flatness F): a rectangle :data:`PLANE_LENGTH_FRACTION` ``x D`` long and as wide as
  the sphere's diameter.

All are matte: ideal Lambertian (:data:`MATTE`), as the guideline's artefacts are meant to be.
Being virtual, they are exactly their nominal size: the "calibrated" diameter and centre
distance are the nominal ones.

Positions (the first ``n`` of each list are used when a run asks for fewer): the sphere at the
volume's centre, then at the 8 corners of the box its centre can reach inside the volume (in
opposite pairs), then at the centre of the near face (10 positions); the ball bar centred in
the volume along the 4 space diagonals of that box, then along a horizontal diagonal at mid
depth, near and far (7 positions); the plane through the volume's centre, face-on along x, y
and both diagonals, then tilted in depth along the volume's xz and yz diagonals (6
positions). Camera frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.design.volume import MeasuringVolume, seen_by_both
from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.scene.model import Material, PlaneObject, Scene, SphereObject

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig

__all__ = [
    "BAR_LENGTH_FRACTION",
    "FEATURES",
    "MATTE",
    "PLANE_LENGTH_FRACTION",
    "SPHERE_DIAMETER_FRACTION",
    "ArtefactPosition",
    "Artefacts",
    "artefact_layout",
]

#: Sphere diameter over the volume's diagonal (VDI/VDE 2634-2: 0.1-0.2).
SPHERE_DIAMETER_FRACTION = 0.15
#: Ball-bar centre distance over the volume's diagonal (VDI/VDE 2634-2: at least 2/3).
BAR_LENGTH_FRACTION = 2.0 / 3.0
#: Plane length over the volume's diagonal.
PLANE_LENGTH_FRACTION = 0.5
#: The artefacts' surface: an ideal Lambertian reflector (Mitsuba ``diffuse``).
MATTE = Material(albedo=0.8, specular=0.0)
#: Features in the order a run measures them, with their number of positions.
FEATURES = {"sphere": 10, "ball_bar": 7, "plane": 6}


@dataclass(frozen=True)
class Artefacts:
    """The artefacts' nominal (= calibrated) sizes, metres."""

    sphere_diameter_m: float
    bar_length_m: float
    plane_size_m: tuple[float, float]

    @classmethod
    def for_volume(cls, volume: MeasuringVolume) -> Artefacts:
        """The sizes the guideline asks for in ``volume`` (module docstring)."""
        d = volume.diagonal_m
        sphere = SPHERE_DIAMETER_FRACTION * d
        return cls(sphere, BAR_LENGTH_FRACTION * d, (PLANE_LENGTH_FRACTION * d, sphere))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready sizes in millimetres."""
        return {
            "sphere_diameter_mm": 1e3 * self.sphere_diameter_m,
            "bar_length_mm": 1e3 * self.bar_length_m,
            "plane_size_mm": [1e3 * v for v in self.plane_size_m],
            "material": MATTE.model_dump(mode="json"),
        }


@dataclass(frozen=True)
class ArtefactPosition:
    """One artefact at one position.

    Attributes
    ----------
    feature : ``"sphere"``, ``"ball_bar"`` or ``"plane"``.
    name : file-name-safe position name, e.g. ``"sphere_01"``.
    centres_m : sphere centres (one for a sphere, two for a bar; none for a plane), camera
        frame, metres.
    radius_m : sphere radius (metres), or None for a plane.
    plane2cam : the plane's pose (local x along its length, z its normal), or None.
    plane_size_m : ``(length, width)`` of the plane, metres, or None.
    """

    feature: str
    name: str
    centres_m: tuple[tuple[float, float, float], ...] = ()
    radius_m: float | None = None
    plane2cam: Pose | None = None
    plane_size_m: tuple[float, float] | None = None

    def scene(self) -> Scene:
        """The artefact alone (no background: every valid pixel belongs to it)."""
        if self.plane2cam is not None:
            plane = PlaneObject(size_m=self.plane_size_m, pose=self.plane2cam, material=MATTE)
            return Scene(objects=(plane,))
        spheres = tuple(
            SphereObject(radius_m=self.radius_m, center_m=c, material=MATTE) for c in self.centres_m
        )
        return Scene(objects=spheres)

    def surface_samples(self) -> np.ndarray:
        """(M, 3) points on the artefact's outline, camera frame, metres (for field checks)."""
        if self.plane2cam is not None:
            length, width = self.plane_size_m  # type: ignore[misc]
            s = np.array([[a, b, 0.0] for a in (-0.5, 0.0, 0.5) for b in (-0.5, 0.0, 0.5)])
            return self.plane2cam.apply(s * [length, width, 0.0])
        axes = np.concatenate([np.eye(3), -np.eye(3)])
        return np.concatenate([np.asarray(c) + self.radius_m * axes for c in self.centres_m])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description in millimetres."""
        data: dict[str, Any] = {"feature": self.feature, "name": self.name}
        if self.plane2cam is not None:
            data["plane2cam"] = {
                "R": self.plane2cam.R.tolist(),
                "t_mm": (1e3 * np.asarray(self.plane2cam.t)).tolist(),
            }
            data["size_mm"] = [1e3 * v for v in self.plane_size_m]  # type: ignore[union-attr]
        else:
            data["centres_mm"] = [[1e3 * v for v in c] for c in self.centres_m]
            data["diameter_mm"] = 2e3 * self.radius_m  # type: ignore[operator]
        return data


def _tuple(point: np.ndarray) -> tuple[float, float, float]:
    return (float(point[0]), float(point[1]), float(point[2]))


def _sphere_positions(volume: MeasuringVolume, radius: float) -> list[ArtefactPosition]:
    lo = np.asarray(volume.lower_m) + radius
    hi = np.asarray(volume.upper_m) - radius
    centre = volume.centre_m
    # Corners in opposite pairs, so that any prefix spans the volume.
    corner_bits = ((0, 0, 0), (1, 1, 1), (1, 0, 0), (0, 1, 1), (0, 1, 0), (1, 0, 1), (1, 1, 0),
                   (0, 0, 1))  # fmt: skip
    points = [centre, *(np.where(bits, hi, lo) for bits in corner_bits)]
    points.append(np.array([centre[0], centre[1], lo[2]]))
    return [
        ArtefactPosition("sphere", f"sphere_{i + 1:02d}", (_tuple(p),), radius)
        for i, p in enumerate(points)
    ]


def _bar_positions(volume: MeasuringVolume, radius: float, length: float) -> list[ArtefactPosition]:
    lo = np.asarray(volume.lower_m) + radius
    hi = np.asarray(volume.upper_m) - radius
    room = hi - lo
    centre = volume.centre_m
    lines = []  # (centre, direction)
    for sx, sy in ((1, 1), (-1, 1), (1, -1), (-1, -1)):  # the 4 space diagonals
        lines.append((centre, np.array([sx * room[0], sy * room[1], room[2]])))
    flat = [(1, 1), (-1, 1), (-1, 1)]
    for (sx, sy), z in zip(flat, (centre[2], lo[2], hi[2]), strict=True):
        lines.append(
            (np.array([centre[0], centre[1], z]), np.array([sx * room[0], sy * room[1], 0]))
        )
    positions = []
    for i, (middle, direction) in enumerate(lines):
        reach = 0.5 * length * direction / np.linalg.norm(direction)
        ends = (middle - reach, middle + reach)
        if not all(((e >= lo - 1e-12) & (e <= hi + 1e-12)).all() for e in ends):
            raise InputError(
                "--volume",
                f"a volume in which a ball bar of {1e3 * length:.1f} mm (2/3 of its diagonal) "
                "fits along its diagonals with spheres inside it (a less flat box)",
                f"{1e3 * room[0]:.1f} x {1e3 * room[1]:.1f} x {1e3 * room[2]:.1f} mm of room",
            )
        name = f"ball_bar_{i + 1:02d}"
        positions.append(ArtefactPosition("ball_bar", name, tuple(map(_tuple, ends)), radius))
    return positions


def _plane_positions(volume: MeasuringVolume, size: tuple[float, float]) -> list[ArtefactPosition]:
    sx, sy, sz = volume.size_m
    z = np.array([0.0, 0.0, 1.0])
    frames = []  # (length axis, width axis): the normal is their cross product
    for angle in (0.0, 90.0, 45.0, -45.0):
        a = np.radians(angle)
        frames.append((np.array([np.cos(a), np.sin(a), 0.0]), np.array([-np.sin(a), np.cos(a), 0])))
    frames.append((np.array([sx, 0.0, sz]) / np.hypot(sx, sz), np.array([0.0, 1.0, 0.0])))
    frames.append((np.array([0.0, sy, sz]) / np.hypot(sy, sz), np.array([-1.0, 0.0, 0.0])))
    positions = []
    for i, (length_axis, width_axis) in enumerate(frames):
        normal = np.cross(length_axis, width_axis)
        rotation = np.stack([length_axis, width_axis, normal], axis=1)
        assert normal @ z > 0  # noqa: S101 - by construction: every plane faces the camera
        pose = Pose(rotation, volume.centre_m)
        positions.append(ArtefactPosition("plane", f"plane_{i + 1:02d}", (), None, pose, size))
    return positions


def artefact_layout(
    volume: MeasuringVolume,
    rig: Rig | None = None,
    positions: int | None = None,
) -> tuple[Artefacts, list[ArtefactPosition]]:
    """The artefacts and their positions in ``volume`` (module docstring).

    Parameters
    ----------
    volume : the measuring volume (camera frame).
    rig : if given, every artefact is checked to lie inside both devices' fields.
    positions : use only the first ``positions`` of each feature (1 to 10); None: all
        (10 spheres, 7 ball bars, 6 planes).

    Returns
    -------
    The sizes and the positions, feature by feature (:data:`FEATURES` order).

    Raises
    ------
    InputError : ``positions`` out of range, a volume too flat for the ball bar, or an
        artefact outside a field (``--volume``).
    """
    most = max(FEATURES.values())
    if positions is not None and (
        isinstance(positions, bool) or not isinstance(positions, int) or not 1 <= positions <= most
    ):
        raise InputError(
            "--positions", f"a whole number of positions per feature, 1-{most}", positions
        )
    sizes = Artefacts.for_volume(volume)
    radius = sizes.sphere_diameter_m / 2
    groups = (
        _sphere_positions(volume, radius),
        _bar_positions(volume, radius, sizes.bar_length_m),
        _plane_positions(volume, sizes.plane_size_m),
    )
    layout = [p for group in groups for p in group[:positions]]
    if rig is not None:
        for position in layout:
            if not seen_by_both(rig, position.surface_samples()):
                raise InputError(
                    "--volume",
                    "a volume whose artefacts both devices see",
                    f"{position.name} leaves a field",
                )
    return sizes, layout
