"""Fringe pattern sequences: N-step phase shifting, Gray code (+ complementary), heterodyne.

A :class:`PatternSequence` is one object that encodes itself (:meth:`~PatternSequence.profile`,
:meth:`~PatternSequence.image`, :meth:`~PatternSequence.images`: what the projector shows)
and decodes camera images of itself (:meth:`~PatternSequence.decode`, math in
:mod:`virtus.phase`).

Conventions
-----------
* Projector coordinates ``(u_p, v_p)`` in px: the centre of projector pixel (col 0, row 0)
  is at ``(0, 0)``, column ``j`` covers ``u_p`` in ``[j - 0.5, j + 0.5)``; images are indexed
  ``[row, col]``.
* Vertical fringes (direction ``"v"``) vary along ``u_p`` (columns) and decode to
  ``phase_v``; horizontal fringes (``"h"``) vary along ``v_p`` (rows) and decode to
  ``phase_h``.
* Absolute phase ``Phi = 2 pi u / T`` for a period ``T`` in projector px (any real ``T > 0``),
  so the phase origin is the centre of pixel 0 whatever ``T`` is.
* Phase frame ``n`` of ``N`` (``n = 1..N``) shows ``0.5 + 0.5 cos(Phi + 2 pi n / N)``, so the
  camera sees ``I_n = A + B cos(Phi + 2 pi n / N)``.
* Fringe order ``k1 = floor(u / T + 1/2)``: the integer with ``Phi - 2 pi k1`` in
  ``[-pi, pi)``, so orders change where the wrapped phase jumps.
* Gray frame ``bit`` (1 = most significant, projected first) of a ``bits``-bit code is white
  where that bit of the reflected binary code of ``k1`` is 1. The complementary frame is the
  least significant bit of the ``(bits + 1)``-bit Gray code of the half-period index
  ``g = floor(2 u / T + 1)`` (whose leading ``bits`` bits are the code of ``k1``): its edges
  lie half a period from the order edges, which lets the decoder fix the one-period jumps a
  Gray code makes at its own edges. Binary frames are evaluated at the centre of each
  projector pixel (a DMD shows one value per pixel).
* The projector is 8-bit: every value shown is ``round(255 v) / 255``.

Frame order of :func:`build_sequence` (so of :func:`default_sequence`): for each direction
(``"v"`` then ``"h"``): for each period, ascending, the phase frames ``n = 1..N``; then the
Gray frames, most significant bit first; then the complementary frame. The white frame and
the black frame come last. The paper's default, 52 frames::

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

import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus import phase as _phase
from virtus.checks import positive, positive_int
from virtus.errors import InputError, VirtusError
from virtus.jsonio import write_json

__all__ = [
    "DEFAULT_HETERODYNE_PERIODS",
    "DIRECTIONS",
    "KINDS",
    "DecodeResult",
    "Frame",
    "PatternSequence",
    "build_sequence",
    "default_sequence",
    "gray_bits_needed",
    "heterodyne_sequence",
]

#: Frame kinds.
KINDS = ("phase", "gray", "gray_complement", "white", "black")
#: Fringe directions: "v" varies along u_p (columns), "h" along v_p (rows).
DIRECTIONS = ("v", "h")
#: Projector levels: pattern values are multiples of 1 / LEVELS (8 bit).
LEVELS = 255
#: Three periods with 64, 63 and 56 fringes over 1152 px (Towers' optimum choice: C. E.
#: Towers, D. P. Towers, J. D. C. Jones, Opt. Lett. 28(11), 887-889, 2003). Their beats with
#: the finest are 1152 px (covers a 1140 px axis) and 144 px: a ratio of 8 at each
#: unwrapping step.
DEFAULT_HETERODYNE_PERIODS = (1152.0 / 64.0, 1152.0 / 63.0, 1152.0 / 56.0)

_FORMAT = "virtus.pattern_sequence"
_VERSION = 1
_FIELDS = ("kind", "direction", "period", "step", "steps", "bit", "bits")


def _quantise(values: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as the 8-bit projector shows them (float64, multiples of 1/255)."""
    return np.rint(np.asarray(values, dtype=np.float64) * LEVELS) / LEVELS


