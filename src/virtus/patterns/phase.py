"""Fringe decoding math: wrapped phase, quality masks, Gray-code and heterodyne unwrapping.

Conventions (shared with :mod:`virtus.patterns`):

* Phase shifting: ``I_n = A + B cos(phi + 2 pi n / N)`` for ``n = 1..N`` (the paper's Eq. 1-2),
  so the least-squares wrapped phase is ``phi = atan2(-sum I_n sin d_n, sum I_n cos d_n)``
  with ``d_n = 2 pi n / N``; wrapped phases lie in ``[-pi, pi)``.
* Absolute phase of a fringe of period ``T`` (projector px) is ``Phi = 2 pi u / T``, with the
  origin ``u = 0`` at the centre of projector pixel 0, so ``u = Phi T / (2 pi)``.
* Fringe order ``k = floor(u / T + 1/2)``: ``Phi = phi + 2 pi k`` with the wrapped phase
  ``phi`` in ``[-pi, pi)``, so orders change where the wrapped phase jumps.
* Gray codes are given most significant bit first.
* Consistency: a decode is checked against redundancy it carries (the half-period code of a
  complementary frame, the residual of temporal unwrapping) and, in images, against its
  neighbours (:func:`order_consistency`): pixels whose fringe order disagrees are *flagged*.

Every function is vectorised over arbitrary trailing ``(...)`` pixel shapes, typically
``(H, W)`` camera images indexed ``[row, col]``. This module only needs numpy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from virtus.checks import finite, positive
from virtus.errors import InputError

TWO_PI = 2.0 * np.pi

__all__ = [
    "absolute_phase_in_window",
    "beat_period",
    "binarize",
    "bits_to_index",
    "complementary_order",
    "coordinate_to_phase",
    "gray_bits_to_order",
    "gray_decode",
    "gray_encode",
    "order_consistency",
    "phase_to_coordinate",
    "quality_mask",
    "stripe_consistency",
    "unwrap_gray",
    "unwrap_heterodyne",
    "unwrap_nearest",
    "unwrap_temporal",
    "unwrap_with_reference",
    "wrap",
    "wrapped_phase",
]


def wrap(phase: np.ndarray) -> np.ndarray:
    """Wrap phase values to ``[-pi, pi)``.

    Parameters
    ----------
    phase : (...) float array, radians.

    Returns
    -------
    (...) float64, radians in ``[-pi, pi)``; NaN stays NaN.
    """
    value = np.asarray(phase, dtype=np.float64)
    wrapped = value - TWO_PI * np.floor((value + np.pi) / TWO_PI)
    # Rounding can leave a value a hair outside the interval: fold it back.
    wrapped = np.where(wrapped >= np.pi, wrapped - TWO_PI, wrapped)
    return np.where(wrapped < -np.pi, wrapped + TWO_PI, wrapped)


#: Pixels per block of :func:`wrapped_phase` (its float64 frames and sums stay in cache).
_PHASE_BLOCK = 16384


def wrapped_phase(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares N-step phase shifting.

    Parameters
    ----------
    frames : (N, ...) real array, N >= 3, any intensity unit (e.g. camera DN). Frame ``n - 1``
        is the image taken with shift ``2 pi n / N``, i.e. ``I_n = A + B cos(phi + 2 pi n / N)``.

    Returns
    -------
    phase : (...) float64, wrapped phase ``phi`` in ``[-pi, pi)`` radians.
    background : (...) float64, ``A`` in the unit of ``frames``.
    modulation : (...) float64, ``B >= 0`` in the unit of ``frames``.
    """
    stack = np.asarray(frames)
    if stack.ndim < 1 or stack.shape[0] < 3:
        raise InputError("frames", "an array of shape (N, ...) with N >= 3", f"shape {stack.shape}")
    if not (np.issubdtype(stack.dtype, np.number) or stack.dtype == np.bool_) or np.iscomplexobj(
        stack
    ):
        raise InputError("frames", "a real numeric array", f"dtype {stack.dtype}")
    steps = stack.shape[0]
    shifts = TWO_PI * np.arange(1, steps + 1) / steps
    # One matrix product gives sum I_n, sum I_n cos d_n and sum I_n sin d_n for every pixel;
    # the rows are scaled so that it gives A, (B cos phi) and (B sin phi) directly:
    # sum I_n cos d_n = (N B / 2) cos phi and sum I_n sin d_n = -(N B / 2) sin phi.
    weights = np.stack([np.ones(steps) / steps, np.cos(shifts), -np.sin(shifts)])
    weights[1:] *= 2.0 / steps
    flat = stack.reshape(steps, -1)
    size = flat.shape[1]
    phase, background, modulation = np.empty(size), np.empty(size), np.empty(size)
    # Pixels in blocks that stay in cache: one float64 copy of a block of frames (not of
    # the stack) and the three sums, written straight into the outputs.
    block = max(1, min(size, _PHASE_BLOCK))
    frames64 = None if flat.dtype == np.float64 else np.empty((steps, block))
    sums = np.empty((3, block))
    for start in range(0, size, block):
        stop = min(start + block, size)
        part = flat[:, start:stop]
        if frames64 is not None:
            part = frames64[:, : stop - start]
            np.copyto(part, flat[:, start:stop], casting="unsafe")
        out = sums[:, : stop - start]
        np.matmul(weights, part, out=out)
        background[start:stop] = out[0]
        np.arctan2(out[2], out[1], out=phase[start:stop])  # in [-pi, pi]
        np.hypot(out[1], out[2], out=modulation[start:stop])
    phase[phase >= np.pi] -= TWO_PI  # +pi belongs to [-pi, pi) as -pi
    shape = stack.shape[1:]
    return phase.reshape(shape), background.reshape(shape), modulation.reshape(shape)


