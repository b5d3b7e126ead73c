"""Fringe decoding on Dr.Jit arrays: :meth:`virtus.patterns.PatternSequence.decode`, run where
the frames were rendered (on the GPU with ``cuda_ad_rgb``), the frames never copied to the host.

Frames on the device are one flat array of ``F * H * W`` values, frame-major: frame ``f``
occupies ``[f P, (f + 1) P)`` with ``P = H W`` pixels in row-major order (``pixel = row W +
col``); its type is ``UInt8`` (8-bit sensors), ``UInt32`` (deeper sensors) or ``Float``.
:func:`decode_on_device` vectorises over the ``P`` pixels and unrolls the frames in Python,
so one decode is one fused kernel; it follows the sequence's own plan
(:meth:`~virtus.patterns.PatternSequence.plans`: phase sets, code frames per bit, unwrapping
method) and the formulas of :mod:`virtus.patterns.phase` step by step.
:meth:`DeviceDecode.to_host` brings the result back in one transfer as the host's
:class:`~virtus.patterns.DecodeResult`, optionally finishing with the host's neighbour check.

Precision. The per-pixel arithmetic (phase sums, ``atan2``, unwrapping, residual and range
checks) runs in float64 by default: a few hundred operations per pixel, a small cost next to
reading the frames even on GPUs with slow float64, and every decision of the host decoder
comes out the same but for exact ties. Measured on noisy, partly dark 960 x 960 frames of
twelve sequences: phases within 6e-14 rad, identical fringe orders, masks and flags except
where integer frames put a decision exactly on its edge in exact arithmetic (6 steps give
phases of exact multiples of pi / 6, and a multi-wavelength residual of exactly pi / 2),
which the host's and the device's last-bit rounding then settle either way: 6 (llvm) and 9
(cuda, H100) of 1.8e6 pixels, for the multi-wavelength sequence only.
``precision="float32"`` rounds the sums of up to a few thousand DN and the absolute phase
(one float32 unit is 3e-5 rad at 320 rad): phases agree to 1e-5 rad RMS, 4e-5 rad at most,
and pixels that close to a decision edge decide either way: 2.4e-5 of the pixels in the
masks and flags of temporal and heterodyne decodes (residual limits), 2e-6 in the fringe
orders of codes without the complementary frame (the branch edge, where the host is as
arbitrary). In both precisions the code threshold ``(mean white + mean black) / 2`` or the
phase background is formed and compared in float64 from exact integer sums, and the
saturation test compares integers, so code bits are read exactly as on the host.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any, overload

import numpy as np

from virtus.checks import finite, positive, positive_int
from virtus.errors import InputError, VirtusError
from virtus.patterns import (
    CODE_FLAG_RAD,
    DIRECTIONS,
    RESIDUAL_FLAG_RAD,
    BitCode,
    DecodePlan,
    DecodeResult,
    PatternSequence,
)
from virtus.patterns import phase as _phase
from virtus.patterns.decode import _RESIDUAL_INVALID_RAD, warn_if_flagged
from virtus.render.backend import mitsuba, variant_of

__all__ = [
    "HOST_FIELDS",
    "DeviceDecode",
    "decode_on_device",
    "frames_to_device",
    "host_field_names",
    "supports",
]

TWO_PI = _phase.TWO_PI
#: Unwrapping methods (``DecodePlan.method``) this module decodes.
METHODS = ("code", "temporal", "heterodyne", "window")
#: Precisions of the per-pixel arithmetic.
PRECISIONS = ("float32", "float64")
#: Bit planes of the packed validity word that :meth:`DeviceDecode.to_host` transfers.
_BIT_MASK_V, _BIT_MASK_H, _BIT_FLAG_V, _BIT_FLAG_H = 1, 2, 4, 8
_PER_DIRECTION = tuple(f"{kind}_{d}" for kind in ("phase", "modulation") for d in DIRECTIONS)
#: :class:`~virtus.patterns.DecodeResult` fields (its real maps) that
#: ``DeviceDecode.to_host(only=...)`` transfers alone.
HOST_FIELDS = ("proj_uv", "background", "modulation", *_PER_DIRECTION)


@dataclass(frozen=True, eq=False)
class DeviceDecode:
    """A decode held on the device: Dr.Jit arrays of ``P = height * width`` pixels each,
    row-major (``pixel = row * width + col``), lazily evaluated (``dr.eval(*d.arrays())``
    materialises them in one kernel). Real maps are ``Float64`` (``Float`` when decoded
    with ``precision="float32"``), masks and flags ``Bool``.

    Attributes
    ----------
    phase_v, phase_h : Float, absolute phase (rad) of the direction's finest period, NaN
        where invalid or the direction is absent.
    mask_v, mask_h : Bool, valid per direction (False for an absent direction).
    mask : Bool, valid in every direction the sequence has.
    flagged_v, flagged_h : Bool, likely fringe-order errors found per pixel (complementary
        code, unwrapping residual), within the direction's mask.
    modulation_v, modulation_h : Float, modulation ``B`` (frame units), the smallest over
        the direction's phase sets; NaN for an absent direction.
    modulation : Float, the smallest ``B`` over every phase set.
    background : Float, background ``A`` (frame units), the mean over every phase set.
    u_p, v_p : Float, projector coordinates (px), NaN where the direction is invalid.
    wrapped_v, wrapped_h : Float, wrapped phase (rad) of the finest period (offset and sign
        removed) for the host's neighbour check; NaN for an absent direction.
    height, width : camera image size (px).
    full_scale : the frames' full scale (frame units).
    frame_count : frames of the decoded sequence.
    directions : directions the sequence has.
    variant : the Mitsuba variant the arrays live in.
    """

    phase_v: Any
    phase_h: Any
    mask_v: Any
    mask_h: Any
    mask: Any
    flagged_v: Any
    flagged_h: Any
    modulation_v: Any
    modulation_h: Any
    modulation: Any
    background: Any
    u_p: Any
    v_p: Any
    wrapped_v: Any
    wrapped_h: Any
    height: int
    width: int
    full_scale: float
    frame_count: int
    directions: tuple[str, ...]
    variant: str

    def arrays(self) -> tuple[Any, ...]:
        """Every Dr.Jit array of the decode, in field order (for ``dr.eval``)."""
        return tuple(getattr(self, f.name) for f in fields(self)[:15])

    @overload
    def to_host(
        self,
        sequence: PatternSequence,
        *,
        neighbour_check: bool | None = ...,
        repair: bool = ...,
        only: None = ...,
    ) -> DecodeResult: ...

    @overload
    def to_host(
        self,
        sequence: PatternSequence,
        *,
        neighbour_check: bool | None = ...,
        repair: bool = ...,
        only: Sequence[str],
    ) -> dict[str, np.ndarray]: ...

    def to_host(
        self,
        sequence: PatternSequence,
        *,
        neighbour_check: bool | None = False,
        repair: bool = False,
        only: Sequence[str] | None = None,
    ) -> DecodeResult | dict[str, np.ndarray]:
        """The decode as the host's :class:`~virtus.patterns.DecodeResult`, from one transfer.

        Parameters
        ----------
        sequence : the sequence that was decoded.
        neighbour_check : ``False`` (default): the result equals
            ``sequence.decode(frames, neighbour_check=False)``. ``None``: run the host's
            neighbour check (``phase.order_consistency``) where ``decode`` runs it by
            default, i.e. for directions without a per-pixel check (codes without the
            complementary frame, the window method); ``True``: for every direction. With
            ``None`` or ``True`` the result equals ``sequence.decode(frames,
            neighbour_check=...)``. The check runs on the host (scipy) on the transferred
            phase and wrapped phase.
        repair : as ``decode(repair=True)``: give flagged pixels the order their neighbours
            agree on (turns the neighbour check on).
        only : names of :data:`HOST_FIELDS` (e.g. ``("proj_uv", "background")``): just these
            fields of the result, bit for bit. Without a neighbour check they are formed on
            the device and transferred alone (views of one float64 buffer; the device fields
            stay unevaluated); with one, they are picked from the whole result.

        Returns
        -------
        :class:`~virtus.patterns.DecodeResult` (float64 maps of the device's values), or with
        ``only`` a dict of its fields by name; a :class:`~virtus.patterns.DecodeWarning` is
        issued as by ``decode``.
        """
        if len(sequence) != self.frame_count or sequence.directions != self.directions:
            raise InputError(
                "sequence",
                f"the decoded sequence ({self.frame_count} frames, directions {self.directions})",
                f"{len(sequence)} frames, directions {sequence.directions}",
            )
        checks = {
            d: sequence.runs_neighbour_check(d, neighbour_check, repair) for d in self.directions
        }
        if only is not None:
            names = host_field_names(only)
            if not any(checks.values()):
                return self._host_fields(sequence, names)
            whole = self.to_host(sequence, neighbour_check=neighbour_check, repair=repair)
            return {name: getattr(whole, name) for name in names}
        planes = self._host_planes(any(checks.values()))
        shape = (self.height, self.width)
        bits = planes.pop("bits").astype(np.uint8)
        nan = np.full(shape, np.nan)
        out: dict[str, dict[str, Any]] = {}
        repaired = 0
        for index, direction in enumerate(DIRECTIONS):
            if direction not in self.directions:
                none = np.zeros(shape, dtype=bool)
                out[direction] = {"phase": nan, "valid": none, "flags": none, "modulation": nan}
                continue
            decoded = {
                "phase": planes[f"phase_{direction}"],
                "valid": (bits & (_BIT_MASK_V << index)) != 0,
                "flags": (bits & (_BIT_FLAG_V << index)) != 0,
                "modulation": planes[f"modulation_{direction}"],
            }
            if checks[direction]:
                # As in PatternSequence.decode: flag (or repair) against neighbours, then
                # keep flags and phases of valid pixels only.
                decoded["wrapped"] = planes[f"wrapped_{direction}"]
                repaired += sequence.check_neighbours(direction, decoded, repair)
                decoded["flags"] &= decoded["valid"]
                decoded["phase"] = np.where(decoded["valid"], decoded["phase"], np.nan)
            out[direction] = decoded
        present = [out[d]["modulation"] for d in self.directions]
        return sequence.assemble_result(
            out,
            modulation=np.minimum.reduce(present) if present else nan,
            background=planes["background"] if present else nan,
            repaired=repaired,
            full_scale=self.full_scale,
        )

    def _host_fields(self, sequence: PatternSequence, names: list[str]) -> dict[str, np.ndarray]:
        """``to_host(only=names)`` without a neighbour check: the fields formed on the device
        (one kernel, with the masks the flag warning counts), copied into one buffer (field
        after field, components interleaved per pixel) and transferred once."""
        mi, dr, _ = mitsuba(self.variant)
        pixels = self.height * self.width
        planes = {name: self._device_field(sequence, name) for name in names}
        valid, flagged = self.mask_v | self.mask_h, self.flagged_v | self.flagged_h
        # Scattered unevaluated, the decode is split over kernels that each recompute part.
        dr.eval(*(part for parts in planes.values() for part in parts), valid, flagged)
        starts = np.cumsum([0] + [len(parts) for parts in planes.values()]).tolist()
        buffer = dr.empty(mi.Float64, starts[-1] * pixels)
        pixel = dr.arange(mi.UInt32, pixels)
        size = dr.opaque(mi.UInt32, pixels)  # a kernel parameter: one kernel for every size
        for start, parts in zip(starts[:-1], planes.values(), strict=True):
            for component, value in enumerate(parts):
                dr.scatter(buffer, value, size * start + pixel * len(parts) + component)
        host, out = buffer.numpy(), {}
        for start, (name, parts) in zip(starts[:-1], planes.items(), strict=True):
            shape = (self.height, self.width, len(parts))[: 2 + (len(parts) > 1)]
            out[name] = host[start * pixels : (start + len(parts)) * pixels].reshape(shape)
        counts = (int(dr.count(value)[0]) for value in (valid, flagged))
        warn_if_flagged(*counts, stacklevel=3)  # to_host's line, as the whole result's
        return out

    def _device_field(self, sequence: PatternSequence, name: str) -> list[Any]:
        """Float64 device values (per component) of field ``name``, as ``to_host`` forms it."""
        mi, _, _ = mitsuba(self.variant)
        if name == "proj_uv":  # PatternSequence._coordinate; NaN for an absent direction
            phases = [mi.Float64(getattr(self, f"phase_{d}")) for d in DIRECTIONS]
            return [
                _coordinate(sequence, d, phase) if d in self.directions else phase
                for d, phase in zip(DIRECTIONS, phases, strict=True)
            ]
        # "modulation": the host's minimum of the directions' minima over their phase sets
        # is the minimum over all sets (exact; never NaN, frames are finite).
        return [mi.Float64(getattr(self, name))]

    def _host_planes(self, wrapped: bool) -> dict[str, np.ndarray]:
        """(H, W) float64 host copies of the maps ``to_host`` needs, from one transfer: the
        planes are concatenated on the device (validity bits packed into one float plane)."""
        _, dr, _ = mitsuba(self.variant)
        dr.eval(*self.arrays())  # materialise every field once, for later device use too
        real = type(self.phase_v)
        bits = dr.zeros(real, self.height * self.width)
        for flag, value in (
            (_BIT_MASK_V, self.mask_v),
            (_BIT_MASK_H, self.mask_h),
            (_BIT_FLAG_V, self.flagged_v),
            (_BIT_FLAG_H, self.flagged_h),
        ):
            bits += dr.select(value, flag, 0.0)
        names = ["background"]
        for direction in self.directions:
            names += [f"phase_{direction}", f"modulation_{direction}"]
            if wrapped:
                names.append(f"wrapped_{direction}")
        host = dr.concat([bits, *(getattr(self, name) for name in names)]).numpy()
        names.insert(0, "bits")
        shape = (self.height, self.width)
        return {
            name: np.asarray(part, dtype=np.float64).reshape(shape)
            for name, part in zip(names, np.split(host, len(names)), strict=True)
        }


def host_field_names(only: Sequence[str]) -> list[str]:
    """``only`` of :meth:`DeviceDecode.to_host` checked: distinct names of
    :data:`HOST_FIELDS` (a single name may be given as a string)."""
    names = [only] if isinstance(only, str) else list(only)
    if not names or len(set(names)) != len(names) or not set(names) <= set(HOST_FIELDS):
        raise InputError("only", f"distinct names of {tuple(HOST_FIELDS)}", only)
    return names


def supports(sequence: PatternSequence) -> bool:
    """True when :func:`decode_on_device` decodes ``sequence`` (every plan uses a method of
    :data:`METHODS`, codes of at most 31 bits with the complement). Not decoded here:
    directions of a code alone (``"code_only"``, e.g. OpenCV's Gray code): decode those on
    the host, :meth:`PatternSequence.decode <virtus.patterns.PatternSequence.decode>`."""
    for plan in sequence.plans().values():
        if plan.method not in METHODS:
            return False
        if plan.code is not None and plan.code.coding.bits + plan.code.coding.complement > 31:
            return False
    return True


def frames_to_device(frames: np.ndarray, variant: str | None = None) -> Any:
    """Upload host frames in the device layout (for tests and captures read from disk).

    Parameters
    ----------
    frames : (F, H, W) uint8, other unsigned or non-negative integer, or floating frames.
    variant : Mitsuba variant (default: :func:`virtus.render.backend.choose_variant`).

    Returns
    -------
    Flat Dr.Jit array of ``F * H * W`` values, frame-major, row-major pixels: ``UInt8`` for
    uint8 frames, ``UInt32`` for other integers, ``Float`` (float32) for floating frames.
    """
    mi, _, _ = mitsuba(variant)
    stack = np.asarray(frames)
    if stack.ndim != 3:
        raise InputError("frames", "an array of shape (F, H, W)", f"shape {stack.shape}")
    flat = np.ascontiguousarray(stack).reshape(-1)
    if stack.dtype == np.uint8:
        return mi.UInt8(flat)
    if np.issubdtype(stack.dtype, np.integer):
        if flat.size and (flat.min() < 0 or flat.max() > np.iinfo(np.uint32).max):
            raise InputError("frames", "integer values in 0..2**32 - 1", (flat.min(), flat.max()))
        return mi.UInt32(flat.astype(np.uint32))
    if np.issubdtype(stack.dtype, np.floating):
        return mi.Float(flat.astype(np.float32))
    raise InputError("frames", "an integer or floating array", f"dtype {stack.dtype}")


def decode_on_device(
    frames: Any,
    sequence: PatternSequence,
    height: int,
    width: int,
    *,
    variant: str | None = None,
    min_modulation: float = 0.02,
    saturation_level: float | None = None,
    full_scale: float | None = None,
    precision: str = "float64",
) -> DeviceDecode:
    """Decode device frames of ``sequence`` on the device: the per-pixel part of
    :meth:`virtus.patterns.PatternSequence.decode` (same arguments and defaults).

    Parameters
    ----------
    frames : flat Dr.Jit ``UInt8``, ``UInt32`` or ``Float`` array of ``F * H * W`` camera
        values in frame-major, row-major order (module docstring), ``F = len(sequence)``.
    sequence : the projected sequence (:func:`supports` says whether it can be decoded here).
    height, width : camera image size (px).
    variant : Mitsuba variant; default the one of the frames' backend.
    min_modulation : valid where every phase set of the direction has ``B >=
        min_modulation * full_scale``.
    saturation_level : a pixel reaching this value (frame units) in any phase frame of a
        direction is invalid in it; ``None`` disables the check.
    full_scale : the frames' full scale: default 255 for ``UInt8`` frames and 1.0 for
        ``Float`` frames; required for ``UInt32`` frames (the type does not say the sensor's
        bit depth). Frames above it are refused (checked on the device, one reduction, only
        where the type allows such values).
    precision : ``"float64"`` (default; the host's decisions exactly) or ``"float32"`` for
        the per-pixel arithmetic and the returned maps (module docstring).

    Returns
    -------
    :class:`DeviceDecode`, lazily evaluated; :meth:`DeviceDecode.to_host` gives the host's
    result without the neighbour check, or with it.

    Raises
    ------
    InputError : bad frames (type, size, values above ``full_scale`` or not finite) or options.
    VirtusError : a sequence this module does not decode (see :func:`supports`).
    """
    if not supports(sequence):
        raise VirtusError(
            f"decode_on_device: unsupported sequence (methods "
            f"{sorted({p.method for p in sequence.plans().values()})}, "
            f"supported {list(METHODS)}, codes of at most 31 bits); decode it on the host "
            "with PatternSequence.decode"
        )
    if precision not in PRECISIONS:
        raise InputError("precision", f"one of {PRECISIONS}", precision)
    mi, dr, name = _backend(frames, variant)
    height = positive_int("height", height)
    width = positive_int("width", width)
    pixels = height * width
    if dr.width(frames) != len(sequence) * pixels:
        raise InputError(
            "frames",
            f"{len(sequence)} x {height} x {width} = {len(sequence) * pixels} values",
            dr.width(frames),
        )
    cut = finite("min_modulation", min_modulation)
    if not 0.0 <= cut < 1.0:
        raise InputError("min_modulation", "a fraction of full scale in [0, 1)", min_modulation)
    level = None if saturation_level is None else finite("saturation_level", saturation_level)
    reader = FrameReader(mi, dr, frames, pixels, precision)
    full_scale = _full_scale(reader, full_scale)
    _check_values(reader, full_scale)
    threshold = _threshold(reader, sequence)
    real = reader.real
    # Option values as kernel parameters: other values reuse the compiled kernel.
    min_level = dr.opaque(real, cut * full_scale)
    nan = dr.full(real, math.nan, pixels)
    out: dict[str, dict[str, Any]] = {}
    modulations: list[Any] = []
    backgrounds: list[Any] = []
    for direction in DIRECTIONS:
        plan = sequence.plan(direction)
        if plan is None:
            none = dr.full(mi.Bool, False, pixels)
            out[direction] = {"phase": nan, "valid": none, "flags": none}
            out[direction] |= {"modulation": nan, "wrapped": nan, "coordinate": nan}
            continue
        decoded = _decode_direction(reader, sequence, direction, plan, threshold, min_level, level)
        modulations += decoded.pop("modulations")
        backgrounds += decoded.pop("backgrounds")
        valid = decoded["valid"]
        decoded["flags"] = decoded["flags"] & valid
        decoded["phase"] = dr.select(valid, decoded["phase"], math.nan)
        decoded["coordinate"] = _coordinate(sequence, direction, decoded["phase"])
        out[direction] = decoded
    mask = dr.full(mi.Bool, bool(sequence.directions), pixels)
    for direction in sequence.directions:
        mask = mask & out[direction]["valid"]
    modulation = nan if not modulations else functools.reduce(dr.minimum, modulations)
    background = nan if not backgrounds else _sum(backgrounds) / len(backgrounds)
    return DeviceDecode(
        phase_v=out["v"]["phase"],
        phase_h=out["h"]["phase"],
        mask_v=out["v"]["valid"],
        mask_h=out["h"]["valid"],
        mask=mask,
        flagged_v=out["v"]["flags"],
        flagged_h=out["h"]["flags"],
        modulation_v=out["v"]["modulation"],
        modulation_h=out["h"]["modulation"],
        modulation=modulation,
        background=background,
        u_p=out["v"]["coordinate"],
        v_p=out["h"]["coordinate"],
        wrapped_v=out["v"]["wrapped"],
        wrapped_h=out["h"]["wrapped"],
        height=height,
        width=width,
        full_scale=full_scale,
        frame_count=len(sequence),
        directions=sequence.directions,
        variant=name,
    )


# --- frames -----------------------------------------------------------------------------


def _backend(frames: Any, variant: str | None) -> tuple[Any, Any, str]:
    """``(mi, dr, variant)`` for ``frames``: the given variant, else the frames' backend's."""
    import drjit as dr

    if not (dr.is_jit_v(frames) and dr.depth_v(frames) == 1):
        raise InputError(
            "frames", "a flat Dr.Jit array (see frames_to_device)", type(frames).__name__
        )
    if variant is None:
        variant = variant_of(frames)
    mi, dr, name = mitsuba(variant)
    if dr.backend_v(frames) != dr.backend_v(mi.Float):
        raise InputError("frames", f"an array of the {name} backend", type(frames).__name__)
    return mi, dr, name


class FrameReader:
    """Gathers frame ``f`` of the flat frame array for every pixel, once per frame.

    ``raw(f)`` is the stored type, ``value(f)`` the working float type (``real``),
    ``exact(f)`` float64 (exact for integer frames: thresholds compare in it).
    """

    def __init__(self, mi: Any, dr: Any, frames: Any, pixels: int, precision: str) -> None:
        self.mi, self.dr = mi, dr
        kinds = {dr.VarType.UInt8: "uint8", dr.VarType.UInt32: "uint32"}
        kinds[dr.VarType.Float32] = "float"
        self.kind = kinds.get(dr.type_v(frames))
        if self.kind is None:
            raise InputError("frames", "a UInt8, UInt32 or Float array", type(frames).__name__)
        self.stored = {"uint8": mi.UInt8, "uint32": mi.UInt32, "float": mi.Float}[self.kind]
        self.frames = self.stored(frames)
        self.real = mi.Float if precision == "float32" else mi.Float64
        self.pixels = pixels
        # The frame stride is a kernel parameter, so one kernel serves every image size.
        self._pixel = dr.arange(mi.UInt32, pixels)
        self._stride = dr.opaque(mi.UInt32, pixels)
        self._raw: dict[int, Any] = {}

    @property
    def integer(self) -> bool:
        return self.kind != "float"

    def raw(self, index: int) -> Any:
        if index not in self._raw:
            offset = self._pixel + self._stride * index
            self._raw[index] = self.dr.gather(self.stored, self.frames, offset)
        return self._raw[index]

    def value(self, index: int) -> Any:
        return self.real(self.raw(index))

    def exact(self, index: int) -> Any:
        return self.mi.Float64(self.raw(index))

    def at_least(self, index: int, level: float) -> Any:
        """Bool: frame ``index >= level``, as numpy compares it (integers exactly, float32
        frames in float32)."""
        mi, dr = self.mi, self.dr
        if not self.integer:
            return self.raw(index) >= dr.opaque(mi.Float, float(np.float32(level)))
        if level <= 0.0:
            return dr.full(mi.Bool, True, self.pixels)
        if level > np.iinfo(np.uint32).max:
            return dr.full(mi.Bool, False, self.pixels)
        return mi.UInt32(self.raw(index)) >= dr.opaque(mi.UInt32, math.ceil(level))


def _full_scale(reader: FrameReader, full_scale: float | None) -> float:
    if full_scale is not None:
        return positive("full_scale", full_scale)
    if reader.kind == "uint32":
        raise InputError(
            "full_scale", "the sensor's full scale for UInt32 frames (e.g. 4095, 65535)", None
        )
    return 255.0 if reader.kind == "uint8" else 1.0


def _check_values(reader: FrameReader, full_scale: float) -> None:
    """Refuse frames above ``full_scale`` (and non-finite float frames), as ``decode`` does:
    one device reduction, skipped where the frame type cannot exceed it."""
    dr = reader.dr
    if reader.kind == "uint8" and full_scale >= 255.0:
        return
    frames = reader.frames
    if reader.integer:
        peak = float(dr.max(frames)[0])
    else:
        peak = float(dr.max(dr.select(dr.isfinite(frames), frames, math.inf))[0])
        if math.isinf(peak):
            raise InputError("frames", "finite values", "non-finite entries")
    if peak > full_scale:
        raise InputError("frames", f"values <= full_scale ({full_scale:g}); pass full_scale", peak)


def _threshold(reader: FrameReader, sequence: PatternSequence) -> Any | None:
    """``(mean white + mean black) / 2`` in float64 (as the host forms it; exact sums of
    integer frames), or None without both kinds of frame."""
    whites = [i for i, f in enumerate(sequence.frames) if f.kind == "white"]
    blacks = [i for i, f in enumerate(sequence.frames) if f.kind == "black"]
    if not whites or not blacks:
        return None
    white = _sum(reader.exact(i) for i in whites) / len(whites)
    black = _sum(reader.exact(i) for i in blacks) / len(blacks)
    return 0.5 * (white + black)


def _sum(values: Any) -> Any:
    values = list(values)
    return sum(values[1:], values[0])


# --- one direction ----------------------------------------------------------------------


def wrapped_phase_set(reader: FrameReader, phase_set: Any) -> tuple[Any, Any, Any]:
    """Wrapped phase (rad, ``[-pi, pi)``, offset and sign removed), background and
    modulation of one phase set (``PhaseCoding.wrapped`` / ``phase.wrapped_phase``)."""
    dr, real = reader.dr, reader.real
    steps = len(phase_set.indices)
    shifts = TWO_PI * np.arange(1, steps + 1) / steps
    total = cosine = sine = dr.zeros(real, reader.pixels)
    for index, shift in zip(phase_set.indices, shifts, strict=True):
        value = reader.value(index)
        total = total + value
        cosine = dr.fma(value, float(np.cos(shift)), cosine)
        sine = dr.fma(value, float(np.sin(shift)), sine)
    # sum I_n cos d_n = (N B / 2) cos phi and sum I_n sin d_n = -(N B / 2) sin phi.
    phi = dr.atan2(-sine, cosine)
    phi = dr.select(phi >= math.pi, phi - TWO_PI, phi)  # +pi belongs to [-pi, pi) as -pi
    background = total / steps
    modulation = (2.0 / steps) * dr.sqrt(dr.fma(cosine, cosine, sine * sine))
    coding = phase_set.coding
    if coding.sign != 1 or coding.offset != 0.0:
        phi = wrap_phase(dr, coding.sign * phi - coding.offset)
    return phi, background, modulation


def wrap_phase(dr: Any, value: Any) -> Any:
    """``phase.wrap``: to ``[-pi, pi)``, rounding folded back."""
    wrapped = value - TWO_PI * dr.floor((value + math.pi) / TWO_PI)
    wrapped = dr.select(wrapped >= math.pi, wrapped - TWO_PI, wrapped)
    return dr.select(wrapped < -math.pi, wrapped + TWO_PI, wrapped)


def _decode_direction(
    reader: FrameReader,
    sequence: PatternSequence,
    direction: str,
    plan: DecodePlan,
    threshold: Any | None,
    min_level: Any,
    saturation_level: float | None,
) -> dict[str, Any]:
    """``PatternSequence._decode_direction`` on the device: absolute phase of the finest
    period, validity, per-pixel flags, the finest wrapped phase, and each set's modulation
    and background."""
    mi, dr = reader.mi, reader.dr
    wrapped, modulations, backgrounds = [], [], []
    valid = dr.full(mi.Bool, True, reader.pixels)
    for phase_set in plan.sets:
        phi, background, modulation = wrapped_phase_set(reader, phase_set)
        valid = valid & (modulation >= min_level)
        if saturation_level is not None:
            for index in phase_set.indices:
                valid = valid & ~reader.at_least(index, saturation_level)
        wrapped.append(phi)
        modulations.append(modulation)
        backgrounds.append(background)
    flags = dr.full(mi.Bool, False, reader.pixels)
    extent = sequence.extent(direction)
    if plan.method == "code":
        absolute, flags = _unwrap_code(reader, sequence, direction, plan, wrapped[0], threshold)
    elif plan.method in ("temporal", "heterodyne"):
        unwrap = _unwrap_temporal if plan.method == "temporal" else _unwrap_heterodyne
        absolute, residual = unwrap(dr, wrapped, plan.periods, extent)
        valid = valid & (residual <= _RESIDUAL_INVALID_RAD)
        flags = residual > RESIDUAL_FLAG_RAD
    else:
        absolute = _in_window(dr, wrapped[0], plan.periods[0], extent)
    coordinate = _coordinate(sequence, direction, absolute)
    valid = valid & (coordinate >= -1.0) & (coordinate <= sequence.span(direction))
    return {
        "phase": absolute,
        "valid": valid,
        "flags": flags,
        "wrapped": wrapped[0],
        "modulation": functools.reduce(dr.minimum, modulations),
        "modulations": modulations,
        "backgrounds": backgrounds,
    }


def _coordinate(sequence: PatternSequence, direction: str, absolute: Any) -> Any:
    """``PatternSequence._coordinate``: projector px from the finest period's phase."""
    plan = sequence.plans()[direction]
    pattern = absolute * (plan.periods[0] / TWO_PI)
    scale = sequence.axis_scale(direction)
    return pattern if scale == 1.0 else pattern / scale


def _unwrap_code(
    reader: FrameReader,
    sequence: PatternSequence,
    direction: str,
    plan: DecodePlan,
    phi: Any,
    threshold: Any | None,
) -> tuple[Any, Any]:
    """Absolute phase and flags of a phase set plus its code: the bits read as
    ``_read_bits`` reads them, the index as ``BitCode.decode``, the branch nearest
    ``BitCode.predicted_phase`` (``phase.unwrap_nearest``)."""
    mi, dr, real = reader.mi, reader.dr, reader.real
    code = plan.code
    coding = code.coding
    if threshold is None:
        # The finest set's background, formed in float64 as the host does (sum / N).
        indices = plan.sets[0].indices
        threshold = _sum(reader.exact(i) for i in indices) / len(indices)
    index = dr.zeros(mi.UInt32, reader.pixels)
    binary = dr.full(mi.Bool, False, reader.pixels)
    for normal, inverse in zip(code.normal, code.inverse, strict=True):
        if normal is not None and inverse is not None:
            bit = reader.raw(normal) > reader.raw(inverse)
        elif normal is not None:
            bit = reader.exact(normal) > threshold
        else:
            bit = reader.exact(inverse) <= threshold
        # Gray -> binary: b_1 = g_1, b_i = b_(i-1) XOR g_i (phase.gray_bits_to_order).
        binary = binary ^ bit if coding.code == "gray" else bit
        index = (index << 1) | dr.select(binary, 1, 0)
    table, slope, intercept = _prediction(
        coding, sequence.span(direction), sequence.axis_scale(direction)
    )
    inside = index < len(table)
    predicted = dr.select(
        inside,
        dr.gather(real, real(table), dr.minimum(index, len(table) - 1)),
        intercept + slope * real(index),
    )
    order = dr.ceil((predicted - phi - math.pi) / TWO_PI)
    absolute = phi + TWO_PI * order
    if coding.complement:
        flags = dr.abs(absolute - predicted) > CODE_FLAG_RAD
    else:
        flags = dr.full(mi.Bool, False, reader.pixels)
    return absolute, flags


@functools.lru_cache(maxsize=64)
def _prediction(coding: BitCode, span: int, scale: float) -> tuple[np.ndarray, float, float]:
    """``BitCode.predicted_phase`` tabulated on the host (rad), once per code: the table
    covers every index a projector pixel shows (and one more); beyond it the host's value is
    the nominal cell centre, affine in the index: ``intercept + slope * index``."""
    last = int(coding.half_index(np.float64(scale * (span - 1))))
    count = (last if coding.complement else last >> 1) + 2
    table = coding.predicted_phase(np.arange(count), span, scale)
    beyond = coding.predicted_phase(np.array([count, count + 1]), span, scale)
    slope = float(beyond[1] - beyond[0])
    return table, slope, float(beyond[0] - slope * count)


def _in_window(dr: Any, phi: Any, period: float, extent: float) -> Any:
    """``phase.absolute_phase_in_window``: the branch in the window of one period centred
    on the axis."""
    centre = TWO_PI * 0.5 * (extent - 1.0) / period
    return wrap_phase(dr, phi - centre) + centre


def _with_reference(dr: Any, fine: Any, reference: Any, ratio: float) -> tuple[Any, Any]:
    """``phase.unwrap_with_reference``: the fine branch nearest ``reference * ratio``, and
    the residual (prediction minus result, rad)."""
    predicted = reference * ratio
    order = dr.round((predicted - fine) / TWO_PI)  # ties to even, as numpy's rint
    absolute = fine + TWO_PI * order
    return absolute, predicted - absolute


def _unwrap_temporal(
    dr: Any, phases: list[Any], periods: tuple[float, ...], extent: float
) -> tuple[Any, Any]:
    """``phase.unwrap_temporal`` (periods ascending, as the plan orders them): the longest
    period absolute in its window, each shorter one from the previous."""
    order = np.argsort(periods)[::-1]  # longest first
    absolute = _in_window(dr, phases[order[0]], periods[order[0]], extent)
    residual = dr.zeros(type(absolute), dr.width(absolute))
    reference = periods[order[0]]
    for index in order[1:]:
        absolute, step = _with_reference(dr, phases[index], absolute, reference / periods[index])
        residual = dr.maximum(residual, dr.abs(step))
        reference = periods[index]
    return absolute, residual


def _unwrap_heterodyne(
    dr: Any, phases: list[Any], periods: tuple[float, ...], extent: float
) -> tuple[Any, Any]:
    """``phase.unwrap_heterodyne``: beats of the finest period with the others, coarsest
    beat absolute in its window, each finer beat and then the finest period from it."""
    finest = int(np.argmin(periods))
    fine_period, fine_phase = periods[finest], phases[finest]
    levels = sorted(
        (
            (_phase.beat_period(fine_period, periods[i]), i)
            for i in range(len(periods))
            if i != finest
        ),
        key=lambda level: -level[0],
    )
    beats = [(period, wrap_phase(dr, fine_phase - phases[i])) for period, i in levels]
    top_period, top_phase = beats[0]
    absolute = _in_window(dr, top_phase, top_period, extent)
    residual = dr.zeros(type(absolute), dr.width(absolute))
    reference = top_period
    for period, wrapped in [*beats[1:], (fine_period, fine_phase)]:
        absolute, step = _with_reference(dr, wrapped, absolute, reference / period)
        residual = dr.maximum(residual, dr.abs(step))
        reference = period
    return absolute, residual
