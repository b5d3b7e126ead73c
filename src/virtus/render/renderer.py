"""``render``: one pose of a rig in a scene -> every frame of a pattern sequence + ground truth."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from virtus.capture.groundtruth import GroundTruth
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.optics import ThinLens
from virtus.geometry.transforms import Pose
from virtus.render.backend import mitsuba, on_gpu
from virtus.render.jit.synthesis import synthesize_on_device
from virtus.render.jit.tracing import (
    DeviceFrames,
    DeviceTrace,
    percentile_of_positive,
    trace_device,
)
from virtus.render.synthesis import synthesize
from virtus.render.tracing import trace
from virtus.scene.model import Scene
from virtus.sensor.camera import NO_LIGHT, Sensor, as_seed
from virtus.sensor.projector import ProjectorModel, as_lookup

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
    lookup : projector pixel model, ``"nearest"``, ``"bilinear"`` or ``"psf"``.
    projector : the full projector model.
    variant : Mitsuba variant that traced it.
    bounces : path vertices per camera sample (1 = direct light only).
    aperture_samples : projector aperture samples per path vertex (1 = pinhole projector).
    projector_lens, camera_lens : thin lenses (defocus, depth of field), or None (pinholes).
    """

    frames: np.ndarray
    gt: GroundTruth
    exposure: float
    sensor: Sensor
    seed: int
    spp: int
    lookup: str
    variant: str
    projector: ProjectorModel | None = None
    bounces: int = 1
    aperture_samples: int = 1
    projector_lens: ThinLens | None = None
    camera_lens: ThinLens | None = None

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
            "projector": None if self.projector is None else self.projector.to_dict(),
            "mitsuba_variant": self.variant,
            "bounces": self.bounces,
            "aperture_samples": self.aperture_samples,
            "projector_lens": None
            if self.projector_lens is None
            else self.projector_lens.to_dict(),
            "camera_lens": None if self.camera_lens is None else self.camera_lens.to_dict(),
        }

    @classmethod
    def settings_of(cls, device: DeviceRendering, frames: Any, gt: Any) -> Rendering:
        """A rendering with ``device``'s settings and the given frames and ground truth."""
        return cls(
            frames=frames,
            gt=gt,
            exposure=device.exposure,
            sensor=device.sensor,
            seed=device.seed,
            spp=device.trace.spp,
            lookup=device.projector.pixel.value,
            variant=device.trace.variant,
            projector=device.projector,
            bounces=device.trace.bounces,
            aperture_samples=device.trace.aperture_samples,
            projector_lens=device.projector_lens,
            camera_lens=device.camera_lens,
        )


@dataclass(frozen=True, eq=False)
class DeviceRendering:
    """The frames of one pose kept on the device that traced them (:func:`render_device`).

    Attributes
    ----------
    frames : the digital frames (:class:`~virtus.render.jit.tracing.DeviceFrames`).
    trace : the pass's taps (its ground truth is computed on demand).
    exposure, sensor, seed, projector, projector_lens, camera_lens : as :class:`Rendering`.
    """

    frames: DeviceFrames
    trace: DeviceTrace
    exposure: float
    sensor: Sensor
    seed: int
    projector: ProjectorModel
    projector_lens: ThinLens | None = None
    camera_lens: ThinLens | None = None

    def to_rendering(self) -> Rendering:
        """The host :class:`Rendering`: frames in one transfer, ground truth computed."""
        gt = self.trace.ground_truth()
        saturated = self.frames.saturated_mask()
        gt = dataclasses.replace(gt, mask_saturated=saturated)
        return Rendering.settings_of(self, self.frames.numpy(), gt)

    def metadata(self) -> dict[str, Any]:
        """:meth:`Rendering.metadata` of this rendering (nothing is copied to the host)."""
        return Rendering.settings_of(self, None, None).metadata()


def render_device(
    rig: Rig,
    scene: Scene,
    sequence: Any,
    *,
    projector: ProjectorModel,
    sensor: Sensor,
    seed: int = 0,
    **options: Any,
) -> DeviceRendering:
    """:func:`render` without leaving the device: trace, synthesis and the sensor run where
    Mitsuba runs (a GPU with ``cuda_ad_rgb``; the CPU with ``llvm_ad_rgb``, the twin the
    tests check). Nothing per pixel reaches the host: the auto exposure's percentile is found
    on the device (two 256 KiB histograms are copied).

    Parameters
    ----------
    rig, scene, sequence, projector, sensor : as :func:`render` (objects, not names).
    seed : seed of the sensor's noise streams.
    options : ``spp``, ``cam2world``, ``variant``, ``bounces``, ``projector_lens``,
        ``camera_lens``, ``aperture_samples`` of :func:`virtus.render.tracing.trace`.
    """
    traced = trace_device(rig, scene, **options)
    if sensor.vignetting != "none":
        mi, _, _ = mitsuba(traced.variant)
        traced = traced.scaled(mi.Float(sensor.vignetting_gain(rig.camera.intrinsics)))
    exposure = sensor.exposure
    if exposure == "auto":
        level = percentile_of_positive(traced.white(), sensor.auto_percentile)
        if level is None:
            raise VirtusError(NO_LIGHT)
        exposure = sensor.exposure_for_level(level)
    frames = synthesize_on_device(
        traced, sequence, projector, sensor, float(exposure), seed, rig.projector.intrinsics
    )
    return DeviceRendering(
        frames=frames, trace=traced, exposure=float(exposure), sensor=sensor, seed=seed,
        projector=projector, projector_lens=options.get("projector_lens"),
        camera_lens=options.get("camera_lens"),
    )  # fmt: skip