def quality_mask(
    modulation: np.ndarray,
    *,
    min_modulation: float,
    full_scale: float = 1.0,
    frames: np.ndarray | None = None,
    saturation_level: float | None = None,
) -> np.ndarray:
    """Pixels whose phase can be trusted: enough fringe modulation and no saturated frame.

    Parameters
    ----------
    modulation : (...) float array, ``B`` in the unit of the frames.
    min_modulation : threshold relative to ``full_scale``, in ``[0, 1)``: valid pixels have
        ``B >= min_modulation * full_scale``.
    full_scale : the frames' full-scale value (255 for 8-bit DN, 1.0 for normalised images).
    frames : (N, ...) real array, the phase frames; needed only with ``saturation_level``.
    saturation_level : a pixel reaching this value (frame units) in any frame is invalid;
        ``None`` disables the check.

    Returns
    -------
    (...) bool, True where valid; NaN modulation is invalid.
    """
    threshold = finite("min_modulation", min_modulation)
    if not 0.0 <= threshold < 1.0:
        raise InputError("min_modulation", "a fraction of full scale in [0, 1)", min_modulation)
    scale = positive("full_scale", full_scale)
    with np.errstate(invalid="ignore"):
        mask = np.asarray(modulation, dtype=np.float64) >= threshold * scale
    if saturation_level is not None:
        level = finite("saturation_level", saturation_level)
        if frames is None:
            raise InputError("frames", "the phase frames when saturation_level is given", None)
        mask &= ~np.any(np.asarray(frames) >= level, axis=0)
    return mask


def binarize(frames: np.ndarray, threshold: np.ndarray) -> np.ndarray:
    """Binary pattern bits: True where a frame is brighter than the per-pixel threshold.

    Parameters
    ----------
    frames : (n, ...) real array, binary-pattern images.
    threshold : (...) float array in the unit of ``frames``, e.g. ``(white + black) / 2`` or
        the phase background ``A``.

    Returns
    -------
    (n, ...) bool.
    """
    return np.asarray(frames) > np.asarray(threshold)[np.newaxis]


def gray_encode(index: np.ndarray) -> np.ndarray:
    """Reflected binary Gray code of non-negative integers: ``g = k XOR (k >> 1)``."""
    k = np.asarray(index, dtype=np.int64)
    return k ^ (k >> 1)


def gray_decode(code: np.ndarray) -> np.ndarray:
    """Inverse of :func:`gray_encode` for non-negative int64 codes."""
    k = np.asarray(code, dtype=np.int64).copy()
    shift = k >> 1
    while np.any(shift):
        k ^= shift
        shift >>= 1
    return k


