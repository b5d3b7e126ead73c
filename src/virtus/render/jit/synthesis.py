"""Frame synthesis and digitisation on the device: the model of
:mod:`virtus.render.synthesis` and :class:`virtus.sensor.camera.Sensor` on Dr.Jit arrays.

One kernel makes a whole pose's frames. Frame ``f`` of pixel ``p`` looks each of the pixel's
S taps (weight, projector coordinates) up in frame ``f``'s row of one table holding every
frame's emitted profile (uniform frames: one entry) -- along u for the frames whose fringes
vary along the projector's columns, along v for the others --, sums them, adds the ambient
light and digitises with the sensor, its noise drawn from the same counter-based streams as
on the host (:mod:`virtus.render.jit.noise`). The digital frames are written into one
device array (:class:`~virtus.render.jit.tracing.DeviceFrames`, frame-major) and the
saturation mask in the same launch. Frames are split into several kernels only when a pose
has more than :data:`_MAX_LANES` pixels x frames.

Two kernel layouts compute these same bits (:func:`layout_for` picks one by backend):

* :data:`LAYOUT_PIXEL` (LLVM, the CPU): a lane per camera pixel. It reads its taps once,
  turns each coordinate into its table positions (nearest entry, or bilinear pair and
  fraction) once, then loops over the frames -- a symbolic loop, so the kernel's source does
  not depend on the sequence. A CPU has a few SIMD lanes per core, and re-reading the taps
  per frame was the cost: on 2 CPU cores (``llvm_ad_rgb``) this layout took 2.3-2.4x less
  synthesis + sensor time and 1.55x less CPU time per pose than 677de4a's lane per (frame,
  pixel); against :data:`LAYOUT_FRAME_PIXEL` (960 px crop, 4 spp, nearest, ``imx174``) 193 ms
  against 320 ms of CPU time for a pose's synthesis + sensor (1.64-1.68x, 3 alternated rounds).
* :data:`LAYOUT_FRAME_PIXEL` (CUDA, the GPU): a lane per (frame, pixel), ``F`` (52 for the
  default sequence) times as many lanes, each reading its taps -- 677de4a's kernel, its
  saturation mask now a masked scatter of ``True`` by every saturated lane in the same
  launch (every writer of a pixel writes the same value). On the GPU the layout hardly
  matters: on an NVIDIA H200 this kernel runs 0.33 ms for a 960 px pose (Dr.Jit's kernel
  history), and a lane per (block of 2-26 frames, pixel) looping over its block, or the
  CPU's lane per pixel, gave the same 3.6-4.0 ms of synthesis wall time (3 alternated
  rounds) -- which was the host's: rebuilding the sequence's table every pose. That table is
  now made once per sequence and projector (:func:`_device_table`), and a warm pose's
  synthesis + sensor takes 0.4-0.6 ms on an H100 or H200.

Both layouts do the same float32 operations in the same order per value, so their frames and
masks are bit-identical on LLVM (tests/render/jit/test_synthesis.py checks it). On CUDA they
were not (the H200 run above: frames of the per-pixel loop differed from the lane per
frame's; by how much, and whether the PTX compiler fuses the two kernels' arithmetic
differently, was not looked into): CUDA only ever uses :data:`LAYOUT_FRAME_PIXEL`, whose
agreement with the CPU is measured by ``benchmarks/bench_profile.py --agreement``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.patterns.sequence import PatternSequence
from virtus.render.backend import mitsuba
from virtus.render.jit.noise import frame_keys, pixel_patterns, standard_normal_jit
from virtus.render.jit.tracing import DeviceFrames, DeviceTrace
from virtus.render.synthesis import as_projector, emitted_profiles, projector_groups, tap_weights
from virtus.render.tracing import Trace
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import Lookup, ProjectorModel

#: Most pixels x frames per kernel: bounds the work of one kernel launch (and the lanes of
#: a :data:`LAYOUT_FRAME_PIXEL` kernel).
_MAX_LANES = 1 << 28
#: Frame kinds: fringes along u (the projector's columns), along v (its rows), uniform.
_AXIS_U, _AXIS_V, _AXIS_NONE = 0, 1, 2
#: Bits of a frame's code that hold its kind; the rest is its row's start in the table.
_KIND_BITS = 2
#: Kernel layouts (see the module docstring): a lane per pixel looping over the frames, or
#: a lane per (frame, pixel).
LAYOUT_PIXEL, LAYOUT_FRAME_PIXEL = "pixel", "frame_pixel"
LAYOUTS = (LAYOUT_PIXEL, LAYOUT_FRAME_PIXEL)


def layout_for(variant: str) -> str:
    """The kernel layout for a Mitsuba variant: :data:`LAYOUT_PIXEL` on LLVM (CPU),
    :data:`LAYOUT_FRAME_PIXEL` on CUDA (GPU)."""
    return LAYOUT_PIXEL if variant.startswith("llvm") else LAYOUT_FRAME_PIXEL


def _profile_table(
    sequence: Any, projector: ProjectorModel, projector_width: int, projector_height: int
) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """Every frame's emitted light in one flat float32 table: ``(table, code, lengths)``,
    ``code`` (F,) uint32 per frame ``start << _KIND_BITS | kind`` (its row's start in the
    table, and which tap coordinate reads it), ``lengths`` the row length of each kind."""
    groups = projector_groups(sequence, projector)
    n_frames = len(sequence.frames)
    rows: list[np.ndarray] = [np.zeros(0, np.float32)] * n_frames
    kind = np.full(n_frames, _AXIS_NONE, dtype=np.uint32)
    sizes = {"v": projector_width, "h": projector_height}
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


def _device_table(
    trace: DeviceTrace, sequence: Any, projector: ProjectorModel
) -> tuple[Any, Any, dict[int, int]]:
    """:func:`_profile_table` on the trace's device: ``(Float table, UInt32 code, lengths)``.
    Made once per (variant, sequence, projector, projector size) while it stays in
    :func:`_table_cache` -- the poses of a dataset or a calibration share it; made per pose,
    it was most of a warm GPU pose's synthesis time. Only a :class:`PatternSequence` (frozen,
    compared by value) is cached: any other object with ``frames`` and ``profile`` may
    change between calls, so its table is made each time."""
    key = (trace.variant, sequence, projector, trace.projector_width, trace.projector_height)
    if isinstance(sequence, PatternSequence):
        return _table_cache(*key)
    return _upload_table(*key)


def _upload_table(
    variant: str, sequence: Any, projector: ProjectorModel, width: int, height: int
) -> tuple[Any, Any, dict[int, int]]:
    """:func:`_profile_table` uploaded to ``variant``'s device (evaluated)."""
    mi, dr, _ = mitsuba(variant)
    table, code, lengths = _profile_table(sequence, projector, width, height)
    table, code = mi.Float(table), mi.UInt32(code)
    dr.eval(table, code)
    return table, code, lengths


