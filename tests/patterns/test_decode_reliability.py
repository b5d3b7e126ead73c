"""Reliability of temporal and heterodyne unwrapping: the residual mask under heavy noise,
per-pixel flags at a known residual, and the decode warning's threshold.

Ground truth is built here: projector coordinates of a smooth surface (heavy noise) or of
random pixels, and phase frames from the frame formula ``0.5 + 0.5 cos(2 pi w / T + 2 pi n
/ N)`` (not from the code under test) with a chosen phase error on one phase set, which
gives each pixel an unwrapping residual known in closed form.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tests import tolerances as tol
from tests.patterns.test_codings import NOISY, both, describe, projected, surface
from virtus.patterns import DecodeWarning, PatternSequence
from virtus.patterns.decode import FLAG_WARN_FRACTION, RESIDUAL_FLAG_RAD

TWO_PI = 2.0 * np.pi

#: Multi-wavelength (1152 / 144 / 18 px) and heterodyne (64 / 63 / 56 fringes over 1152 px)
#: sequences: in both the first unwrapping step has ratio 8 (1152 -> 144), so a phase error
#: delta on the 1152 px set (temporal) or on the 63-fringe set (heterodyne: it shifts the
#: 1152 px beat by -delta) gives a residual of exactly 8 |delta| (the later steps see
#: correct references: residual 0).
CRAFTED = {
    "temporal": (describe(both({"kind": "phase", "periods": [1152, 144, 18], "steps": 6})), 1152.0),
    "heterodyne": (
        describe(both({"kind": "phase", "periods": [1152 / 64, 1152 / 63, 1152 / 56], "steps": 6})),
        1152 / 63,
    ),
}
#: Residuals of the crafted pixel groups (rad): kept and unflagged, kept and flagged
#: (between RESIDUAL_FLAG_RAD = 0.4 pi and the invalid limit pi / 2), invalid.
CLEAN_RAD, FLAGGED_RAD, INVALID_RAD = 0.2 * np.pi, 0.45 * np.pi, 0.6 * np.pi


def crafted_frames(
    sequence: PatternSequence, erred_period: float, u: np.ndarray, v: np.ndarray, delta
) -> np.ndarray:
    """Float frames (full scale 1) ``0.1 + 0.8 (0.5 + 0.5 cos(2 pi w / T + e + 2 pi n / N))``
    with ``e = delta`` (per pixel) on the phase set of period ``erred_period``, else 0."""
    out = np.empty((len(sequence), *u.shape))
    for index, frame in enumerate(sequence.frames):
        assert frame.kind == "phase"
        w = u if frame.direction == "v" else v
        error = delta if frame.period == erred_period else 0.0
        x = TWO_PI * w / frame.period + error + TWO_PI * frame.step / frame.steps
        out[index] = 0.1 + 0.8 * (0.5 + 0.5 * np.cos(x))
    return out


def residual_groups(shares: dict[float, int], seed: int) -> tuple[np.ndarray, ...]:
    """(1, N) coordinates away from the projector's ends and the residual of each pixel:
    ``shares`` maps a residual (rad) to its pixel count, in shuffled order."""
    rng = np.random.default_rng(seed)
    residual = rng.permutation(np.concatenate([np.full(n, r) for r, n in shares.items()]))
    count = residual.size
    # The coarse phase error moves the window-decoded 1152 px level by up to 44 px: stay
    # 150 px inside both ends.
    u = rng.uniform(150.0, 912.0 - 150.0, count)
    v = rng.uniform(150.0, 1140.0 - 150.0, count)
    return u[None], v[None], residual[None]


def decode_recording(sequence: PatternSequence, frames: np.ndarray):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sequence.decode(frames, full_scale=1.0)
    return result, [w for w in caught if issubclass(w.category, DecodeWarning)]


# --- heavy noise: the residual mask removes the wrong orders ----------------------------


#: Fringe amplitude (DN, B = half of it) per sequence for sigma = 6 DN: low enough that
#: noise reaches hundreds of wrong fringe orders without the residual mask (measured ~190
#: heterodyne, ~30 multi-wavelength, over 3 seeds), high enough that the mask leaves none
#: (measured 0 on 3 seeds; at 60 DN one or two wrong orders survive it).
HEAVY_NOISE_AMPLITUDE_DN = {"heterodyne": 80.0, "multiwavelength": 70.0}
HEAVY_NOISE_SIGMA_DN = 6.0


def heavy_noise_frames(name: str) -> tuple[PatternSequence, np.ndarray, np.ndarray, np.ndarray]:
    """(sequence, uint8 frames, u, v): the smooth surface under sigma = 6 DN noise, 90 DN
    ambient light."""
    sequence = NOISY[name]()
    u, v = surface()
    rng = np.random.default_rng(31)
    frames = projected(sequence, u, v, 90.0, HEAVY_NOISE_AMPLITUDE_DN[name])
    frames += rng.normal(0.0, HEAVY_NOISE_SIGMA_DN, frames.shape)
    return sequence, np.clip(np.rint(frames), 0, 255).astype(np.uint8), u, v


def order_errors(result, sequence: PatternSequence, u: np.ndarray, v: np.ndarray) -> int:
    """Valid pixels (per direction) off their true coordinate by half a period or more."""
    count = 0
    for column, (direction, truth) in enumerate((("v", u), ("h", v))):
        mask = getattr(result, f"mask_{direction}")
        error = np.abs(result.proj_uv[..., column][mask] - truth[mask])
        count += int(np.count_nonzero(error >= sequence.periods(direction)[0] / 2))
    return count


@pytest.mark.parametrize("name", sorted(HEAVY_NOISE_AMPLITUDE_DN))
def test_heavy_noise_leaves_no_valid_pixel_half_a_period_off(name: str) -> None:
    sequence, frames, u, v = heavy_noise_frames(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        result = sequence.decode(frames)
    assert order_errors(result, sequence, u, v) == 0
    # Not vacuous: most pixels stay valid, and the noise does push many residuals past the
    # flag limit (the mask has work to do).
    assert result.mask.mean() > 0.5
    assert result.summary()["flagged_fraction"] > FLAG_WARN_FRACTION


# --- flags at a known residual ----------------------------------------------------------


@pytest.mark.parametrize("method", sorted(CRAFTED))
def test_a_known_share_of_pixels_is_flagged_and_masked_by_their_residual(method: str) -> None:
    sequence, erred = CRAFTED[method]
    assert sequence.plans()["v"].method == method
    assert RESIDUAL_FLAG_RAD < FLAGGED_RAD < np.pi / 2 < INVALID_RAD
    u, v, residual = residual_groups({CLEAN_RAD: 500, FLAGGED_RAD: 300, INVALID_RAD: 200}, 3)
    frames = crafted_frames(sequence, erred, u, v, residual / 8.0)
    result, _ = decode_recording(sequence, frames)
    clean, flagged, invalid = (residual == r for r in (CLEAN_RAD, FLAGGED_RAD, INVALID_RAD))
    for direction in ("v", "h"):
        mask = getattr(result, f"mask_{direction}")
        flags = getattr(result, f"flagged_{direction}")
        np.testing.assert_array_equal(mask, clean | flagged, err_msg=direction)
        np.testing.assert_array_equal(flags, flagged, err_msg=direction)
    assert result.summary()["flagged_fraction"] == pytest.approx(300 / 800)
    # Kept pixels, flagged or not, decode to their coordinates: the residual is below pi.
    error = result.proj_uv[result.mask] - np.stack([u, v], axis=-1)[result.mask]
    assert np.max(np.abs(error)) < tol.DECODE_EXACT_PX


# --- the decode warning -----------------------------------------------------------------


@pytest.mark.parametrize("method", sorted(CRAFTED))
@pytest.mark.parametrize(("flagged", "warns"), [(0, False), (30, False), (80, True)])
def test_decode_warns_only_above_five_percent_flagged(method: str, flagged: int, warns) -> None:
    # 1000 valid pixels, ``flagged`` of them flagged: 0 % and 3 % stay quiet, 8 % warns.
    sequence, erred = CRAFTED[method]
    u, v, residual = residual_groups({CLEAN_RAD: 1000 - flagged, FLAGGED_RAD: flagged}, 4)
    result, warned = decode_recording(sequence, crafted_frames(sequence, erred, u, v, residual / 8))
    assert result.mask.all()
    assert int(result.flagged.sum()) == flagged
    assert bool(warned) is warns, [str(w.message) for w in warned]
    if warns:
        assert "flagged" in str(warned[0].message)
