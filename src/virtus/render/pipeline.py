"""``render``: one pose of a rig in a scene -> every frame of a pattern sequence + ground truth."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from virtus.devices import Rig
from virtus.errors import InputError
from virtus.groundtruth import GroundTruth
from virtus.render.synthesis import synthesize
from virtus.render.synthesis_jit import synthesize_digital
from virtus.render.tracing import trace
from virtus.scene import Scene
from virtus.sensor import Sensor, as_lookup, as_seed
from virtus.transforms import Pose

#: Where frames are synthesised (see :func:`render`).
SYNTHESIS = ("auto", "sparse", "jit")


@dataclass(frozen=True, eq=False)
class Rendering:
    """The frames and ground truth of one pose, with how they were made.

    Attributes
    ----------
    frames : (F, H, W) uint8 or uint16 camera frames, in sequence order.
    gt : ground truth of the same pass (camera frame, metres, projector pixels).
    exposure : digital numbers per unit radiance that was used.
    sensor : the camera sensor model.
    seed : seed of the sensor's counter-based noise streams.
    spp : supersamples per pixel.
    lookup : projector pixel model, ``"nearest"`` or ``"bilinear"``.
    variant : Mitsuba variant that traced it.
    """

    frames: np.ndarray
    gt: GroundTruth
    exposure: float
    sensor: Sensor
    seed: int
    spp: int
    lookup: str
    variant: str

    @property
    def bit_depth(self) -> int:
        """Bits of the frames' digital numbers."""
        return self.sensor.bit_depth

    def metadata(self) -> dict[str, Any]:
        """JSON-ready description of how the frames were rendered."""
        return {
            "exposure_dn_per_radiance": self.exposure,
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
    lookup: str = "nearest",
    exposure: float | Literal["auto"] = "auto",
    bit_depth: int = 8,
    variant: str | None = None,
    rng: np.random.Generator | int | None = None,
    cam2world: Pose | None = None,
    sensor: Sensor | None = None,
    synthesis: Literal["auto", "sparse", "jit"] = "auto",
    threads: int | None = None,
    block_pixels: int | None = None,
) -> Rendering:
    """Render every frame of ``sequence`` for one pose from a single ray-tracing pass.

    Parameters
    ----------
    rig : camera, projector and ``proj2cam`` (virtus.devices).
    scene : the scene (virtus.scene); world frame = camera frame unless ``cam2world``.
    sequence : pattern sequence (virtus.patterns) with ``frames`` and ``profile(i)``.
    spp : supersamples per pixel, a perfect square (stratified grid centred on the pixel).
    lookup : projector pixel model, ``"nearest"`` (DMD pixels) or ``"bilinear"``.
    exposure : ``"auto"`` (white frame's 99th percentile at 90 % of full scale) or digital
        numbers per unit radiance (see :mod:`virtus.sensor`).
    bit_depth : 8, 10, 12 or 16.
    variant : Mitsuba variant; default ``$VIRTUS_MITSUBA_VARIANT`` or automatic.
    rng : seed of the sensor's counter-based noise streams (see :func:`virtus.sensor.as_seed`).
    cam2world : camera pose in the scene's world frame (default identity).
    sensor : a full :class:`~virtus.sensor.Sensor` (overrides ``exposure`` and ``bit_depth``).
    synthesis : where frames are synthesised: ``"sparse"`` (scipy sparse products on the
        host, fastest on CPUs), ``"jit"`` (Dr.Jit gathers where Mitsuba runs, fastest on
        GPUs), ``"auto"`` (``"jit"`` for CUDA variants, else ``"sparse"``). Same frames.
    threads, block_pixels : host synthesis threads and block size (the frames do not depend
        on them; defaults: every CPU, 16384 pixels).

    Returns
    -------
    :class:`Rendering` with frames (F, H, W) and ground truth.
    """
    sensor = sensor or Sensor(bit_depth=bit_depth, exposure=exposure)
    lookup = as_lookup(lookup).value
    if synthesis not in SYNTHESIS:
        raise InputError("synthesis", f"one of {SYNTHESIS}", synthesis)
    seed = as_seed(rng)
    traced = trace(rig, scene, spp=spp, cam2world=cam2world, variant=variant)
    exposure_value = sensor.exposure_for(traced.white)
    if synthesis == "jit" or (synthesis == "auto" and traced.variant.startswith("cuda")):
        frames = synthesize_digital(traced, sequence, lookup, sensor, exposure_value, seed)
    else:
        # The sensor is pointwise, so it runs on each synthesised block (no float stack).
        options = {} if block_pixels is None else {"block_pixels": block_pixels}
        frames = synthesize(
            traced,
            sequence,
            lookup,
            transform=lambda block, frames, pixels: sensor.digitize(
                block, exposure_value, seed=seed, frames=frames, pixels=pixels
            ),
            dtype=sensor.dtype,
            threads=threads,
            **options,
        )
    return Rendering(
        frames=frames,
        gt=traced.gt,
        exposure=exposure_value,
        sensor=sensor,
        seed=seed,
        spp=traced.spp,
        lookup=lookup,
        variant=traced.variant,
    )