def gray_bits_to_order(bits: np.ndarray) -> np.ndarray:
    """Fringe order from binarised Gray-code frames.

    Parameters
    ----------
    bits : (n, ...) bool, Gray-code bits, most significant first.

    Returns
    -------
    (...) int64, the binary index ``k`` (``0 <= k < 2**n``).
    """
    stack = np.asarray(bits, dtype=bool)
    if stack.ndim < 1 or stack.shape[0] < 1:
        raise InputError("bits", "an array of shape (n, ...) with n >= 1", f"shape {stack.shape}")
    # Gray -> binary: b_1 = g_1, b_i = b_(i-1) XOR g_i (a loop: bool accumulate is slow).
    binary = np.zeros(stack.shape[1:], dtype=bool)
    order = np.zeros(stack.shape[1:], dtype=np.int64)
    for gray_bit in stack:
        binary ^= gray_bit
        order <<= 1
        order |= binary
    return order


def bits_to_index(bits: np.ndarray, code: str = "gray") -> np.ndarray:
    """Integer index from binarised code frames, most significant bit first.

    Parameters
    ----------
    bits : (n, ...) bool, the code's bits, most significant first.
    code : ``"gray"`` (reflected binary code, see :func:`gray_bits_to_order`) or
        ``"binary"`` (plain binary).

    Returns
    -------
    (...) int64 in ``[0, 2**n)``.
    """
    if code == "gray":
        return gray_bits_to_order(bits)
    if code != "binary":
        raise InputError("code", "'gray' or 'binary'", code)
    stack = np.asarray(bits, dtype=bool)
    if stack.ndim < 1 or stack.shape[0] < 1:
        raise InputError("bits", "an array of shape (n, ...) with n >= 1", f"shape {stack.shape}")
    index = np.zeros(stack.shape[1:], dtype=np.int64)
    for bit in stack:
        index <<= 1
        index |= bit
    return index


def complementary_order(code: np.ndarray) -> np.ndarray:
    """Floor order ``floor(u / T)`` from the half-period code of the complementary Gray code.

    The ``n`` Gray frames plus the complementary frame form the ``(n + 1)``-bit Gray code of
    the half-period index ``g = floor(2 u / T + 1)``; its ``n`` leading bits are the Gray code
    of the fringe order ``k1 = floor(u / T + 1/2)``. This returns ``k2 = floor((g - 1) / 2)
    = floor(u / T)``, whose edges lie half a period away from those of ``k1``; a misread bit
    at a ``k1`` edge only moves ``g`` to a neighbour with the same ``k2``.

    Parameters
    ----------
    code : (...) int, ``g`` decoded by :func:`gray_bits_to_order` from the ``n + 1`` bits.

    Returns
    -------
    (...) int64, ``k2 = floor(u / T)`` (-1 left of ``u = 0``).
    """
    return (np.asarray(code, dtype=np.int64) - 1) >> 1


def unwrap_gray(
    phase: np.ndarray, order: np.ndarray, floor_order: np.ndarray | None = None
) -> np.ndarray:
    """Absolute phase from a wrapped phase and Gray-code fringe orders.

    Parameters
    ----------
    phase : (...) float, wrapped phase in radians (any 2 pi branch; wrapped to [-pi, pi)).
    order : (...) int, ``k1 = floor(u / T + 1/2)`` from the Gray code.
    floor_order : (...) int, ``k2 = floor(u / T)`` from :func:`complementary_order`, or
        ``None`` to use ``k1`` everywhere (period-edge jumps are then left in).

    Returns
    -------
    (...) float64, absolute phase ``Phi = 2 pi u / T`` in radians.

    Notes
    -----
    With ``phi`` in ``[-pi, pi)``: ``k = k1`` where ``|phi| < pi/2``, ``k2`` where
    ``phi >= pi/2`` and ``k2 + 1`` where ``phi < -pi/2``. Each order is thus read at least a
    quarter period away from its own code edges, where a blurred or pixelated Gray code is
    unambiguous (complementary Gray code; Zhang, Chen, Wu et al., Opt. Lasers Eng. 2018-2019).
    """
    phi = wrap(phase)
    k1 = np.asarray(order, dtype=np.int64)
    if floor_order is None:
        k = k1
    else:
        k2 = np.asarray(floor_order, dtype=np.int64)
        half = 0.5 * np.pi
        k = np.where(phi >= half, k2, np.where(phi < -half, k2 + 1, k1))
    return phi + TWO_PI * k