#: The tables of the last few (variant, sequence, projector, projector size) keys.
_table_cache = functools.lru_cache(maxsize=8)(_upload_table)


@dataclass
class _Pose:
    """What both layouts read: the pose's taps and the sequence's table on the device, the
    sensor's streams, and the output (``out``, frame-major, and ``saturated``, per pixel)."""

    mi: Any
    dr: Any
    trace: DeviceTrace
    projector: ProjectorModel
    sensor: Sensor
    n_frames: int
    weight: Any  # Float (P * S,) tap weights
    table: Any  # Float: every frame's row (_profile_table)
    code: Any  # UInt32 (F,): start << _KIND_BITS | kind per frame
    lengths: dict[int, int]  # row length per frame kind present
    keys: tuple[Any, Any] | None  # the frames' noise stream keys (a noisy sensor)
    prnu: Any  # Float (P,) or None
    dsnu: Any  # Float (P,) or None
    gain: Any  # opaque Float: the exposure
    out: Any
    saturated: Any

    @property
    def integer(self) -> Any:
        """The digital frames' Dr.Jit type."""
        return self.mi.UInt8 if self.sensor.bit_depth == 8 else self.mi.UInt32

    @property
    def read(self) -> Lookup:
        """How the table is read: the pixel model's lookup (a ``psf`` table, already
        spread, is read bilinearly)."""
        return Lookup.bilinear if self.projector.pixel == Lookup.psf else self.projector.pixel

    def lasts(self) -> dict[int, Any]:
        """The last entry of each kind's rows: a projector's value, opaque so that no kernel
        bakes it in."""
        return {k: self.dr.opaque(self.mi.Float, float(n - 1)) for k, n in self.lengths.items()}

    def digitize(self, radiance: Any, frame: Any, pixel: Any, lanes_per_pixel: bool) -> Any:
        """The digital values (``integer``) of ``radiance`` (Float, before the ambient light)
        at lanes of frame ``frame`` and pixel ``pixel``; ``lanes_per_pixel``: lane ``p`` is
        pixel ``p`` (per-pixel arrays are read as they are, else gathered)."""
        mi, dr, trace = self.mi, self.dr, self.trace

        def at_pixel(values: Any) -> Any:
            if values is None or lanes_per_pixel:
                return values
            return dr.gather(mi.Float, values, pixel)

        if trace.ambient is not None:
            radiance += at_pixel(trace.ambient)
        noise = None
        if self.keys is not None:
            k0, k1 = (dr.gather(mi.UInt32, key, frame) for key in self.keys)
            normal = standard_normal_jit(mi, dr, k0, k1, pixel)
            noise = (normal, at_pixel(self.prnu), at_pixel(self.dsnu))
        # The exposure (a pose's auto exposure) enters as an opaque variable, so the kernel
        # compiled for one pose serves the next: radiance * exposure is the same float32
        # product, and digitize_jit's own factor 1.0 leaves it unchanged.
        return self.integer(self.sensor.digitize_jit(radiance * self.gain, 1.0, dr, noise))

    def is_saturated(self, digital: Any) -> Any:
        """Bool per lane: ``digital`` at or above the sensor's saturation level."""
        return self.mi.UInt32(digital) >= self.mi.UInt32(self.sensor.saturation_dn)