@dataclass(frozen=True)
class Frame:
    """One projected frame.

    Attributes
    ----------
    kind : ``"phase"``, ``"gray"``, ``"gray_complement"``, ``"white"`` or ``"black"``.
    direction : ``"v"`` (varies along u_p), ``"h"`` (varies along v_p), ``None`` for the
        uniform white and black frames.
    period : fringe period ``T`` in projector px (phase frames; for Gray and complementary
        frames the period whose fringe order they encode), ``None`` for uniform frames.
    step, steps : phase frames only: shift index ``n`` in ``1..N`` and ``N >= 3``.
    bit, bits : Gray frames only: bit index in ``1..bits``, 1 the most significant.
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
        if self.kind in ("white", "black"):
            for name in _FIELDS[1:]:
                if getattr(self, name) is not None:
                    raise InputError(name, f"None for a {self.kind} frame", getattr(self, name))
            return
        if self.direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", self.direction)
        object.__setattr__(self, "period", positive("period", self.period))
        if self.kind == "phase":
            steps = positive_int("steps", self.steps, minimum=3)
            step = positive_int("step", self.step)
            if step > steps:
                raise InputError("step", f"an integer in 1..{steps}", self.step)
            object.__setattr__(self, "steps", steps)
            object.__setattr__(self, "step", step)
        elif self.step is not None or self.steps is not None:
            raise InputError("step", f"None for a {self.kind} frame", self.step)
        if self.kind == "gray":
            bits = positive_int("bits", self.bits)
            bit = positive_int("bit", self.bit)
            if bit > bits:
                raise InputError("bit", f"an integer in 1..{bits}", self.bit)
            object.__setattr__(self, "bits", bits)
            object.__setattr__(self, "bit", bit)
        elif self.bit is not None or self.bits is not None:
            raise InputError("bit", f"None for a {self.kind} frame", self.bit)

    @property
    def uniform(self) -> bool:
        """True for the white and black frames."""
        return self.direction is None

    def values(self, coordinate: np.ndarray) -> np.ndarray:
        """The pattern before 8-bit quantisation, at any projector coordinate.

        Phase frames give the cosine at the exact coordinate; Gray and complementary frames
        the value of the projector pixel containing it; uniform frames 1 or 0.

        Parameters
        ----------
        coordinate : (...) float, projector px along the frame's axis (u_p for ``"v"``,
            v_p for ``"h"``).

        Returns
        -------
        (...) float64 in [0, 1], same shape as ``coordinate``.
        """
        u = np.asarray(coordinate, dtype=np.float64)
        if self.kind == "white":
            return np.ones_like(u)
        if self.kind == "black":
            return np.zeros_like(u)
        period = float(self.period)  # type: ignore[arg-type]
        if self.kind == "phase":
            shift = 2.0 * np.pi * self.step / self.steps  # type: ignore[operator]
            return 0.5 + 0.5 * np.cos(_phase.coordinate_to_phase(u, period) + shift)
        centre = np.floor(u + 0.5)  # centre of the projector pixel containing u
        if self.kind == "gray":
            code = _phase.gray_encode(np.floor(centre / period + 0.5))
            return ((code >> (self.bits - self.bit)) & 1).astype(np.float64)  # type: ignore[operator]
        return (_phase.gray_encode(np.floor(2.0 * centre / period + 1.0)) & 1).astype(np.float64)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict holding ``kind`` and the fields that apply to it."""
        return {k: getattr(self, k) for k in _FIELDS if getattr(self, k) is not None}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Frame:
        """Inverse of :meth:`to_dict`; ``index`` and ``file`` keys (written by
        :meth:`PatternSequence.describe` and :meth:`PatternSequence.save`) are ignored."""
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError("frame", "a mapping with a 'kind' key", data)
        unknown = set(data) - set(_FIELDS) - {"index", "file"}
        if unknown:
            raise InputError("frame", f"keys among {list(_FIELDS)}", sorted(unknown))
        return cls(**{k: data[k] for k in _FIELDS if k in data})


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Decoded camera images; every map is ``(H, W)``, indexed ``[row, col]`` of the camera.

    Attributes
    ----------
    proj_uv : (H, W, 2) float64, projector coordinates ``(u_p, v_p)`` in px; ``u_p`` is NaN
        where ``mask_v`` is False, ``v_p`` where ``mask_h`` is False.
    phase_v, phase_h : (H, W) float64, absolute phase in radians of the direction's finest
        period (``Phi = 2 pi u / period_v``); NaN where invalid or the direction is absent.
    modulation : (H, W) float64, fringe modulation ``B`` in frame units: the smallest over
        the sequence's phase sets.
    background : (H, W) float64, background ``A`` in frame units: the mean over the phase sets.
    mask : (H, W) bool, valid in every direction the sequence has.
    mask_v, mask_h : (H, W) bool, valid per direction (all False for an absent direction).
    period_v, period_h : the finest period (px) of each direction, ``None`` if absent.
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


