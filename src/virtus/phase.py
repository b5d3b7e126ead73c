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
    "complementary_order",
    "coordinate_to_phase",
    "gray_bits_to_order",
    "gray_decode",
    "gray_encode",
    "phase_to_coordinate",
    "quality_mask",
    "unwrap_gray",
    "unwrap_heterodyne",
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
    # One matrix product gives sum I_n, sum I_n cos d_n and sum I_n sin d_n for every pixel.
    weights = np.stack([np.ones(steps), np.cos(shifts), np.sin(shifts)])
    flat = stack.reshape(steps, -1).astype(np.float64, copy=False)
    sums = weights @ flat
    # sum I_n cos d_n = (N B / 2) cos phi and sum I_n sin d_n = -(N B / 2) sin phi.
    phase = np.arctan2(-sums[2], sums[1])  # in [-pi, pi]
    phase[phase >= np.pi] -= TWO_PI  # +pi belongs to [-pi, pi) as -pi
    background = sums[0] / steps
    modulation = (2.0 / steps) * np.hypot(sums[1], sums[2])
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


def phase_to_coordinate(phase: np.ndarray, period: float) -> np.ndarray:
    """Projector coordinate ``u = Phi T / (2 pi)`` (px) from absolute phase ``Phi`` (rad)."""
    return np.asarray(phase, dtype=np.float64) * (positive("period", period) / TWO_PI)


def coordinate_to_phase(coordinate: np.ndarray, period: float) -> np.ndarray:
    """Absolute phase ``Phi = 2 pi u / T`` (rad) of projector coordinate ``u`` (px)."""
    return np.asarray(coordinate, dtype=np.float64) * (TWO_PI / positive("period", period))
