"""The keys a design sweep varies, and the scanner and target each variant builds.

``--vary KEY=V1,V2,...`` (several ``--vary`` make the Cartesian product of their values):

=====================  ===========================================================  ========
key                    meaning                                                      values
=====================  ===========================================================  ========
``baseline_mm``        projector centre's distance from the camera's, along the     > 0
                       base rig's direction (the paper's: 125 mm left, 100 mm down)
``toe_in_deg``         angle between the optical axes: the projector aims at the    [0, 60)
                       camera axis point ``|t| / tan(toe_in)`` (0 = parallel axes);
                       default: it aims at the working distance, as the paper's rig
``working_distance_m`` distance of the target (a matte plane facing the camera)     (0, 20]
``period_px``          finest fringe period, projector px                           [3, 1024]
``steps``              phase steps N                                                3..64
``coding``             ``gray`` (Gray code + complement) or ``heterodyne`` (three
                       periods, ratios 64:63:56 as the built-in heterodyne set)
``sensor``             a sensor preset (:data:`virtus.sensor.camera.SENSOR_PRESETS`)
``exposure``           fraction of full scale the white frame's 99th percentile     (0, 1]
                       reaches (auto exposure's target)
``bit_depth``          ADC bits                                                     8, 10, 12, 16
``projector``          a projector preset (:data:`virtus.sensor.projector.PROJECTOR_PRESETS`)
``blur_px``            projector lens blur, Gaussian sigma in projector px (the     [0, 100]
                       ``psf`` pixel model)
=====================  ===========================================================  ========

A variant whose projector lights less than :data:`MIN_OVERLAP` of the camera's field on the
target (checked analytically before anything is rendered) is an impossible rig and is
refused, naming the variant.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.devices import Camera, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.patterns import PatternSequence, build_sequence, gray_bits_needed
from virtus.scanner import Scanner
from virtus.sensor.camera import BIT_DEPTHS, SENSOR_PRESETS
from virtus.sensor.projector import PROJECTOR_PRESETS, Lookup

__all__ = [
    "CODINGS",
    "DEFAULT_WORKING_DISTANCE_M",
    "KEYS",
    "MAX_VALUES",
    "MAX_VARIANTS",
    "MIN_OVERLAP",
    "Variant",
    "coarse_camera",
    "overlap_fraction",
    "parse_vary",
    "variants",
    "with_coarse_camera",
]

#: Phase-unwrapping codings a sweep can choose.
CODINGS = ("gray", "heterodyne")
#: Period ratios of the heterodyne coding (finest first; the built-in set's 64:63:56).
_HETERODYNE_RATIOS = (1.0, 64.0 / 63.0, 64.0 / 56.0)
#: Target distance when ``working_distance_m`` is not varied, metres (the paper's).
DEFAULT_WORKING_DISTANCE_M = 1.0
#: Smallest share of the camera's field the projector must light on the target.
MIN_OVERLAP = 0.05
#: Most values of one key, and most variants of one sweep.
MAX_VALUES = 64
MAX_VARIANTS = 1024


def _number(low: float, high: float, *, open_low: bool = False, integer: bool = False):  # noqa: ANN202
    def parse(key: str, text: str) -> float | int:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            value = None
        interval = f"{'(' if open_low else '['}{low:g}, {high:g}]"
        what = f"{'an integer' if integer else 'a number'} in {interval}"
        if (
            value is None
            or not math.isfinite(value)
            or not low <= value <= high
            or (open_low and value == low)
        ):
            raise InputError(f"--vary {key}", what, text)
        return value

    return parse


def _choice(names: tuple[str, ...] | list[str]):  # noqa: ANN202
    def parse(key: str, text: str) -> str | int:
        if text not in [str(n) for n in names]:
            raise InputError(f"--vary {key}", f"one of {', '.join(map(str, names))}", text)
        return text

    return parse


#: Key -> parser of one value (text -> value), in the order of the module docstring.
KEYS: dict[str, Any] = {
    "baseline_mm": _number(0.0, 5000.0, open_low=True),
    "toe_in_deg": _number(0.0, 59.999),
    "working_distance_m": _number(0.0, 20.0, open_low=True),
    "period_px": _number(3.0, 1024.0),
    "steps": _number(3, 64, integer=True),
    "coding": _choice(CODINGS),
    "sensor": _choice(list(SENSOR_PRESETS)),
    "exposure": _number(0.0, 1.0, open_low=True),
    "bit_depth": _number(min(BIT_DEPTHS), max(BIT_DEPTHS), integer=True),
    "projector": _choice(list(PROJECTOR_PRESETS)),
    "blur_px": _number(0.0, 100.0),
}


def parse_vary(items: list[str]) -> dict[str, list[Any]]:
    """``["KEY=V1,V2", ...]`` -> ``{key: [values]}`` (checked: known keys, each once, valid
    values, at most :data:`MAX_VALUES` distinct values a key, :data:`MAX_VARIANTS` in all)."""
    if not items:
        raise InputError("--vary", "at least one KEY=VALUES", "none")
    out: dict[str, list[Any]] = {}
    for item in items:
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not text.strip():
            raise InputError("--vary", "KEY=V1,V2,...", item)
        if key not in KEYS:
            raise InputError("--vary key", f"one of {', '.join(KEYS)}", key)
        if key in out:
            raise InputError("--vary key", "each key once", key)
        parts = [p.strip() for p in text.split(",")]
        if len(parts) > MAX_VALUES:
            raise InputError(f"--vary {key}", f"at most {MAX_VALUES} values", len(parts))
        values = list(dict.fromkeys(KEYS[key](key, p) for p in parts))
        if key == "bit_depth" and any(v not in BIT_DEPTHS for v in values):
            raise InputError("--vary bit_depth", f"values among {BIT_DEPTHS}", text)
        out[key] = values
    count = math.prod(len(v) for v in out.values())
    if count > MAX_VARIANTS:
        raise InputError("--vary", f"at most {MAX_VARIANTS} variants in all", count)
    return out


@dataclass(frozen=True)
class Variant:
    """One combination of the varied keys' values (``values``: key -> value, in ``--vary``
    order); :meth:`build` makes its scanner and target distance from a base scanner."""

    index: int
    values: tuple[tuple[str, Any], ...]

    @property
    def name(self) -> str:
        """``key=value,key=value`` (for messages and the table)."""
        return ",".join(f"{k}={v}" for k, v in self.values)

    @property
    def file(self) -> str:
        """The variant's result file, relative to the run's directory."""
        return f"variants/{self.index:04d}.json"

    def build(self, base: Scanner) -> tuple[Scanner, float]:
        """The scanner of this variant (``base`` with the varied keys applied) and the
        target's distance (metres); :class:`InputError` naming the variant when its values
        make no valid scanner."""
        values = dict(self.values)
        try:
            return _build(base, values)
        except InputError as error:
            raise InputError(f"variant {self.name}: {error.name}", error.expected,
                             error.got) from None  # fmt: skip


def variants(vary: dict[str, list[Any]]) -> list[Variant]:
    """The Cartesian product of the varied values, in ``vary`` order (last key fastest)."""
    keys = list(vary)
    combos = itertools.product(*(vary[k] for k in keys))
    return [Variant(i, tuple(zip(keys, combo, strict=True))) for i, combo in enumerate(combos)]


def _build(base: Scanner, values: dict[str, Any]) -> tuple[Scanner, float]:
    distance = float(values.get("working_distance_m", DEFAULT_WORKING_DISTANCE_M))
    scanner = base
    if {"baseline_mm", "toe_in_deg", "working_distance_m"} & set(values):
        scanner = scanner.with_(rig=_rig(base.rig, values, distance))
    if {"period_px", "steps", "coding"} & set(values):
        scanner = scanner.with_(sequence=_sequence(base, values))
    sensor = scanner.sensor
    if "sensor" in values:
        sensor = SENSOR_PRESETS[values["sensor"]]
    if "bit_depth" in values:
        sensor = sensor.with_(bit_depth=int(values["bit_depth"]))
    if "exposure" in values:
        sensor = sensor.with_(exposure="auto", auto_target=float(values["exposure"]))
    projector = scanner.projector
    if "projector" in values:
        projector = PROJECTOR_PRESETS[values["projector"]]
    if "blur_px" in values:
        projector = projector.with_(pixel=Lookup.psf, psf_sigma_px=float(values["blur_px"]))
    return scanner.with_(sensor=sensor, projector=projector), distance


def _rig(base: Rig, values: dict[str, Any], distance: float) -> Rig:
    t = np.asarray(base.proj2cam.t, dtype=np.float64)
    direction = t / np.linalg.norm(t)
    baseline = values.get("baseline_mm")
    centre = direction * (float(baseline) * 1e-3 if baseline is not None else np.linalg.norm(t))
    if "toe_in_deg" in values:
        toe = math.radians(float(values["toe_in_deg"]))
        lateral = float(np.hypot(centre[0], centre[1]))
        target = (
            centre + (0.0, 0.0, 1.0)
            if toe == 0
            else np.array((0.0, 0.0, centre[2] + lateral / math.tan(toe)))
        )
    else:
        target = np.array((0.0, 0.0, distance))
    proj2cam = Pose.look_at(centre, target, image_down=(0.0, 1.0, 0.0))
    return Rig(base.camera, base.projector, proj2cam)


def _sequence(base: Scanner, values: dict[str, Any]) -> PatternSequence:
    old = base.sequence
    directions = old.directions
    period = float(values.get("period_px", min(old.periods(directions[0]))))
    steps = int(values.get("steps", _base_steps(old, directions[0])))
    if values.get("coding", "gray") == "heterodyne":
        periods = [period * r for r in _HETERODYNE_RATIOS]
        return build_sequence(old.width, old.height, periods=periods, steps=steps,
                              directions=directions)  # fmt: skip
    span = max(old.width, old.height)
    bits = gray_bits_needed(span, period)
    return build_sequence(old.width, old.height, periods=period, steps=steps, gray_bits=bits,
                          directions=directions)  # fmt: skip


def _base_steps(sequence: PatternSequence, direction: str) -> int:
    plan = sequence.plan(direction)
    return plan.sets[0].coding.steps if plan is not None and plan.sets else 18


def coarse_camera(intrinsics: Intrinsics, grid: int) -> Intrinsics:
    """The camera's lens on a sensor of about ``grid`` pixels along its longer side (same
    field of view; pixel edges kept): where a sweep samples its prediction."""
    factor = min(1.0, grid / max(intrinsics.width, intrinsics.height))
    width = max(1, round(intrinsics.width * factor))
    height = max(1, round(intrinsics.height * factor))
    sx, sy = width / intrinsics.width, height / intrinsics.height
    return Intrinsics(
        intrinsics.fx * sx, intrinsics.fy * sy, (intrinsics.cx + 0.5) * sx - 0.5,
        (intrinsics.cy + 0.5) * sy - 0.5, width, height, intrinsics.dist,
    )  # fmt: skip


def with_coarse_camera(scanner: Scanner, grid: int) -> Scanner:
    """``scanner`` with its camera on :func:`coarse_camera` and one sample per pixel (the
    pixel centre: a coarse pixel's footprint would average the fringes, a fine one's does
    not)."""
    rig = scanner.rig
    camera = Camera(coarse_camera(rig.camera.intrinsics, grid))
    return scanner.with_(
        rig=Rig(camera, rig.projector, rig.proj2cam), render=scanner.render.with_(spp=1)
    )


def overlap_fraction(rig: Rig, distance: float, grid: int = 33) -> float:
    """Share of a ``grid x grid`` sample of the camera's field whose point on the plane
    ``z = distance`` (camera frame) lies in front of the projector and inside its image."""
    camera = rig.camera.intrinsics
    u = np.linspace(0, camera.width - 1, grid)
    v = np.linspace(0, camera.height - 1, grid)
    pixels = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    rays = camera.unproject(pixels)
    with np.errstate(invalid="ignore", divide="ignore"):
        points = rays * (distance / rays[:, 2:3])
        local = rig.cam2proj.apply(points)
        ahead = local[:, 2] > 0
        projected = rig.projector.intrinsics.project(np.where(ahead[:, None], local, 1.0))
    projector = rig.projector.intrinsics
    inside = (
        ahead
        & (projected[:, 0] >= -0.5) & (projected[:, 0] < projector.width - 0.5)
        & (projected[:, 1] >= -0.5) & (projected[:, 1] < projector.height - 0.5)
    )  # fmt: skip
    return float(np.mean(inside))
