"""Decoding math of virtus.patterns.phase against ground truth built here (seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError
from virtus.patterns import phase

TWO_PI = 2.0 * np.pi


def phase_frames(phi: np.ndarray, a: np.ndarray, b: np.ndarray, steps: int) -> np.ndarray:
    """I_n = A + B cos(phi + 2 pi n / N), n = 1..N (the project's sign convention)."""
    n = np.arange(1, steps + 1).reshape(-1, *([1] * np.ndim(phi)))
    return a + b * np.cos(phi + TWO_PI * n / steps)


def assert_phase_equal(actual: np.ndarray, expected: np.ndarray, atol: float) -> None:
    """Phases equal modulo 2 pi."""
    difference = phase.wrap(np.asarray(actual) - np.asarray(expected))
    assert np.max(np.abs(difference)) <= atol


def test_wrap_range() -> None:
    values = np.array([-np.pi, np.pi, 3 * np.pi, -3 * np.pi, 0.0, 1e-18, -1e-18, 7.0])
    wrapped = phase.wrap(values)
    assert np.all(wrapped >= -np.pi) and np.all(wrapped < np.pi)
    assert wrapped[1] == -np.pi  # +pi belongs to the next branch
    assert_phase_equal(wrapped, values, tol.FLOAT64_EXACT)


@pytest.mark.parametrize("steps", [3, 4, 5, 7, 18])
def test_wrapped_phase_recovers_phase_background_modulation(steps: int) -> None:
    rng = np.random.default_rng(steps)
    phi = rng.uniform(-np.pi, np.pi, (40, 30))
    a = rng.uniform(10, 100, phi.shape)
    b = rng.uniform(5, 80, phi.shape)
    got_phi, got_a, got_b = phase.wrapped_phase(phase_frames(phi, a, b, steps))
    assert got_phi.shape == phi.shape
    assert np.all(got_phi >= -np.pi) and np.all(got_phi < np.pi)
    assert_phase_equal(got_phi, phi, tol.PHASE_EXACT_RAD)
    np.testing.assert_allclose(got_a, a, rtol=0, atol=tol.INTENSITY_EXACT_DN)
    np.testing.assert_allclose(got_b, b, rtol=0, atol=tol.INTENSITY_EXACT_DN)


def test_wrapped_phase_sign_convention() -> None:
    # Frames built with the opposite sign, I_n = A + B cos(phi - 2 pi n / N), decode to -phi:
    # guards against a silently flipped convention.
    phi = np.linspace(-3.0, 3.0, 13)
    steps = 4
    n = np.arange(1, steps + 1)[:, None]
    flipped = 10 + 5 * np.cos(phi - TWO_PI * n / steps)
    got, _, _ = phase.wrapped_phase(flipped)
    assert_phase_equal(got, -phi, tol.PHASE_EXACT_RAD)


def test_wrapped_phase_rejects_too_few_steps() -> None:
    with pytest.raises(InputError) as info:
        phase.wrapped_phase(np.zeros((2, 4, 4)))
    assert info.value.name == "frames"


def test_gray_code_round_trip_and_single_bit_steps() -> None:
    k = np.arange(0, 4096)
    code = phase.gray_encode(k)
    np.testing.assert_array_equal(phase.gray_decode(code), k)
    changed = code[1:] ^ code[:-1]
    assert np.all(changed & (changed - 1) == 0)  # neighbours differ in exactly one bit
    bits = np.array([(code >> (11 - b)) & 1 for b in range(12)], dtype=bool)
    np.testing.assert_array_equal(phase.gray_bits_to_order(bits), k)


def test_unwrap_gray_with_complement_fixes_edge_misreads() -> None:
    rng = np.random.default_rng(7)
    period = 17.3  # non-integer: the order edges fall inside projector pixels
    edges = np.arange(0, 60) * period / 2  # order edges and the wrapped-phase jumps
    u = np.concatenate(
        [rng.uniform(-0.5, 1000, 5000), edges + 1e-6, edges - 1e-6, edges + 0.4, edges - 0.4]
    )
    u = u[u >= -0.5]
    true_phase = TWO_PI * u / period
    wrapped = phase.wrap(true_phase)
    # A blurred or pixelated binary code is read as if at a slightly wrong position: here
    # up to +-0.5 px, independently for the Gray code and the complementary frame.
    k1_read = np.floor((u + rng.uniform(-0.5, 0.5, u.size)) / period + 0.5).astype(np.int64)
    g_read = np.floor(2 * (u + rng.uniform(-0.5, 0.5, u.size)) / period + 1).astype(np.int64)
    assert np.sum(k1_read != np.floor(u / period + 0.5)) > 50  # misreads do happen
    absolute = phase.unwrap_gray(wrapped, k1_read, phase.complementary_order(g_read))
    np.testing.assert_allclose(absolute, true_phase, rtol=0, atol=tol.PHASE_EXACT_RAD)
    # Without the complement the misreads stay: one-period jumps.
    plain = phase.unwrap_gray(wrapped, k1_read)
    assert np.max(np.abs(plain - true_phase)) > np.pi


def test_heterodyne_unwrapping_is_exact_and_checks_coverage() -> None:
    periods = [1152 / 64, 1152 / 63, 1152 / 56]
    u = np.linspace(-0.5, 1139.5, 20001)
    wrapped = [phase.wrap(TWO_PI * u / p) for p in periods]
    absolute, residual = phase.unwrap_heterodyne(wrapped, periods, 1140)
    np.testing.assert_allclose(
        phase.phase_to_coordinate(absolute, periods[0]), u, atol=tol.DECODE_EXACT_PX
    )
    assert np.max(residual) < tol.HETERODYNE_RESIDUAL_EXACT
    with pytest.raises(InputError) as info:
        phase.unwrap_heterodyne(wrapped[:1] + wrapped[2:], [periods[0], periods[2]], 1140)
    assert info.value.name == "periods"  # beat 144 px does not cover 1140 px


def test_phase_coordinate_conversions() -> None:
    u = np.array([-0.5, 0.0, 17.99, 911.5])
    np.testing.assert_allclose(phase.coordinate_to_phase(u, 18.0), TWO_PI * u / 18.0)
    np.testing.assert_allclose(phase.phase_to_coordinate(phase.coordinate_to_phase(u, 7.7), 7.7), u)
    with pytest.raises(InputError):
        phase.phase_to_coordinate(u, 0.0)


def test_quality_mask_modulation_and_saturation() -> None:
    modulation = np.array([[0.0, 5.0, 6.0, np.nan]])
    frames = np.array([[[10, 10, 255, 10]], [[20, 20, 20, 20]], [[30, 30, 30, 30]]])
    mask = phase.quality_mask(modulation, min_modulation=0.02, full_scale=255)  # 5.1 DN
    np.testing.assert_array_equal(mask, [[False, False, True, False]])
    saturated = phase.quality_mask(
        modulation, min_modulation=0.0, full_scale=255, frames=frames, saturation_level=255
    )
    np.testing.assert_array_equal(saturated, [[True, True, False, False]])
    with pytest.raises(InputError) as info:
        phase.quality_mask(modulation, min_modulation=1.5)
    assert info.value.name == "min_modulation"


def test_unwrap_nearest_picks_the_branch_in_a_half_open_window() -> None:
    predicted = np.array([0.0, 10.0, 10.0, -4.0])
    wrapped = phase.wrap(np.array([np.pi, 10.0 + np.pi - 1e-9, 10.0 - np.pi, -4.0 + 0.3]))
    got = phase.unwrap_nearest(wrapped, predicted)
    np.testing.assert_allclose(
        got, [-np.pi, 10.0 + np.pi - 1e-9, 10.0 - np.pi, -3.7], atol=tol.PHASE_EXACT_RAD
    )


def test_binary_and_gray_bits_to_index() -> None:
    k = np.arange(64)
    bits = np.array([(k >> (5 - b)) & 1 for b in range(6)], dtype=bool)
    np.testing.assert_array_equal(phase.bits_to_index(bits, "binary"), k)
    gray = phase.gray_encode(k)
    bits = np.array([(gray >> (5 - b)) & 1 for b in range(6)], dtype=bool)
    np.testing.assert_array_equal(phase.bits_to_index(bits, "gray"), k)
    with pytest.raises(InputError):
        phase.bits_to_index(bits, "excess-3")


def test_temporal_unwrapping_is_exact_and_checks_coverage() -> None:
    periods = [18.0, 144.0, 1152.0]
    u = np.linspace(-0.5, 1139.5, 20001)
    wrapped = [phase.wrap(TWO_PI * u / p) for p in periods]
    absolute, residual = phase.unwrap_temporal(wrapped, periods, 1140)
    np.testing.assert_allclose(
        phase.phase_to_coordinate(absolute, 18.0), u, atol=tol.DECODE_EXACT_PX
    )
    assert np.max(residual) < tol.HETERODYNE_RESIDUAL_EXACT
    with pytest.raises(InputError) as info:
        phase.unwrap_temporal(wrapped[:2], periods[:2], 1140)
    assert info.value.name == "periods"


def smooth_phase(shape=(120, 160), period=18.0):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    absolute = TWO_PI * (0.7 * cols + 0.2 * rows + 3.3) / period
    return absolute, phase.wrap(absolute)


def test_order_consistency_flags_and_corrects_order_errors() -> None:
    absolute, wrapped = smooth_phase()
    valid = np.ones(absolute.shape, dtype=bool)
    flagged, correction = phase.order_consistency(absolute, wrapped, valid)
    assert not flagged.any() and not correction.any()
    # Isolated misreads and a wrong description (every other half period one order low).
    rng = np.random.default_rng(3)
    spots = rng.random(absolute.shape) < 0.01
    for wrong in (spots, wrapped < 0):
        broken = absolute - TWO_PI * wrong
        flagged, correction = phase.order_consistency(broken, wrapped, valid)
        fixed = broken + TWO_PI * correction
        if wrong is spots:
            np.testing.assert_array_equal(flagged, spots)
        assert flagged.mean() >= min(wrong.mean(), 1 - wrong.mean()) - 0.01
        # Repaired to one consistent surface (at most a global order off).
        assert np.unique(np.rint((fixed - absolute) / TWO_PI)).size == 1


def test_order_consistency_leaves_depth_edges_and_unrelated_points_alone() -> None:
    absolute, wrapped = smooth_phase()
    # An object in front: a different, unrelated surface inside a disc (a depth edge).
    rows, cols = np.mgrid[0:120, 0:160]
    disc = (rows - 60) ** 2 + (cols - 80) ** 2 < 30**2
    other = TWO_PI * (0.9 * cols - 0.3 * rows + 250.0) / 18.0
    scene = np.where(disc, other, absolute)
    valid = np.ones(scene.shape, dtype=bool)
    flagged, _ = phase.order_consistency(scene, phase.wrap(scene), valid)
    assert flagged.mean() < tol.FLAGGED_CORRECT_MAX
    # Unrelated points (no continuous surface): the check abstains.
    random = TWO_PI * np.random.default_rng(1).uniform(0, 900, (50, 60)) / 18.0
    flagged, _ = phase.order_consistency(random, phase.wrap(random), np.ones((50, 60), bool))
    assert not flagged.any()


def _wrapped_phase_direct(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The N-step formulas written out on a float64 copy of the whole stack: the reference
    for :func:`phase.wrapped_phase`'s blocked evaluation."""
    stack = np.asarray(frames, dtype=np.float64)
    steps = len(stack)
    shifts = TWO_PI * np.arange(1, steps + 1) / steps
    c = np.tensordot(np.cos(shifts), stack, axes=1)
    s = np.tensordot(np.sin(shifts), stack, axes=1)
    return np.arctan2(-s, c), stack.mean(axis=0), (2.0 / steps) * np.hypot(c, s)


@pytest.mark.parametrize(
    ("steps", "dtype", "shape"),
    [
        (3, np.float32, (37, 41)),
        (4, np.uint16, (128, 129)),  # just over one block of pixels
        (5, np.float64, (128, 128)),  # exactly one block
        (8, np.uint8, (300, 71)),
        (18, np.float32, (2, 70, 130)),  # extra leading axes
    ],
)
def test_wrapped_phase_blocks_equal_the_formulas_on_the_whole_stack(
    steps: int, dtype: type, shape: tuple[int, ...]
) -> None:
    rng = np.random.default_rng(steps)
    phi = rng.uniform(-np.pi, np.pi, shape)
    # B >= 5: where B -> 0 the phase itself is undefined and rounding can move it anywhere.
    frames = phase_frames(phi, rng.uniform(60, 120, shape), rng.uniform(5, 60, shape), steps)
    frames = frames.astype(dtype)
    got = phase.wrapped_phase(frames)
    expected = _wrapped_phase_direct(frames)
    for value in got:
        assert value.dtype == np.float64 and value.shape == shape
    # Float rounding only: the blocked sums are the same products in another order.
    assert_phase_equal(got[0], expected[0], tol.FLOAT64_EXACT)
    np.testing.assert_allclose(got[1], expected[1], rtol=1e-13, atol=0)
    np.testing.assert_allclose(got[2], expected[2], rtol=1e-9, atol=1e-10)
    assert np.all(got[0] >= -np.pi) and np.all(got[0] < np.pi)


def test_wrapped_phase_of_no_pixels_is_empty() -> None:
    for value in phase.wrapped_phase(np.zeros((4, 0, 3), dtype=np.uint16)):
        assert value.shape == (0, 3) and value.dtype == np.float64
