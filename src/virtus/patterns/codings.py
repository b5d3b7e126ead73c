"""Codings of fringe frames, numpy only: N-step phase shifting (:class:`PhaseCoding`) and
Gray or plain binary codes of the fringe order (:class:`BitCode`). Each encodes frame values
and decodes its own images; :func:`gray_bits_needed` sizes a code for an axis.

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
  pattern units; decoded ``proj_uv`` is in projector px. Projector px ``j`` shows the
  pattern at ``w = scale j``: with scale 2, DMD row ``2j``, the first row of the pair
  ``(2j, 2j + 1)`` that px ``j`` stands for, not the pair's centre ``2j + 0.5`` (a 0.25 px
  difference; :mod:`virtus.patterns.files` says what that means for a real projector).
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
* Codes alone (a direction without phase frames, e.g. OpenCV's ``GrayCodePattern``): the
  code's ``period`` is its stripe width ``T`` in pattern units, and a pixel decodes to the
  *stripe centre*: the index ``k`` (``h`` with the complementary frame) names the projector
  pixels that show it, ``j_first..j_last``, and the decoded coordinate is their mid-point
  ``(j_first + j_last) / 2`` px (pixel ``j``'s centre is ``j``, OpenCV's convention), exact
  whatever the stripe width (:meth:`BitCode.cell_centres`). With ``align: edge`` and
  ``T = scale`` (a word per projector pixel, as OpenCV's) that is ``k = j`` itself; with
  ``T = scale L / 2**bits`` (``bits`` bits over ``L >= 2**bits`` px) pixel ``j`` shows
  ``k = floor(j 2**bits / L)`` and stripe ``k`` spans pixels ``ceil(k L / 2**bits) ..
  ceil((k + 1) L / 2**bits) - 1`` (for ``L / 2**bits = S`` whole: centre
  ``k S + (S - 1) / 2``); these two are the defaults of a code block without ``period``
  (:mod:`virtus.patterns.files`). An index no projector pixel shows is invalid.
* Every frame is 8-bit: each value shown is ``round(255 v) / 255``. White frames show 1,
  black and ``ignore`` frames 0 (ignored frames are in a capture but not decoded).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.checks import positive, positive_int
from virtus.errors import InputError
from virtus.patterns import phase as _phase

__all__ = [
    "ALIGNS",
    "MAX_BITS",
    "PROFILES",
    "BitCode",
    "PhaseCoding",
    "axis_extent",
    "gray_bits_needed",
]

#: Phase frame profiles.
PROFILES = ("sinusoidal", "binary", "dithered")
#: Code alignments: code edges where a zero-offset wrapped phase jumps, or at period starts.
ALIGNS = ("centre", "edge")
#: Most bits of one code (bounds checked before allocating).
MAX_BITS = 24
#: 1-D ordered (Bayer) dither thresholds of the ``dithered`` profile, by pixel index mod 8.
_BAYER = (np.array([0, 4, 2, 6, 1, 5, 3, 7], dtype=np.float64) + 0.5) / 8.0


def _choice(name: str, value: Any, options: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in options:
        raise InputError(name, f"one of {options}", value)
    return value


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

    def pixel_cells(self, span: int, scale: float = 1.0) -> np.ndarray:
        """(span,) int64, non-decreasing: the index each projector pixel ``j = 0..span-1``
        shows, as :meth:`decode` returns it (``h`` with the complement, the order without)."""
        cells = self.half_index(scale * np.arange(positive_int("span", span), dtype=np.float64))
        return cells if self.complement else cells >> 1

    def cell_centres(self, index: np.ndarray, span: int, scale: float = 1.0) -> np.ndarray:
        """Projector px of the centre of the stripe a decoded index names (a code decoded
        alone, module docstring): ``(j_first + j_last) / 2`` over the projector pixels that
        show ``index``, NaN for an index no pixel shows.

        Parameters
        ----------
        index : (...) int, from :meth:`decode`.
        span : projector px along the axis.
        scale : pattern units per projector px.

        Returns
        -------
        (...) float64, projector px along the axis (pixel ``j``'s centre is ``j``).
        """
        cells = self.pixel_cells(span, scale)
        index = np.asarray(index, dtype=np.int64)
        first = np.searchsorted(cells, index, side="left")
        last = np.searchsorted(cells, index, side="right") - 1
        return np.where(last >= first, 0.5 * (first + last), np.nan)

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


def axis_extent(span: int, scale: float) -> float:
    """Pattern units from the first to the last pixel centre of an axis of ``span``
    projector px at ``scale`` pattern units per px, plus one."""
    return scale * (span - 1.0) + 1.0


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
