"""Device-resident passes: taps and frames that stay where Mitsuba traced them.

:func:`trace_device` is :func:`virtus.render.tracing.trace` without the host round trip:
the camera rays are uploaded once per camera and kept on the device, the taps of every
Mitsuba call are written straight into device arrays, and the pixel-centre ground truth is
computed only when asked for (:meth:`DeviceTrace.ground_truth`). The frames synthesised
from it (:func:`virtus.render.jit.synthesis.synthesize_on_device`) are one device array,
copied to the host in one transfer (:meth:`DeviceFrames.numpy`) or handed to PyTorch
without a copy (:meth:`DeviceFrames.torch`, DLPack).

On a CUDA variant this is the GPU path; on ``llvm_ad_rgb`` the same code runs on the CPU,
which is how the test suite checks it against the host path.

Layouts (as :class:`virtus.render.tracing.Trace`): taps are (P, S) row-major flattened to
P * S, column ``s * T + k * aperture_samples + j``; frames are (F, H, W) flattened
frame-major to F * P.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.capture.groundtruth import GroundTruth
from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics, ThinLens
from virtus.geometry.transforms import Pose
from virtus.render.backend import mitsuba, variant_of
from virtus.render.rays import camera_rays
from virtus.render.tracing import (
    Pass,
    Trace,
    _inside,
    prepare_pass,
    project_normalized,
)
from virtus.scene.model import Scene

__all__ = ["DeviceFrames", "DeviceTrace", "DeviceTruth", "flat_array", "to_host", "trace_device"]


@dataclass(frozen=True, eq=False)
class DeviceTruth:
    """The pixel-centre ground truth of one pass as device arrays (P = H * W, row-major
    pixels): what :func:`virtus.render.tracing.centre_truth` computes, left on the device.

    Attributes
    ----------
    points : three Float64 (P,) components, camera frame, metres; NaN where nothing is hit.
    normals : three Float (P,) unit components (float32, Mitsuba's shading normal), camera
        frame, toward the camera; NaN where nothing is hit.
    proj_uv : two Float64 (P,) projector pixel coordinates (distortion applied); NaN where
        nothing is hit or the point is behind the projector.
    hit, shadow, outside : Bool (P,), as :class:`virtus.capture.groundtruth.GroundTruth`'s masks.
    """

    points: tuple[Any, Any, Any]
    normals: tuple[Any, Any, Any]
    proj_uv: tuple[Any, Any]
    hit: Any
    shadow: Any
    outside: Any

    @property
    def valid(self) -> Any:
        """Bool (P,): hit, lit and inside the projector image (``GroundTruth.mask``)."""
        return self.hit & ~self.shadow & ~self.outside

    def to_host(self, height: int, width: int, multibounce: Any) -> GroundTruth:
        """The host :class:`~virtus.capture.groundtruth.GroundTruth` (float64, one transfer per
        array), ``mask_multibounce`` from ``multibounce`` (Bool (P,))."""
        mi, _ = _modules_of(self.hit)
        image = (height, width)
        points = to_host(list(self.points), mi.Float64).reshape(*image, 3)
        masks = to_host([self.hit, self.shadow, self.outside, multibounce], mi.Bool, stacked=True)
        hit, shadow, outside, multi = masks.reshape(4, *image)
        return GroundTruth(
            depth=points[..., 2],
            points=points,
            normals=to_host(list(self.normals), mi.Float64).reshape(*image, 3),
            proj_uv=to_host(list(self.proj_uv), mi.Float64).reshape(*image, 2),
            mask_hit=hit,
            mask_shadow=shadow,
            mask_outside=outside,
            mask_multibounce=multi,
        )


def flat_array(components: list[Any], kind: Any, *, stacked: bool = False) -> Any:
    """Device arrays (P,) each, converted to ``kind`` on the device, as one flat device
    array (not yet evaluated): pixel-major ``(P, k)`` (components interleaved), or with
    ``stacked`` component-major ``(k, P)``."""
    mi, dr = _modules_of(components[0])
    count, pixels = len(components), dr.width(components[0])
    if count == 1:
        return kind(components[0])
    flat = dr.zeros(kind, count * pixels)
    index = dr.arange(mi.UInt32, pixels)
    for k, component in enumerate(components):
        dr.scatter(flat, kind(component), index + k * pixels if stacked else index * count + k)
    return flat


def to_host(components: list[Any], kind: Any, *, stacked: bool = False) -> np.ndarray:
    """:func:`flat_array` as one flat host array, from one transfer."""
    return np.asarray(flat_array(components, kind, stacked=stacked).numpy())


@functools.lru_cache(maxsize=2)
def _device_centre_directions(variant: str, intrinsics: Intrinsics) -> tuple[Any, Any, Any]:
    """The pixel-centre ray directions (camera frame) as three device ``Float64`` arrays,
    uploaded once per camera."""
    mi, dr, _ = mitsuba(variant)
    centre, _ = camera_rays(intrinsics, 1)
    directions = tuple(mi.Float64(centre[i]) for i in range(3))
    dr.eval(*directions)
    return directions  # type: ignore[return-value]


def centre_truth_device(ps: Pass) -> DeviceTruth:
    """:func:`virtus.render.tracing.centre_truth` kept on the device (same rays, same
    projector model, float64)."""
    dr = ps.dr
    c = ps.tracer.centre_device(
        list(_device_centre_directions(ps.variant, ps.camera)), ps.rig.cam2proj
    )
    u, v = project_normalized(ps.projector, c["xn"], c["yn"])
    outside = c["hit"] & ~_inside(u, v, ps.projector)
    dr.eval(u, v, outside)
    return DeviceTruth(
        points=(c["px"], c["py"], c["pz"]),
        normals=(c["nx"], c["ny"], c["nz"]),
        proj_uv=(u, v),
        hit=c["hit"],
        shadow=c["occluded"],
        outside=outside,
    )


@dataclass(frozen=True, eq=False)
class DeviceTrace:
    """The taps of one pass as Dr.Jit arrays on the device that traced them.

    Attributes
    ----------
    height, width, spp, projector_width, projector_height, bounces, aperture_samples,
    variant : as :class:`virtus.render.tracing.Trace`.
    weight, u_p, v_p : Float (P * S,) tap weights and projector coordinates (Trace's
        (P, S) arrays, row-major).
    ambient : Float (P,) ambient radiance, or None where the scene has none.
    truth : gives the pixel-centre ground truth on the host (an uploaded :class:`Trace`'s).
    device_truth : computes it on demand as device arrays (:class:`DeviceTruth`; a traced
        pass's).
    """

    height: int
    width: int
    spp: int
    projector_width: int
    projector_height: int
    weight: Any
    u_p: Any
    v_p: Any
    ambient: Any
    variant: str
    bounces: int = 1
    aperture_samples: int = 1
    truth: Callable[[], GroundTruth] | None = None
    device_truth: Callable[[], DeviceTruth] | None = None

    @property
    def n_pixels(self) -> int:
        return self.height * self.width

    @property
    def taps_per_sample(self) -> int:
        return self.bounces * self.aperture_samples

    @property
    def taps_per_pixel(self) -> int:
        """Taps per pixel, S = spp * bounces * aperture_samples."""
        return self.spp * self.taps_per_sample

    def modules(self) -> tuple[Any, Any]:
        """``(mitsuba, drjit)`` in this pass's variant."""
        mi, dr, _ = mitsuba(self.variant)
        return mi, dr

    def white(self) -> Any:
        """Float (P,) radiance under a full-on projector, ambient included."""
        _, dr = self.modules()
        white = dr.block_sum(self.weight, self.taps_per_pixel)
        return white if self.ambient is None else white + self.ambient

    def scaled(self, gain: Any) -> DeviceTrace:
        """A copy whose weights and ambient are multiplied per pixel by ``gain`` (Float
        (P,), e.g. the camera's vignetting)."""
        mi, dr = self.modules()
        pixel = dr.arange(mi.UInt32, self.n_pixels * self.taps_per_pixel) // self.taps_per_pixel
        weight = self.weight * dr.gather(mi.Float, gain, pixel)
        ambient = None if self.ambient is None else self.ambient * gain
        dr.eval(weight, ambient)
        return dataclasses.replace(self, weight=weight, ambient=ambient)

    def vertex_radiance(self) -> Any:
        """Float (bounces * P,) white-projector radiance by path vertex, vertex-major (as
        :attr:`Trace.bounce_radiance`)."""
        mi, dr = self.modules()
        pixel = dr.arange(mi.UInt32, self.n_pixels)
        per_sample, aperture = self.taps_per_sample, self.aperture_samples
        rows = []
        for vertex in range(self.bounces):
            total = dr.zeros(mi.Float, self.n_pixels)
            for sample in range(self.spp):
                for j in range(aperture):
                    column = sample * per_sample + vertex * aperture + j
                    total += dr.gather(mi.Float, self.weight, pixel * self.taps_per_pixel + column)
            rows.append(total)
        out = dr.zeros(mi.Float, self.bounces * self.n_pixels)
        for vertex, row in enumerate(rows):
            dr.scatter(out, row, pixel + vertex * self.n_pixels)
        dr.eval(out)
        return out

    def ground_truth(self) -> GroundTruth:
        """Pixel-centre ground truth on the host, with ``mask_multibounce`` from the taps
        (a traced pass computes it on the device and copies each array once)."""
        if self.device_truth is not None:
            return self.device_truth().to_host(self.height, self.width, self.multibounce())
        if self.truth is None:
            raise ValueError("this device trace was made without its ground truth")
        multibounce = np.asarray(self.multibounce().numpy(), dtype=bool)
        return dataclasses.replace(
            self.truth(), mask_multibounce=multibounce.reshape(self.height, self.width)
        )

    def multibounce(self) -> Any:
        """Bool (P,): interreflections bring more white-projector radiance than the direct
        path (``GroundTruth.mask_multibounce``); all False for one bounce."""
        mi, dr = self.modules()
        if self.bounces == 1:
            return dr.full(mi.Bool, False, self.n_pixels)
        per_vertex = self.vertex_radiance()
        pixel = dr.arange(mi.UInt32, self.n_pixels)
        indirect = dr.zeros(mi.Float, self.n_pixels)
        for vertex in range(1, self.bounces):  # vertex order, as the host sums its rows
            indirect += dr.gather(mi.Float, per_vertex, pixel + vertex * self.n_pixels)
        return indirect > dr.gather(mi.Float, per_vertex, pixel)

    @classmethod
    def from_trace(cls, trace: Trace) -> DeviceTrace:
        """Upload a host :class:`Trace` (its ground truth comes along as it is)."""
        mi, dr, _ = mitsuba(trace.variant)
        ambient = mi.Float(trace.ambient) if np.any(trace.ambient) else None

        def flat(array: np.ndarray) -> Any:
            return mi.Float(np.ascontiguousarray(array, dtype=np.float32).reshape(-1))

        weight, u_p, v_p = flat(trace.weight), flat(trace.u_p), flat(trace.v_p)
        dr.eval(weight, u_p, v_p, ambient)
        return cls(
            height=trace.height, width=trace.width, spp=trace.spp,
            projector_width=trace.projector_width, projector_height=trace.projector_height,
            weight=weight, u_p=u_p, v_p=v_p, ambient=ambient, variant=trace.variant,
            bounces=trace.bounces, aperture_samples=trace.aperture_samples,
            truth=lambda: trace.gt,
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class DeviceFrames:
    """Digital frames of one pose on the device.

    Attributes
    ----------
    data : UInt8 (8-bit sensors) or UInt32 (F * H * W,) digital numbers, frame-major.
    n_frames, height, width : the frame stack's shape.
    dtype : numpy dtype of the frames on the host (uint8 or uint16).
    saturated : Bool (H * W,) pixels at or above the sensor's saturation in some frame.
    variant : the Mitsuba variant (device) holding them.
    """

    data: Any
    n_frames: int
    height: int
    width: int
    dtype: Any
    saturated: Any
    variant: str

    def numpy(self) -> np.ndarray:
        """(F, H, W) frames on the host: one transfer (16-bit frames travel packed two per
        32-bit word, so no byte is copied that the host does not keep)."""
        shape = (self.n_frames, self.height, self.width)
        if np.dtype(self.dtype).itemsize == 1:
            return np.asarray(self.data.numpy(), dtype=self.dtype).reshape(shape)
        mi, dr = _modules_of(self.data)
        size = self.n_frames * self.height * self.width
        pair = dr.arange(mi.UInt32, (size + 1) // 2) * 2
        low = dr.gather(mi.UInt32, self.data, pair)
        high = dr.gather(mi.UInt32, self.data, pair + 1, pair + 1 < size)
        packed = np.asarray((low | (high << 16)).numpy(), dtype="<u4")
        return packed.view("<u2")[:size].astype(self.dtype, copy=False).reshape(shape)

    def frame(self, index: int) -> np.ndarray:
        """(H, W) frame ``index`` on the host (one frame's transfer)."""
        mi, dr = _modules_of(self.data)
        n_pixels = self.height * self.width
        values = dr.gather(
            type(self.data), self.data, dr.arange(mi.UInt32, n_pixels) + index * n_pixels
        )
        return np.asarray(values.numpy()).astype(self.dtype).reshape(self.height, self.width)

    def saturated_mask(self) -> np.ndarray:
        """(H, W) bool saturation mask on the host."""
        return np.asarray(self.saturated.numpy(), dtype=bool).reshape(self.height, self.width)

    def torch(self) -> Any:
        """The frames as a (F, H, W) PyTorch tensor on the same device, without a copy
        (DLPack; torch is an optional extra)."""
        try:
            import torch
        except ImportError:
            from virtus.errors import VirtusError

            raise VirtusError("DeviceFrames.torch needs PyTorch (pip install torch)") from None
        tensor = torch.from_dlpack(self.data)
        return tensor.reshape(self.n_frames, self.height, self.width)


@functools.lru_cache(maxsize=2)
def _device_directions(variant: str, intrinsics: Intrinsics, spp: int) -> Any:
    """The supersample ray directions (camera frame) as a device ``Vector3f``, uploaded
    once per camera (datasets and calibrations trace many poses with one camera)."""
    mi, dr, _ = mitsuba(variant)
    _, samples = camera_rays(intrinsics, spp)
    directions = mi.Vector3f(samples[0], samples[1], samples[2])
    dr.eval(directions)
    return directions


def _project_taps(ps: Pass, tap: dict[str, Any]) -> tuple[Any, Any, Any]:
    """``(weight, u_p, v_p)`` of one tap on the device; applies the projector's lens
    distortion to taps that carry normalised coordinates (as the host path does)."""
    if "weight" in tap:
        return tap["weight"], tap["u_p"], tap["v_p"]
    mi, dr, projector = ps.mi, ps.dr, ps.projector
    u, v = (
        mi.Float(c)
        for c in project_normalized(projector, mi.Float64(tap["xn"]), mi.Float64(tap["yn"]))
    )
    lit = (tap["radiance"] > 0) & _inside(u, v, projector)
    return (
        dr.select(lit, tap["radiance"], 0.0),
        dr.select(lit, u, 0.0),
        dr.select(lit, v, 0.0),
    )


def trace_device(
    rig: Rig,
    scene: Scene,
    *,
    spp: int = 4,
    cam2world: Pose | None = None,
    variant: str | None = None,
    bounces: int = 1,
    projector_lens: ThinLens | None = None,
    camera_lens: ThinLens | None = None,
    aperture_samples: int | None = None,
) -> DeviceTrace:
    """Trace one pose and keep its taps on the device (parameters and model as
    :func:`virtus.render.tracing.trace`, whose taps it reproduces)."""
    ps = prepare_pass(
        rig, scene, spp=spp, cam2world=cam2world, variant=variant, bounces=bounces,
        projector_lens=projector_lens, camera_lens=camera_lens,
        aperture_samples=aperture_samples,
    )  # fmt: skip
    mi, dr = ps.mi, ps.dr
    directions = _device_directions(ps.variant, ps.camera, ps.spp)
    taps, n_rays = ps.taps_per_sample, ps.n_rays
    size = n_rays * taps
    weight, u_p, v_p = (dr.zeros(mi.Float, size) for _ in range(3))
    per_sample: dict[str, Any] = {}
    for first in range(0, n_rays, ps.chunk):
        count = min(ps.chunk, n_rays - first)
        if count == n_rays:
            rays = directions
        else:
            rays = dr.gather(mi.Vector3f, directions, dr.arange(mi.UInt32, first, first + count))
        tap_list, samples = ps.tracer.samples_device(rays, first, **ps.options())
        if count == n_rays and len(tap_list) == 1 and "weight" in tap_list[0]:
            # One call, one tap per sample: Mitsuba's arrays already have the layout.
            weight, u_p, v_p = (tap_list[0][key] for key in ("weight", "u_p", "v_p"))
            per_sample = dict(samples)
            break
        sample = dr.arange(mi.UInt32, count) + first
        for column, tap in enumerate(tap_list):
            values = _project_taps(ps, tap)
            for target, value in zip((weight, u_p, v_p), values, strict=True):
                dr.scatter(target, value, sample * taps + column)
        for key, value in samples.items():
            if key not in per_sample:
                per_sample[key] = dr.zeros(mi.Float, n_rays)
            dr.scatter(per_sample[key], value, sample)
        dr.eval(weight, u_p, v_p, *per_sample.values())
    ambient = None
    if "rho_d" in per_sample:
        level = dr.opaque(mi.Float, float(scene.ambient))  # a scene's value, not a literal
        ambient = level * dr.block_sum(per_sample["rho_d"], ps.spp) / ps.spp
    if "lights" in per_sample:
        lights = dr.block_sum(per_sample["lights"], ps.spp) / ps.spp
        ambient = lights if ambient is None else ambient + lights
    if ambient is not None:
        dr.eval(ambient)
    projector = ps.projector
    return DeviceTrace(
        height=ps.height, width=ps.width, spp=ps.spp, projector_width=projector.width,
        projector_height=projector.height, weight=weight, u_p=u_p, v_p=v_p, ambient=ambient,
        variant=ps.variant, bounces=ps.bounces, aperture_samples=ps.aperture_samples,
        device_truth=functools.partial(centre_truth_device, ps),
    )  # fmt: skip


def percentile_of_positive(values: Any, q: float) -> float | None:
    """``np.percentile(v[v > 0], q)`` of a device Float array, computed where it lives.

    Positive float32 values sort like their bit patterns, so two histogram passes over the
    bits (high 16, then low 16 within the bucket that holds the rank) find the exact
    order statistics numpy's linear interpolation uses; each histogram's running sum is made
    on the device and only it (256 KiB) reaches the host. Returns None when no value is
    positive.
    """
    mi, dr = _modules_of(values)
    bits = dr.reinterpret_array(mi.UInt32, values)
    positive = values > 0
    high = bits >> 16
    cumulative = _cumulative_histogram(mi, dr, high, positive)
    total = int(cumulative[-1])
    if total == 0:
        return None
    position = (total - 1) * q / 100.0
    ranks = sorted({int(np.floor(position)), min(int(np.floor(position)) + 1, total - 1)})
    found = {}
    buckets = {rank: int(np.searchsorted(cumulative, rank, side="right")) for rank in ranks}
    for bucket in sorted(set(buckets.values())):  # usually both ranks share one bucket
        before = int(cumulative[bucket - 1]) if bucket else 0
        # The bucket is opaque: one compiled kernel for every pose's bucket.
        inside = positive & (high == dr.opaque(mi.UInt32, bucket))
        low = _cumulative_histogram(mi, dr, bits & 0xFFFF, inside)
        for rank in (r for r, b in buckets.items() if b == bucket):
            index = int(np.searchsorted(low, rank - before, side="right"))
            found[rank] = np.array([(bucket << 16) | index], dtype=np.uint32).view(np.float32)[0]
    pair = np.array([found[ranks[0]], found[ranks[-1]]], dtype=np.float32)
    return float(np.percentile(pair, 100.0 * (position - np.floor(position))))


def _cumulative_histogram(mi: Any, dr: Any, keys: Any, active: Any) -> np.ndarray:
    """(65536,) uint32 running counts (inclusive) of UInt32 ``keys`` < 65536 where
    ``active``: entry ``k`` counts the keys <= ``k``."""
    counts = dr.zeros(mi.UInt32, 1 << 16)
    dr.scatter_reduce(dr.ReduceOp.Add, counts, mi.UInt32(1), keys, active)
    return np.asarray(dr.cumsum(counts).numpy(), dtype=np.uint32)


def _modules_of(array: Any) -> tuple[Any, Any]:
    """``(mitsuba, drjit)`` of the variant that owns a Dr.Jit array."""
    mi, dr, _ = mitsuba(variant_of(array))
    return mi, dr
