"""Fringe pattern sequences as data: phase shifting, Gray and binary codes, temporal unwrapping.

A :class:`PatternSequence` is one object that encodes itself (:meth:`~PatternSequence.profile`,
:meth:`~PatternSequence.image`, :meth:`~PatternSequence.images`: what the projector shows),
says how its frames decode (:meth:`~PatternSequence.plans`) and decodes camera images of
itself (:meth:`~PatternSequence.decode`, driver in :mod:`virtus.patterns.decode`, math in
:mod:`virtus.patterns.phase`). Each frame is a :class:`~virtus.patterns.frames.Frame` (one
record of plain fields); the codings behind them, :class:`~virtus.patterns.codings.PhaseCoding`
and :class:`~virtus.patterns.codings.BitCode`, encode and decode themselves (conventions in
:mod:`virtus.patterns.codings`). Sequences are read from and written to a description file
(:mod:`virtus.patterns.files`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive, positive_int
from virtus.errors import InputError
from virtus.patterns import decode as _decode
from virtus.patterns import phase as _phase
from virtus.patterns.codings import BitCode, PhaseCoding, axis_extent
from virtus.patterns.decode import CodePlan, DecodePlan, DecodeResult, PhaseSet
from virtus.patterns.frames import (
    _CODE_KINDS,
    _COMPLEMENT_KINDS,
    DIRECTIONS,
    MAX_FRAMES,
    Frame,
    _known_keys,
)

__all__ = ["LEVELS", "PatternSequence"]

#: Projector levels: pattern values are multiples of 1 / LEVELS (8 bit).
LEVELS = 255


def _quantise(values: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as the 8-bit projector shows them (float64, multiples of 1/255)."""
    return np.rint(np.asarray(values, dtype=np.float64) * LEVELS) / LEVELS


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


