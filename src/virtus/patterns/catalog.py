"""Built-in pattern sequences: :func:`build_sequence` (the standard frame order), the
paper's :func:`default_sequence` and :func:`heterodyne_sequence`.

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

from collections.abc import Sequence

import numpy as np

from virtus.checks import positive, positive_int
from virtus.errors import InputError
from virtus.patterns.frames import DIRECTIONS, Frame
from virtus.patterns.sequence import PatternSequence

__all__ = [
    "DEFAULT_HETERODYNE_PERIODS",
    "build_sequence",
    "default_sequence",
    "heterodyne_sequence",
]

#: Three periods with 64, 63 and 56 fringes over 1152 px (Towers' optimum choice: C. E.
#: Towers, D. P. Towers, J. D. C. Jones, Opt. Lett. 28(11), 887-889, 2003). Their beats with
#: the finest are 1152 px (covers a 1140 px axis) and 144 px: a ratio of 8 at each
#: unwrapping step.
DEFAULT_HETERODYNE_PERIODS = (1152.0 / 64.0, 1152.0 / 63.0, 1152.0 / 56.0)


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