def _frame_kind(code: Any) -> tuple[Any, Any, Any]:
    """A frame's ``code`` (UInt32 ``start << _KIND_BITS | kind``) read: its row's start in
    the table, and whether its fringes vary along u (Bool) and along v (Bool)."""
    start, kind = code >> _KIND_BITS, code & ((1 << _KIND_BITS) - 1)
    return start, kind == _AXIS_U, kind == _AXIS_V


def _table_position(mi: Any, dr: Any, c: Any, last: Any, read: Lookup) -> tuple[Any, Any, Any]:
    """Where projector coordinate ``c`` (Float, table entries) reads a row whose last entry
    is ``last``: ``(left, right, fraction)`` -- UInt32, UInt32, Float for ``bilinear``;
    ``(index, index, None)`` for ``nearest`` (the nearest entry). Clamped to the row."""
    if read == Lookup.nearest:
        index = mi.UInt32(dr.clip(dr.floor(c + 0.5), 0.0, last))
        return index, index, None
    x = dr.clip(c, 0.0, last)
    left = dr.minimum(dr.floor(x), dr.maximum(last - 1.0, 0.0))
    right = dr.minimum(left + 1.0, last)
    return mi.UInt32(left), mi.UInt32(right), x - left


def _read_table(mi: Any, dr: Any, table: Any, start: Any, position: tuple) -> Any:
    """Float: the row starting at ``start`` read at ``position`` (:func:`_table_position`)."""
    left, right, fraction = position
    if fraction is None:  # nearest
        return dr.gather(mi.Float, table, start + left)
    value = dr.gather(mi.Float, table, start + left) * (1.0 - fraction)
    value += dr.gather(mi.Float, table, start + right) * fraction
    return value


# --- LAYOUT_PIXEL: a lane per pixel, a symbolic loop over the frames ----------------------


def _tap_positions(pose: _Pose) -> list[tuple[Any, dict[int, tuple[Any, Any, Any]]]]:
    """Per tap column of every pixel (lane ``p``): its weight and, per frame kind present,
    its table position ``(left, right, fraction)``: the nearest entry has fraction None; a
    uniform frame reads entry 0. Frame-independent, so computed once per pixel before the
    frame loop, with a per-frame lookup's arithmetic."""
    mi, dr, trace, projector = pose.mi, pose.dr, pose.trace, pose.projector
    taps, read = trace.taps_per_pixel, pose.read
    pixel = dr.arange(mi.UInt32, trace.n_pixels)
    lasts = pose.lasts()
    zero = dr.zeros(mi.UInt32, trace.n_pixels)
    uniform = (zero, zero, None if read == Lookup.nearest else dr.zeros(mi.Float, trace.n_pixels))
    out = []
    for column in range(taps):
        tap = pixel * taps + column
        positions: dict[int, tuple[Any, Any, Any]] = {_AXIS_NONE: uniform}
        for code, coordinates in ((_AXIS_U, trace.u_p), (_AXIS_V, trace.v_p)):
            if code not in lasts:
                continue
            c = dr.gather(mi.Float, coordinates, tap)
            if projector.supersampling > 1:
                c = projector.table_coordinate(c)
            positions[code] = _table_position(mi, dr, c, lasts[code], read)
        out.append((dr.gather(mi.Float, pose.weight, tap), positions))
    return out


