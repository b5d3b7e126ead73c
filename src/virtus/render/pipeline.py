"""``render``: one pose of a rig in a scene -> every frame of a pattern sequence + ground truth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from virtus.checks import as_rng
from virtus.devices import Rig
from virtus.errors import InputError
from virtus.render.groundtruth import GroundTruth
from virtus.render.sensor import Sensor
from virtus.render.synthesis import synthesize
from virtus.render.synthesis_jit import synthesize_digital
from virtus.render.tracing import trace
from virtus.scene import Scene
from virtus.transforms import Pose


@dataclass(frozen=True, eq=False)
class Rendering:
    """The capture of one pose.

    Attributes
    ----------
    frames : (F, H, W) uint8 or uint16 camera frames, in sequence order.
    gt : ground truth of the same pass (camera frame, metres, projector pixels).
    exposure : digital numbers per unit radiance that was used.
    bit_depth : 8 or 16.
    spp : supersamples per pixel.
    lookup : pattern lookup, ``"nearest"`` or ``"bilinear"``.
    variant : Mitsuba variant that traced it.
    """

    frames: np.ndarray
    gt: GroundTruth
    exposure: float
    bit_depth: int
    spp: int
    lookup: str
    variant: str

    def metadata(self) -> dict[str, Any]:
        """JSON-ready description of how the frames were made."""
        return {
            "exposure_dn_per_radiance": self.exposure,
            "bit_depth": self.bit_depth,
            "spp": self.spp,
            "lookup": self.lookup,
            "mitsuba_variant": self.variant,
        }


def render(
    rig: Rig,
    scene: Scene,
    sequence: Any,
    *,
    spp: int = 4,
    lookup: Literal["nearest", "bilinear"] = "nearest",
    exposure: float | Literal["auto"] = "auto",
    bit_depth: int = 8,
    variant: str | None = None,
    rng: np.random.Generator | int | None = None,
    cam2world: Pose | None = None,
    sensor: Sensor | None = None,
    synthesis: Literal["auto", "sparse", "jit"] = "auto",
) -> Rendering:
    """Render every frame of ``sequence`` for one pose from a single ray-tracing pass.

    Parameters
    ----------
    rig : camera, projector and ``proj2cam`` (virtus.devices).
    scene : the scene (virtus.scene); world frame = camera frame unless ``cam2world``.
    sequence : pattern sequence (virtus.patterns) with ``frames`` and ``profile(i)``.
    spp : supersamples per pixel, a perfect square (stratified grid centred on the pixel).
    lookup : ``"nearest"`` (DMD pixels) or ``"bilinear"`` pattern lookup.
    exposure : ``"auto"`` (white frame's 99th percentile at 90 % of full scale) or digital
        numbers per unit radiance (see :mod:`virtus.render.sensor`).
    bit_depth : 8 or 16.
    variant : Mitsuba variant; default ``$VIRTUS_MITSUBA_VARIANT`` or automatic.
    rng : randomness for the sensor stage (noise-free today; kept for determinism).
    cam2world : camera pose in the scene's world frame (default identity).
    sensor : a full :class:`Sensor` (overrides ``exposure`` and ``bit_depth``).
    synthesis : where frames are synthesised: ``"sparse"`` (scipy sparse products on the
        host, fastest on CPUs), ``"jit"`` (Dr.Jit gathers where Mitsuba runs, fastest on
        GPUs), ``"auto"`` (``"jit"`` for CUDA variants, else ``"sparse"``). Same frames.

    Returns
    -------
    :class:`Rendering` with frames (F, H, W) and ground truth.
    """
    sensor = sensor or Sensor(bit_depth=bit_depth, exposure=exposure)
    if synthesis not in ("auto", "sparse", "jit"):
        raise InputError("synthesis", '"auto", "sparse" or "jit"', synthesis)
    generator = as_rng(rng)
    traced = trace(rig, scene, spp=spp, cam2world=cam2world, variant=variant)
    exposure_value = sensor.exposure_for(traced.white)
    if synthesis == "jit" or (synthesis == "auto" and traced.variant.startswith("cuda")):
        frames = synthesize_digital(traced, sequence, lookup, sensor, exposure_value)
    else:
        # The sensor is pointwise, so it runs on each synthesised block (no float stack).
        frames = synthesize(
            traced,
            sequence,
            lookup,
            transform=lambda block, frames, pixels: sensor.digitize(
                block, exposure_value, generator
            ),
            dtype=sensor.dtype,
        )
    return Rendering(
        frames=frames,
        gt=traced.gt,
        exposure=exposure_value,
        bit_depth=sensor.bit_depth,
        spp=traced.spp,
        lookup=lookup,
        variant=traced.variant,
    )
