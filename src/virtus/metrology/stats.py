"""Error statistics and histograms shared by the fits and the cloud-to-mesh distance.

Values are in metres (SI inside); :meth:`ErrorStats.to_dict` reports them in millimetres
with the unit in each key, as human-facing metrics should.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.checks import as_float_array, positive_int
from virtus.errors import InputError

__all__ = ["ErrorStats", "Histogram", "error_stats", "histogram"]


@dataclass(frozen=True)
class Histogram:
    """Counts of values in bins.

    Attributes
    ----------
    counts : (B,) int64 number of values per bin.
    edges : (B + 1,) float64 bin edges, in the unit of the values (metres here).
    """

    counts: np.ndarray
    edges: np.ndarray

    def to_dict(self, scale: float = 1.0) -> dict[str, list]:
        """JSON-ready ``{"counts", "edges"}``; edges multiplied by ``scale`` (1e3 for mm)."""
        return {"counts": self.counts.tolist(), "edges": (self.edges * scale).tolist()}


def histogram(values: object, bins: int = 50, value_range: tuple[float, float] | None = None):
    """Histogram of finite ``values`` ((N,) float) in ``bins`` equal bins.

    ``value_range`` defaults to a range symmetric about zero that holds every value, so
    signed errors are centred.
    """
    data = as_float_array("values", values, (None,))
    bins = positive_int("bins", bins)
    if value_range is None:
        half = float(np.max(np.abs(data))) if data.size else 1.0
        half = half if half > 0 else 1.0
        value_range = (-half, half)
    low, high = (float(v) for v in value_range)
    if not high > low:
        raise InputError("value_range", "(low, high) with high > low", value_range)
    counts, edges = np.histogram(data, bins=bins, range=(low, high))
    return Histogram(counts.astype(np.int64), edges)


@dataclass(frozen=True)
class ErrorStats:
    """Summary of signed errors (metres).

    Attributes
    ----------
    n : number of values.
    mean : signed mean (bias).
    mae : mean absolute error.
    rmse : root mean square error.
    std : standard deviation about the mean.
    max_abs : largest absolute error.
    p50_abs, p95_abs, p99_abs : percentiles of the absolute error.
    hist : histogram of the signed errors.
    """

    n: int
    mean: float
    mae: float
    rmse: float
    std: float
    max_abs: float
    p50_abs: float
    p95_abs: float
    p99_abs: float
    hist: Histogram

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict in millimetres (keys carry ``_mm``)."""
        mm = 1e3
        return {
            "n": self.n,
            "mean_mm": self.mean * mm,
            "mae_mm": self.mae * mm,
            "rmse_mm": self.rmse * mm,
            "std_mm": self.std * mm,
            "max_abs_mm": self.max_abs * mm,
            "p50_abs_mm": self.p50_abs * mm,
            "p95_abs_mm": self.p95_abs * mm,
            "p99_abs_mm": self.p99_abs * mm,
            "histogram_mm": self.hist.to_dict(mm),
        }


def error_stats(errors: object, bins: int = 50) -> ErrorStats:
    """Statistics of signed errors.

    Parameters
    ----------
    errors : (N,) float, metres, finite, N >= 1.
    bins : histogram bins.
    """
    data = as_float_array("errors", errors, (None,))
    if data.size == 0:
        raise InputError("errors", "at least one value", "an empty array")
    absolute = np.abs(data)
    p50, p95, p99 = np.percentile(absolute, [50, 95, 99])
    return ErrorStats(
        n=int(data.size),
        mean=float(data.mean()),
        mae=float(absolute.mean()),
        rmse=float(np.sqrt(np.mean(data * data))),
        std=float(data.std()),
        max_abs=float(absolute.max()),
        p50_abs=float(p50),
        p95_abs=float(p95),
        p99_abs=float(p99),
        hist=histogram(data, bins),
    )
