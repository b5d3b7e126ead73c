"""Decoding camera images of a pattern sequence into projector coordinates, numpy only.

The driver, :func:`decode_frames`, follows a sequence's decode plans
(:meth:`PatternSequence.plans <virtus.patterns.PatternSequence.plans>`: a :class:`DecodePlan`
per direction, of :class:`PhaseSet` and :class:`CodePlan`) with the math of
:mod:`virtus.patterns.phase` and gives a :class:`DecodeResult`;
:meth:`PatternSequence.decode <virtus.patterns.PatternSequence.decode>` calls it.

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
* one phase set whose period covers the axis: absolute as it is;
* a code alone, no phase frames (:func:`decode_code_only`, e.g. OpenCV's
  ``GrayCodePattern``): the centre of the code's stripe (``proj_uv``; the column or row
  index for a code per projector pixel), no phase (``phase_*`` NaN, ``period_*`` None), the
  stripe width in ``stripe_*`` and the smallest bit contrast in ``confidence_*``.

Gray/binary frames are thresholded at ``(mean white + mean black) / 2`` when the sequence
has both, else at the phase background ``A``. Decoding says when it is likely wrong
(``DecodeResult.flagged``): pixels whose phase is off its half-period code cell by more
than :data:`CODE_FLAG_RAD`, whose temporal/heterodyne residual exceeds
:data:`RESIDUAL_FLAG_RAD`, or whose fringe order disagrees with their neighbours on a
continuous surface (``phase.order_consistency``; this catches a wrong description, e.g.
swapped alignment or bit order, which every single pixel would fit), or, for a code alone,
whose coordinate jumps away from most of their neighbours' (``phase.stripe_consistency``,
which flags the whole direction when most changes between neighbours are such jumps: a
wrong bit order or code). Above
:data:`FLAG_WARN_FRACTION` of valid pixels a :class:`DecodeWarning` is issued.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.checks import finite, positive
from virtus.errors import InputError
from virtus.patterns import phase as _phase
from virtus.patterns.codings import BitCode, PhaseCoding, axis_extent
from virtus.patterns.frames import DIRECTIONS

__all__ = [
    "CODE_FLAG_RAD",
    "FLAG_WARN_FRACTION",
    "RESIDUAL_FLAG_RAD",
    "CodePlan",
    "DecodePlan",
    "DecodeResult",
    "DecodeWarning",
    "PhaseSet",
    "assemble_result",
    "check_neighbours",
    "check_saturation_level",
    "decode_code_only",
    "decode_frames",
    "runs_neighbour_check",
    "warn_if_flagged",
]

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
#: A code alone: neighbouring camera pixels whose coordinates differ by more than this many
#: stripes, and more than :data:`STRIPE_JUMP_PX`, jump (a continuous surface changes by
#: about a stripe; a misread bit, a wrong bit order or code by far more).
STRIPE_JUMP_STRIPES = 2.0
STRIPE_JUMP_PX = 8.0


class DecodeWarning(UserWarning):
    """Many decoded pixels look wrong: the sequence description probably does not match."""


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Decoded camera images; every map is ``(H, W)``, indexed ``[row, col]`` of the camera.

    Attributes
    ----------
    proj_uv : (H, W, 2) float64, projector coordinates ``(u_p, v_p)`` in px; ``u_p`` is NaN
        where ``mask_v`` is False, ``v_p`` where ``mask_h`` is False. A direction decoded
        from a code alone holds the centre of the stripe its code names
        (:mod:`~virtus.patterns.codings`): the projector column (row) index for a code per
        pixel, as OpenCV's ``GrayCodePattern`` decodes it.
    phase_v, phase_h : (H, W) float64, absolute phase in radians of the direction's finest
        period (``Phi = 2 pi w / period_v``, ``w`` the pattern coordinate, ``= u_p`` at scale
        1); NaN where invalid, where the direction is absent and everywhere for a direction
        decoded from a code alone (it has no phase).
    modulation : (H, W) float64, fringe modulation ``B`` in frame units: the smallest over
        the sequence's phase sets (and its codes alone: half their ``confidence``).
    background : (H, W) float64, background ``A`` in frame units: the mean over the phase sets
        (and codes alone: ``(white + black) / 2``, else the mean of their pattern/inverse
        pairs).
    mask : (H, W) bool, valid in every direction the sequence has.
    mask_v, mask_h : (H, W) bool, valid per direction (all False for an absent direction).
    period_v, period_h : the finest period (pattern units) of each direction, ``None`` if
        absent or decoded from a code alone.
    flagged : (H, W) bool, valid pixels (in some direction) whose fringe order is likely
        wrong: ``flagged_v | flagged_h``.
    flagged_v, flagged_h : (H, W) bool, per direction, within ``mask_v`` / ``mask_h``.
    modulation_v, modulation_h : (H, W) float64, ``B`` per direction (frame units; NaN if
        absent; half of ``confidence_*`` for a code alone).
    repaired : pixels whose fringe order was repaired (``decode(repair=True)``), all
        directions counted (codes alone are flagged, never repaired).
    full_scale : the frames' full scale (frame units).
    confidence_v, confidence_h : (H, W) float64, directions decoded from a code alone: the
        smallest contrast of the pixel's bits in frame units (``|pattern - inverse|`` for a
        pair, ``2 |frame - (white + black) / 2|`` for a single frame), which ``mask_*``
        compares with ``min_contrast * full_scale``; NaN for other directions.
    confidence : (H, W) float64, the smallest ``confidence_*`` (NaN without a code alone).
    stripe_v, stripe_h : stripe width in projector px (code period / scale, halved with the
        complementary frame) of a direction decoded from a code alone (1 for OpenCV's Gray
        code), else ``None``.
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
    confidence: np.ndarray | None = None
    confidence_v: np.ndarray | None = None
    confidence_h: np.ndarray | None = None
    stripe_v: float | None = None
    stripe_h: float | None = None

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
        units and as a fraction of ``full_scale``; a direction decoded from a code alone has
        ``period`` None and its ``stripe`` width (px) too. Undefined values are None.
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
            stripe = getattr(self, f"stripe_{direction}")
            if period is None and stripe is None:
                continue
            mask = getattr(self, f"mask_{direction}")
            values = getattr(self, f"modulation_{direction}")
            finite_values = values[np.isfinite(values)]
            levels = (
                np.percentile(finite_values, (5, 50, 95)) if finite_values.size else [np.nan] * 3
            )
            out[direction] = {
                "period": None if period is None else float(period),
                "valid_fraction": _share(mask, np.ones_like(mask)),
                "flagged_fraction": _share(getattr(self, f"flagged_{direction}"), mask),
                "modulation": _percentiles(levels, 1.0),
                "modulation_rel": _percentiles(levels, self.full_scale),
            }
            if stripe is not None:
                out[direction]["stripe"] = float(stripe)
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


# --- decode plans -----------------------------------------------------------------------


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

    method: str  # "code", "temporal", "heterodyne", "window" or "code_only" (no sets)
    sets: tuple[PhaseSet, ...]  # ascending period: sets[0] is the reported (finest) period
    code: CodePlan | None = None

    @property
    def periods(self) -> tuple[float, ...]:
        return tuple(s.coding.period for s in self.sets)


# --- decoding ---------------------------------------------------------------------------


def decode_frames(
    frames: np.ndarray,
    plans: Mapping[str, DecodePlan],
    *,
    kinds: Sequence[str],
    size: tuple[int, int],
    scale: tuple[float, float] = (1.0, 1.0),
    min_modulation: float = 0.02,
    saturation_level: float | None = None,
    full_scale: float | None = None,
    repair: bool = False,
    neighbour_check: bool | None = None,
    min_contrast: float = 0.02,
) -> DecodeResult:
    """Decode camera images of a sequence into projector coordinates by its decode plans:
    what :meth:`PatternSequence.decode <virtus.patterns.PatternSequence.decode>` runs
    (the other parameters, the result and the warning are described there).

    Parameters
    ----------
    frames : (F, H, W) real or integer array, ``F = len(kinds)``: the camera images.
    plans : direction -> :class:`DecodePlan`, the sequence's ``plans()``.
    kinds : the kind of every frame in sequence order (white and black set the threshold).
    size : projector ``(width, height)`` in px.
    scale : pattern units per projector px for directions ``("v", "h")``.
    """
    stack = _check_frames(frames, len(kinds))
    min_contrast = finite("min_contrast", min_contrast)
    if not 0.0 <= min_contrast < 1.0:
        raise InputError("min_contrast", "a fraction of full scale in [0, 1)", min_contrast)
    if full_scale is None:
        integer = np.issubdtype(stack.dtype, np.integer)
        full_scale = float(np.iinfo(stack.dtype).max) if integer else 1.0
    full_scale = positive("full_scale", full_scale)
    saturation_level = check_saturation_level(saturation_level, full_scale)
    if stack.max() > full_scale:
        # e.g. float frames in DN decoded with the default 1.0: the modulation threshold
        # would be meaningless, so refuse instead of passing every pixel.
        raise InputError(
            "frames", f"values <= full_scale ({full_scale:g}); pass full_scale", stack.max()
        )
    shape = stack.shape[1:]
    uniform = _uniform_means(stack, kinds)
    threshold = None if uniform is None else 0.5 * (uniform[0] + uniform[1])
    nan = np.full(shape, np.nan)
    none = np.zeros(shape, dtype=bool)
    out: dict[str, dict[str, Any]] = {}
    modulations: list[np.ndarray] = []
    backgrounds: list[np.ndarray] = []
    repaired = 0
    for direction, span, axis_scale in zip(DIRECTIONS, size, scale, strict=True):
        plan = plans.get(direction)
        if plan is None:
            out[direction] = {"phase": nan, "valid": none, "flags": none, "modulation": nan}
            continue
        if plan.method == "code_only":
            decoded = decode_code_only(
                stack, plan, span, axis_scale, uniform, min_contrast=min_contrast,
                saturation_level=saturation_level, full_scale=full_scale,
            )  # fmt: skip
        else:
            decoded = _decode_direction(
                stack, plan, span, axis_scale, threshold, min_modulation, saturation_level,
                full_scale,
            )  # fmt: skip
        modulations += decoded.pop("modulations")
        backgrounds += decoded.pop("backgrounds")
        if runs_neighbour_check(plan, neighbour_check, repair):
            repaired += check_neighbours(plan, span, axis_scale, decoded, repair)
        decoded["flags"] &= decoded["valid"]
        decoded["phase"] = np.where(decoded["valid"], decoded["phase"], np.nan)
        if "coordinate" in decoded:
            decoded["coordinate"] = np.where(decoded["valid"], decoded["coordinate"], np.nan)
        out[direction] = decoded
    return assemble_result(
        out,
        plans,
        scale,
        modulation=np.minimum.reduce(modulations) if modulations else nan,
        background=np.mean(backgrounds, axis=0) if backgrounds else nan,
        repaired=repaired,
        full_scale=full_scale,
    )


def check_saturation_level(
    level: object, full_scale: float, name: str = "saturation_level"
) -> float | None:
    """``level`` as a float in ``(0, full_scale]`` (None stays None: no saturation check),
    or :class:`InputError` naming ``name``: a level of 0 or below would call every pixel
    saturated, one above full scale none."""
    if level is None:
        return None
    if isinstance(level, bool):
        raise InputError(name, "a number", level)
    value = finite(name, level)
    if not 0.0 < value <= full_scale:
        raise InputError(name, f"a level in (0, {full_scale:g}] (the frames' full scale)", level)
    return value


def runs_neighbour_check(plan: DecodePlan, neighbour_check: bool | None, repair: bool) -> bool:
    """Whether a decode compares the fringe orders of ``plan``'s direction with neighbours:
    when asked, when repairing, and by default where no per-pixel check exists (codes
    without the complementary frame, the window method)."""
    per_pixel_check = plan.method in ("temporal", "heterodyne") or (
        plan.code is not None and plan.code.coding.complement
    )
    return bool(neighbour_check or repair or (neighbour_check is None and not per_pixel_check))


def assemble_result(
    out: dict[str, dict[str, Any]],
    plans: Mapping[str, DecodePlan],
    scale: tuple[float, float],
    *,
    modulation: np.ndarray,
    background: np.ndarray,
    repaired: int,
    full_scale: float,
) -> DecodeResult:
    """The :class:`DecodeResult` of per-direction decodes (``out[d]``: ``phase`` NaN
    where invalid, ``valid``, ``flags`` within it, ``modulation``, for a code alone
    ``coordinate`` (px, NaN where invalid) and ``confidence``; every direction of
    :data:`DIRECTIONS`) of a sequence with these ``plans`` and ``scale`` (pattern units per
    projector px for ``("v", "h")``), warning when many pixels are flagged. Shared by the
    host decoder and the device decoder's
    :meth:`virtus.render.jit.decode.DeviceDecode.to_host`."""
    shape = out["v"]["valid"].shape
    directions = tuple(d for d in DIRECTIONS if d in plans)
    mask = np.full(shape, bool(directions))  # no fringes: nothing is valid
    for direction in directions:
        mask &= out[direction]["valid"]
    coordinates = [
        out[d]["coordinate"]
        if "coordinate" in out[d]
        else _coordinate(plans.get(d), s, out[d]["phase"])
        for d, s in zip(DIRECTIONS, scale, strict=True)
    ]
    nan = np.full(shape, np.nan)
    confidences = {d: out[d].get("confidence", nan) for d in DIRECTIONS}
    alone = [confidences[d] for d in directions if "confidence" in out[d]]
    stripes = {d: _stripe(plans.get(d), s) for d, s in zip(DIRECTIONS, scale, strict=True)}
    result = DecodeResult(
        proj_uv=np.stack(coordinates, axis=-1),
        phase_v=out["v"]["phase"],
        phase_h=out["h"]["phase"],
        modulation=modulation,
        background=background,
        mask=mask,
        mask_v=out["v"]["valid"],
        mask_h=out["h"]["valid"],
        period_v=plans["v"].periods[0] if "v" in plans and plans["v"].periods else None,
        period_h=plans["h"].periods[0] if "h" in plans and plans["h"].periods else None,
        flagged=out["v"]["flags"] | out["h"]["flags"],
        flagged_v=out["v"]["flags"],
        flagged_h=out["h"]["flags"],
        modulation_v=out["v"]["modulation"],
        modulation_h=out["h"]["modulation"],
        repaired=repaired,
        full_scale=full_scale,
        confidence=np.minimum.reduce(alone) if alone else nan,
        confidence_v=confidences["v"],
        confidence_h=confidences["h"],
        stripe_v=stripes["v"],
        stripe_h=stripes["h"],
    )
    _warn_if_flagged(result)
    return result


def check_neighbours(
    plan: DecodePlan | None, span: int, scale: float, decoded: dict[str, Any], repair: bool
) -> int:
    """Flag (or repair) orders that disagree with neighbours; returns pixels repaired
    (``plan``'s direction: ``span`` projector px, ``scale`` pattern units per px). A code
    alone is flagged where its coordinate jumps (``phase.stripe_consistency``), never
    repaired."""
    stripe = _stripe(plan, scale)
    if stripe is not None:
        limit = max(STRIPE_JUMP_STRIPES * stripe, STRIPE_JUMP_PX)
        jumps = _phase.stripe_consistency(decoded["coordinate"], decoded["valid"], limit)
        decoded["flags"] = decoded["flags"] | jumps
        return 0
    spatial, correction = _phase.order_consistency(
        decoded["phase"], decoded.pop("wrapped"), decoded["valid"]
    )
    if not repair or not spatial.any():
        decoded["flags"] = decoded["flags"] | spatial
        return 0
    decoded["phase"] = decoded["phase"] + _phase.TWO_PI * correction
    decoded["flags"] = decoded["flags"] & ~spatial
    decoded["valid"] = decoded["valid"] & _in_range(plan, span, scale, decoded["phase"])
    return int(np.count_nonzero(spatial))


def _check_frames(frames: np.ndarray, count: int) -> np.ndarray:
    stack = np.asarray(frames)
    if stack.dtype == np.bool_ or not (
        np.issubdtype(stack.dtype, np.integer) or np.issubdtype(stack.dtype, np.floating)
    ):
        raise InputError("frames", "a real or integer array", f"dtype {stack.dtype}")
    if stack.ndim != 3 or stack.shape[0] != count:
        raise InputError("frames", f"an array of shape ({count}, H, W)", f"shape {stack.shape}")
    if np.issubdtype(stack.dtype, np.floating):
        bad = ~np.isfinite(stack)
        if bad.any():
            raise InputError("frames", "finite values", f"{int(bad.sum())} non-finite entries")
    return stack


def _stripe(plan: DecodePlan | None, scale: float) -> float | None:
    """Stripe width (projector px) of a code alone: its period, half of it with the
    complementary frame; None for other plans."""
    if plan is None or plan.method != "code_only":
        return None
    coding = plan.code.coding  # type: ignore[union-attr]
    return coding.period / scale / (2.0 if coding.complement else 1.0)


def _uniform_means(stack: np.ndarray, kinds: Sequence[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """``(mean white, mean black)`` (float64), or None without both kinds."""
    whites = [i for i, kind in enumerate(kinds) if kind == "white"]
    blacks = [i for i, kind in enumerate(kinds) if kind == "black"]
    if not whites or not blacks:
        return None
    white = stack[whites].mean(axis=0, dtype=np.float64)
    return white, stack[blacks].mean(axis=0, dtype=np.float64)


def _coordinate(plan: DecodePlan | None, scale: float, absolute: np.ndarray) -> np.ndarray:
    """Projector px from the absolute phase of ``plan``'s finest period (``scale`` pattern
    units per projector px); ``absolute`` as it is without a plan."""
    if plan is None:
        return absolute
    pattern = _phase.phase_to_coordinate(absolute, plan.periods[0])
    return pattern if scale == 1.0 else pattern / scale


def _in_range(plan: DecodePlan | None, span: int, scale: float, absolute: np.ndarray) -> np.ndarray:
    """Coordinates within half a pixel beyond the projector, ``[-1, L]`` px (``L = span``)."""
    coordinate = _coordinate(plan, scale, absolute)
    return (coordinate >= -1.0) & (coordinate <= span)


def _decode_direction(
    stack: np.ndarray,
    plan: DecodePlan,
    span: int,
    scale: float,
    threshold: np.ndarray | None,
    min_modulation: float,
    saturation_level: float | None,
    full_scale: float,
) -> dict[str, Any]:
    """Absolute phase of the finest period, validity, per-pixel flags, the finest
    wrapped phase, and each set's modulation and background (``plan``'s direction: ``span``
    projector px, ``scale`` pattern units per px)."""
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
    extent = axis_extent(span, scale)
    if plan.method == "code":
        code = plan.code
        cut = backgrounds[0] if threshold is None else threshold
        index = code.coding.decode(_read_bits(stack, code, cut))  # type: ignore[union-attr]
        predicted = code.coding.predicted_phase(index, span, scale)  # type: ignore[union-attr]
        absolute = _phase.unwrap_nearest(wrapped[0], predicted)
        if code.coding.complement:  # type: ignore[union-attr]
            flags = np.abs(absolute - predicted) > CODE_FLAG_RAD
    elif plan.method in ("temporal", "heterodyne"):
        unwrap = _phase.unwrap_temporal if plan.method == "temporal" else _phase.unwrap_heterodyne
        absolute, residual = unwrap(wrapped, plan.periods, extent)
        valid &= residual <= _RESIDUAL_INVALID_RAD
        flags = residual > RESIDUAL_FLAG_RAD
    else:
        absolute = _phase.absolute_phase_in_window(wrapped[0], plan.periods[0], extent)
    valid &= _in_range(plan, span, scale, absolute)
    return {
        "phase": absolute,
        "valid": valid,
        "flags": flags,
        "wrapped": wrapped[0],
        "modulation": np.minimum.reduce(modulations),
        "modulations": modulations,
        "backgrounds": backgrounds,
    }


def decode_code_only(
    stack: np.ndarray,
    plan: DecodePlan,
    span: int,
    scale: float,
    uniform: tuple[np.ndarray, np.ndarray] | None,
    *,
    min_contrast: float,
    saturation_level: float | None,
    full_scale: float,
) -> dict[str, Any]:
    """Decode a direction from its code alone (``plan.method == "code_only"``).

    Each bit of a pattern/inverse pair is ``pattern > inverse`` (OpenCV's
    ``GrayCodePattern`` rule) with contrast ``|pattern - inverse|``; a single bit frame is
    compared with ``t = (white + black) / 2`` (its inverse frame alone: ``frame <= t``) with
    contrast ``2 |frame - t|``, the pair's contrast for a pixel that sees exactly white or
    black. The index (Gray or plain binary, :meth:`BitCode.decode`) gives the centre of its
    stripe (:meth:`BitCode.cell_centres`, px).

    Parameters
    ----------
    stack : (F, H, W) frames.
    plan : the direction's plan; ``span`` projector px along its axis, ``scale`` pattern
        units per px.
    uniform : ``(mean white, mean black)`` (float64), required when a bit has a single frame.
    min_contrast : valid pixels have every bit contrast ``>= min_contrast * full_scale``
        and, with a single frame, ``white - black`` too; an index that no projector pixel
        shows is invalid.
    saturation_level : a pixel reaching it in any code frame is invalid; None: no check.
    full_scale : the frames' full scale.

    Returns
    -------
    dict of (H, W) maps: ``phase`` (NaN), ``coordinate`` (px), ``valid``, ``flags`` (False),
    ``confidence`` (smallest bit contrast, frame units), ``modulation`` (half of it), and
    the lists ``modulations``, ``backgrounds`` (``(white + black) / 2``, else the mean of
    the pairs).
    """
    code = plan.code
    coding = code.coding  # type: ignore[union-attr]
    shape = stack.shape[1:]
    single = None in code.normal or None in code.inverse  # type: ignore[union-attr]
    if single and uniform is None:
        raise InputError("frames", "white and black frames for single code frames", "none")
    threshold = None if uniform is None else 0.5 * (uniform[0] + uniform[1])
    confidence = np.full(shape, np.inf)
    pairs, indices = [], []
    for normal, inverse in zip(code.normal, code.inverse, strict=True):  # type: ignore[union-attr]
        shown = [i for i in (normal, inverse) if i is not None]
        indices += shown
        values = [stack[i].astype(np.float64) for i in shown]
        if len(values) == 2:
            contrast = np.abs(values[0] - values[1])
            pairs.append(0.5 * (values[0] + values[1]))
        else:
            contrast = 2.0 * np.abs(values[0] - threshold)
        np.minimum(confidence, contrast, out=confidence)
    index = coding.decode(_read_bits(stack, code, threshold))  # type: ignore[arg-type]
    coordinate = coding.cell_centres(index, span, scale)
    valid = np.isfinite(coordinate) & _phase.quality_mask(
        confidence,
        min_modulation=min_contrast,
        full_scale=full_scale,
        frames=None if saturation_level is None else stack[indices],
        saturation_level=saturation_level,
    )
    if single:
        valid &= uniform[0] - uniform[1] >= min_contrast * full_scale  # type: ignore[index]
    background = threshold if threshold is not None else np.mean(pairs, axis=0)
    modulation = 0.5 * confidence
    return {
        "phase": np.full(shape, np.nan),
        "coordinate": coordinate,
        "valid": valid,
        "flags": np.zeros(shape, dtype=bool),
        "confidence": confidence,
        "modulation": modulation,
        "modulations": [modulation],
        "backgrounds": [background],
    }


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
    # stacklevel: PatternSequence.decode's line (DeviceDecode.to_host's on the device).
    warn_if_flagged(valid, int(np.count_nonzero(result.flagged)), stacklevel=5)


def warn_if_flagged(valid: int, flagged: int, *, stacklevel: int) -> None:
    """Issue the :class:`DecodeWarning` of a decode with ``valid`` pixels valid in some
    direction, ``flagged`` of them flagged, when more than :data:`FLAG_WARN_FRACTION` are
    (``stacklevel`` as ``warnings.warn`` counts it from here)."""
    if valid and flagged > FLAG_WARN_FRACTION * valid:
        warnings.warn(
            f"decode: {flagged / valid:.1%} of valid pixels are flagged as likely fringe-order "
            f"errors (more than {FLAG_WARN_FRACTION:.0%}): the sequence description probably "
            "does not match the frames (code alignment, bit order, periods, frame order); "
            "see DecodeResult.flagged and summary()",
            DecodeWarning,
            stacklevel=stacklevel,
        )