def render(
    rig: Rig,
    scene: Scene,
    sequence: Any,
    *,
    spp: int = 4,
    lookup: str | None = None,
    projector: ProjectorModel | None = None,
    exposure: float | Literal["auto"] = "auto",
    bit_depth: int = 8,
    variant: str | None = None,
    rng: np.random.Generator | int | None = None,
    cam2world: Pose | None = None,
    sensor: Sensor | None = None,
    synthesis: Literal["auto", "sparse", "jit"] = "auto",
    threads: int | None = None,
    block_pixels: int | None = None,
    bounces: int = 1,
    projector_lens: ThinLens | None = None,
    camera_lens: ThinLens | None = None,
    aperture_samples: int | None = None,
) -> Rendering:
    """Render every frame of ``sequence`` for one pose from a single ray-tracing pass.

    Parameters
    ----------
    rig : camera, projector and ``proj2cam`` (virtus.geometry.devices).
    scene : the scene (virtus.scene.model); world frame = camera frame unless ``cam2world``.
    sequence : pattern sequence (virtus.patterns) with ``frames`` and ``profile(i)``.
    spp : supersamples per pixel, a perfect square (stratified grid centred on the pixel).
    lookup : projector pixel model of an otherwise ideal projector: ``"nearest"`` (DMD pixels,
        the default) or ``"bilinear"``; shorthand for ``projector=ProjectorModel(pixel=...)``.
    projector : the projector model (:class:`virtus.sensor.projector.ProjectorModel`: response,
        black level, pixel PSF, fall-off); give it or ``lookup``, not both.
    exposure : ``"auto"`` (white frame's 99th percentile at 90 % of full scale) or digital
        numbers per unit radiance (see :mod:`virtus.sensor.camera`).
    bit_depth : 8, 10, 12 or 16.
    variant : Mitsuba variant; default ``$VIRTUS_MITSUBA_VARIANT`` or automatic.
    rng : seed of the sensor's counter-based noise streams (see
    :func:`virtus.sensor.camera.as_seed`).
    cam2world : camera pose in the scene's world frame (default identity).
    sensor : a full :class:`~virtus.sensor.camera.Sensor` (overrides ``exposure`` and
    ``bit_depth``).
    synthesis : where frames are synthesised: ``"sparse"`` (scipy sparse products on the
        host, fastest on CPUs), ``"jit"`` (the device-resident path of :func:`render_device`,
        then one copy to the host; fastest on GPUs), ``"auto"`` (``"jit"`` for CUDA variants,
        else ``"sparse"``). Same frames but for 1 DN where a value sits on a rounding edge.
    threads, block_pixels : host synthesis threads and block size (the frames do not depend
        on them; defaults: every CPU, 16384 pixels).
    bounces, projector_lens, camera_lens, aperture_samples : light transport and lenses, as
        :func:`virtus.render.tracing.trace` (interreflections, projector defocus, camera depth
        of field); the defaults are direct light through pinholes.

    Returns
    -------
    :class:`Rendering` with frames (F, H, W) and ground truth.
    """
    sensor = sensor or Sensor(bit_depth=bit_depth, exposure=exposure)
    if projector is None:
        projector = ProjectorModel(pixel=as_lookup(lookup or "nearest"))
    elif lookup is not None and as_lookup(lookup) != projector.pixel:
        raise InputError("lookup", f"the projector's pixel model {projector.pixel.value!r}", lookup)
    lookup = projector.pixel.value
    intrinsics = rig.projector.intrinsics
    if synthesis not in SYNTHESIS:
        raise InputError("synthesis", f"one of {SYNTHESIS}", synthesis)
    seed = as_seed(rng)
    options = {
        "spp": spp, "cam2world": cam2world, "variant": variant, "bounces": bounces,
        "projector_lens": projector_lens, "camera_lens": camera_lens,
        "aperture_samples": aperture_samples,
    }  # fmt: skip
    on_device = synthesis == "jit" or (synthesis == "auto" and on_gpu(variant))
    if on_device:
        device = render_device(
            rig, scene, sequence, projector=projector, sensor=sensor, seed=seed, **options
        )
        return device.to_rendering()
    traced = trace(rig, scene, **options)
    if sensor.vignetting != "none":
        # The camera lens's fall-off scales everything a pixel receives (auto exposure
        # then sees the vignetted white frame, as a real camera's does).
        gain = sensor.vignetting_gain(rig.camera.intrinsics)
        traced = dataclasses.replace(
            traced, weight=traced.weight * gain[:, None], ambient=traced.ambient * gain
        )
    exposure_value = sensor.exposure_for(traced.white)
    # The sensor is pointwise, so it runs on each synthesised block (no float stack).
    block = {} if block_pixels is None else {"block_pixels": block_pixels}
    frames = synthesize(
        traced,
        sequence,
        projector,
        projector_intrinsics=intrinsics,
        transform=lambda values, frames, pixels: sensor.digitize(
            values, exposure_value, seed=seed, frames=frames, pixels=pixels
        ),
        dtype=sensor.dtype,
        threads=threads,
        **block,
    )
    saturated = (frames >= sensor.saturation_dn).any(axis=0)
    return Rendering(
        frames=frames,
        gt=dataclasses.replace(traced.gt, mask_saturated=saturated),
        exposure=exposure_value,
        sensor=sensor,
        seed=seed,
        spp=traced.spp,
        lookup=lookup,
        variant=traced.variant,
        projector=projector,
        bounces=traced.bounces,
        aperture_samples=traced.aperture_samples,
        projector_lens=projector_lens,
        camera_lens=camera_lens,
    )
