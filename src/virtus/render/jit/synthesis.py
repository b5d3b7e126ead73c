"""Frame synthesis and digitisation on the device: the model of
:mod:`virtus.render.synthesis` and :class:`virtus.sensor.camera.Sensor` on Dr.Jit arrays.

One kernel makes a whole pose's frames: lane ``i`` is pixel ``p = i mod P`` of frame
``f = i div P``; it reads its S taps (weight, projector coordinate), looks each up in frame
``f``'s row of one table holding every frame's emitted profile (uniform frames: one entry),
sums them, adds the ambient light, and digitises with the sensor -- its noise drawn from the
same counter-based streams as on the host (:mod:`virtus.render.jit.noise`). Only the
digital frames are written, into one device array
(:class:`~virtus.render.jit.tracing.DeviceFrames`).
Frames are split into several kernels only when a pose has more than
:data:`_MAX_LANES` pixels x frames.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.render.jit.noise import noise_streams
from virtus.render.jit.tracing import DeviceFrames, DeviceTrace
from virtus.render.synthesis import as_projector, emitted_profiles, projector_groups, tap_weights
from virtus.render.tracing import Trace
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import Lookup, ProjectorModel

#: Most lanes (pixels x frames) per kernel: UInt32 lane indices, bounded temporaries.
_MAX_LANES = 1 << 28
#: Frame axis codes of the profile table.
_AXIS_U, _AXIS_V, _AXIS_NONE = 0, 1, 2


def _profile_table(
    trace: DeviceTrace, sequence: Any, projector: ProjectorModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every frame's emitted light in one flat float32 table: ``(table, offset, length,
    axis)``, the last three (F,) per frame (its row's start and length in the table, and
    which tap coordinate reads it)."""
    groups = projector_groups(sequence, projector)
    n_frames = len(sequence.frames)
    rows: list[np.ndarray] = [np.zeros(0, np.float32)] * n_frames
    axis = np.full(n_frames, _AXIS_NONE, dtype=np.uint32)
    lengths = {"v": trace.projector_width, "h": trace.projector_height}
    for direction, code in (("v", _AXIS_U), ("h", _AXIS_V)):
        if groups[direction]:
            table = emitted_profiles(projector, sequence, groups[direction], lengths[direction])
            for k, index in enumerate(groups[direction]):
                rows[index] = np.ascontiguousarray(table[:, k])
                axis[index] = code
    for index in groups[None]:
        level = projector.emitted_profile(sequence, index).astype(np.float32).reshape(-1)
        if level.shape != (1,):
            raise InputError(f"sequence.profile({index})", "shape (1,)", level.shape)
        rows[index] = level
    length = np.array([row.size for row in rows], dtype=np.uint32)
    offset = np.concatenate([[0], np.cumsum(length)[:-1]]).astype(np.uint32)
    return np.concatenate(rows).astype(np.float32), offset, length, axis


