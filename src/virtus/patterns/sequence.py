"""Fringe pattern sequences as data: phase shifting, Gray and binary codes, temporal unwrapping.

A :class:`PatternSequence` is one object that encodes itself (:meth:`~PatternSequence.profile`,
:meth:`~PatternSequence.image`, :meth:`~PatternSequence.images`: what the projector shows)
and decodes camera images of itself (:meth:`~PatternSequence.decode`, math in
:mod:`virtus.patterns.phase`). Each frame is a :class:`Frame` (one record of plain fields); the
codings behind them, :class:`PhaseCoding` and :class:`BitCode`, encode and decode
themselves. Sequences are read from and written to a description file (below).

Conventions
-----------
* Projector coordinates ``(u_p, v_p)`` in px: the centre of projector pixel (col 0, row 0)
  is at ``(0, 0)``, column ``j`` covers ``u_p`` in ``[j - 0.5, j + 0.5)``; images are indexed
  ``[row, col]``.
* Vertical fringes (direction ``"v"``) vary along ``u_p`` (columns) and decode to
  ``phase_v``; horizontal fringes (``"h"``) vary along ``v_p`` (rows) and decode to
  ``phase_h``.
* Pattern coordinate ``w = scale * u`` along each axis (``scale`` per direction, default 1;
  e.g. 2 on the rows of a diamond-pixel DMD whose rows are counted in pairs). Periods are in
  pattern units; decoded ``proj_uv`` is in projector px.
* Absolute phase ``Phi = 2 pi w / T`` for a period ``T`` (any real ``T > 0``), so the phase
  origin is the centre of pixel 0 whatever ``T`` is.
* Phase frame ``n`` of ``N`` (``n = 1..N``) shows ``f(Phi + offset + sign 2 pi n / N)`` with
  ``f(x) = 0.5 + 0.5 cos x`` (``profile: sinusoidal``, the default; ``offset = 0``,
  ``sign = +1`` give the paper's ``I_n = A + B cos(Phi + 2 pi n / N)``). ``binary``: the
  square wave ``f(x) = 1`` where ``cos x >= 0`` (``x`` mod ``2 pi`` in ``[-pi/2, pi/2]``,
  closed: symmetric about the phase origin, so (P/2 + 1) of P pixels are on when P/4 is a
  whole number of pixels), evaluated at each projector pixel's centre. ``dithered``: the
  sinusoid at each pixel centre, thresholded by a 1-D ordered (Bayer) dither along the axis,
  threshold
  ``(b[j mod 8] + 1/2) / 8`` with ``b = (0, 4, 2, 6, 1, 5, 3, 7)`` for pixel ``j`` (a binary
  DMD approximation; its mean over 8 pixels follows the sinusoid to 1/16).
* Fringe order and codes. A code numbers intervals of a period: ``align: centre`` (the
  default) codes the order ``k = floor(w / T + 1/2)``, whose edges are where the wrapped
  phase of a zero-offset fringe jumps (``Phi - 2 pi k`` in ``[-pi, pi)``); ``align: edge``
  codes ``k = floor(w / T)``, whose edges are the period starts ``w = k T``, where the
  phase of a zero-offset fringe is ``0 mod 2 pi`` and ``cos`` is brightest. Labs that
  generate codes "aligned to the fringe edges" (e.g. LightCrafter pattern sets, with their
  phase taken in ``[0, 2 pi)``) use ``edge``: code ``floor(x / T)`` for projector column
  ``x`` with fringes ``cos(2 pi x / T + ...)``. Decoding uses either convention exactly.
* Code frames are evaluated at each projector pixel's centre ``w = scale j``. Bit frame
  ``bit`` (1 = most significant) of a ``bits``-bit code shows that bit of the code word of
  ``k``: the reflected binary (Gray) code ``k XOR (k >> 1)`` for kind ``gray``, ``k`` itself
  for kind ``binary``. Projection order is the order of the frames (most or least
  significant first). The complementary frame (``gray_complement``/``binary_complement``)
  shows the least significant bit of the ``(bits + 1)``-bit code word of the half-period
  index ``h = floor(2 w / T + s)`` (``s = 1`` centre, ``0`` edge), whose leading ``bits``
  bits are the code of ``k = h >> 1``: its edges lie half a period from the order edges.
  ``inverted: true`` frames show the inverse of their bit; a bit projected both ways is
  read by comparing the two images, a single one by a threshold.
* Every frame is 8-bit: each value shown is ``round(255 v) / 255``. White frames show 1,
  black and ``ignore`` frames 0 (ignored frames are in a capture but not decoded).

Decoding, per direction
-----------------------
* one phase set plus a complete code of the same period: unwrapped to the branch nearest the
  centre of the projector interval the code names (``phase.unwrap_nearest``). With the
  complementary frame that interval is half a period, so the code may be misread up to a
  quarter period; without it the interval is exactly the pixels of one code value, exact
  for ideal images but fragile within the phase noise of each code edge (where the two ends
  of a one-period cell have the same phase);
* two or more phase sets whose longest period covers the axis: multi-wavelength temporal
  unwrapping, longest to shortest (``phase.unwrap_temporal``);
* two or more phase sets otherwise: heterodyne, the longest beat with the finest must cover
  the axis (``phase.unwrap_heterodyne``);
* one phase set whose period covers the axis: absolute as it is.

Gray/binary frames are thresholded at ``(mean white + mean black) / 2`` when the sequence
has both, else at the phase background ``A``. Decoding says when it is likely wrong
(``DecodeResult.flagged``): pixels whose phase is off its half-period code cell by more
than :data:`CODE_FLAG_RAD`, whose temporal/heterodyne residual exceeds
:data:`RESIDUAL_FLAG_RAD`, or whose fringe order disagrees with their neighbours on a
continuous surface (``phase.order_consistency``; this catches a wrong description, e.g.
swapped alignment or bit order, which every single pixel would fit). Above
:data:`FLAG_WARN_FRACTION` of valid pixels a :class:`DecodeWarning` is issued.

Sequence description file (YAML or JSON, one schema)
----------------------------------------------------
Read by :func:`load_sequence_file` (``.yaml``, ``.yml``, ``.json``; at most 1 MB, UTF-8) and
:meth:`PatternSequence.from_dict`; unknown keys anywhere are refused. Top level::

    format: virtus.pattern_sequence   # optional; if present exactly this
    version: 2                        # optional; 1 or 2
    width: 912                        # projector columns (px)
    height: 1140                      # projector rows (px)
    scale: {v: 1, h: 2}               # optional pattern units per projector px, per direction
    description: free text            # optional
    blocks: [...]                     # compact form, or
    frames: [...]                     # the lossless per-frame form (what to_dict writes)
    files: [000.png, ...]             # optional, one image per frame (importing captures)
    bit_depth: 8                      # optional; only 8

``blocks`` (each expands into frames, in this order)::

    {kind: phase, direction: v, period: 18, steps: 18,        # or periods: [..] (one set each)
     profile: sinusoidal, offset: 0.0, sign: 1}                # optional, these defaults
    {kind: gray, direction: v, period: 18, bits: 6,            # kind gray or binary
     bit_order: msb_first, align: centre, complement: false,   # optional, these defaults
     inverted: false}       # true: each bit (and complement) as a pair: frame, then inverse
    {kind: white, count: 1}                                    # white, black or ignore

``frames`` entries are :meth:`Frame.to_dict` dicts: ``kind`` plus the fields that apply
(``direction``, ``period``, ``step``/``steps``, ``bit``/``bits``, ``profile``, ``offset``,
``sign``, ``align``, ``inverted``; defaults left out), optionally ``index`` (its position)
and ``file``. Counts are bounded: at most :data:`MAX_FRAMES` frames, :data:`MAX_BITS` bits.
Examples: ``examples/sequences/*.yaml``.

The paper's default, 52 frames (:func:`default_sequence`, ``examples/sequences/paper.yaml``;
:func:`build_sequence` order: per direction ``"v"`` then ``"h"``, per period ascending the
phase frames ``n = 1..N``, then the Gray frames most significant first, then the
complementary frame; white and black last)::

    [0:18]   phase, "v", T = 18 px, step 1..18
    [18:24]  gray,  "v", bit 1..6
    [24]     gray_complement, "v"
    [25:43]  phase, "h", T = 18 px, step 1..18
    [43:49]  gray,  "h", bit 1..6
    [49]     gray_complement, "h"
    [50]     white
    [51]     black
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import finite, positive, positive_int
from virtus.errors import InputError, VirtusError
from virtus.io.jsonio import write_json
from virtus.patterns import phase as _phase

__all__ = [
    "CODE_FLAG_RAD",
    "DEFAULT_HETERODYNE_PERIODS",
    "DIRECTIONS",
    "FLAG_WARN_FRACTION",
    "KINDS",
    "MAX_BITS",
    "MAX_FRAMES",
    "RESIDUAL_FLAG_RAD",
    "BitCode",
    "CodePlan",
    "DecodePlan",
    "DecodeResult",
    "DecodeWarning",
    "Frame",
    "PatternSequence",
    "PhaseCoding",
    "PhaseSet",
    "build_sequence",
    "default_sequence",
    "gray_bits_needed",
    "heterodyne_sequence",
    "load_sequence_file",
]

#: Frame kinds.
KINDS = (
    "phase",
    "gray",
    "binary",
    "gray_complement",
    "binary_complement",
    "white",
    "black",
    "ignore",
)
#: Code frame kinds -> the code they belong to.
_CODE_KINDS = {"gray": "gray", "binary": "binary"}
_COMPLEMENT_KINDS = {"gray_complement": "gray", "binary_complement": "binary"}
_UNIFORM_KINDS = ("white", "black", "ignore")
#: Fringe directions: "v" varies along u_p (columns), "h" along v_p (rows).
DIRECTIONS = ("v", "h")
#: Phase frame profiles.
PROFILES = ("sinusoidal", "binary", "dithered")
#: Code alignments: code edges where a zero-offset wrapped phase jumps, or at period starts.
ALIGNS = ("centre", "edge")
#: Projector levels: pattern values are multiples of 1 / LEVELS (8 bit).
LEVELS = 255
#: Most frames in one sequence, and most bits of one code (bounds checked before allocating).
MAX_FRAMES = 4096
MAX_BITS = 24
#: Three periods with 64, 63 and 56 fringes over 1152 px (Towers' optimum choice: C. E.
#: Towers, D. P. Towers, J. D. C. Jones, Opt. Lett. 28(11), 887-889, 2003). Their beats with
#: the finest are 1152 px (covers a 1140 px axis) and 144 px: a ratio of 8 at each
#: unwrapping step.
DEFAULT_HETERODYNE_PERIODS = (1152.0 / 64.0, 1152.0 / 63.0, 1152.0 / 56.0)
#: A pixel is flagged when its absolute phase lies farther than this from the centre of its
#: half-period code cell (complementary code): a cell is pi wide, so a correct decode stays
#: within pi/2 plus half a projector pixel; 3 pi / 4 is an eighth of a period beyond the cell.
CODE_FLAG_RAD = 0.75 * np.pi
#: Temporal/heterodyne pixels are flagged above this unwrapping residual (rad; at 0.4 pi a
#: 3-sigma excursion of a well-exposed pixel stays below it) and invalid
#: above pi/2 (there the order is within a quarter fringe of a rounding boundary).
RESIDUAL_FLAG_RAD = 0.4 * np.pi
_RESIDUAL_INVALID_RAD = 0.5 * np.pi
#: decode warns when more than this share of valid pixels is flagged.
FLAG_WARN_FRACTION = 0.05
#: 1-D ordered (Bayer) dither thresholds of the ``dithered`` profile, by pixel index mod 8.
_BAYER = (np.array([0, 4, 2, 6, 1, 5, 3, 7], dtype=np.float64) + 0.5) / 8.0

_FORMAT = "virtus.pattern_sequence"
_VERSION = 2
_READS_VERSIONS = (1, 2)
_FIELDS = (
    "kind",
    "direction",
    "period",
    "step",
    "steps",
    "bit",
    "bits",
    "profile",
    "offset",
    "sign",
    "align",
    "inverted",
)
_DEFAULTS = {
    "profile": "sinusoidal",
    "offset": 0.0,
    "sign": 1,
    "align": "centre",
    "inverted": False,
}
_MAX_FILE_BYTES = 1 << 20


class DecodeWarning(UserWarning):
    """Many decoded pixels look wrong: the sequence description probably does not match."""


def _quantise(values: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as the 8-bit projector shows them (float64, multiples of 1/255)."""
    return np.rint(np.asarray(values, dtype=np.float64) * LEVELS) / LEVELS