def _frame_radiance(mi: Any, dr: Any, table: Any, taps: list, code: Any) -> Any:
    """Float (P,): the sum over the taps of weight x the emitted light of the frame whose
    ``code`` (UInt32 ``start << _KIND_BITS | kind``) is given."""
    start, on_u, on_v = _frame_kind(code)
    radiance = dr.zeros(mi.Float, dr.width(code))
    for weight, positions in taps:
        u = positions.get(_AXIS_U, positions[_AXIS_NONE])
        v = positions.get(_AXIS_V, positions[_AXIS_NONE])
        left = dr.select(on_u, u[0], dr.select(on_v, v[0], 0))
        if u[2] is None:  # nearest
            position = (left, left, None)
        else:
            right = dr.select(on_u, u[1], dr.select(on_v, v[1], 0))
            fraction = dr.select(on_u, u[2], dr.select(on_v, v[2], 0.0))
            position = (left, right, fraction)
        radiance += weight * _read_table(mi, dr, table, start, position)
    return radiance


def _pixel_kernel(pose: _Pose, first: int, count: int) -> None:
    """Frames ``first .. first + count - 1`` into ``pose.out`` and ``pose.saturated``: one
    kernel of a lane per pixel looping over the frames."""
    mi, dr, n_pixels = pose.mi, pose.dr, pose.trace.n_pixels
    taps = _tap_positions(pose)
    pixel = dr.arange(mi.UInt32, n_pixels)

    def body(frame: Any, saturated: Any) -> tuple[Any, Any]:
        code = dr.gather(mi.UInt32, pose.code, frame)
        radiance = _frame_radiance(mi, dr, pose.table, taps, code)
        digital = pose.digitize(radiance, frame, pixel, lanes_per_pixel=True)
        dr.scatter(pose.out, digital, frame * n_pixels + pixel)
        return frame + 1, saturated | pose.is_saturated(digital)

    end = dr.opaque(mi.UInt32, first + count)
    frame = dr.zeros(mi.UInt32, n_pixels) + dr.opaque(mi.UInt32, first)
    _, pose.saturated = dr.while_loop(
        (frame, pose.saturated), lambda frame, _: frame < end, body, label="frames"
    )
    dr.eval(pose.out, pose.saturated)


# --- LAYOUT_FRAME_PIXEL: a lane per (frame, pixel) ----------------------------------------


def _lane_radiance(pose: _Pose, frame: Any, pixel: Any) -> Any:
    """Float per lane: the sum over pixel ``pixel``'s taps of weight x frame ``frame``'s
    emitted light, each lane reading only its frame's coordinate (masked gathers)."""
    mi, dr, trace, projector = pose.mi, pose.dr, pose.trace, pose.projector
    taps, read = trace.taps_per_pixel, pose.read
    start, on_u, on_v = _frame_kind(dr.gather(mi.UInt32, pose.code, frame))
    lasts = pose.lasts()
    last = dr.select(on_v, lasts.get(_AXIS_V, 0.0), 0.0)
    last = dr.select(on_u, lasts.get(_AXIS_U, 0.0), last)
    radiance = dr.zeros(mi.Float, dr.width(frame))
    for column in range(taps):
        tap = pixel * taps + column
        c = dr.zeros(mi.Float, dr.width(frame))
        for axis, coordinates, active in ((_AXIS_U, trace.u_p, on_u), (_AXIS_V, trace.v_p, on_v)):
            if axis in lasts:
                c += dr.gather(mi.Float, coordinates, tap, active)
        if projector.supersampling > 1:
            c = projector.table_coordinate(c)
        value = _read_table(mi, dr, pose.table, start, _table_position(mi, dr, c, last, read))
        radiance += dr.gather(mi.Float, pose.weight, tap) * value
    return radiance


