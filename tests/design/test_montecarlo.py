"""The Monte Carlo check of the model (virtus.design.montecarlo): its comparisons. The check
itself runs over the issue's cases in tests/test_uncertainty.py."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.design.montecarlo import MonteCarlo, monte_carlo
from virtus.errors import InputError
from virtus.scanner import Scanner


def _synthetic(sigma: np.ndarray, draws: int, seed: int = 0) -> MonteCarlo:
    """Measured stds of ``draws`` normal draws of the given per-pixel sigma."""
    samples = np.random.default_rng(seed).standard_normal((draws, sigma.size)) * sigma
    measured = samples.std(axis=0, ddof=1)
    return MonteCarlo({"u_p": sigma}, {"u_p": measured}, 1.0, 0.0, draws)


def test_the_pooled_p95_has_no_sampling_bias_where_the_raw_one_has():
    sigma = np.full(20_000, 0.01)  # a plane: nearly constant sigma
    ratios = _synthetic(sigma, 40).ratios("u_p")
    assert ratios["median"] == pytest.approx(0.99, abs=0.01)  # chi's median, df = 39
    assert ratios["p95_raw"] == pytest.approx(1 + 1.645 / np.sqrt(2 * 39), abs=0.02)  # ~1.19
    assert ratios["p95_pooled"] == pytest.approx(1.0, abs=0.02)


def test_ratios_follow_a_wrong_prediction():
    sigma = np.random.default_rng(3).uniform(0.005, 0.02, 20_000)
    result = _synthetic(sigma, 40)
    assert result.ratios("u_p")["p95_pooled"] == pytest.approx(1.0, abs=0.02)
    assert result.scaled(2.0).ratios("u_p")["median"] == pytest.approx(0.5, abs=0.02)


@pytest.mark.parametrize("draws", [1, 0, 10_001, 2.5, True])
def test_monte_carlo_bounds_its_draws(draws):
    with pytest.raises(InputError, match="draws"):
        monte_carlo(Scanner(), None, draws)