def synthesize_on_device(
    trace: DeviceTrace,
    sequence: Any,
    projector: ProjectorModel | str,
    sensor: Sensor,
    exposure: float,
    seed: int = 0,
    projector_intrinsics: Any | None = None,
) -> DeviceFrames:
    """Digital frames of ``sequence`` from a device trace, made and kept on its device.

    Parameters
    ----------
    trace : the pose's taps (:func:`virtus.render.jit.tracing.trace_device`).
    sequence : the pattern sequence.
    projector : the projector model, or a pixel model name.
    sensor : the camera sensor; a noisy one draws the host's counter-based streams.
    exposure : digital numbers per unit radiance.
    seed : seed of the noise streams.
    projector_intrinsics : the projector's intrinsics (needed with a fall-off).

    Returns
    -------
    :class:`DeviceFrames`: the same frames as :func:`virtus.render.synthesis.synthesize`
    followed by ``sensor.digitize`` (float32 sums in another order, and the noise's
    ``log``/``cos`` rounding, can move a value sitting on a rounding edge by 1 DN).
    """
    projector = as_projector(projector)
    mi, dr = trace.modules()
    n_frames, n_pixels, taps = len(sequence.frames), trace.n_pixels, trace.taps_per_pixel
    table, offset, length, axis = _profile_table(trace, sequence, projector)
    table_dr, offset_dr = mi.Float(table), mi.UInt32(offset)
    length_dr, axis_dr = mi.Float(length.astype(np.float32)), mi.UInt32(axis)
    weight = tap_weights(trace, projector, projector_intrinsics)
    dr.eval(weight)  # gathered by every lane of the kernel below
    scale = projector.supersampling
    read = Lookup.bilinear if projector.pixel == Lookup.psf else projector.pixel
    integer = mi.UInt8 if sensor.bit_depth == 8 else mi.UInt32
    frames_per_kernel = max(1, min(n_frames, _MAX_LANES // n_pixels))
    if frames_per_kernel < n_frames:
        out = dr.zeros(integer, n_frames * n_pixels)
    all_frames = np.arange(n_frames)
    for first in range(0, n_frames, frames_per_kernel):
        count = min(frames_per_kernel, n_frames - first)
        lane = dr.arange(mi.UInt32, count * n_pixels) + dr.opaque(mi.UInt32, first * n_pixels)
        frame = lane // n_pixels
        pixel = lane - frame * n_pixels
        start = dr.gather(mi.UInt32, offset_dr, frame)
        last = dr.gather(mi.Float, length_dr, frame) - 1.0
        frame_axis = dr.gather(mi.UInt32, axis_dr, frame)
        on_u, on_v = frame_axis == _AXIS_U, frame_axis == _AXIS_V
        radiance = dr.zeros(mi.Float, count * n_pixels)
        for column in range(taps):
            tap = pixel * taps + column
            c = dr.gather(mi.Float, trace.u_p, tap, on_u) + dr.gather(
                mi.Float, trace.v_p, tap, on_v
            )
            if scale > 1:
                c = projector.table_coordinate(c)
            if read == Lookup.nearest:
                col = mi.UInt32(dr.clip(dr.floor(c + 0.5), 0.0, last))
                value = dr.gather(mi.Float, table_dr, start + col)
            else:
                x = dr.clip(c, 0.0, last)
                left = dr.minimum(dr.floor(x), dr.maximum(last - 1.0, 0.0))
                frac = x - left
                right = dr.minimum(left + 1.0, last)
                value = dr.gather(mi.Float, table_dr, start + mi.UInt32(left)) * (1.0 - frac)
                value += dr.gather(mi.Float, table_dr, start + mi.UInt32(right)) * frac
            radiance += dr.gather(mi.Float, weight, tap) * value
        if trace.ambient is not None:
            radiance += dr.gather(mi.Float, trace.ambient, pixel)
        noise = None
        if sensor.noisy:
            noise = noise_streams(
                mi, dr, trace.variant, sensor, seed, frame - first, pixel, n_pixels,
                all_frames[first : first + count],
            )  # fmt: skip
        # The exposure (a pose's auto exposure) enters as an opaque variable, so the kernel
        # compiled for one pose serves the next: radiance * exposure is the same float32
        # product, and digitize_jit's own factor 1.0 leaves it unchanged.
        radiance = radiance * dr.opaque(mi.Float, float(exposure))
        digital = integer(sensor.digitize_jit(radiance, 1.0, dr, noise))
        if count == n_frames:  # one kernel makes the whole stack: no scatter, no zero fill
            out = digital
        else:
            dr.scatter(out, digital, lane)
        dr.eval(out)
    saturated = dr.zeros(mi.Bool, n_pixels)
    pixel = dr.arange(mi.UInt32, n_pixels)
    level = sensor.saturation_dn
    for index in range(n_frames):
        saturated |= mi.UInt32(dr.gather(integer, out, pixel + index * n_pixels)) >= level
    dr.eval(saturated)
    return DeviceFrames(
        data=out, n_frames=n_frames, height=trace.height, width=trace.width,
        dtype=sensor.dtype, saturated=saturated, variant=trace.variant,
    )  # fmt: skip


def synthesize_digital(
    trace: Trace,
    sequence: Any,
    projector: ProjectorModel | str,
    sensor: Sensor,
    exposure: float,
    seed: int = 0,
    projector_intrinsics: Any | None = None,
) -> np.ndarray:
    """(F, H, W) digital frames of a host :class:`Trace` synthesised on its device
    (:func:`synthesize_on_device` after one upload, one transfer back)."""
    device = DeviceTrace.from_trace(trace)
    return synthesize_on_device(
        device, sequence, projector, sensor, exposure, seed, projector_intrinsics
    ).numpy()
