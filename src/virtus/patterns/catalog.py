"""Built-in pattern sequences: :func:`build_sequence` (the standard frame order), the
paper's :func:`default_sequence` and :func:`heterodyne_sequence`, and OpenCV's Gray code
alone, :func:`opencv_graycode_sequence`.

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

OpenCV's ``structured_light.GrayCodePattern`` (:func:`opencv_graycode_sequence`, the
``preset: opencv_graycode`` of a sequence file, ``examples/sequences/opencv_graycode.yaml``):
with ``n = ceil(log2 width)`` column bits and ``m = ceil(log2 height)`` row bits, what
``GrayCodePattern.generate`` returns, then white and black as users append them
(``getImagesForShadowMasks``; OpenCV's capture sample appends white, then black), ``2 n +
2 m + 2`` frames (44 for 912 x 1140, 42 for 1920 x 1080)::

    [0:2n]        gray, "v", period 1, edge-aligned: bit 1..n (most significant first),
                  each bit then its inverse: column j shows Gray bit of g = j ^ (j >> 1)
    [2n:2n+2m]    gray, "h", the same for row i
    [2n+2m]       white
    [2n+2m+1]     black

Each projector column (row) has its own code word, so the decode (pattern > inverse per
bit, as OpenCV's ``getProjPixel``) gives the column (row) index itself.
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
    "opencv_graycode_sequence",
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


def _uniform_order(white_black: bool | Sequence[str]) -> tuple[str, ...]:
    """The uniform frames appended after a code: True ``("white", "black")``, False none, or
    the two kinds in the order given."""
    if isinstance(white_black, bool | np.bool_):
        return ("white", "black") if white_black else ()
    order = tuple(white_black) if isinstance(white_black, Sequence) else None
    if (
        isinstance(white_black, str)
        or order is None
        or not all(isinstance(kind, str) for kind in order)  # sorted() needs one type
        or sorted(order) != ["black", "white"]
    ):
        raise InputError(
            "white_black", "true, false, [white, black] or [black, white]", white_black
        )
    return order


def opencv_graycode_sequence(
    width: int, height: int, white_black: bool | Sequence[str] = True
) -> PatternSequence:
    """OpenCV's ``structured_light.GrayCodePattern`` frames (module docstring): per axis
    ``ceil(log2 size)`` Gray bits, most significant first, each bit then its inverse,
    columns then rows, then the uniform frames.

    Parameters
    ----------
    width, height : projector size in px, each >= 2 (OpenCV's ``Params.width``/``height``).
    white_black : True (default): white then black appended (OpenCV's capture sample);
        False: none; ``("black", "white")`` (or ``("white", "black")``): both, in that order.

    Returns
    -------
    :class:`PatternSequence` whose :meth:`~PatternSequence.images` are OpenCV's patterns
    pixel for pixel, decoding to projector column and row indices.
    """
    width = positive_int("width", width, minimum=2)
    height = positive_int("height", height, minimum=2)
    uniform = _uniform_order(white_black)
    frames: list[Frame] = []
    for direction, span in zip(DIRECTIONS, (width, height), strict=True):
        bits = (span - 1).bit_length()  # ceil(log2 span), as OpenCV computes it
        frames += [
            Frame("gray", direction, 1.0, bit=b, bits=bits, align="edge", inverted=inverse)
            for b in range(1, bits + 1)
            for inverse in (False, True)
        ]
    frames += [Frame(kind) for kind in uniform]
    return PatternSequence(width, height, tuple(frames))