# --- codings ----------------------------------------------------------------------------


@dataclass(frozen=True)
class PhaseCoding:
    """N-step phase shifting of one period: encodes frame values, decodes wrapped phase.

    Attributes
    ----------
    period : fringe period ``T`` in pattern units (projector px times the axis scale).
    steps : ``N >= 3``.
    profile : ``"sinusoidal"``, ``"binary"`` or ``"dithered"`` (module docstring).
    offset : phase offset in radians added to every frame.
    sign : ``+1``: frame ``n`` shows ``f(Phi + offset + 2 pi n / N)``; ``-1``: ``- 2 pi n / N``.
    """

    period: float
    steps: int
    profile: str = "sinusoidal"
    offset: float = 0.0
    sign: int = 1

    def values(self, step: int, coordinate: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """Frame ``step``'s value (before 8-bit quantisation) at projector coordinates.

        Parameters
        ----------
        step : ``n`` in ``1..N``.
        coordinate : (...) float, projector px along the axis.
        scale : pattern units per projector px on this axis.

        Returns
        -------
        (...) float64 in [0, 1]: the exact sinusoid for ``sinusoidal``; the value of the
        projector pixel containing the coordinate for ``binary`` and ``dithered``.
        """
        u = np.asarray(coordinate, dtype=np.float64)
        shift = self.sign * (2.0 * np.pi * step / self.steps)
        if self.profile == "sinusoidal":
            w = u if scale == 1.0 else scale * u
            return 0.5 + 0.5 * np.cos(
                _phase.coordinate_to_phase(w, self.period) + self.offset + shift
            )
        pixel = np.floor(u + 0.5)
        if self.profile == "binary":
            cycles = pixel * scale / self.period + (self.offset + shift) / (2.0 * np.pi)
            # cos >= 0 on [-1/4, 1/4] cycles (closed, so the stripe is symmetric about the
            # phase origin and the fundamental unbiased); rounding at 1e-9 cycle makes the
            # zeros of cos at pixel centres exact.
            centred = np.mod(np.round(cycles + 0.5, 9), 1.0) - 0.5
            return (np.abs(centred) <= 0.25).astype(np.float64)
        phase = _phase.coordinate_to_phase(pixel * scale, self.period) + self.offset + shift
        threshold = _BAYER[np.mod(pixel, 8).astype(np.int64)]
        return (0.5 + 0.5 * np.cos(phase) > threshold).astype(np.float64)

    def wrapped(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wrapped phase of ``Phi = 2 pi w / T`` from the set's images.

        Parameters
        ----------
        frames : (N, ...) real, images of steps ``1..N`` in order, any intensity unit.

        Returns
        -------
        phase : (...) float64 in ``[-pi, pi)`` radians (offset and sign removed).
        background, modulation : (...) float64 ``A`` and ``B`` in the unit of ``frames``.
        """
        phi, background, modulation = _phase.wrapped_phase(frames)
        if self.sign == 1 and self.offset == 0.0:
            return phi, background, modulation
        return _phase.wrap(self.sign * phi - self.offset), background, modulation


@dataclass(frozen=True)
class BitCode:
    """A Gray or plain binary code numbering the fringe orders of one period.

    Attributes
    ----------
    code : ``"gray"`` or ``"binary"``.
    period : period ``T`` whose orders it numbers, pattern units.
    bits : code bits (1 = most significant).
    align : ``"centre"``: order ``floor(w / T + 1/2)``; ``"edge"``: ``floor(w / T)``.
    complement : the complementary (half-period) frame is projected.
    """

    code: str
    period: float
    bits: int
    align: str = "centre"
    complement: bool = False

    @property
    def _shift(self) -> float:
        return 1.0 if self.align == "centre" else 0.0

    def half_index(self, pattern: np.ndarray) -> np.ndarray:
        """(...) int64 half-period index ``h = floor(2 w / T + s)`` of pattern coordinates."""
        w = np.asarray(pattern, dtype=np.float64)
        return np.floor(2.0 * w / self.period + self._shift).astype(np.int64)

    def word(self, index: np.ndarray) -> np.ndarray:
        """(...) int64 code word of non-negative indices (Gray or plain binary)."""
        return _phase.gray_encode(index) if self.code == "gray" else np.asarray(index, np.int64)

    def bit_values(self, bit: int | None, coordinate: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """Frame values (0 or 1) at projector coordinates: bit ``bit`` (1 = most significant)
        of the order's code word, or the complementary frame for ``bit=None``; each
        projector pixel shows the value at its centre."""
        pattern = np.floor(np.asarray(coordinate, dtype=np.float64) + 0.5) * scale
        half = self.half_index(pattern)
        if bit is None:
            return (self.word(half) & 1).astype(np.float64)
        return ((self.word(half >> 1) >> (self.bits - bit)) & 1).astype(np.float64)

    def bits_needed(self, span: int, scale: float = 1.0) -> int:
        """Fewest bits that number every order over ``span`` projector px (with the
        complementary frame, its half-period code must fit in one bit more)."""
        last = self.half_index(scale * (positive_int("span", span) - 1.0))
        codes = int(last) + 1 if self.complement else int(last >> 1) + 1
        needed = int(np.ceil(np.log2(codes))) if codes > 1 else 0
        return max(1, needed - 1 if self.complement else needed)

    def decode(self, bits: np.ndarray) -> np.ndarray:
        """(...) int64 index from binarised frames ``(bits (+1), ...)``, most significant
        first (complementary frame last): ``h`` with the complement, the order without."""
        return _phase.bits_to_index(bits, self.code)

    def predicted_phase(self, index: np.ndarray, span: int, scale: float = 1.0) -> np.ndarray:
        """Absolute phase (rad) of the centre of the projector interval a decoded index
        names: the nominal half-period cell with the complement; without it the pixels that
        show this order (so that a one-period cell holds exactly one phase branch).

        Parameters
        ----------
        index : (...) int, from :meth:`decode`.
        span : projector px along the axis.
        scale : pattern units per projector px.
        """
        index = np.asarray(index, dtype=np.int64)
        if self.complement:
            centre = 0.5 * self.period * (index - self._shift + 0.5)
        else:
            pixel_orders = self.half_index(scale * np.arange(span, dtype=np.float64)) >> 1
            first = np.searchsorted(pixel_orders, index, side="left")
            last = np.searchsorted(pixel_orders, index, side="right") - 1
            nominal = self.period * (index - 0.5 * self._shift + 0.5)
            centre = np.where(last >= first, 0.5 * scale * (first + last), nominal)
        return _phase.coordinate_to_phase(centre, self.period)


# --- frames -----------------------------------------------------------------------------


def _choice(name: str, value: Any, options: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in options:
        raise InputError(name, f"one of {options}", value)
    return value


@dataclass(frozen=True)
class Frame:
    """One projected frame (plain fields; :meth:`coding` gives the coding it belongs to).

    Attributes
    ----------
    kind : one of :data:`KINDS`.
    direction : ``"v"`` (varies along u_p), ``"h"`` (varies along v_p), ``None`` for the
        uniform white, black and ignore frames.
    period : fringe period ``T`` in pattern units (phase frames; for code frames the period
        whose fringe order they encode), ``None`` for uniform frames.
    step, steps : phase frames only: shift index ``n`` in ``1..N`` and ``N >= 3``.
    bit, bits : Gray/binary bit frames only: bit index in ``1..bits``, 1 the most
        significant; ``bits <= MAX_BITS``.
    profile, offset, sign : phase frames only (defaults ``"sinusoidal"``, ``0.0`` rad, ``+1``).
    align, inverted : code and complementary frames only (defaults ``"centre"``, False).
    """

    kind: str
    direction: str | None = None
    period: float | None = None
    step: int | None = None
    steps: int | None = None
    bit: int | None = None
    bits: int | None = None
    profile: str | None = None
    offset: float | None = None
    sign: int | None = None
    align: str | None = None
    inverted: bool | None = None

    def __post_init__(self) -> None:
        _choice("kind", self.kind, KINDS)
        if self.kind in _UNIFORM_KINDS:
            self._none(_FIELDS[1:])
            return
        if self.direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", self.direction)
        self._set("period", positive("period", self.period))
        if self.kind == "phase":
            self._none(("bit", "bits", "align", "inverted"))
            steps = positive_int("steps", self.steps, minimum=3)
            if steps > MAX_FRAMES:
                raise InputError("steps", f"an integer in 3..{MAX_FRAMES}", self.steps)
            step = positive_int("step", self.step)
            if step > steps:
                raise InputError("step", f"an integer in 1..{steps}", self.step)
            sign = _DEFAULTS["sign"] if self.sign is None else self.sign
            if isinstance(sign, bool) or sign not in (1, -1):
                raise InputError("sign", "+1 or -1", self.sign)
            offset = _DEFAULTS["offset"] if self.offset is None else self.offset
            profile = _DEFAULTS["profile"] if self.profile is None else self.profile
            self._set("steps", steps)
            self._set("step", step)
            self._set("profile", _choice("profile", profile, PROFILES))
            self._set("offset", finite("offset", offset))
            self._set("sign", int(sign))
            return
        self._none(("step", "steps", "profile", "offset", "sign"))
        align = _DEFAULTS["align"] if self.align is None else self.align
        inverted = _DEFAULTS["inverted"] if self.inverted is None else self.inverted
        self._set("align", _choice("align", align, ALIGNS))
        if not isinstance(inverted, bool | np.bool_):
            raise InputError("inverted", "true or false", self.inverted)
        self._set("inverted", bool(inverted))
        if self.kind in _COMPLEMENT_KINDS:
            self._none(("bit", "bits"))
            return
        bits = positive_int("bits", self.bits)
        if bits > MAX_BITS:
            raise InputError("bits", f"an integer in 1..{MAX_BITS}", self.bits)
        bit = positive_int("bit", self.bit)
        if bit > bits:
            raise InputError("bit", f"an integer in 1..{bits}", self.bit)
        self._set("bits", bits)
        self._set("bit", bit)

    def _set(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)

    def _none(self, names: Iterable[str]) -> None:
        for name in names:
            if getattr(self, name) is not None:
                raise InputError(name, f"None for a {self.kind} frame", getattr(self, name))

    @property
    def uniform(self) -> bool:
        """True for the white, black and ignore frames."""
        return self.direction is None

    def coding(self, bits: int | None = None, complement: bool = False) -> PhaseCoding | BitCode:
        """The coding this frame belongs to (phase and code frames only). A complementary
        frame does not know the code's length: pass ``bits`` (and ``complement``)."""
        if self.kind == "phase":
            return PhaseCoding(self.period, self.steps, self.profile, self.offset, self.sign)  # type: ignore[arg-type]
        if self.uniform:
            raise InputError("frame", "a phase or code frame", self.kind)
        code = _CODE_KINDS.get(self.kind) or _COMPLEMENT_KINDS[self.kind]
        return BitCode(code, self.period, self.bits or bits or 1, self.align, complement)  # type: ignore[arg-type]

    def values(self, coordinate: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """The pattern before 8-bit quantisation, at any projector coordinate.

        Sinusoidal phase frames give the cosine at the exact coordinate; binary and dithered
        phase frames and code frames the value of the projector pixel containing it;
        uniform frames 1 (white) or 0 (black, ignore).

        Parameters
        ----------
        coordinate : (...) float, projector px along the frame's axis (u_p for ``"v"``,
            v_p for ``"h"``).
        scale : pattern units per projector px on that axis.

        Returns
        -------
        (...) float64 in [0, 1], same shape as ``coordinate``.
        """
        u = np.asarray(coordinate, dtype=np.float64)
        if self.uniform:
            return np.full_like(u, 1.0 if self.kind == "white" else 0.0)
        coding = self.coding()
        if isinstance(coding, PhaseCoding):
            return coding.values(self.step, u, scale)  # type: ignore[arg-type]
        value = coding.bit_values(self.bit, u, scale)
        return 1.0 - value if self.inverted else value

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict holding ``kind`` and the fields that apply to it (defaults left
        out)."""
        out = {}
        for name in _FIELDS:
            value = getattr(self, name)
            if value is not None and not (name in _DEFAULTS and value == _DEFAULTS[name]):
                out[name] = value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Frame:
        """Inverse of :meth:`to_dict`; ``index`` and ``file`` keys (written by
        :meth:`PatternSequence.describe` and :meth:`PatternSequence.save`) are ignored."""
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError("frame", "a mapping with a 'kind' key", data)
        _known_keys("frame", data, (*_FIELDS, "index", "file"))
        return cls(**{k: data[k] for k in _FIELDS if k in data})


def _known_keys(name: str, data: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Refuse keys of ``data`` outside ``allowed``, naming them."""
    unknown = sorted(str(key) for key in set(data) - set(allowed))
    if unknown:
        raise InputError(name, f"keys among {sorted(allowed)}", f"unknown keys {unknown}")


# --- decode result ----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Decoded camera images; every map is ``(H, W)``, indexed ``[row, col]`` of the camera.

    Attributes
    ----------
    proj_uv : (H, W, 2) float64, projector coordinates ``(u_p, v_p)`` in px; ``u_p`` is NaN
        where ``mask_v`` is False, ``v_p`` where ``mask_h`` is False.
    phase_v, phase_h : (H, W) float64, absolute phase in radians of the direction's finest
        period (``Phi = 2 pi w / period_v``, ``w`` the pattern coordinate, ``= u_p`` at scale
        1); NaN where invalid or the direction is absent.
    modulation : (H, W) float64, fringe modulation ``B`` in frame units: the smallest over
        the sequence's phase sets.
    background : (H, W) float64, background ``A`` in frame units: the mean over the phase sets.
    mask : (H, W) bool, valid in every direction the sequence has.
    mask_v, mask_h : (H, W) bool, valid per direction (all False for an absent direction).
    period_v, period_h : the finest period (pattern units) of each direction, ``None`` if absent.
    flagged : (H, W) bool, valid pixels (in some direction) whose fringe order is likely
        wrong: ``flagged_v | flagged_h``.
    flagged_v, flagged_h : (H, W) bool, per direction, within ``mask_v`` / ``mask_h``.
    modulation_v, modulation_h : (H, W) float64, ``B`` per direction (frame units; NaN if absent).
    repaired : pixels whose fringe order was repaired (``decode(repair=True)``), all
        directions counted.
    full_scale : the frames' full scale (frame units).
    """

    proj_uv: np.ndarray
    phase_v: np.ndarray
    phase_h: np.ndarray
    modulation: np.ndarray
    background: np.ndarray
    mask: np.ndarray
    mask_v: np.ndarray
    mask_h: np.ndarray
    period_v: float | None = None
    period_h: float | None = None
    flagged: np.ndarray | None = None
    flagged_v: np.ndarray | None = None
    flagged_h: np.ndarray | None = None
    modulation_v: np.ndarray | None = None
    modulation_h: np.ndarray | None = None
    repaired: int = 0
    full_scale: float = 1.0

    def summary(self) -> dict[str, Any]:
        """JSON-ready decode statistics.

        Returns
        -------
        dict with ``valid_fraction`` (share of camera pixels valid in every direction),
        ``flagged_fraction`` (flagged share of pixels valid in some direction), ``repaired``,
        ``full_scale``, and per direction present (``"v"``, ``"h"``): ``period``,
        ``valid_fraction``, ``flagged_fraction`` (of that direction's valid pixels) and
        ``modulation`` / ``modulation_rel``: percentiles ``p5``, ``p50``, ``p95`` of ``B``
        over all camera pixels (so a capture that decodes nowhere still says why), in frame
        units and as a fraction of ``full_scale``. Undefined values are None.
        """
        any_valid = self.mask_v | self.mask_h
        out: dict[str, Any] = {
            "valid_fraction": _share(self.mask, np.ones_like(self.mask)),
            "flagged_fraction": _share(self.flagged, any_valid),
            "repaired": int(self.repaired),
            "full_scale": float(self.full_scale),
        }
        for direction in DIRECTIONS:
            period = getattr(self, f"period_{direction}")
            if period is None:
                continue
            mask = getattr(self, f"mask_{direction}")
            values = getattr(self, f"modulation_{direction}")
            finite_values = values[np.isfinite(values)]
            levels = (
                np.percentile(finite_values, (5, 50, 95)) if finite_values.size else [np.nan] * 3
            )
            out[direction] = {
                "period": float(period),
                "valid_fraction": _share(mask, np.ones_like(mask)),
                "flagged_fraction": _share(getattr(self, f"flagged_{direction}"), mask),
                "modulation": _percentiles(levels, 1.0),
                "modulation_rel": _percentiles(levels, self.full_scale),
            }
        return out


def _share(part: np.ndarray, whole: np.ndarray) -> float | None:
    """Share of ``whole``'s True pixels that are True in ``part``; None if ``whole`` is empty."""
    count = int(np.count_nonzero(whole))
    return None if count == 0 else int(np.count_nonzero(part & whole)) / count


def _percentiles(levels: Sequence[float], unit: float) -> dict[str, float | None]:
    return {
        name: (None if not np.isfinite(value) else float(value) / unit)
        for name, value in zip(("p5", "p50", "p95"), levels, strict=True)
    }


# --- sequences --------------------------------------------------------------------------


@dataclass(frozen=True)
class PhaseSet:
    """One period's phase frames: the coding and frame indices of steps 1..N (part of a
    :class:`DecodePlan`)."""

    coding: PhaseCoding
    indices: tuple[int, ...]


@dataclass(frozen=True)
class CodePlan:
    """A direction's code frames: per bit (most significant first, complement last) the
    index of the frame showing it and of the one showing its inverse (or None)."""

    coding: BitCode
    normal: tuple[int | None, ...]
    inverse: tuple[int | None, ...]


@dataclass(frozen=True)
class DecodePlan:
    """Which frames decode one direction, and how (checked once, when a
    :class:`PatternSequence` is made; :meth:`PatternSequence.plan`)."""

    method: str  # "code", "temporal", "heterodyne" or "window"
    sets: tuple[PhaseSet, ...]  # ascending period: sets[0] is the reported (finest) period
    code: CodePlan | None = None

    @property
    def periods(self) -> tuple[float, ...]:
        return tuple(s.coding.period for s in self.sets)


def _scale_pair(value: Any) -> tuple[float, float]:
    """``(scale_v, scale_h)`` from a pair, a mapping ``{"v": .., "h": ..}`` or None."""
    if value is None:
        return (1.0, 1.0)
    if isinstance(value, Mapping):
        _known_keys("scale", value, DIRECTIONS)
        return tuple(positive(f"scale.{d}", value.get(d, 1.0)) for d in DIRECTIONS)  # type: ignore[return-value]
    if isinstance(value, str) or np.ndim(value) != 1 or len(value) != 2:
        raise InputError("scale", "(scale_v, scale_h) or {v: .., h: ..}", value)
    return (positive("scale", value[0]), positive("scale", value[1]))


@dataclass(frozen=True)
class PatternSequence:
    """An ordered set of projector frames that knows how to encode and decode itself.

    Parameters
    ----------
    width, height : projector size in px (columns, rows).
    frames : the frames in projection order, at most :data:`MAX_FRAMES`.
    scale : pattern units per projector px, ``(along u_p, along v_p)`` = for directions
        ``("v", "h")``, or a mapping ``{"v": .., "h": ..}``; default ``(1, 1)``.

    Every direction present must be decodable on its own (module docstring): one phase set
    plus a complete code of the same period (each bit once, plain or as an inverted pair, and
    optionally the complementary frame), enough bits to number every order; two or more
    phase sets (multi-wavelength when the longest period covers the axis, else heterodyne
    with a beat that covers it); or one phase set whose period covers the axis. White, black
    and ignore frames may appear any number of times, anywhere.

    Raises
    ------
    InputError : if the frames do not form such a sequence.
    """

    width: int
    height: int
    frames: tuple[Frame, ...]
    scale: tuple[float, float] = (1.0, 1.0)
    _plans: dict[str, DecodePlan] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "width", positive_int("width", self.width))
        object.__setattr__(self, "height", positive_int("height", self.height))
        frames = tuple(self.frames) if isinstance(self.frames, Iterable) else ()
        if not frames or not all(isinstance(f, Frame) for f in frames):
            raise InputError("frames", "a non-empty sequence of Frame", self.frames)
        if len(frames) > MAX_FRAMES:
            raise InputError("frames", f"at most {MAX_FRAMES} frames", len(frames))
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "scale", _scale_pair(self.scale))
        plans = {d: self._plan_direction(d) for d in DIRECTIONS}
        object.__setattr__(self, "_plans", {d: p for d, p in plans.items() if p is not None})

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def directions(self) -> tuple[str, ...]:
        """Directions present, in ``("v", "h")`` order."""
        return tuple(d for d in DIRECTIONS if d in self._plans)

    def plans(self) -> dict[str, DecodePlan]:
        """Direction -> how it decodes (:class:`DecodePlan`), for the directions present:
        what :meth:`decode` follows, and any other decoder of these frames (the device
        decoder, :mod:`virtus.render.jit.decode`)."""
        return dict(self._plans)

    def plan(self, direction: str) -> DecodePlan | None:
        """``direction``'s :class:`DecodePlan`, or None when it is absent."""
        self.span(direction)
        return self._plans.get(direction)

    def span(self, direction: str) -> int:
        """Projector px along the axis that ``direction``'s fringes vary on."""
        if direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", direction)
        return self.width if direction == "v" else self.height

    def axis_scale(self, direction: str) -> float:
        """Pattern units per projector px along ``direction``'s axis."""
        self.span(direction)
        return self.scale[DIRECTIONS.index(direction)]

    def extent(self, direction: str) -> float:
        """Pattern units from the first to the last pixel centre, plus one."""
        return self.axis_scale(direction) * (self.span(direction) - 1.0) + 1.0

    def periods(self, direction: str) -> tuple[float, ...]:
        """Phase periods (pattern units, ascending) of ``direction``; empty if it is absent.
        The first is the period of the decoded absolute phase."""
        self.span(direction)
        plan = self._plans.get(direction)
        return () if plan is None else plan.periods

    def index_of(self, kind: str, direction: str | None = None, **fields: Any) -> int:
        """Index of the one frame with this ``kind``, ``direction`` and ``fields`` (e.g.
        ``index_of("phase", "v", period=18.0, step=1)``)."""
        hits = [
            i
            for i, f in enumerate(self.frames)
            if f.kind == kind
            and f.direction == direction
            and all(getattr(f, k) == v for k, v in fields.items())
        ]
        if len(hits) != 1:
            raise InputError("frame", "exactly one matching frame", f"{len(hits)} matches")
        return hits[0]

    # --- planning -----------------------------------------------------------------------

    def _plan_direction(self, direction: str) -> DecodePlan | None:
        mine = [(i, f) for i, f in enumerate(self.frames) if f.direction == direction]
        if not mine:
            return None
        sets = self._phase_sets(direction, [(i, f) for i, f in mine if f.kind == "phase"])
        periods = tuple(s.coding.period for s in sets)
        extent = self.extent(direction)
        code_frames = [(i, f) for i, f in mine if f.kind != "phase"]
        if code_frames:
            return DecodePlan("code", sets, self._code_plan(direction, periods, code_frames))
        if len(periods) == 1:
            if periods[0] < extent:
                raise InputError(
                    "frames",
                    f"a code, more periods, or a period >= {extent:g} ({direction!r})",
                    f"one period of {periods[0]:.6g}",
                )
            return DecodePlan("window", sets)
        if periods[-1] >= extent:
            return DecodePlan("temporal", sets)
        longest = max(_phase.beat_period(periods[0], p) for p in periods[1:])
        if longest < extent:
            raise InputError(
                "frames",
                f"periods whose longest beat (or longest period) is >= {extent:g} ({direction!r})",
                f"{longest:.6g} for periods {list(periods)}",
            )
        return DecodePlan("heterodyne", sets)

    @staticmethod
    def _phase_sets(direction: str, frames: list[tuple[int, Frame]]) -> tuple[PhaseSet, ...]:
        """Phase sets of one direction, ascending period, each with steps 1..N once."""
        codings: dict[float, PhaseCoding] = {}
        by_period: dict[float, dict[int, int]] = {}
        for i, f in frames:
            coding = f.coding()
            if codings.setdefault(f.period, coding) != coding:  # type: ignore[arg-type]
                raise InputError(
                    "frames",
                    f"one step count, profile, offset and sign per period ({direction!r}, "
                    f"T = {f.period})",
                    (codings[f.period], coding),  # type: ignore[index]
                )
            by_step = by_period.setdefault(f.period, {})  # type: ignore[arg-type]
            if f.step in by_step:
                raise InputError("frames", "each phase step once", f.to_dict())
            by_step[f.step] = i  # type: ignore[index]
        if not by_period:
            raise InputError("frames", f"phase frames for direction {direction!r}", "none")
        sets = []
        for period in sorted(by_period):
            steps = codings[period].steps
            if len(by_period[period]) != steps:
                raise InputError(
                    "frames",
                    f"steps 1..{steps} of period {period} ({direction!r})",
                    sorted(by_period[period]),
                )
            indices = tuple(by_period[period][n] for n in range(1, steps + 1))
            sets.append(PhaseSet(codings[period], indices))
        return tuple(sets)

    def _code_plan(
        self, direction: str, periods: tuple[float, ...], frames: list[tuple[int, Frame]]
    ) -> CodePlan:
        """Check a direction's code frames and say which frame shows which bit."""
        if len(periods) != 1 or any(f.period != periods[0] for _, f in frames):
            raise InputError(
                "frames",
                f"code frames with exactly one phase period, the same ({direction!r})",
                sorted({periods[0], *(f.period for _, f in frames)}),
            )
        kinds = {(_CODE_KINDS.get(f.kind) or _COMPLEMENT_KINDS[f.kind], f.align) for _, f in frames}
        if len(kinds) != 1:
            raise InputError("frames", f"one code and alignment ({direction!r})", sorted(kinds))
        ((code, align),) = kinds
        bit_frames = [f for _, f in frames if f.kind in _CODE_KINDS]
        if not bit_frames:
            raise InputError("frames", f"bit frames with the complement ({direction!r})", 0)
        bits = bit_frames[0].bits
        slots: dict[tuple[int, bool], int] = {}
        for i, f in frames:
            slot = (f.bit if f.bit is not None else 0, f.inverted)
            if f.bits not in (None, bits) or slot in slots:
                raise InputError(
                    "frames",
                    f"{bits}-bit code frames, each bit (and complement) at most once per "
                    f"polarity ({direction!r})",
                    f.to_dict(),
                )
            slots[slot] = i  # type: ignore[index]
        order = [*range(1, bits + 1)]  # type: ignore[operator]
        missing = [b for b in order if (b, False) not in slots and (b, True) not in slots]
        if missing:
            raise InputError("frames", f"every bit 1..{bits} of the code ({direction!r})", missing)
        complement = (0, False) in slots or (0, True) in slots
        if complement:
            order.append(0)
        coding = BitCode(code, periods[0], bits, align, complement)  # type: ignore[arg-type]
        span, scale = self.span(direction), self.axis_scale(direction)
        need = coding.bits_needed(span, scale)
        if bits < need:  # type: ignore[operator]
            extra = ", with the complement" if complement else ""
            raise InputError(
                "bits",
                f">= {need} to number every period-{periods[0]:g} fringe over {span} px "
                f"({align}-aligned{extra})",
                bits,
            )
        return CodePlan(
            coding,
            tuple(slots.get((b, False)) for b in order),
            tuple(slots.get((b, True)) for b in order),
        )

    # --- encoding -----------------------------------------------------------------------

    def _frame(self, index: int) -> Frame:
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise InputError("index", "an integer frame index", index)
        if not -len(self) <= index < len(self):
            raise InputError("index", f"a frame index in 0..{len(self) - 1}", index)
        return self.frames[index]

    def values(self, index: int, coordinate: np.ndarray) -> np.ndarray:
        """What frame ``index`` shows at any projector coordinate along its axis, 8-bit.

        Parameters
        ----------
        index : frame index.
        coordinate : (...) float, projector px (u_p for ``"v"``, v_p for ``"h"``; ignored
            for uniform frames).

        Returns
        -------
        (...) float64 in [0, 1], multiples of 1/255 (see :meth:`Frame.values`).
        """
        frame = self._frame(index)
        scale = 1.0 if frame.uniform else self.axis_scale(frame.direction)  # type: ignore[arg-type]
        return _quantise(frame.values(coordinate, scale))

    def profile(self, index: int) -> np.ndarray:
        """What frame ``index`` shows along its varying axis.

        Returns
        -------
        (L,) float64 in [0, 1], 8-bit quantised (multiples of 1/255): ``L = width`` for
        direction ``"v"`` (entry ``j`` = column ``u_p = j``), ``L = height`` for ``"h"``
        (entry = row ``v_p``), ``L = 1`` for white, black and ignore frames.
        """
        frame = self._frame(index)
        length = 1 if frame.uniform else self.span(frame.direction)  # type: ignore[arg-type]
        return self.values(index, np.arange(length, dtype=np.float64))

    def image(self, index: int) -> np.ndarray:
        """Frame ``index`` as a ``(height, width)`` float64 image in [0, 1], 8-bit quantised."""
        frame = self._frame(index)
        values = self.profile(index)
        if frame.direction == "v":
            values = values[np.newaxis, :]
        elif frame.direction == "h":
            values = values[:, np.newaxis]
        return np.broadcast_to(values, (self.height, self.width)).copy()

    def images(self) -> np.ndarray:
        """All frames as ``(F, height, width)`` uint8 (0..255), in sequence order."""
        out = np.empty((len(self), self.height, self.width), dtype=np.uint8)
        for index in range(len(self)):
            out[index] = np.rint(self.image(index) * LEVELS).astype(np.uint8)
        return out

    # --- description and files ----------------------------------------------------------

    def describe(self) -> list[dict[str, Any]]:
        """One JSON-ready dict per frame: ``index``, ``kind`` and the fields that apply
        (:meth:`Frame.to_dict`)."""
        return [{"index": i, **frame.to_dict()} for i, frame in enumerate(self.frames)]

    def to_dict(self) -> dict[str, Any]:
        """Lossless JSON-ready description, the per-frame form of the description file
        (periods stay exact float64 values; ``scale`` only when not 1)."""
        out: dict[str, Any] = {
            "format": _FORMAT,
            "version": _VERSION,
            "width": self.width,
            "height": self.height,
            "bit_depth": 8,
        }
        if self.scale != (1.0, 1.0):
            out["scale"] = dict(zip(DIRECTIONS, self.scale, strict=True))
        out["frames"] = self.describe()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PatternSequence:
        """A sequence from a description (module docstring): the per-frame form written by
        :meth:`to_dict` and :meth:`save`, or the compact ``blocks`` form.

        Raises
        ------
        InputError : on unknown keys, a bad value or a sequence that cannot be decoded.
        """
        if not isinstance(data, Mapping):
            raise InputError("data", "a mapping (sequence description)", data)
        _known_keys("sequence", data, _TOP_KEYS)
        if data.get("format", _FORMAT) != _FORMAT:
            raise InputError("format", repr(_FORMAT), data.get("format"))
        if data.get("version", _VERSION) not in _READS_VERSIONS:
            raise InputError("version", f"one of {_READS_VERSIONS}", data.get("version"))
        if data.get("bit_depth", 8) != 8:
            raise InputError("bit_depth", "8", data.get("bit_depth"))
        if ("frames" in data) == ("blocks" in data):
            raise InputError("sequence", "exactly one of 'frames' and 'blocks'", sorted(data))
        if "blocks" in data:
            frames = _expand_blocks(data["blocks"])
        else:
            frames = _frames_from_entries(data["frames"])
        sequence = cls(data.get("width"), data.get("height"), frames, data.get("scale"))  # type: ignore[arg-type]
        _files(data, len(sequence))
        return sequence

    def save(self, directory: str | os.PathLike[str]) -> Path:
        """Write 8-bit grayscale PNGs ``000.png, 001.png, ...`` (``width`` x ``height``) and
        ``sequence.json`` (:meth:`to_dict` plus a ``file`` entry per frame) into
        ``directory``, created if needed; files of the same names are replaced.

        Returns
        -------
        Path of ``sequence.json``; :meth:`from_dict` and :func:`load_sequence_file` read it.
        """
        import cv2  # only needed to write files

        folder = Path(directory)
        folder.mkdir(parents=True, exist_ok=True)
        digits = max(3, len(str(len(self) - 1)))
        data = self.to_dict()
        for index, entry in enumerate(data["frames"]):
            name = f"{index:0{digits}d}.png"
            pixels = np.rint(self.image(index) * LEVELS).astype(np.uint8)
            if not cv2.imwrite(str(folder / name), pixels):
                raise VirtusError(f"could not write {folder / name}")
            entry["file"] = name
        return write_json(folder / "sequence.json", data)

    # --- decoding -----------------------------------------------------------------------

    def decode(
        self,
        frames: np.ndarray,
        *,
        min_modulation: float = 0.02,
        saturation_level: float | None = None,
        full_scale: float | None = None,
        repair: bool = False,
        neighbour_check: bool | None = None,
    ) -> DecodeResult:
        """Decode camera images of this sequence into projector coordinates.

        Parameters
        ----------
        frames : (F, H, W) real or integer array, ``F = len(self)``: camera images in
            sequence order, indexed ``[frame, row, col]``, any intensity unit.
        min_modulation : a pixel is valid in a direction when every phase set of that
            direction has modulation ``B >= min_modulation * full_scale``.
        saturation_level : a pixel reaching this value (frame units, e.g. 255 for 8-bit) in
            any phase frame of a direction is invalid in it; ``None`` disables the check.
        full_scale : the frames' full scale; default ``iinfo(dtype).max`` for integer frames
            (255 for uint8) and 1.0 for float frames (normalised images); frames above it
            are refused.
        repair : give flagged pixels the fringe order their neighbours on the same surface
            agree on (``phase.order_consistency``); ``DecodeResult.repaired`` counts them.
        neighbour_check : compare fringe orders with neighbouring pixels (needs images of
            continuous surfaces; it abstains by itself on unrelated points). Default: only
            for directions without a per-pixel check, i.e. codes without the complementary
            frame (the complement and the unwrapping residual check each pixel alone, and the
            neighbour check costs about 0.25 s per direction at 960 x 960); ``repair``
            turns it on.

        Returns
        -------
        DecodeResult

        Warns
        -----
        DecodeWarning : when more than :data:`FLAG_WARN_FRACTION` of valid pixels is flagged.

        Notes
        -----
        Code frames are thresholded at ``(mean white + mean black) / 2`` when the sequence
        has both, else at the phase background ``A`` (an inverted pair by comparing its two
        images). Temporal and heterodyne pixels whose unwrapping residual exceeds ``pi / 2``
        are invalid (order unreliable). Coordinates decoded outside ``[-1, L]`` px (more
        than half a pixel beyond the projector) are invalid.
        """
        stack = self._check_frames(frames)
        if full_scale is None:
            integer = np.issubdtype(stack.dtype, np.integer)
            full_scale = float(np.iinfo(stack.dtype).max) if integer else 1.0
        full_scale = positive("full_scale", full_scale)
        if stack.max() > full_scale:
            # e.g. float frames in DN decoded with the default 1.0: the modulation threshold
            # would be meaningless, so refuse instead of passing every pixel.
            raise InputError(
                "frames", f"values <= full_scale ({full_scale:g}); pass full_scale", stack.max()
            )
        shape = stack.shape[1:]
        threshold = self._threshold(stack)
        nan = np.full(shape, np.nan)
        none = np.zeros(shape, dtype=bool)
        out: dict[str, dict[str, Any]] = {}
        modulations: list[np.ndarray] = []
        backgrounds: list[np.ndarray] = []
        repaired = 0
        for direction in DIRECTIONS:
            plan = self._plans.get(direction)
            if plan is None:
                out[direction] = {"phase": nan, "valid": none, "flags": none, "modulation": nan}
                continue
            decoded = self._decode_direction(
                stack, direction, plan, threshold, min_modulation, saturation_level, full_scale
            )
            modulations += decoded.pop("modulations")
            backgrounds += decoded.pop("backgrounds")
            if self.runs_neighbour_check(direction, neighbour_check, repair):
                repaired += self.check_neighbours(direction, decoded, repair)
            decoded["flags"] &= decoded["valid"]
            decoded["phase"] = np.where(decoded["valid"], decoded["phase"], np.nan)
            out[direction] = decoded
        return self.assemble_result(
            out,
            modulation=np.minimum.reduce(modulations) if modulations else nan,
            background=np.mean(backgrounds, axis=0) if backgrounds else nan,
            repaired=repaired,
            full_scale=full_scale,
        )

    def runs_neighbour_check(
        self, direction: str, neighbour_check: bool | None, repair: bool
    ) -> bool:
        """Whether :meth:`decode` compares ``direction``'s orders with neighbours: when
        asked, when repairing, and by default where no per-pixel check exists (codes without
        the complementary frame, the window method)."""
        plan = self._plans[direction]
        per_pixel_check = plan.method in ("temporal", "heterodyne") or (
            plan.code is not None and plan.code.coding.complement
        )
        return bool(neighbour_check or repair or (neighbour_check is None and not per_pixel_check))

    def assemble_result(
        self,
        out: dict[str, dict[str, Any]],
        *,
        modulation: np.ndarray,
        background: np.ndarray,
        repaired: int,
        full_scale: float,
    ) -> DecodeResult:
        """The :class:`DecodeResult` of per-direction decodes (``out[d]``: ``phase`` NaN
        where invalid, ``valid``, ``flags`` within it, ``modulation``; every direction of
        :data:`DIRECTIONS`), warning when many pixels are flagged. Shared by the host
        decoder and the device decoder's :meth:`virtus.render.jit.decode.DeviceDecode.to_host`."""
        shape = out["v"]["valid"].shape
        mask = np.full(shape, bool(self.directions))  # no fringes: nothing is valid
        for direction in self.directions:
            mask &= out[direction]["valid"]
        coordinates = [self._coordinate(d, out[d]["phase"]) for d in DIRECTIONS]
        result = DecodeResult(
            proj_uv=np.stack(coordinates, axis=-1),
            phase_v=out["v"]["phase"],
            phase_h=out["h"]["phase"],
            modulation=modulation,
            background=background,
            mask=mask,
            mask_v=out["v"]["valid"],
            mask_h=out["h"]["valid"],
            period_v=self._plans["v"].periods[0] if "v" in self._plans else None,
            period_h=self._plans["h"].periods[0] if "h" in self._plans else None,
            flagged=out["v"]["flags"] | out["h"]["flags"],
            flagged_v=out["v"]["flags"],
            flagged_h=out["h"]["flags"],
            modulation_v=out["v"]["modulation"],
            modulation_h=out["h"]["modulation"],
            repaired=repaired,
            full_scale=full_scale,
        )
        _warn_if_flagged(result)
        return result

    def _check_frames(self, frames: np.ndarray) -> np.ndarray:
        stack = np.asarray(frames)
        if stack.dtype == np.bool_ or not (
            np.issubdtype(stack.dtype, np.integer) or np.issubdtype(stack.dtype, np.floating)
        ):
            raise InputError("frames", "a real or integer array", f"dtype {stack.dtype}")
        if stack.ndim != 3 or stack.shape[0] != len(self):
            raise InputError(
                "frames", f"an array of shape ({len(self)}, H, W)", f"shape {stack.shape}"
            )
        if np.issubdtype(stack.dtype, np.floating):
            bad = ~np.isfinite(stack)
            if bad.any():
                raise InputError("frames", "finite values", f"{int(bad.sum())} non-finite entries")
        return stack

    def _threshold(self, stack: np.ndarray) -> np.ndarray | None:
        """``(mean white + mean black) / 2`` (float64), or None without both kinds."""
        whites = [i for i, f in enumerate(self.frames) if f.kind == "white"]
        blacks = [i for i, f in enumerate(self.frames) if f.kind == "black"]
        if not whites or not blacks:
            return None
        white = stack[whites].mean(axis=0, dtype=np.float64)
        return 0.5 * (white + stack[blacks].mean(axis=0, dtype=np.float64))

    def _coordinate(self, direction: str, absolute: np.ndarray) -> np.ndarray:
        """Projector px from the absolute phase of ``direction``'s finest period."""
        plan = self._plans.get(direction)
        if plan is None:
            return absolute
        pattern = _phase.phase_to_coordinate(absolute, plan.periods[0])
        scale = self.axis_scale(direction)
        return pattern if scale == 1.0 else pattern / scale

    def _in_range(self, direction: str, absolute: np.ndarray) -> np.ndarray:
        """Coordinates within half a pixel beyond the projector, ``[-1, L]`` px."""
        coordinate = self._coordinate(direction, absolute)
        return (coordinate >= -1.0) & (coordinate <= self.span(direction))

    def _decode_direction(
        self,
        stack: np.ndarray,
        direction: str,
        plan: DecodePlan,
        threshold: np.ndarray | None,
        min_modulation: float,
        saturation_level: float | None,
        full_scale: float,
    ) -> dict[str, Any]:
        """Absolute phase of the finest period, validity, per-pixel flags, the finest
        wrapped phase, and each set's modulation and background."""
        wrapped, modulations, backgrounds = [], [], []
        valid = np.ones(stack.shape[1:], dtype=bool)
        for phase_set in plan.sets:
            phase_frames = stack[list(phase_set.indices)]
            phi, background, modulation = phase_set.coding.wrapped(phase_frames)
            valid &= _phase.quality_mask(
                modulation,
                min_modulation=min_modulation,
                full_scale=full_scale,
                frames=phase_frames,
                saturation_level=saturation_level,
            )
            wrapped.append(phi)
            modulations.append(modulation)
            backgrounds.append(background)
        flags = np.zeros(stack.shape[1:], dtype=bool)
        extent = self.extent(direction)
        if plan.method == "code":
            code = plan.code
            cut = backgrounds[0] if threshold is None else threshold
            index = code.coding.decode(_read_bits(stack, code, cut))  # type: ignore[union-attr]
            predicted = code.coding.predicted_phase(  # type: ignore[union-attr]
                index, self.span(direction), self.axis_scale(direction)
            )
            absolute = _phase.unwrap_nearest(wrapped[0], predicted)
            if code.coding.complement:  # type: ignore[union-attr]
                flags = np.abs(absolute - predicted) > CODE_FLAG_RAD
        elif plan.method in ("temporal", "heterodyne"):
            unwrap = (
                _phase.unwrap_temporal if plan.method == "temporal" else _phase.unwrap_heterodyne
            )
            absolute, residual = unwrap(wrapped, plan.periods, extent)
            valid &= residual <= _RESIDUAL_INVALID_RAD
            flags = residual > RESIDUAL_FLAG_RAD
        else:
            absolute = _phase.absolute_phase_in_window(wrapped[0], plan.periods[0], extent)
        valid &= self._in_range(direction, absolute)
        return {
            "phase": absolute,
            "valid": valid,
            "flags": flags,
            "wrapped": wrapped[0],
            "modulation": np.minimum.reduce(modulations),
            "modulations": modulations,
            "backgrounds": backgrounds,
        }

    def check_neighbours(self, direction: str, decoded: dict[str, Any], repair: bool) -> int:
        """Flag (or repair) orders that disagree with neighbours; returns pixels repaired."""
        spatial, correction = _phase.order_consistency(
            decoded["phase"], decoded.pop("wrapped"), decoded["valid"]
        )
        if not repair or not spatial.any():
            decoded["flags"] = decoded["flags"] | spatial
            return 0
        decoded["phase"] = decoded["phase"] + _phase.TWO_PI * correction
        decoded["flags"] = decoded["flags"] & ~spatial
        decoded["valid"] = decoded["valid"] & self._in_range(direction, decoded["phase"])
        return int(np.count_nonzero(spatial))


def _read_bits(stack: np.ndarray, code: CodePlan, threshold: np.ndarray) -> np.ndarray:
    """(bits (+1), H, W) bool: each bit from its pair (frame brighter than its inverse) or
    from one frame against the threshold; most significant first, complement last."""
    rows = []
    for normal, inverse in zip(code.normal, code.inverse, strict=True):
        if normal is not None and inverse is not None:
            rows.append(stack[normal] > stack[inverse])
        elif normal is not None:
            rows.append(stack[normal] > threshold)
        else:
            rows.append(stack[inverse] <= threshold)
    return np.stack(rows)


def _warn_if_flagged(result: DecodeResult) -> None:
    valid = int(np.count_nonzero(result.mask_v | result.mask_h))
    flagged = int(np.count_nonzero(result.flagged))
    if valid and flagged > FLAG_WARN_FRACTION * valid:
        warnings.warn(
            f"decode: {flagged / valid:.1%} of valid pixels are flagged as likely fringe-order "
            f"errors (more than {FLAG_WARN_FRACTION:.0%}): the sequence description probably "
            "does not match the frames (code alignment, bit order, periods, frame order); "
            "see DecodeResult.flagged and summary()",
            DecodeWarning,
            stacklevel=3,
        )


# --- description file -------------------------------------------------------------------

_TOP_KEYS = (
    "format",
    "version",
    "width",
    "height",
    "scale",
    "description",
    "bit_depth",
    "blocks",
    "frames",
    "files",
)
_BLOCK_KEYS = {
    "phase": ("kind", "direction", "period", "periods", "steps", "profile", "offset", "sign"),
    "code": (
        "kind",
        "direction",
        "period",
        "bits",
        "bit_order",
        "align",
        "complement",
        "inverted",
    ),
    "uniform": ("kind", "count"),
}
_BIT_ORDERS = ("msb_first", "lsb_first")


def _count(name: str, value: Any, total: int) -> int:
    """A user-given frame count, bounded so the running total stays <= MAX_FRAMES."""
    count = positive_int(name, value)
    if total + count > MAX_FRAMES:
        raise InputError(name, f"at most {MAX_FRAMES} frames in all", total + count)
    return count


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise InputError(name, "true or false", value)
    return value


def _expand_blocks(blocks: Any) -> tuple[Frame, ...]:
    """Frames from the compact ``blocks`` list (module docstring), bounds checked first."""
    if not isinstance(blocks, list) or not blocks:
        raise InputError("blocks", "a non-empty list of block mappings", blocks)
    frames: list[Frame] = []
    for position, block in enumerate(blocks):
        name = f"blocks[{position}]"
        if not isinstance(block, Mapping) or "kind" not in block:
            raise InputError(name, "a mapping with a 'kind' key", block)
        kind = block["kind"]
        if kind == "phase":
            frames += _phase_block(name, block, len(frames))
        elif kind in _CODE_KINDS:
            frames += _code_block(name, block, len(frames))
        elif kind in _UNIFORM_KINDS:
            _known_keys(name, block, _BLOCK_KEYS["uniform"])
            count = _count(f"{name}.count", block.get("count", 1), len(frames))
            frames += [Frame(kind)] * count
        else:
            kinds = ("phase", *_CODE_KINDS, *_UNIFORM_KINDS)
            raise InputError(f"{name}.kind", f"one of {kinds}", kind)
    return tuple(frames)


def _phase_block(name: str, block: Mapping[str, Any], total: int) -> list[Frame]:
    _known_keys(name, block, _BLOCK_KEYS["phase"])
    if ("period" in block) == ("periods" in block):
        raise InputError(name, "exactly one of 'period' and 'periods'", sorted(block))
    periods = [block["period"]] if "period" in block else block["periods"]
    if not isinstance(periods, list) or not periods or len(periods) > MAX_FRAMES:
        raise InputError(f"{name}.periods", f"a list of 1..{MAX_FRAMES} periods", periods)
    steps = positive_int(f"{name}.steps", block.get("steps"), minimum=3)
    _count(f"{name}.steps", steps * len(periods), total)
    extra = {k: block[k] for k in ("profile", "offset", "sign") if k in block}
    return [
        Frame("phase", block.get("direction"), period, step=n, steps=steps, **extra)
        for period in periods
        for n in range(1, steps + 1)
    ]


def _code_block(name: str, block: Mapping[str, Any], total: int) -> list[Frame]:
    _known_keys(name, block, _BLOCK_KEYS["code"])
    bits = positive_int(f"{name}.bits", block.get("bits"))
    if bits > MAX_BITS:
        raise InputError(f"{name}.bits", f"an integer in 1..{MAX_BITS}", bits)
    order = _choice(f"{name}.bit_order", block.get("bit_order", "msb_first"), _BIT_ORDERS)
    complement = _flag(f"{name}.complement", block.get("complement", False))
    inverted = _flag(f"{name}.inverted", block.get("inverted", False))
    polarities = (False, True) if inverted else (False,)
    _count(name, (bits + complement) * len(polarities), total)
    common = {"align": block.get("align"), "period": block.get("period")}
    kind = block["kind"]
    sequence = range(1, bits + 1) if order == "msb_first" else range(bits, 0, -1)
    frames = [
        Frame(kind, block.get("direction"), bit=b, bits=bits, inverted=p, **common)
        for b in sequence
        for p in polarities
    ]
    if complement:
        frames += [
            Frame(f"{kind}_complement", block.get("direction"), inverted=p, **common)
            for p in polarities
        ]
    return frames


def _frames_from_entries(entries: Any) -> tuple[Frame, ...]:
    """Frames from the per-frame list (each entry's optional ``index`` must be its place)."""
    if not isinstance(entries, list):
        raise InputError("frames", "a list of frame dicts", entries)
    if len(entries) > MAX_FRAMES:
        raise InputError("frames", f"at most {MAX_FRAMES} frames", len(entries))
    for position, entry in enumerate(entries):
        if isinstance(entry, Mapping) and entry.get("index", position) != position:
            raise InputError(f"frames[{position}].index", str(position), entry.get("index"))
    return tuple(Frame.from_dict(entry) for entry in entries)


def _files(data: Mapping[str, Any], count: int) -> list[str] | None:
    """The image list of a description: top-level ``files`` or a ``file`` in every frame
    entry (as :meth:`PatternSequence.save` writes); None when there is none."""
    files = data.get("files")
    if files is None and isinstance(data.get("frames"), list):
        entries = data["frames"]
        if entries and all(isinstance(e, Mapping) and "file" in e for e in entries):
            files = [e["file"] for e in entries]
    if files is None:
        return None
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        raise InputError("files", "a list of file names", files)
    if len(files) != count:
        raise InputError("files", f"{count} file names (one per frame)", len(files))
    return files


def load_sequence_file(path: str | os.PathLike[str]) -> tuple[PatternSequence, list[str] | None]:
    """Read a sequence description file (module docstring).

    Parameters
    ----------
    path : a ``.yaml``, ``.yml`` or ``.json`` file of at most 1 MB, UTF-8.

    Returns
    -------
    sequence : the :class:`PatternSequence`.
    files : the image file names it lists, one per frame (``files:`` or the per-frame
        ``file`` entries), or None.

    Raises
    ------
    InputError : a missing, oversized, non-UTF-8 or malformed file, or a bad description.
    """
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json"):
        raise InputError("path", "a .yaml, .yml or .json file", str(file))
    if not file.is_file():
        raise InputError("path", "an existing file", str(file))
    size = file.stat().st_size
    if size > _MAX_FILE_BYTES:
        raise InputError("path", f"a file of at most {_MAX_FILE_BYTES} bytes", f"{size} bytes")
    try:
        text = file.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError("path", "UTF-8 text", f"{file}: {error}") from None
    if suffix == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as error:
            raise InputError("path", "valid JSON", f"{file}: {error}") from None
    else:
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as error:
            raise InputError("path", "valid YAML", f"{file}: {error}") from None
    sequence = PatternSequence.from_dict(data)
    return sequence, _files(data, len(sequence))


# --- standard sequences -----------------------------------------------------------------


def gray_bits_needed(
    span: int,
    period: float,
    complement: bool = True,
    *,
    align: str = "centre",
    scale: float = 1.0,
) -> int:
    """Fewest Gray (or binary) code bits that number every fringe order over ``span``
    projector px (with the complementary frame, its half-period code must fit in one more
    bit); ``period`` in pattern units, ``scale`` pattern units per projector px."""
    period = positive("period", period)
    code = BitCode("gray", period, 1, _choice("align", align, ALIGNS), bool(complement))
    return code.bits_needed(span, positive("scale", scale))


def build_sequence(
    width: int,
    height: int,
    *,
    periods: float | Sequence[float] = 18.0,
    steps: int | Sequence[int] = 18,
    gray_bits: int | None = None,
    complementary: bool = True,
    directions: Sequence[str] = DIRECTIONS,
    white: bool = True,
    black: bool = True,
) -> PatternSequence:
    """Build a sequence in the standard frame order (module docstring).

    Parameters
    ----------
    width, height : projector size in px.
    periods : one period (with ``gray_bits``, or covering the axis) or two or more
        (heterodyne), projector px, need not be integers.
    steps : phase steps ``N >= 3``, one for all periods or one per period (ascending order).
    gray_bits : Gray code bits (single period only); ``None``: no Gray code.
    complementary : add the complementary Gray frame (ignored without ``gray_bits``).
    directions : subset of ``("v", "h")``, in projection order.
    white, black : add the uniform frames (both present: they set the Gray threshold).

    Raises
    ------
    InputError : on a bad argument or a direction that could not be decoded.
    """
    if isinstance(directions, str) or not directions:
        raise InputError("directions", f"a non-empty sequence of {DIRECTIONS}", directions)
    if any(d not in DIRECTIONS for d in directions) or len(set(directions)) != len(directions):
        raise InputError("directions", f"distinct entries of {DIRECTIONS}", directions)
    period_list = [periods] if np.ndim(periods) == 0 else list(periods)  # type: ignore[arg-type]
    period_list = sorted(positive("periods", p) for p in period_list)
    if not period_list or len(set(period_list)) != len(period_list):
        raise InputError("periods", "one or more distinct periods", periods)
    step_list = [steps] * len(period_list) if np.ndim(steps) == 0 else list(steps)  # type: ignore[list-item]
    if len(step_list) != len(period_list):
        raise InputError("steps", f"one value or {len(period_list)} values", steps)
    step_list = [positive_int("steps", n, minimum=3) for n in step_list]
    if gray_bits is not None:
        gray_bits = positive_int("gray_bits", gray_bits)
        if len(period_list) != 1:
            raise InputError("periods", "a single period with gray_bits", periods)
    frames: list[Frame] = []
    for direction in directions:
        for period, count in zip(period_list, step_list, strict=True):
            frames += [
                Frame("phase", direction, period, step=n, steps=count) for n in range(1, count + 1)
            ]
        if gray_bits is not None:
            frames += [
                Frame("gray", direction, period_list[0], bit=b, bits=gray_bits)
                for b in range(1, gray_bits + 1)
            ]
            if complementary:
                frames.append(Frame("gray_complement", direction, period_list[0]))
    if white:
        frames.append(Frame("white"))
    if black:
        frames.append(Frame("black"))
    return PatternSequence(width, height, tuple(frames))


def default_sequence(width: int = 912, height: int = 1140) -> PatternSequence:
    """The paper's 52 frames: 18 steps of period 18 px, 6-bit Gray code + complement,
    vertical then horizontal, then white and black (order in the module docstring)."""
    return build_sequence(width, height, periods=18.0, steps=18, gray_bits=6, complementary=True)


def heterodyne_sequence(
    width: int = 912,
    height: int = 1140,
    *,
    periods: Sequence[float] = DEFAULT_HETERODYNE_PERIODS,
    steps: int | Sequence[int] = 6,
    directions: Sequence[str] = DIRECTIONS,
    white: bool = True,
    black: bool = True,
) -> PatternSequence:
    """Multi-frequency (heterodyne) phase shifting, by default three periods (64, 63 and 56
    fringes over 1152 px) of 6 steps in both directions plus white and black: 38 frames.

    The finest period is the one decoded; its beats with the others (1152 px and 144 px by
    default) must include one that covers each axis. See
    :func:`virtus.patterns.phase.unwrap_heterodyne`.
    """
    if np.ndim(periods) != 1 or len(periods) < 2:
        raise InputError("periods", "two or more periods", periods)
    return build_sequence(
        width,
        height,
        periods=periods,
        steps=steps,
        directions=directions,
        white=white,
        black=black,
    )