@dataclass(frozen=True)
class _Plan:
    """Which frames decode one direction, and how (checked once, at construction)."""

    method: str  # "gray", "heterodyne" or "window"
    periods: tuple[float, ...]  # ascending: periods[0] is the reported (finest) period
    phase_sets: tuple[tuple[int, ...], ...]  # frame indices of each period, steps 1..N
    gray: tuple[int, ...] = ()  # Gray frame indices, most significant bit first
    complement: int | None = None  # index of the complementary frame


@dataclass(frozen=True)
class PatternSequence:
    """An ordered set of projector frames that knows how to encode and decode itself.

    Parameters
    ----------
    width, height : projector size in px (columns, rows).
    frames : the frames in projection order.

    Every direction present must be decodable on its own, with one of: one phase set plus a
    complete Gray code of the same period (optionally with its complementary frame); two or
    more phase sets whose longest beat covers the axis (heterodyne); one phase set whose
    period covers the axis. At most one white and one black frame.

    Raises
    ------
    InputError : if the frames do not form such a sequence.
    """

    width: int
    height: int
    frames: tuple[Frame, ...]
    _plans: dict[str, _Plan] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "width", positive_int("width", self.width))
        object.__setattr__(self, "height", positive_int("height", self.height))
        frames = tuple(self.frames) if isinstance(self.frames, Iterable) else ()
        if not frames or not all(isinstance(f, Frame) for f in frames):
            raise InputError("frames", "a non-empty sequence of Frame", self.frames)
        object.__setattr__(self, "frames", frames)
        for kind in ("white", "black"):
            if sum(f.kind == kind for f in frames) > 1:
                raise InputError("frames", f"at most one {kind} frame", [f.kind for f in frames])
        plans = {d: self._plan_direction(d) for d in DIRECTIONS}
        object.__setattr__(self, "_plans", {d: p for d, p in plans.items() if p is not None})

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def directions(self) -> tuple[str, ...]:
        """Directions present, in ``("v", "h")`` order."""
        return tuple(d for d in DIRECTIONS if d in self._plans)

    def span(self, direction: str) -> int:
        """Projector px along the axis that ``direction``'s fringes vary on."""
        if direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", direction)
        return self.width if direction == "v" else self.height

    def periods(self, direction: str) -> tuple[float, ...]:
        """Phase periods (px, ascending) of ``direction``; empty if it is absent. The first is
        the period of the decoded absolute phase."""
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

    def _plan_direction(self, direction: str) -> _Plan | None:
        mine = [(i, f) for i, f in enumerate(self.frames) if f.direction == direction]
        if not mine:
            return None
        sets: dict[float, dict[int, int]] = {}
        steps: dict[float, int] = {}
        for i, f in mine:
            if f.kind != "phase":
                continue
            if steps.setdefault(f.period, f.steps) != f.steps:  # type: ignore[arg-type]
                raise InputError(
                    "frames",
                    f"one step count per period ({direction!r}, T = {f.period})",
                    (steps[f.period], f.steps),  # type: ignore[index]
                )
            by_step = sets.setdefault(f.period, {})  # type: ignore[arg-type]
            if f.step in by_step:
                raise InputError("frames", "each phase step once", f.to_dict())
            by_step[f.step] = i  # type: ignore[index]
        if not sets:
            raise InputError("frames", f"phase frames for direction {direction!r}", "none")
        for period, by_step in sets.items():
            if len(by_step) != steps[period]:
                raise InputError(
                    "frames",
                    f"steps 1..{steps[period]} of period {period} ({direction!r})",
                    sorted(by_step),
                )
        periods = tuple(sorted(sets))
        phase_sets = tuple(tuple(sets[p][n] for n in range(1, steps[p] + 1)) for p in periods)
        span = self.span(direction)
        gray = [(i, f) for i, f in mine if f.kind == "gray"]
        complement = [(i, f) for i, f in mine if f.kind == "gray_complement"]
        if gray or complement:
            if len(periods) != 1 or any(f.period != periods[0] for _, f in gray + complement):
                raise InputError(
                    "frames",
                    f"Gray frames with exactly one phase period, the same ({direction!r})",
                    list(periods),
                )
            if not gray:
                raise InputError("frames", f"Gray frames with the complement ({direction!r})", 0)
            bits = gray[0][1].bits
            by_bit = {f.bit: i for i, f in gray}
            if (
                any(f.bits != bits for _, f in gray)
                or len(gray) != bits
                or sorted(by_bit) != list(range(1, bits + 1))  # type: ignore[arg-type]
                or len(complement) > 1
            ):
                raise InputError(
                    "frames",
                    f"Gray bits 1..{bits} once each and at most one complement ({direction!r})",
                    ([f.bit for _, f in gray], len(complement)),
                )
            need = gray_bits_needed(span, periods[0], complement=bool(complement))
            if bits < need:  # type: ignore[operator]
                raise InputError(
                    "bits",
                    f">= {need} to number every period-{periods[0]} fringe over {span} px",
                    bits,
                )
            return _Plan(
                "gray",
                periods,
                phase_sets,
                tuple(by_bit[b] for b in range(1, bits + 1)),  # type: ignore[operator]
                complement[0][0] if complement else None,
            )
        if len(periods) == 1:
            if periods[0] < span:
                raise InputError(
                    "frames",
                    f"a Gray code, more periods, or a period >= {span} px ({direction!r})",
                    f"one period of {periods[0]:.6g} px",
                )
            return _Plan("window", periods, phase_sets)
        longest = max(_phase.beat_period(periods[0], p) for p in periods[1:])
        if longest < span:
            raise InputError(
                "frames",
                f"periods whose longest beat is >= {span} px ({direction!r})",
                f"{longest:.6g} px for periods {list(periods)}",
            )
        return _Plan("heterodyne", periods, phase_sets)

    # --- encoding -----------------------------------------------------------------------

    def _frame(self, index: int) -> Frame:
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise InputError("index", "an integer frame index", index)
        if not -len(self) <= index < len(self):
            raise InputError("index", f"a frame index in 0..{len(self) - 1}", index)
        return self.frames[index]

    def profile(self, index: int) -> np.ndarray:
        """What frame ``index`` shows along its varying axis.

        Returns
        -------
        (L,) float64 in [0, 1], 8-bit quantised (multiples of 1/255): ``L = width`` for
        direction ``"v"`` (entry ``j`` = column ``u_p = j``), ``L = height`` for ``"h"``
        (entry = row ``v_p``), ``L = 1`` for white and black frames.
        """
        frame = self._frame(index)
        length = 1 if frame.uniform else self.span(frame.direction)  # type: ignore[arg-type]
        return _quantise(frame.values(np.arange(length, dtype=np.float64)))

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
        (``direction``, ``period``, ``step``/``steps`` or ``bit``/``bits``)."""
        return [{"index": i, **frame.to_dict()} for i, frame in enumerate(self.frames)]

    def to_dict(self) -> dict[str, Any]:
        """Lossless JSON-ready description (periods stay exact float64 values)."""
        return {
            "format": _FORMAT,
            "version": _VERSION,
            "width": self.width,
            "height": self.height,
            "bit_depth": 8,
            "frames": self.describe(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PatternSequence:
        """Inverse of :meth:`to_dict` (also reads the ``sequence.json`` of :meth:`save`)."""
        if not isinstance(data, Mapping) or data.get("format") != _FORMAT:
            raise InputError("data", f"a mapping with format {_FORMAT!r}", data)
        if data.get("version") != _VERSION:
            raise InputError("version", str(_VERSION), data.get("version"))
        entries = data.get("frames")
        if not isinstance(entries, list):
            raise InputError("frames", "a list of frame dicts", entries)
        for position, entry in enumerate(entries):
            if isinstance(entry, Mapping) and entry.get("index", position) != position:
                raise InputError(f"frames[{position}].index", str(position), entry.get("index"))
        return cls(
            data.get("width"),  # type: ignore[arg-type]
            data.get("height"),  # type: ignore[arg-type]
            tuple(Frame.from_dict(entry) for entry in entries),
        )

    def save(self, directory: str | os.PathLike[str]) -> Path:
        """Write 8-bit grayscale PNGs ``000.png, 001.png, ...`` (``width`` x ``height``) and
        ``sequence.json`` (:meth:`to_dict` plus a ``file`` entry per frame) into
        ``directory``, created if needed; files of the same names are replaced.

        Returns
        -------
        Path of ``sequence.json``; :meth:`from_dict` reads it back.
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

        Returns
        -------
        DecodeResult

        Notes
        -----
        Gray frames are thresholded at ``(white + black) / 2`` when both uniform frames are in
        the sequence, else at the phase background ``A``. Heterodyne pixels whose unwrapping
        residual exceeds ``pi / 2`` are invalid (order unreliable). Coordinates decoded
        outside ``[-1, L]`` px (more than half a pixel beyond the projector) are invalid.
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
        threshold = None
        if any(f.kind == "white" for f in self.frames) and any(
            f.kind == "black" for f in self.frames
        ):
            white = stack[self.index_of("white")].astype(np.float64)
            threshold = 0.5 * (white + stack[self.index_of("black")])
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        modulations: list[np.ndarray] = []
        backgrounds: list[np.ndarray] = []
        for direction in DIRECTIONS:
            plan = self._plans.get(direction)
            if plan is None:
                out[direction] = (np.full(shape, np.nan), np.zeros(shape, dtype=bool))
                continue
            absolute, valid = self._decode_direction(
                stack,
                direction,
                plan,
                threshold,
                min_modulation,
                saturation_level,
                full_scale,
                modulations,
                backgrounds,
            )
            out[direction] = (absolute, valid)
        mask = np.full(shape, bool(self.directions))  # no fringes: nothing is valid
        for direction in self.directions:
            mask &= out[direction][1]
        coordinates = [
            _phase.phase_to_coordinate(out[d][0], self._plans[d].periods[0])
            if d in self._plans
            else out[d][0]
            for d in DIRECTIONS
        ]
        return DecodeResult(
            proj_uv=np.stack(coordinates, axis=-1),
            phase_v=out["v"][0],
            phase_h=out["h"][0],
            modulation=np.minimum.reduce(modulations) if modulations else np.full(shape, np.nan),
            background=np.mean(backgrounds, axis=0) if backgrounds else np.full(shape, np.nan),
            mask=mask,
            mask_v=out["v"][1],
            mask_h=out["h"][1],
            period_v=self._plans["v"].periods[0] if "v" in self._plans else None,
            period_h=self._plans["h"].periods[0] if "h" in self._plans else None,
        )

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

    def _decode_direction(
        self,
        stack: np.ndarray,
        direction: str,
        plan: _Plan,
        threshold: np.ndarray | None,
        min_modulation: float,
        saturation_level: float | None,
        full_scale: float,
        modulations: list[np.ndarray],
        backgrounds: list[np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Absolute phase of the finest period (NaN where invalid) and the validity mask."""
        wrapped = []
        valid = np.ones(stack.shape[1:], dtype=bool)
        for indices in plan.phase_sets:
            phase_frames = stack[list(indices)]
            phi, background, modulation = _phase.wrapped_phase(phase_frames)
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
        span = self.span(direction)
        if plan.method == "gray":
            cut = backgrounds[-len(wrapped)] if threshold is None else threshold
            bits = _phase.binarize(stack[list(plan.gray)], cut)
            order = _phase.gray_bits_to_order(bits)
            floor_order = None
            if plan.complement is not None:
                extra = _phase.binarize(stack[[plan.complement]], cut)
                half_period = _phase.gray_bits_to_order(np.concatenate([bits, extra]))
                floor_order = _phase.complementary_order(half_period)
            absolute = _phase.unwrap_gray(wrapped[0], order, floor_order)
        elif plan.method == "heterodyne":
            absolute, residual = _phase.unwrap_heterodyne(wrapped, plan.periods, span)
            # Past pi/2 the predicted order was within a quarter fringe of a rounding
            # boundary: the order is unreliable there.
            valid &= residual <= 0.5 * np.pi
        else:
            absolute = _phase.absolute_phase_in_window(wrapped[0], plan.periods[0], span)
        coordinate = _phase.phase_to_coordinate(absolute, plan.periods[0])
        valid &= (coordinate >= -1.0) & (coordinate <= span)
        return np.where(valid, absolute, np.nan), valid


def gray_bits_needed(span: int, period: float, complement: bool = True) -> int:
    """Fewest Gray bits that number every fringe order over ``span`` projector px (with the
    complementary frame, its half-period code must fit in one more bit)."""
    last = positive_int("span", span) - 1  # centre of the last pixel
    period = positive("period", period)
    if complement:
        codes = int(np.floor(2.0 * last / period + 1.0)) + 1
        return max(1, int(np.ceil(np.log2(codes))) - 1)
    codes = int(np.floor(last / period + 0.5)) + 1
    return max(1, int(np.ceil(np.log2(codes))))


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
    default) must include one that covers each axis. See :func:`virtus.phase.unwrap_heterodyne`.
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
