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
from virtus.render.settings import RenderSettings
from virtus.render.synthesis import synthesize
from virtus.render.tracing import trace
from virtus.scene.model import Scene
from virtus.sensor.camera import NO_LIGHT, Sensor
from virtus.sensor.noise import as_seed
from virtus.sensor.projector import ProjectorModel

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


def _trace_options(settings: RenderSettings, cam2world: Pose | None) -> dict[str, Any]:
    """The keywords of :func:`virtus.render.tracing.trace` (and ``trace_device``) for one
    pose rendered with ``settings``."""
    return {
        "spp": settings.spp, "cam2world": cam2world, "variant": settings.variant,
        "bounces": settings.bounces, "projector_lens": settings.projector_lens,
        "camera_lens": settings.camera_lens, "aperture_samples": settings.aperture_samples,
    }  # fmt: skip


def render_device(
    rig: Rig,
    scene: Scene,
    sequence: Any,
    settings: RenderSettings | None = None,
    *,
    projector: ProjectorModel,
    sensor: Sensor,
    seed: int = 0,
    cam2world: Pose | None = None,
) -> DeviceRendering:
    """:func:`render` without leaving the device: trace, synthesis and the sensor run where
    Mitsuba runs (a GPU with ``cuda_ad_rgb``; the CPU with ``llvm_ad_rgb``, the twin the
    tests check). Nothing per pixel reaches the host: the auto exposure's percentile is found
    on the device (two 256 KiB histograms are copied).

    Parameters
    ----------
    rig, scene, sequence, settings, projector, sensor, cam2world : as :func:`render`
        (objects, not names).
    seed : seed of the sensor's noise streams.
    """
    settings = RenderSettings() if settings is None else settings
    options = _trace_options(settings, cam2world)
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
        projector=projector, projector_lens=settings.projector_lens,
        camera_lens=settings.camera_lens,
    )  # fmt: skip


def render(
    rig: Rig,
    scene: Scene,
    sequence: Any,
    settings: RenderSettings | None = None,
    *,
    projector: ProjectorModel | None = None,
    sensor: Sensor | None = None,
    rng: np.random.Generator | int | None = None,
    cam2world: Pose | None = None,
    synthesis: Literal["auto", "sparse", "jit"] = "auto",
    threads: int | None = None,
    block_pixels: int | None = None,
) -> Rendering:
    """Render every frame of ``sequence`` for one pose from a single ray-tracing pass.

    Parameters
    ----------
    rig : camera, projector and ``proj2cam`` (virtus.geometry.devices).
    scene : the scene (virtus.scene.model); world frame = camera frame unless ``cam2world``.
    sequence : pattern sequence (virtus.patterns) with ``frames`` and ``profile(i)``.
    settings : the render settings (:class:`~virtus.render.settings.RenderSettings`: spp,
        Mitsuba variant, bounces, lenses, aperture samples; default ``RenderSettings()``:
        4 spp, automatic variant, direct light through pinholes).
    projector : the projector model (:class:`virtus.sensor.projector.ProjectorModel`: response,
        black level, pixel model and PSF, fall-off); default: ideal sharp DMD pixels.
    sensor : the camera model (:class:`~virtus.sensor.camera.Sensor`: bit depth, exposure,
        EMVA 1288); default ``Sensor()``: 8 bits, auto exposure (the white frame's 99th
        percentile at 90 % of full scale), noiseless.
    rng : seed of the sensor's counter-based noise streams (see
        :func:`virtus.sensor.camera.as_seed`).
    cam2world : camera pose in the scene's world frame (default identity).
    synthesis : where frames are synthesised: ``"sparse"`` (scipy sparse products on the
        host, fastest on CPUs), ``"jit"`` (the device-resident path of :func:`render_device`,
        then one copy to the host; fastest on GPUs), ``"auto"`` (``"jit"`` for CUDA variants,
        else ``"sparse"``). Same frames but for 1 DN where a value sits on a rounding edge.
    threads, block_pixels : host synthesis threads and block size (the frames do not depend
        on them; defaults: every CPU, 16384 pixels).

    Returns
    -------
    :class:`Rendering` with frames (F, H, W) and ground truth.
    """
    settings = RenderSettings() if settings is None else settings
    sensor = sensor or Sensor()
    if projector is None:
        projector = ProjectorModel()
    lookup = projector.pixel.value
    intrinsics = rig.projector.intrinsics
    if synthesis not in SYNTHESIS:
        raise InputError("synthesis", f"one of {SYNTHESIS}", synthesis)
    seed = as_seed(rng)
    options = _trace_options(settings, cam2world)
    on_device = synthesis == "jit" or (synthesis == "auto" and on_gpu(settings.variant))
    if on_device:
        device = render_device(
            rig, scene, sequence, settings, projector=projector, sensor=sensor, seed=seed,
            cam2world=cam2world,
        )  # fmt: skip
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
    # The sensor is pointwise, so it runs on each synthesised block (no float stack), and
    # the saturation mask is taken there too, while the block is in cache (blocks of one
    # call cover disjoint pixels; the calls run one after the other).
    block = {} if block_pixels is None else {"block_pixels": block_pixels}
    saturated = np.zeros(traced.height * traced.width, dtype=bool)

    def digitize(values: np.ndarray, frames: np.ndarray, pixels: slice) -> np.ndarray:
        digital = sensor.digitize(values, exposure_value, seed=seed, frames=frames, pixels=pixels)
        saturated[pixels] |= (digital >= sensor.saturation_dn).any(axis=0)
        return digital

    frames = synthesize(
        traced,
        sequence,
        projector,
        projector_intrinsics=intrinsics,
        transform=digitize,
        dtype=sensor.dtype,
        threads=threads,
        **block,
    )
    saturated = saturated.reshape(traced.height, traced.width)
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
        projector_lens=settings.projector_lens,
        camera_lens=settings.camera_lens,
    )
