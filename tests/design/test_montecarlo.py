"""The Monte Carlo check of the model (virtus.design.montecarlo): its comparisons. The check
itself runs over the issue's cases in tests/test_uncertainty.py."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.design.montecarlo import MonteCarlo, monte_carlo, p95_sampling_inflation
from virtus.errors import InputError
from virtus.scanner import Scanner


def _synthetic(sigma: np.ndarray, draws: int, seed: int = 0) -> MonteCarlo:
    """Measured stds of ``draws`` normal draws of the given per-pixel sigma."""
    samples = np.random.default_rng(seed).standard_normal((draws, sigma.size)) * sigma
    measured = samples.std(axis=0, ddof=1)
    return MonteCarlo({"u_p": sigma}, {"u_p": measured}, 1.0, 0.0, draws)


@pytest.mark.parametrize("draws", [40, 200])
def test_the_raw_p95_is_inflated_by_sampling_as_computed_and_the_pooled_one_is_not(draws):
    sigma = np.full(20_000, 0.01)  # a plane: nearly constant sigma
    ratios = _synthetic(sigma, draws).ratios("u_p")
    assert ratios["median"] == pytest.approx(1.0, abs=0.01)  # chi's median: 0.991, 0.998
    assert ratios["p95_sampling"] == pytest.approx(p95_sampling_inflation(draws))
    assert ratios["p95_raw"] == pytest.approx(ratios["p95_sampling"], abs=0.01)  # 1.18, 1.08
    assert ratios["p95_pooled"] == pytest.approx(1.0, abs=0.02)


def test_p95_sampling_inflation_is_the_chi_quantile():
    assert p95_sampling_inflation(40) == pytest.approx(1 + 1.645 / np.sqrt(2 * 39), abs=0.01)
    assert p95_sampling_inflation(200) == pytest.approx(1.0819, abs=1e-4)
    assert p95_sampling_inflation(10_000) < 1.02
    with pytest.raises(InputError, match="draws"):
        p95_sampling_inflation(1)


def test_ratios_follow_a_wrong_prediction():
    sigma = np.random.default_rng(3).uniform(0.005, 0.02, 20_000)
    result = _synthetic(sigma, 40)
    assert result.ratios("u_p")["p95_pooled"] == pytest.approx(1.0, abs=0.02)
    assert result.scaled(2.0).ratios("u_p")["median"] == pytest.approx(0.5, abs=0.02)


@pytest.mark.parametrize("draws", [1, 0, 10_001, 2.5, True])
def test_monte_carlo_bounds_its_draws(draws):
    with pytest.raises(InputError, match="draws"):
        monte_carlo(Scanner(), None, draws)