@dataclass(frozen=True)
class PatternSequence:
    """An ordered set of projector frames that knows how to encode and decode itself.

    Parameters
    ----------
    width, height : projector size in px (columns, rows).
    frames : the frames in projection order, at most :data:`MAX_FRAMES`.
    scale : pattern units per projector px, ``(along u_p, along v_p)`` = for directions
        ``("v", "h")``, or a mapping ``{"v": .., "h": ..}``; default ``(1, 1)``.

    Every direction present must be decodable on its own (:mod:`~virtus.patterns.decode`):
    one phase set plus a complete code of the same period (each bit once, plain or as an
    inverted pair, and optionally the complementary frame), enough bits to number every
    order; two or more phase sets (multi-wavelength when the longest period covers the axis,
    else heterodyne with a beat that covers it); one phase set whose period covers the
    axis; or a complete code alone (no phase frames: decoded to the centres of its stripes,
    :mod:`~virtus.patterns.codings`; a bit without its inverse frame needs white and black
    frames for its threshold). White, black and ignore frames may appear any number of
    times, anywhere.

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
        return axis_extent(self.span(direction), self.axis_scale(direction))

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
        code_frames = [(i, f) for i, f in mine if f.kind != "phase"]
        if len(code_frames) == len(mine):  # a code alone: decoded to stripe centres
            return DecodePlan("code_only", (), self._code_plan(direction, None, code_frames))
        sets = _phase_sets(direction, [(i, f) for i, f in mine if f.kind == "phase"])
        periods = tuple(s.coding.period for s in sets)
        extent = self.extent(direction)
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

    def _code_plan(
        self, direction: str, periods: tuple[float, ...] | None, frames: list[tuple[int, Frame]]
    ) -> CodePlan:
        """Check a direction's code frames and say which frame shows which bit
        (``periods`` None: a code alone, whose frames share one period, the stripe width)."""
        period = frames[0][1].period if periods is None else periods[0]
        if (periods is not None and len(periods) != 1) or any(
            f.period != period for _, f in frames
        ):
            what = "one period (stripe width)" if periods is None else "exactly one phase period"
            raise InputError(
                "frames",
                f"code frames with {what}, the same ({direction!r})",
                sorted({period, *(f.period for _, f in frames)}),
            )
        kinds = {(_CODE_KINDS.get(f.kind) or _COMPLEMENT_KINDS[f.kind], f.align) for _, f in frames}
        if len(kinds) != 1:
            raise InputError("frames", f"one code and alignment ({direction!r})", sorted(kinds))
        ((code, align),) = kinds
        bit_frames = [f for _, f in frames if f.kind in _CODE_KINDS]
        if not bit_frames:
            raise InputError("frames", f"bit frames with the complement ({direction!r})", 0)
        bits = bit_frames[0].bits
        slots: dict[tuple[int, bool | None], int] = {}
        for i, f in frames:
            slot = (f.bit if f.bit is not None else 0, f.inverted)
            if f.bits not in (None, bits) or slot in slots:
                raise InputError(
                    "frames",
                    f"{bits}-bit code frames, each bit (and complement) at most once per "
                    f"polarity ({direction!r})",
                    f.to_dict(),
                )
            slots[slot] = i
        order = [*range(1, bits + 1)]  # type: ignore[operator]
        missing = [b for b in order if (b, False) not in slots and (b, True) not in slots]
        if missing:
            raise InputError("frames", f"every bit 1..{bits} of the code ({direction!r})", missing)
        complement = (0, False) in slots or (0, True) in slots
        if complement:
            order.append(0)
        single = any((b, False) not in slots or (b, True) not in slots for b in order)
        kinds = {f.kind for f in self.frames}
        if periods is None and single and not {"white", "black"} <= kinds:
            raise InputError(
                "frames",
                f"white and black frames, or an inverse frame for every code bit: without "
                f"phase frames ({direction!r}) single code frames are thresholded at "
                f"(white + black) / 2",
                f"no {' or '.join(k for k in ('white', 'black') if k not in kinds)} frame",
            )
        coding = BitCode(code, period, bits, align, complement)  # type: ignore[arg-type]
        span, scale = self.span(direction), self.axis_scale(direction)
        need = coding.bits_needed(span, scale)
        if bits < need:  # type: ignore[operator]
            extra = ", with the complement" if complement else ""
            raise InputError(
                "bits",
                f">= {need} to number every period-{period:g} fringe over {span} px "
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
        (periods stay exact float64 values; ``scale`` only when not 1):
        :func:`virtus.patterns.files.sequence_to_dict`."""
        from virtus.patterns.files import sequence_to_dict  # files imports this module

        return sequence_to_dict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PatternSequence:
        """A sequence from a description (:mod:`virtus.patterns.files`): the per-frame form
        written by :meth:`to_dict` and :meth:`save`, or the compact ``blocks`` form.

        Raises
        ------
        InputError : on unknown keys, a bad value or a sequence that cannot be decoded.
        """
        from virtus.patterns.files import sequence_from_dict  # files imports this module

        return sequence_from_dict(data, cls)

    def save(self, directory: str | os.PathLike[str]) -> Path:
        """Write 8-bit grayscale PNGs ``000.png, 001.png, ...`` (``width`` x ``height``) and
        ``sequence.json`` (:meth:`to_dict` plus a ``file`` entry per frame) into
        ``directory``, created if needed; files of the same names are replaced
        (:func:`virtus.patterns.files.save_sequence`).

        Returns
        -------
        Path of ``sequence.json``; :meth:`from_dict` and
        :func:`~virtus.patterns.files.load_sequence_file` read it.
        """
        from virtus.patterns.files import save_sequence  # files imports this module

        return save_sequence(self, directory)

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
        min_contrast: float = 0.02,
    ) -> DecodeResult:
        """Decode camera images of this sequence into projector coordinates.

        Parameters
        ----------
        frames : (F, H, W) real or integer array, ``F = len(self)``: camera images in
            sequence order, indexed ``[frame, row, col]``, any intensity unit.
        min_modulation : a pixel is valid in a direction when every phase set of that
            direction has modulation ``B >= min_modulation * full_scale``.
        saturation_level : a pixel reaching this value (frame units, e.g. 255 for 8-bit) in
            any phase frame of a direction (code frame of a code alone) is invalid in it;
            ``None`` disables the check.
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
            turns it on. Codes alone (no phase frames) have no per-pixel check: theirs
            (``phase.stripe_consistency``) flags coordinates that jump away from their
            neighbours, and never repairs.
        min_contrast : directions decoded from a code alone (no phase frames): a pixel is
            valid when its every bit contrast is ``>= min_contrast * full_scale``, and, where
            bits are thresholded, ``white - black`` is too. Default 0.02: 5.1 DN at 8 bit.
            ``5 / 255`` on 8-bit frames is OpenCV ``GrayCodePattern``'s rule exactly (a
            pixel is decoded when every ``|pattern - inverse| >= 5``; its separate shadow
            mask, ``white - black > 40``, is not applied).

        Returns
        -------
        DecodeResult

        Warns
        -----
        DecodeWarning : when more than
            :data:`~virtus.patterns.decode.FLAG_WARN_FRACTION` of valid pixels is flagged.

        Notes
        -----
        Code frames are thresholded at ``(mean white + mean black) / 2`` when the sequence
        has both, else at the phase background ``A`` (an inverted pair by comparing its two
        images). Temporal and heterodyne pixels whose unwrapping residual exceeds ``pi / 2``
        are invalid (order unreliable). Coordinates decoded outside ``[-1, L]`` px (more
        than half a pixel beyond the projector) are invalid.

        A direction without phase frames decodes from its code alone
        (:func:`~virtus.patterns.decode.decode_code_only`): ``proj_uv`` holds the centre of
        the code's stripe (the projector column or row index for a code per pixel),
        ``phase_*`` is NaN and ``period_*`` None, ``stripe_*`` the stripe width and
        ``confidence_*`` the smallest bit contrast; each bit of a pattern/inverse pair is
        ``pattern > inverse`` with contrast ``|pattern - inverse|``, a single bit frame is
        compared with ``(white + black) / 2`` with contrast ``2 |frame - threshold|``.
        """
        return _decode.decode_frames(
            frames,
            self.plans(),
            kinds=tuple(f.kind for f in self.frames),
            size=(self.width, self.height),
            scale=self.scale,
            min_modulation=min_modulation,
            saturation_level=saturation_level,
            full_scale=full_scale,
            repair=repair,
            neighbour_check=neighbour_check,
            min_contrast=min_contrast,
        )

    def runs_neighbour_check(
        self, direction: str, neighbour_check: bool | None, repair: bool
    ) -> bool:
        """Whether :meth:`decode` compares ``direction``'s orders with neighbours: when
        asked, when repairing, and by default where no per-pixel check exists (codes without
        the complementary frame, the window method)."""
        return _decode.runs_neighbour_check(self._plans[direction], neighbour_check, repair)

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
        return _decode.assemble_result(
            out,
            self.plans(),
            self.scale,
            modulation=modulation,
            background=background,
            repaired=repaired,
            full_scale=full_scale,
        )

    def check_neighbours(self, direction: str, decoded: dict[str, Any], repair: bool) -> int:
        """Flag (or repair) orders that disagree with neighbours; returns pixels repaired."""
        return _decode.check_neighbours(
            self._plans.get(direction),
            self.span(direction),
            self.axis_scale(direction),
            decoded,
            repair,
        )