def _frame_pixel_kernel(pose: _Pose, first: int, count: int) -> None:
    """Frames ``first .. first + count - 1`` into ``pose.out`` and ``pose.saturated``: one
    kernel of a lane per (frame, pixel); lane ``i`` is pixel ``i mod P`` of frame
    ``first + i div P``."""
    mi, dr, n_pixels = pose.mi, pose.dr, pose.trace.n_pixels
    lane = dr.arange(mi.UInt32, count * n_pixels) + dr.opaque(mi.UInt32, first * n_pixels)
    frame = lane // n_pixels
    pixel = lane - frame * n_pixels
    digital = pose.digitize(_lane_radiance(pose, frame, pixel), frame, pixel, False)
    if count == pose.n_frames:  # one kernel makes the whole stack: no scatter
        pose.out = digital
    else:
        dr.scatter(pose.out, digital, lane)
    # Every saturated lane writes True to its pixel: writers of a pixel agree.
    dr.scatter(pose.saturated, mi.Bool(True), pixel, pose.is_saturated(digital))
    dr.eval(pose.out, pose.saturated)


def synthesize_on_device(
    trace: DeviceTrace,
    sequence: Any,
    projector: ProjectorModel | str,
    sensor: Sensor,
    exposure: float,
    seed: int = 0,
    projector_intrinsics: Any | None = None,
    layout: str | None = None,
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
    layout : the kernel layout, one of :data:`LAYOUTS` (default: :func:`layout_for` the
        trace's variant); the same frames either way.

    Returns
    -------
    :class:`DeviceFrames`: the same frames as :func:`virtus.render.synthesis.synthesize`
    followed by ``sensor.digitize`` (float32 sums in another order, and the noise's
    ``log``/``cos`` rounding, can move a value sitting on a rounding edge by 1 DN).
    """
    layout = layout_for(trace.variant) if layout is None else layout
    if layout not in LAYOUTS:
        raise InputError("layout", f"one of {', '.join(LAYOUTS)}", layout)
    projector = as_projector(projector)
    mi, dr = trace.modules()
    n_frames, n_pixels = len(sequence.frames), trace.n_pixels
    if n_frames * n_pixels >= 1 << 32:  # the frames' UInt32 indices; before any allocation
        raise InputError("sequence", f"fewer than {(1 << 32) // n_pixels} frames", n_frames)
    table, code, lengths = _device_table(trace, sequence, projector)
    weight = tap_weights(trace, projector, projector_intrinsics)
    dr.eval(weight)
    noisy = sensor.noisy
    prnu, dsnu = pixel_patterns(trace.variant, sensor, n_pixels) if noisy else (None, None)
    pose = _Pose(
        mi=mi, dr=dr, trace=trace, projector=projector, sensor=sensor, n_frames=n_frames,
        weight=weight, table=table, code=code, lengths=lengths,
        keys=frame_keys(mi, seed, np.arange(n_frames)) if noisy else None,
        prnu=prnu, dsnu=dsnu, gain=dr.opaque(mi.Float, float(exposure)), out=None,
        saturated=dr.full(mi.Bool, False, n_pixels),
    )  # fmt: skip
    kernel = _pixel_kernel if layout == LAYOUT_PIXEL else _frame_pixel_kernel
    frames_per_kernel = max(1, min(n_frames, _MAX_LANES // n_pixels))
    if layout == LAYOUT_PIXEL or frames_per_kernel < n_frames:  # else the kernel's own result
        pose.out = dr.empty(pose.integer, n_frames * n_pixels)
    for first in range(0, n_frames, frames_per_kernel):
        kernel(pose, first, min(frames_per_kernel, n_frames - first))
    return DeviceFrames(
        data=pose.out, n_frames=n_frames, height=trace.height, width=trace.width,
        dtype=sensor.dtype, saturated=pose.saturated, variant=trace.variant,
    )  # fmt: skip


def synthesize_digital(
    trace: Trace,
    sequence: Any,
    projector: ProjectorModel | str,
    sensor: Sensor,
    exposure: float,
    seed: int = 0,
    projector_intrinsics: Any | None = None,
    layout: str | None = None,
) -> np.ndarray:
    """(F, H, W) digital frames of a host :class:`Trace` synthesised on its device
    (:func:`synthesize_on_device` after one upload, one transfer back)."""
    device = DeviceTrace.from_trace(trace)
    return synthesize_on_device(
        device, sequence, projector, sensor, exposure, seed, projector_intrinsics, layout
    ).numpy()