def unwrap_nearest(phase: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Absolute phase: the ``2 pi`` branch of ``phase`` nearest a predicted absolute phase.

    Parameters
    ----------
    phase : (...) float, wrapped phase in radians (any branch).
    predicted : (...) float, predicted absolute phase in radians, e.g. the phase of the centre
        of the projector interval that a pixel's code names.

    Returns
    -------
    (...) float64, ``phase + 2 pi k`` with ``result - predicted`` in ``[-pi, pi)``; the
    interval is half-open like a projector pixel, so a code cell exactly one period wide
    gives exactly one branch.
    """
    phi = np.asarray(phase, dtype=np.float64)
    centre = np.asarray(predicted, dtype=np.float64)
    order = np.ceil((centre - phi - np.pi) / TWO_PI)
    return phi + TWO_PI * order


def beat_period(period_a: float, period_b: float) -> float:
    """Period of the beat (heterodyne) of two fringe periods: ``Ta Tb / |Tb - Ta|`` (px)."""
    a = positive("period_a", period_a)
    b = positive("period_b", period_b)
    if a == b:
        raise InputError("period_b", f"a period different from {a}", period_b)
    return a * b / abs(b - a)


def absolute_phase_in_window(phase: np.ndarray, period: float, extent: float) -> np.ndarray:
    """Absolute phase of a fringe whose period covers the whole projector axis.

    The ``2 pi`` ambiguity is resolved inside the window of length ``period`` centred on the
    axis (``u`` in ``[c - T/2, c + T/2)``, ``c = (extent - 1) / 2``), which covers every
    projector pixel ``[-0.5, extent - 0.5]`` when ``period >= extent``.

    Parameters
    ----------
    phase : (...) float, wrapped phase, radians.
    period : fringe period T, projector px, ``>= extent``.
    extent : number of projector pixels along the axis.

    Returns
    -------
    (...) float64, absolute phase, radians.
    """
    period = positive("period", period)
    extent = positive("extent", extent)
    if period < extent:
        raise InputError("period", f"a period >= the projector extent {extent} px", period)
    centre = TWO_PI * 0.5 * (extent - 1.0) / period
    return wrap(np.asarray(phase, dtype=np.float64) - centre) + centre


def unwrap_with_reference(
    phase: np.ndarray, reference: np.ndarray, ratio: float
) -> tuple[np.ndarray, np.ndarray]:
    """Temporal unwrapping step: absolute phase from a coarser absolute reference phase.

    Parameters
    ----------
    phase : (...) float, wrapped phase of the fine fringe, radians.
    reference : (...) float, absolute phase of the coarse fringe, radians.
    ratio : ``T_coarse / T_fine`` (> 0), so that ``reference * ratio`` predicts the fine
        absolute phase.

    Returns
    -------
    absolute : (...) float64, ``phase + 2 pi k`` with the nearest integer ``k``.
    residual : (...) float64, prediction minus result, in ``[-pi, pi]`` radians; near
        ``+-pi`` the order is unreliable (the noise of ``reference * ratio`` reached pi).
    """
    ratio = positive("ratio", ratio)
    fine = np.asarray(phase, dtype=np.float64)
    predicted = np.asarray(reference, dtype=np.float64) * ratio
    order = np.rint((predicted - fine) / TWO_PI)
    absolute = fine + TWO_PI * order
    return absolute, predicted - absolute


def unwrap_heterodyne(
    phases: Sequence[np.ndarray] | np.ndarray, periods: Sequence[float], extent: float
) -> tuple[np.ndarray, np.ndarray]:
    """Multi-frequency (heterodyne) unwrapping.

    The finest period ``T1`` beats with every other period ``Ti``: the wrapped phase
    difference ``phi_1 - phi_i`` is the phase of a fringe of period ``T1 Ti / (Ti - T1)``.
    The longest beat must cover the projector axis (``>= extent``) and is made absolute with
    :func:`absolute_phase_in_window`; each shorter beat, then ``T1`` itself, is unwrapped from
    the previous level with :func:`unwrap_with_reference` (Towers et al., Opt. Lett. 28,
    887, 2003). A level ``r`` times finer than its reference multiplies the reference's phase
    noise by ``r``, so keep the ratios modest (8 for the 64/63/56-fringe choice).

    Parameters
    ----------
    phases : (m, ...) float, wrapped phases in radians, ``phases[i]`` for ``periods[i]``.
    periods : (m,) fringe periods in projector px, m >= 2, all different.
    extent : projector pixels along the axis.

    Returns
    -------
    absolute : (...) float64, absolute phase ``2 pi u / T1`` of the finest period, radians.
    residual : (...) float64, the largest ``|residual|`` of the unwrapping steps, radians
        (see :func:`unwrap_with_reference`); near pi the fringe order is unreliable.
    """
    values = [positive("periods", p) for p in periods]
    if len(values) < 2 or len(set(values)) != len(values):
        raise InputError("periods", "two or more different periods", periods)
    if len(phases) != len(values):
        raise InputError("phases", f"{len(values)} phase maps (one per period)", len(phases))
    finest = int(np.argmin(values))
    fine_period = values[finest]
    fine_phase = np.asarray(phases[finest], dtype=np.float64)
    # (beat period, beat phase) from the coarsest beat down; the beat grows with u because
    # 1/T1 > 1/Ti.
    levels = sorted(
        (
            (
                beat_period(fine_period, values[i]),
                wrap(fine_phase - np.asarray(phases[i])),
            )
            for i in range(len(values))
            if i != finest
        ),
        key=lambda level: -level[0],
    )
    top_period, top_phase = levels[0]
    if top_period < extent:
        raise InputError(
            "periods",
            f"periods whose longest beat with the finest covers the extent {extent} px",
            f"longest beat {top_period:.6g} px",
        )
    absolute = absolute_phase_in_window(top_phase, top_period, extent)
    residual = np.zeros_like(absolute)
    reference_period = top_period
    for period, phase in [*levels[1:], (fine_period, fine_phase)]:
        absolute, step_residual = unwrap_with_reference(phase, absolute, reference_period / period)
        residual = np.maximum(residual, np.abs(step_residual))
        reference_period = period
    return absolute, residual


def unwrap_temporal(
    phases: Sequence[np.ndarray] | np.ndarray, periods: Sequence[float], extent: float
) -> tuple[np.ndarray, np.ndarray]:
    """Multi-wavelength (hierarchical temporal) unwrapping.

    The longest period must cover the projector axis (``>= extent``): its phase is absolute
    by :func:`absolute_phase_in_window`. Each shorter period, longest to shortest, is then
    unwrapped from the previous one with :func:`unwrap_with_reference` (ratio
    ``T_(i+1) / T_i``, best an integer or close to one; Saldner & Huntley, Appl. Opt. 36,
    2770, 1997). The phase noise of a level is multiplied by its ratio, so keep ratios modest
    (the order is wrong once ratio x noise reaches pi).

    Parameters
    ----------
    phases : (m, ...) float, wrapped phases in radians, ``phases[i]`` for ``periods[i]``.
    periods : (m,) fringe periods, m >= 2, all different; the longest ``>= extent``.
    extent : projector pixels (pattern units) along the axis.

    Returns
    -------
    absolute : (...) float64, absolute phase ``2 pi u / T_min`` of the shortest period, rad.
    residual : (...) float64, the largest ``|residual|`` of the steps, radians.
    """
    values = [positive("periods", p) for p in periods]
    if len(values) < 2 or len(set(values)) != len(values):
        raise InputError("periods", "two or more different periods", periods)
    if len(phases) != len(values):
        raise InputError("phases", f"{len(values)} phase maps (one per period)", len(phases))
    order = np.argsort(values)[::-1]  # longest first
    if values[order[0]] < extent:
        raise InputError(
            "periods", f"a longest period that covers the extent {extent} px", max(values)
        )
    absolute = absolute_phase_in_window(phases[order[0]], values[order[0]], extent)
    residual = np.zeros_like(absolute)
    reference_period = values[order[0]]
    for index in order[1:]:
        absolute, step_residual = unwrap_with_reference(
            phases[index], absolute, reference_period / values[index]
        )
        residual = np.maximum(residual, np.abs(step_residual))
        reference_period = values[index]
    return absolute, residual


def phase_to_coordinate(phase: np.ndarray, period: float) -> np.ndarray:
    """Projector coordinate ``u = Phi T / (2 pi)`` (px) from absolute phase ``Phi`` (rad)."""
    return np.asarray(phase, dtype=np.float64) * (positive("period", period) / TWO_PI)


def coordinate_to_phase(coordinate: np.ndarray, period: float) -> np.ndarray:
    """Absolute phase ``Phi = 2 pi u / T`` (rad) of projector coordinate ``u`` (px)."""
    return np.asarray(coordinate, dtype=np.float64) * (TWO_PI / positive("period", period))


#: Neighbour links whose wrapped phases differ by at most this (rad) are taken to lie on one
#: continuous surface: a smooth surface sampled at >= 8 camera px per fringe period stays
#: far below it, a depth edge passes it only by chance (about 1 link in 4).
CONTINUITY_RAD = 0.25 * np.pi
#: The neighbour check needs fringes sampled that finely: it abstains unless more than this
#: share of the links between valid neighbours is continuous (images of unrelated points,
#: or fringes too fine for the camera, give about 1/4).
MIN_CONTINUOUS_SHARE = 0.5
#: Two regions are tied by an order offset only when this share of the valid links between
#: them is continuous and agrees on one offset (an order error inside a smooth surface gives
#: 1.0; a depth edge about 1/4 and mixed offsets).
MIN_LINK_SUPPORT = 0.9
#: A region whose absolute phase spans at least this (rad) is never flagged: a misread code
#: near a cell edge makes a band narrower than one code cell (one period), while a surface
#: seen across a depth edge whose parallax happens to be a whole number of periods (a sphere
#: before a wall) spans many periods and only looks like an order error.
MAX_ERROR_SPAN_RAD = TWO_PI


def order_consistency(
    absolute: np.ndarray, wrapped: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Fringe orders that disagree with their neighbours on a continuous surface.

    On a continuous surface two neighbouring camera pixels have close wrapped phases and
    absolute phases that differ by the same small amount; a fringe-order error breaks this
    by a whole ``2 pi``. The image is cut into *regions* of valid pixels joined by
    consistent links (wrapped difference ``<= CONTINUITY_RAD``, absolute difference equal to
    it). Regions touching along continuous links that jump by ``2 pi j`` are tied by the
    order offset ``j`` when :data:`MIN_LINK_SUPPORT` of their shared links agree; in each
    group of tied regions the offset carried by most pixels is taken as right and every
    other pixel is flagged with the order correction that makes it agree -- unless its
    region spans :data:`MAX_ERROR_SPAN_RAD` or more of phase (a whole surface, not a band of
    misread code).

    Parameters
    ----------
    absolute : (H, W) float, absolute phase in radians (NaN where invalid).
    wrapped : (H, W) float, the wrapped phase it was unwrapped from, radians.
    valid : (H, W) bool, pixels to check.

    Returns
    -------
    flagged : (H, W) bool, valid pixels whose order disagrees with the majority of their
        tied regions.
    correction : (H, W) int64, orders to add to ``absolute`` (``+ 2 pi correction``) to make
        them agree; 0 where not flagged.

    Notes
    -----
    Nothing is flagged (the check abstains) unless more than :data:`MIN_CONTINUOUS_SHARE`
    of the links between valid neighbours is continuous, or for arrays that are not 2-D.
    Uses scipy (``ndimage.label``, ``sparse.csgraph``).
    """
    valid = np.asarray(valid, dtype=bool)
    flagged = np.zeros(valid.shape, dtype=bool)
    correction = np.zeros(valid.shape, dtype=np.int64)
    if valid.ndim != 2 or min(valid.shape) < 1:
        return flagged, correction
    absolute = np.where(valid, np.asarray(absolute, dtype=np.float64), 0.0)
    wrapped = np.where(valid, np.asarray(wrapped, dtype=np.float64), 0.0)
    links = [_links(absolute, wrapped, valid, axis) for axis in (0, 1)]
    both = sum(int(link[0].sum()) for link in links)
    continuous = sum(int(link[1].sum()) for link in links)
    if both == 0 or continuous <= MIN_CONTINUOUS_SHARE * both:
        return flagged, correction
    from scipy import ndimage

    height, width = valid.shape
    grid = np.zeros((2 * height - 1, 2 * width - 1), dtype=bool)
    grid[::2, ::2] = valid
    grid[1::2, ::2] = links[0][1] & (links[0][2] == 0)  # row neighbours
    grid[::2, 1::2] = links[1][1] & (links[1][2] == 0)  # column neighbours
    labels, count = ndimage.label(grid)
    region = labels[::2, ::2]  # 0 outside valid pixels, regions 1..count
    pairs = []
    for axis, (has_both, is_continuous, jump) in zip((0, 1), links, strict=True):
        first = region[:-1, :] if axis == 0 else region[:, :-1]
        second = region[1:, :] if axis == 0 else region[:, 1:]
        cross = has_both & (first != second)
        pairs.append((first[cross], second[cross], is_continuous[cross], jump[cross]))
    a, b, cont, jump = (np.concatenate(column) for column in zip(*pairs, strict=True))
    offsets = _region_offsets(a, b, cont, jump, region, count)
    if count:
        index = np.arange(1, count + 1)
        span = ndimage.maximum(absolute, region, index) - ndimage.minimum(absolute, region, index)
        offsets[1:][np.asarray(span) >= MAX_ERROR_SPAN_RAD] = 0
    correction = np.where(valid, offsets[region], 0)
    return correction != 0, correction


#: :func:`stripe_consistency` abstains unless more than this share of the links between
#: valid neighbours is continuous (no jump): images of unrelated points give under 0.1, a
#: continuous surface about 1, a wrong bit order 0.3-1 (fewer at coarser camera sampling).
MIN_STRIPE_CONTINUOUS = 0.25
#: It judges the whole image only from at least this many changes of coordinate between
#: valid neighbours, and flags it all when more than this share of them are jumps. Measured:
#: a wrong bit order 0.84-1 (Gray, 6 bits to a word per pixel; binary 1.0); a right one
#: about 0 on smooth surfaces, but depth edges count too: 0.56 for edges every 23 px
#: parallel to 18 px stripes whose edges a strict ``min_contrast`` masked.
MIN_STRIPE_CHANGES = 64
MAX_JUMP_SHARE = 0.75


def stripe_consistency(coordinate: np.ndarray, valid: np.ndarray, limit: float) -> np.ndarray:
    """Pixels of a code decoded alone (no phase) whose coordinate disagrees with their
    neighbours'.

    On a continuous surface neighbouring camera pixels decode to the same or the next
    stripe; a misread bit moves a pixel far away (a *jump*: a coordinate difference above
    ``limit``). A valid pixel is flagged when it jumps from more than half of its valid
    4-neighbours (an isolated misread; a straight depth edge has one such neighbour, a
    corner two of four). When most changes of coordinate between valid neighbours are jumps
    (a wrong bit order or code: each pixel decodes, neighbouring stripes do not follow),
    every valid pixel is flagged. Errors smaller than ``limit`` go unflagged.

    Parameters
    ----------
    coordinate : (H, W) float, decoded projector px (any value where invalid).
    valid : (H, W) bool, pixels to check.
    limit : coordinate difference (px) above which neighbours jump.

    Returns
    -------
    (H, W) bool, flagged valid pixels (all False for arrays that are not 2-D).

    Notes
    -----
    Nothing is flagged (the check abstains) unless more than :data:`MIN_STRIPE_CONTINUOUS`
    of the links between valid neighbours is continuous. The whole image is judged only
    from at least :data:`MIN_STRIPE_CHANGES` changes, and flagged when more than
    :data:`MAX_JUMP_SHARE` of them jump.
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2:
        return np.zeros(valid.shape, dtype=bool)
    values = np.where(valid, np.asarray(coordinate, dtype=np.float64), 0.0)
    neighbours = np.zeros(valid.shape, dtype=np.int64)
    jumps = np.zeros(valid.shape, dtype=np.int64)
    links = changes = jumped = 0
    for axis in (0, 1):
        cut = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        nxt = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        both = valid[cut] & valid[nxt]
        difference = np.abs(values[cut] - values[nxt])
        jump = both & (difference > limit)
        links += int(np.count_nonzero(both))
        changes += int(np.count_nonzero(both & (difference > 0.0)))
        jumped += int(np.count_nonzero(jump))
        for part in (cut, nxt):
            neighbours[part] += both
            jumps[part] += jump
    if links == 0 or links - jumped <= MIN_STRIPE_CONTINUOUS * links:
        return np.zeros(valid.shape, dtype=bool)
    if changes >= MIN_STRIPE_CHANGES and jumped > MAX_JUMP_SHARE * changes:
        return valid.copy()
    return valid & (2 * jumps > neighbours)


def _links(
    absolute: np.ndarray, wrapped: np.ndarray, valid: np.ndarray, axis: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Links between each pixel and its next neighbour along ``axis``: both valid,
    continuous, and the order jump ``round((dPhi - dphi) / 2 pi)`` (first minus second)."""
    cut = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
    nxt = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
    both = valid[cut] & valid[nxt]
    local = wrap(wrapped[cut] - wrapped[nxt])
    continuous = both & (np.abs(local) <= CONTINUITY_RAD)
    jump = np.rint((absolute[cut] - absolute[nxt] - local) / TWO_PI).astype(np.int64)
    return both, continuous, np.where(continuous, jump, 0)


def _region_offsets(
    a: np.ndarray, b: np.ndarray, cont: np.ndarray, jump: np.ndarray, region: np.ndarray, count: int
) -> np.ndarray:
    """(count + 1,) int64 order corrections per region (index 0: invalid pixels, 0)."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    offsets = np.zeros(count + 1, dtype=np.int64)
    if a.size == 0:
        return offsets
    low, high = np.minimum(a, b), np.maximum(a, b)
    signed = np.where(a == low, jump, -jump)  # order of `low` minus continuity from `high`
    pair_key = low.astype(np.int64) * (count + 1) + high
    keys, totals = np.unique(pair_key, return_counts=True)
    votes, vote_counts = np.unique(
        np.stack([pair_key[cont], signed[cont]]), axis=1, return_counts=True
    )
    if votes.size == 0:
        return offsets
    # Strongest offset per pair (the last of each key after sorting by count).
    order = np.lexsort((vote_counts, votes[0]))
    votes, vote_counts = votes[:, order], vote_counts[order]
    last = np.r_[votes[0, 1:] != votes[0, :-1], True]
    pair, offset, support = votes[0, last], votes[1, last], vote_counts[last]
    support = support / totals[np.searchsorted(keys, pair)]
    keep = (support >= MIN_LINK_SUPPORT) & (offset != 0)
    if not keep.any():
        return offsets
    pair, offset, strength = pair[keep], offset[keep], vote_counts[last][keep]
    # Only regions with ties take part: number them 1..m, node 0 is a virtual root tied to
    # every one, so one search covers all groups; the maximum spanning tree keeps the best
    # supported ties where they form cycles.
    involved, compact = np.unique(
        np.r_[pair // (count + 1), pair % (count + 1)], return_inverse=True
    )
    low, high = np.split(compact + 1, 2)
    nodes = involved.size + 1
    rows = np.r_[low, np.zeros(nodes - 1, dtype=np.int64)]
    cols = np.r_[high, np.arange(1, nodes)]
    weights = np.r_[1.0 / strength, np.full(nodes - 1, 1e9)]
    tree = minimum_spanning_tree(coo_array((weights, (rows, cols)), shape=(nodes, nodes)))
    tie = {(int(lo), int(hi)): int(o) for lo, hi, o in zip(low, high, offset, strict=True)}
    visit, parent = breadth_first_order(tree, 0, directed=False)
    potential = np.zeros(nodes, dtype=np.int64)  # P[low] = P[high] + offset(low, high)
    group = np.zeros(nodes, dtype=np.int64)
    for node in visit[1:]:
        up = parent[node]
        group[node] = node if up == 0 else group[up]
        if up == 0:
            continue
        if (node, up) in tie:
            potential[node] = potential[up] + tie[(node, up)]
        else:
            potential[node] = potential[up] - tie[(up, node)]
    sizes = np.bincount(region.ravel(), minlength=count + 1)[involved]
    for root in np.unique(group[1:]):
        inside = np.flatnonzero(group == root)
        values, where = np.unique(potential[inside], return_inverse=True)
        reference = values[np.argmax(np.bincount(where, weights=sizes[inside - 1]))]
        offsets[involved[inside - 1]] = reference - potential[inside]
    return offsets
