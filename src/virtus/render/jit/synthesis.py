"""Frame synthesis and digitisation on the device: the model of
:mod:`virtus.render.synthesis` and :class:`virtus.sensor.camera.Sensor` on Dr.Jit arrays.

One kernel makes a whole pose's frames: lane ``p`` is one camera pixel. It reads its S taps
(weight, projector coordinates) once and turns each coordinate into its table positions (the
nearest entry, or the bilinear pair and fraction) along u, for the frames whose fringes vary
along the projector's columns, and along v, for the others. Then it loops over the frames (a
symbolic loop: the kernel's source does not depend on the sequence, whose frame count, kinds
and rows are data): frame ``f`` looks every tap up in its row of one table holding every
frame's emitted profile (uniform frames: one entry), sums them, adds the ambient light,
digitises with the sensor --
its noise drawn from the same counter-based streams as on the host
(:mod:`virtus.render.jit.noise`) -- and writes pixel ``p`` of frame ``f`` into one device
array (:class:`~virtus.render.jit.tracing.DeviceFrames`, frame-major), noting saturation as
it goes. Tap data are read once per pixel, not once per frame and pixel; the output is
written once, with no second pass for the saturation mask.
Frames are split into several kernels only when a pose has more than :data:`_MAX_LANES`
pixels x frames.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.render.jit.noise import frame_keys, pixel_patterns, standard_normal_jit
from virtus.render.jit.tracing import DeviceFrames, DeviceTrace
from virtus.render.synthesis import as_projector, emitted_profiles, projector_groups, tap_weights
from virtus.render.tracing import Trace
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import Lookup, ProjectorModel

#: Most pixels x frames per kernel: bounds the work of one kernel launch.
_MAX_LANES = 1 << 28
#: Frame kinds: fringes along u (the projector's columns), along v (its rows), uniform.
_AXIS_U, _AXIS_V, _AXIS_NONE = 0, 1, 2
#: Bits of a frame's code that hold its kind; the rest is its row's start in the table.
_KIND_BITS = 2


def _profile_table(
    trace: DeviceTrace, sequence: Any, projector: ProjectorModel
) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """Every frame's emitted light in one flat float32 table: ``(table, code, lengths)``,
    ``code`` (F,) uint32 per frame ``start << _KIND_BITS | kind`` (its row's start in the
    table, and which tap coordinate reads it), ``lengths`` the row length of each kind."""
    groups = projector_groups(sequence, projector)
    n_frames = len(sequence.frames)
    rows: list[np.ndarray] = [np.zeros(0, np.float32)] * n_frames
    kind = np.full(n_frames, _AXIS_NONE, dtype=np.uint32)
    sizes = {"v": trace.projector_width, "h": trace.projector_height}
    lengths = {_AXIS_NONE: 1}
    for direction, code in (("v", _AXIS_U), ("h", _AXIS_V)):
        if groups[direction]:
            table = emitted_profiles(projector, sequence, groups[direction], sizes[direction])
            lengths[code] = table.shape[0]
            for k, index in enumerate(groups[direction]):
                rows[index] = np.ascontiguousarray(table[:, k])
                kind[index] = code
    for index in groups[None]:
        level = projector.emitted_profile(sequence, index).astype(np.float32).reshape(-1)
        if level.shape != (1,):
            raise InputError(f"sequence.profile({index})", "shape (1,)", level.shape)
        rows[index] = level
    table = np.concatenate(rows).astype(np.float32)
    if table.size >= 1 << (32 - _KIND_BITS):
        raise InputError("sequence", "fewer frames x projector pixels", f"{table.size} entries")
    start = np.concatenate([[0], np.cumsum([row.size for row in rows])[:-1]]).astype(np.uint32)
    return table, start << _KIND_BITS | kind, lengths


def _tap_positions(
    trace: DeviceTrace, weight: Any, projector: ProjectorModel, lengths: dict[int, int]
) -> list[tuple[Any, dict[int, tuple[Any, Any, Any]]]]:
    """Per tap column of every pixel (lane ``p``): its weight and, per frame kind in
    ``lengths`` (its table rows' length), its table position ``(left, right, fraction)``:
    the nearest entry has fraction None; a uniform frame reads entry 0. Frame-independent,
    so computed once per pixel before the frame loop, with a per-frame lookup's arithmetic."""
    mi, dr = trace.modules()
    taps = trace.taps_per_pixel
    scale = projector.supersampling
    read = Lookup.bilinear if projector.pixel == Lookup.psf else projector.pixel
    pixel = dr.arange(mi.UInt32, trace.n_pixels)
    # The last entry of a row: a projector's value, opaque so that no kernel bakes it in.
    lasts = {code: dr.opaque(mi.Float, float(lengths[code] - 1)) for code in lengths}
    zero = dr.zeros(mi.UInt32, trace.n_pixels)
    uniform = (zero, zero, None if read == Lookup.nearest else dr.zeros(mi.Float, trace.n_pixels))
    out = []
    for column in range(taps):
        tap = pixel * taps + column
        positions: dict[int, tuple[Any, Any, Any]] = {_AXIS_NONE: uniform}
        for code, coordinates in ((_AXIS_U, trace.u_p), (_AXIS_V, trace.v_p)):
            if code not in lengths:
                continue
            last = lasts[code]
            c = dr.gather(mi.Float, coordinates, tap)
            if scale > 1:
                c = projector.table_coordinate(c)
            if read == Lookup.nearest:
                index = mi.UInt32(dr.clip(dr.floor(c + 0.5), 0.0, last))
                positions[code] = (index, index, None)
            else:
                x = dr.clip(c, 0.0, last)
                left = dr.minimum(dr.floor(x), dr.maximum(last - 1.0, 0.0))
                right = dr.minimum(left + 1.0, last)
                positions[code] = (mi.UInt32(left), mi.UInt32(right), x - left)
        out.append((dr.gather(mi.Float, weight, tap), positions))
    return out


def _frame_radiance(mi: Any, dr: Any, table: Any, taps: list, code: Any) -> Any:
    """Float (P,): the sum over the taps of weight x the emitted light of the frame whose
    ``code`` (UInt32 ``start << _KIND_BITS | kind``) is given."""
    start, kind = code >> _KIND_BITS, code & ((1 << _KIND_BITS) - 1)
    on_u, on_v = kind == _AXIS_U, kind == _AXIS_V
    radiance = dr.zeros(mi.Float, dr.width(code))
    for weight, positions in taps:
        u = positions.get(_AXIS_U, positions[_AXIS_NONE])
        v = positions.get(_AXIS_V, positions[_AXIS_NONE])
        left = dr.select(on_u, u[0], dr.select(on_v, v[0], 0))
        if u[2] is None:  # nearest
            value = dr.gather(mi.Float, table, start + left)
        else:
            right = dr.select(on_u, u[1], dr.select(on_v, v[1], 0))
            fraction = dr.select(on_u, u[2], dr.select(on_v, v[2], 0.0))
            value = dr.gather(mi.Float, table, start + left) * (1.0 - fraction)
            value += dr.gather(mi.Float, table, start + right) * fraction
        radiance += weight * value
    return radiance


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
    n_frames, n_pixels = len(sequence.frames), trace.n_pixels
    if n_frames * n_pixels >= 1 << 32:  # the frames' UInt32 indices; before any allocation
        raise InputError("sequence", f"fewer than {(1 << 32) // n_pixels} frames", n_frames)
    table, code, lengths = _profile_table(trace, sequence, projector)
    table_dr, code_dr = mi.Float(table), mi.UInt32(code)
    weight = tap_weights(trace, projector, projector_intrinsics)
    dr.eval(weight)
    keys = frame_keys(mi, seed, np.arange(n_frames)) if sensor.noisy else None
    prnu, dsnu = pixel_patterns(trace.variant, sensor, n_pixels) if sensor.noisy else (None,) * 2
    integer = mi.UInt8 if sensor.bit_depth == 8 else mi.UInt32
    out = dr.empty(integer, n_frames * n_pixels)
    pixel = dr.arange(mi.UInt32, n_pixels)
    saturated = dr.full(mi.Bool, False, n_pixels)
    level = mi.UInt32(sensor.saturation_dn)
    # The exposure (a pose's auto exposure) enters as an opaque variable, so the kernel
    # compiled for one pose serves the next: radiance * exposure is the same float32
    # product, and digitize_jit's own factor 1.0 leaves it unchanged.
    gain = dr.opaque(mi.Float, float(exposure))
    frames_per_kernel = max(1, min(n_frames, _MAX_LANES // n_pixels))
    for first in range(0, n_frames, frames_per_kernel):
        taps = _tap_positions(trace, weight, projector, lengths)  # in this kernel, per pixel

        def body(frame: Any, saturated: Any, taps: list = taps) -> tuple[Any, Any]:
            frame_code = dr.gather(mi.UInt32, code_dr, frame)
            radiance = _frame_radiance(mi, dr, table_dr, taps, frame_code)
            if trace.ambient is not None:
                radiance += trace.ambient
            noise = None
            if keys is not None:
                k0, k1 = (dr.gather(mi.UInt32, key, frame) for key in keys)
                noise = (standard_normal_jit(mi, dr, k0, k1, pixel), prnu, dsnu)
            digital = integer(sensor.digitize_jit(radiance * gain, 1.0, dr, noise))
            dr.scatter(out, digital, frame * n_pixels + pixel)
            return frame + 1, saturated | (mi.UInt32(digital) >= level)

        end = dr.opaque(mi.UInt32, min(first + frames_per_kernel, n_frames))
        frame = dr.zeros(mi.UInt32, n_pixels) + dr.opaque(mi.UInt32, first)
        _, saturated = dr.while_loop(
            (frame, saturated), lambda frame, _, end=end: frame < end, body, label="frames"
        )
        dr.eval(out, saturated)
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
