"""Fringe pattern sequences: N-step phase shifting, Gray code (+ complementary), multi-frequency.

A :class:`PatternSequence` is one object that knows how to encode itself (the 8-bit frames a
projector shows) and how to decode camera images of those frames back to projector
coordinates (:meth:`PatternSequence.decode`, math in :mod:`virtus.phase`).

Conventions
-----------
* Projector pixels: the centre of column 0 is at ``u_p = 0``; column ``j`` covers
  ``u_p in [j - 0.5, j + 0.5)``. Likewise rows and ``v_p``.
* Vertical fringes (direction ``"v"``) vary along ``u_p`` (projector columns) and decode to
  ``phase_v``; horizontal fringes (``"h"``) vary along ``v_p`` and decode to ``phase_h``.
* Absolute phase ``Phi = 2 pi u_p / T`` for period ``T`` in projector pixels (any real
  ``T > 0``), so the phase origin is the centre of column 0 whatever ``T`` is.
* Phase-shift frame ``n`` of ``N`` (``n = 1..N``) shows
  ``0.5 + 0.5 cos(Phi + 2 pi n / N)``, so a camera sees ``I_n = A + B cos(Phi + 2 pi n / N)``.
* Fringe order ``k = floor(u_p / T + 1/2)``: the integer with ``Phi - 2 pi k in [-pi, pi)``.
  An ``n``-bit Gray code frame shows bit ``b`` (``b = 1`` is the most significant) of the
  reflected binary code of ``k``. The complementary frame is the least significant bit of
  the ``(n + 1)``-bit Gray code of ``g = floor(2 u_p / T + 1)``: its code edges fall half a
  period away from the order edges (where ``Phi`` wraps), which lets the decoder correct
  the one-pixel jumps that Gray codes make at period edges. Gray codes are evaluated at the
  centre of each projector column (the DMD shows one value per pixel).
* Every value a frame shows is quantised to 8 bits: ``round(255 v) / 255``.

Frame order of :func:`phase_gray_sequence` (and so of :func:`default_sequence`): for each
direction in ``directions`` (default ``("v", "h")``): the ``N`` phase-shift frames
``n = 1..N``, the Gray code frames ``b = 1..n`` (most significant first), the complementary
frame; then the white frame and the black frame. The paper's default is
``[0:18]`` vertical phase, ``[18:24]`` vertical Gray bits 1-6, ``[24]`` vertical complement,
``[25:43]`` horizontal phase, ``[43:49]`` horizontal Gray, ``[49]`` horizontal complement,
``[50]`` white, ``[51]`` black: 52 frames.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from virtus.checks import positive, positive_int
from virtus.errors import InputError

#: Frame kinds.
KINDS = ("phase", "gray", "gray_complement", "white", "black")
#: Fringe directions: "v" varies along projector columns (u_p), "h" along rows (v_p).
DIRECTIONS = ("v", "h")
#: Projector bit depth: every pattern value is quantised to this many levels - 1.
LEVELS = 255
#: Format tag of :meth:`PatternSequence.to_dict`.
FORMAT = "virtus.patterns/1"

#: Towers' optimum three-frequency choice: 64, 63 and 56 fringes over 1152 px. The beat of
#: the first two (1 fringe over 1152 px) covers a 1140 px projector axis; the beat of the first
#: and the last (8 fringes) bridges it to the finest period with a ratio of 8 at each level.
#: C. E. Towers, D. P. Towers, J. D. C. Jones, "Optimum frequency selection in multifrequency
#: interferometry", Opt. Lett. 28(11), 887-889 (2003).
DEFAULT_HETERODYNE_PERIODS = (1152 / 64, 1152 / 63, 1152 / 56)


# --------------------------------------------------------------------------------------------
# Frames
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    """Description of one projected frame.

    Attributes
    ----------
    kind : ``"phase"``, ``"gray"``, ``"gray_complement"``, ``"white"`` or ``"black"``.
    direction : ``"v"`` (varies along ``u_p``), ``"h"`` (along ``v_p``), ``None`` for the
        uniform white and black frames.
    period : fringe period ``T`` in projector pixels for phase frames; for Gray frames the
        period whose fringe order the code counts; ``None`` for uniform frames.
    step, steps : phase-shift index ``n`` (1..N) and ``N`` (>= 3), phase frames only.
    bit, bits : Gray bit ``b`` (1 = most significant) of an ``n = bits``-bit code; the
        complementary frame has ``bits`` (the code it completes) and no ``bit``.
    """

    kind: str
    direction: str | None = None
    period: float | None = None
    step: int | None = None
    steps: int | None = None
    bit: int | None = None
    bits: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError("kind", f"one of {KINDS}", self.kind)
        uniform = self.kind in ("white", "black")
        if uniform:
            if self.direction is not None or self.period is not None:
                raise InputError(
                    "direction", f"None for a {self.kind} frame", (self.direction, self.period)
                )
        else:
            if self.direction not in DIRECTIONS:
                raise InputError("direction", f"one of {DIRECTIONS}", self.direction)
            object.__setattr__(self, "period", positive("period", self.period))
        if self.kind == "phase":
            steps = positive_int("steps", self.steps, minimum=3)
            step = positive_int("step", self.step)
            if step > steps:
                raise InputError("step", f"an integer in 1..{steps}", step)
            object.__setattr__(self, "steps", steps)
            object.__setattr__(self, "step", step)
        elif self.step is not None or self.steps is not None:
            raise InputError("step", f"None for a {self.kind} frame", (self.step, self.steps))
        if self.kind in ("gray", "gray_complement"):
            bits = positive_int("bits", self.bits)
            object.__setattr__(self, "bits", bits)
            if self.kind == "gray":
                bit = positive_int("bit", self.bit)
                if bit > bits:
                    raise InputError("bit", f"an integer in 1..{bits}", bit)
                object.__setattr__(self, "bit", bit)
            elif self.bit is not None:
                raise InputError("bit", "None for a gray_complement frame", self.bit)
        elif self.bit is not None or self.bits is not None:
            raise InputError("bit", f"None for a {self.kind} frame", (self.bit, self.bits))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict holding only the fields that apply to this kind."""
        out: dict[str, Any] = {"kind": self.kind, "direction": self.direction}
        for key in ("period", "step", "steps", "bit", "bits"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Frame:
        """Inverse of :meth:`to_dict` (an ``index`` key, as in :meth:`describe`, is ignored)."""
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError("frame", "a mapping with a 'kind' key", data)
        unknown = set(data) - {"kind", "direction", "period", "step", "steps", "bit", "bits"}
        unknown -= {"index", "file"}
        if unknown:
            raise InputError("frame", "only Frame fields", sorted(unknown))
        return cls(
            kind=data["kind"],
            direction=data.get("direction"),
            period=data.get("period"),
            step=data.get("step"),
            steps=data.get("steps"),
            bit=data.get("bit"),
            bits=data.get("bits"),
        )


def phase_shift_frames(direction: str, period: float, steps: int) -> tuple[Frame, ...]:
    """The ``steps`` frames ``n = 1..N`` of one N-step phase-shift set."""
    return tuple(
        Frame("phase", direction, period, step=n, steps=steps) for n in range(1, steps + 1)
    )


def gray_code_frames(
    direction: str, period: float, bits: int, complement: bool = True
) -> tuple[Frame, ...]:
    """Gray code frames ``b = 1..bits`` (most significant first), then the complement."""
    frames = tuple(Frame("gray", direction, period, bit=b, bits=bits) for b in range(1, bits + 1))
    if complement:
        frames += (Frame("gray_complement", direction, period, bits=bits),)
    return frames


def gray_encode(values: np.ndarray) -> np.ndarray:
    """Reflected binary (Gray) code of non-negative integers, same shape and dtype."""
    values = np.asarray(values)
    return values ^ (values >> 1)


def fringe_order(coord: np.ndarray, period: float) -> np.ndarray:
    """Fringe order ``k = floor(coord / T + 1/2)`` (int64): ``2 pi coord / T - 2 pi k`` is the
    wrapped phase in ``[-pi, pi)``. ``coord`` in projector pixels."""
    return np.floor(np.asarray(coord, dtype=np.float64) / period + 0.5).astype(np.int64)


def complement_code(coord: np.ndarray, period: float) -> np.ndarray:
    """Half-period code ``g = floor(2 coord / T + 1)`` (int64) of the complementary Gray code;
    its ``(n + 1)``-bit Gray code has the ``n``-bit code of the fringe order on top."""
    return np.floor(2.0 * np.asarray(coord, dtype=np.float64) / period + 1.0).astype(np.int64)


def quantize(values: np.ndarray) -> np.ndarray:
    """Quantise pattern values in [0, 1] to the projector's 8 bits, returned as float / 255."""
    return np.rint(np.asarray(values, dtype=np.float64) * LEVELS) / LEVELS


def gray_bits_needed(span: int, period: float, complement: bool) -> int:
    """Fewest Gray bits that number every fringe order over ``span`` projector pixels."""
    last = span - 1  # centre of the last column
    if complement:
        codes = int(complement_code(last, period)) + 1
        return max(1, math.ceil(math.log2(codes)) - 1)
    codes = int(fringe_order(last, period)) + 1
    return max(1, math.ceil(math.log2(codes)))


def beat_period(fine: float, coarse: float) -> float:
    """Equivalent period of the beat of two fringe periods, ``T1 T2 / |T2 - T1|`` (px)."""
    return fine * coarse / abs(coarse - fine)


# --------------------------------------------------------------------------------------------
# Sequences
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PatternSequence:
    """An ordered set of projector frames that can encode and decode itself.

    Parameters
    ----------
    width, height : projector size in pixels (columns, rows).
    frames : the frames in projection order.

    Each fringe direction present must be decodable on its own: either one phase-shift set
    plus Gray code frames of the same period (optionally with the complement), or two or more
    phase-shift sets of different periods whose beat (with the finest) covers the axis
    (heterodyne), or one set whose period alone covers the axis. At most one white and one
    black frame.
    """

    width: int
    height: int
    frames: tuple[Frame, ...]
    _plan: dict[str, _DirectionPlan] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "width", positive_int("width", self.width))
        object.__setattr__(self, "height", positive_int("height", self.height))
        frames = tuple(self.frames)
        if not frames or not all(isinstance(f, Frame) for f in frames):
            raise InputError("frames", "a non-empty sequence of Frame", self.frames)
        object.__setattr__(self, "frames", frames)
        for kind in ("white", "black"):
            if sum(f.kind == kind for f in frames) > 1:
                raise InputError("frames", f"at most one {kind} frame", [f.kind for f in frames])
        plan = {d: _plan_direction(d, self.span(d), frames) for d in DIRECTIONS}
        object.__setattr__(self, "_plan", {d: p for d, p in plan.items() if p is not None})

    # -- sizes and lookup ---------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self.frames)

    def span(self, direction: str) -> int:
        """Number of projector pixels along the axis a direction's fringes vary on."""
        if direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", direction)
        return self.width if direction == "v" else self.height

    @property
    def directions(self) -> tuple[str, ...]:
        """Fringe directions present, in ``("v", "h")`` order."""
        return tuple(d for d in DIRECTIONS if d in self._plan)

    def period(self, direction: str) -> float | None:
        """Period (px) whose absolute phase the decoder reports for ``direction`` (the finest)."""
        plan = self._plan.get(direction)
        return None if plan is None else plan.periods[0]

    def index_of(self, kind: str, direction: str | None = None, **fields: Any) -> int:
        """Index of the unique frame matching ``kind``, ``direction`` and ``fields``."""
        hits = [
            i
            for i, f in enumerate(self.frames)
            if f.kind == kind
            and f.direction == direction
            and all(getattr(f, k) == v for k, v in fields.items())
        ]
        if len(hits) != 1:
            raise InputError("frame", "exactly one matching frame", (kind, direction, fields))
        return hits[0]

    def _frame(self, index: int) -> Frame:
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise InputError("index", "an integer frame index", index)
        if not -len(self.frames) <= index < len(self.frames):
            raise InputError("index", f"a frame index in [0, {len(self.frames)})", index)
        return self.frames[index]

    # -- encoding -----------------------------------------------------------------------------

    def profile(self, index: int) -> np.ndarray:
        """Frame ``index`` along its varying axis, as the projector shows it.

        Returns
        -------
        (L,) float64 in [0, 1], 8-bit quantised (``k / 255``): ``L = width`` for direction
        ``"v"`` (entry ``j`` = column ``j``), ``L = height`` for ``"h"`` (entry = row);
        shape ``(1,)`` for the uniform white (1.0) and black (0.0) frames.
        """
        frame = self._frame(index)
        if frame.kind == "white":
            return np.ones(1)
        if frame.kind == "black":
            return np.zeros(1)
        coord = np.arange(self.span(frame.direction), dtype=np.float64)  # pixel centres
        if frame.kind == "phase":
            shift = 2.0 * np.pi * frame.step / frame.steps
            return quantize(0.5 + 0.5 * np.cos(2.0 * np.pi * coord / frame.period + shift))
        if frame.kind == "gray":
            code = gray_encode(fringe_order(coord, frame.period))
            return ((code >> (frame.bits - frame.bit)) & 1).astype(np.float64)
        code = gray_encode(complement_code(coord, frame.period))
        return (code & 1).astype(np.float64)

    def image(self, index: int) -> np.ndarray:
        """Frame ``index`` as a ``(height, width)`` float64 image in [0, 1] (8-bit quantised)."""
        frame = self._frame(index)
        prof = self.profile(index)
        if frame.direction == "v":
            return np.repeat(prof[np.newaxis, :], self.height, axis=0)
        if frame.direction == "h":
            return np.repeat(prof[:, np.newaxis], self.width, axis=1)
        return np.full((self.height, self.width), prof[0])

    def images(self) -> np.ndarray:
        """All frames as a ``(F, height, width)`` uint8 stack (0..255), in sequence order."""
        out = np.empty((len(self.frames), self.height, self.width), dtype=np.uint8)
        for i in range(len(self.frames)):
            out[i] = np.rint(self.image(i) * LEVELS).astype(np.uint8)
        return out

    # -- description and I/O ------------------------------------------------------------------

    def describe(self) -> list[dict[str, Any]]:
        """One JSON-ready dict per frame: ``index``, ``kind``, ``direction`` and the fields that
        apply (``period``; ``step``/``steps`` or ``bit``/``bits``)."""
        return [{"index": i, **f.to_dict()} for i, f in enumerate(self.frames)]

    def to_dict(self) -> dict[str, Any]:
        """Lossless JSON-ready description (periods are stored as exact float reprs)."""
        return {
            "format": FORMAT,
            "width": self.width,
            "height": self.height,
            "frames": self.describe(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PatternSequence:
        """Inverse of :meth:`to_dict`; other top-level keys (e.g. file lists) are ignored."""
        if not isinstance(data, Mapping):
            raise InputError("data", "a mapping", data)
        if data.get("format", FORMAT) != FORMAT:
            raise InputError("format", repr(FORMAT), data.get("format"))
        for key in ("width", "height", "frames"):
            if key not in data:
                raise InputError("data", f"a '{key}' key", sorted(data))
        frames = data["frames"]
        if isinstance(frames, str | bytes) or not isinstance(frames, Iterable):
            raise InputError("frames", "a list of frame dicts", frames)
        frames = list(frames)
        for i, item in enumerate(frames):
            if isinstance(item, Mapping) and item.get("index", i) != i:
                raise InputError("frames", f"frame {i} to have index {i}", item.get("index"))
        return cls(data["width"], data["height"], tuple(Frame.from_dict(f) for f in frames))


# --------------------------------------------------------------------------------------------
# Builders
# --------------------------------------------------------------------------------------------


def phase_gray_sequence(
    width: int,
    height: int,
    *,
    period: float = 18.0,
    steps: int = 18,
    bits: int | None = 6,
    complement: bool = True,
    directions: Sequence[str] = DIRECTIONS,
    white_black: bool = True,
) -> PatternSequence:
    """N-step phase shifting unwrapped by an n-bit Gray code (+ complementary frame).

    Parameters
    ----------
    width, height : projector size in pixels.
    period : fringe period ``T`` in projector pixels (any real > 0).
    steps : phase steps ``N`` (>= 3).
    bits : Gray code bits ``n``; ``None`` picks the fewest that number every fringe order of
        the longer axis. Too few raises :class:`InputError`.
    complement : add the complementary frame that corrects period-edge jumps.
    directions : fringe directions, subset of ``("v", "h")``, in projection order.
    white_black : append a white and a black frame (used as the Gray code threshold).
    """
    directions = _check_directions(directions)
    period = positive("period", period)
    steps = positive_int("steps", steps, minimum=3)
    if bits is None:
        spans = [width if d == "v" else height for d in directions]
        bits = max(gray_bits_needed(positive_int("width", s), period, complement) for s in spans)
    bits = positive_int("bits", bits)
    frames: list[Frame] = []
    for d in directions:
        frames += phase_shift_frames(d, period, steps)
        frames += gray_code_frames(d, period, bits, complement)
    if white_black:
        frames += [Frame("white"), Frame("black")]
    return PatternSequence(width, height, tuple(frames))


def heterodyne_sequence(
    width: int,
    height: int,
    *,
    periods: Sequence[float] = DEFAULT_HETERODYNE_PERIODS,
    steps: int | Sequence[int] = 6,
    directions: Sequence[str] = DIRECTIONS,
    white_black: bool = False,
) -> PatternSequence:
    """Multi-frequency (heterodyne) phase shifting.

    The finest period ``T1`` gives the reported phase; each other period ``Ti`` beats with it
    to an equivalent period ``T1 Ti / (Ti - T1)``. The longest beat must cover the axis
    (>= width or height); decoding unwraps from the longest beat down to ``T1``, so the ratio
    of successive beat periods (8 for the default, Towers' 64/63/56 fringes over 1152 px)
    sets the noise margin.

    Parameters
    ----------
    periods : two or more distinct periods in projector pixels.
    steps : phase steps per period, one int for all or one per period (each >= 3).
    directions, white_black : as in :func:`phase_gray_sequence`.
    """
    directions = _check_directions(directions)
    if isinstance(periods, str | bytes) or not isinstance(periods, Sequence) or len(periods) < 2:
        raise InputError("periods", "two or more periods in projector px", periods)
    periods = [positive("periods", p) for p in periods]
    if isinstance(steps, Sequence):
        if len(steps) != len(periods):
            raise InputError("steps", f"{len(periods)} step counts (one per period)", steps)
        step_list = [positive_int("steps", s, minimum=3) for s in steps]
    else:
        step_list = [positive_int("steps", steps, minimum=3)] * len(periods)
    frames: list[Frame] = []
    for d in directions:
        for period, n in zip(periods, step_list, strict=True):
            frames += phase_shift_frames(d, period, n)
    if white_black:
        frames += [Frame("white"), Frame("black")]
    return PatternSequence(width, height, tuple(frames))


def default_sequence(width: int = 912, height: int = 1140) -> PatternSequence:
    """The paper's sequence: 18 steps of period 18 px, 6-bit Gray code + complement, vertical
    then horizontal, then white and black: 52 frames (order in the module docstring)."""
    return phase_gray_sequence(width, height, period=18.0, steps=18, bits=6, complement=True)


def _check_directions(directions: Sequence[str]) -> tuple[str, ...]:
    out = tuple(directions) if not isinstance(directions, str) else (directions,)
    if not out or any(d not in DIRECTIONS for d in out) or len(set(out)) != len(out):
        raise InputError("directions", 'distinct entries of ("v", "h")', directions)
    return out


# --------------------------------------------------------------------------------------------
# Decoding plan: which frames serve which step, checked once at construction
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _DirectionPlan:
    periods: tuple[float, ...]  # ascending; periods[0] is the reported (finest) period
    phase_sets: tuple[tuple[int, ...], ...]  # frame indices of each period, steps 1..N
    gray: tuple[int, ...]  # Gray frame indices, bit 1 (MSB) first; empty without Gray code
    complement: int | None  # index of the complementary frame


def _plan_direction(direction: str, span: int, frames: tuple[Frame, ...]) -> _DirectionPlan | None:
    mine = [(i, f) for i, f in enumerate(frames) if f.direction == direction]
    if not mine:
        return None
    phase: dict[float, list[tuple[int, Frame]]] = {}
    for i, f in mine:
        if f.kind == "phase":
            phase.setdefault(f.period, []).append((i, f))
    if not phase:
        raise InputError("frames", f"phase-shift frames for direction {direction!r}", "none")
    sets = []
    for period in sorted(phase):
        members = phase[period]
        steps = members[0][1].steps
        by_step = {f.step: i for i, f in members}
        if any(f.steps != steps for _, f in members) or sorted(by_step) != list(
            range(1, steps + 1)
        ) or len(members) != steps:
            raise InputError(
                "frames",
                f"steps 1..N exactly once for period {period} ({direction!r})",
                sorted(f.step for _, f in members),
            )
        sets.append(tuple(by_step[n] for n in range(1, steps + 1)))
    periods = tuple(sorted(phase))
    gray = [(i, f) for i, f in mine if f.kind == "gray"]
    comp = [(i, f) for i, f in mine if f.kind == "gray_complement"]
    if gray or comp:
        if len(periods) != 1:
            raise InputError(
                "frames", f"one phase period with Gray code ({direction!r})", list(periods)
            )
        period = periods[0]
        bits = (gray or comp)[0][1].bits
        if any(f.period != period or f.bits != bits for _, f in gray + comp):
            raise InputError(
                "frames", f"Gray frames of period {period} and {bits} bits", direction
            )
        by_bit = {f.bit: i for i, f in gray}
        if len(gray) != bits or sorted(by_bit) != list(range(1, bits + 1)) or len(comp) > 1:
            raise InputError(
                "frames",
                f"Gray bits 1..{bits} once each and at most one complement ({direction!r})",
                (sorted(f.bit for _, f in gray), len(comp)),
            )
        need = gray_bits_needed(span, period, bool(comp))
        if bits < need:
            raise InputError(
                "bits", f">= {need} to number every period-{period} fringe over {span} px", bits
            )
        return _DirectionPlan(
            periods, tuple(sets), tuple(by_bit[b] for b in range(1, bits + 1)),
            comp[0][0] if comp else None,
        )
    reach = periods[0] if len(periods) == 1 else max(
        beat_period(periods[0], p) for p in periods[1:]
    )
    if reach < span:
        what = "period" if len(periods) == 1 else "longest beat period"
        raise InputError(
            "frames",
            f"Gray code, or a {what} >= {span} px to unwrap direction {direction!r}",
            f"{what} {reach:.6g} px",
        )
    return _DirectionPlan(periods, tuple(sets), (), None)
