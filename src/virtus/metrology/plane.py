"""Plane fit and flatness.

Total least squares (the plane through the centroid normal to the direction of least
variance, from an SVD), optionally after MSAC on 3-point samples to reject outliers.
Flatness is the peak-to-valley of the inliers' signed distances (ISO 12781's minimum-zone
flatness is at most this value; for dense, well-spread points the two agree closely).
Lengths in metres; the plane is ``normal . x = offset`` with a unit normal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.checks import as_points, as_rng, positive, positive_int
from virtus.errors import DegenerateData, InputError

__all__ = ["PlaneFit", "fit_plane"]

_SCORING_POINTS = 4000
_BATCH = 256


@dataclass(frozen=True)
class PlaneFit:
    """Result of :func:`fit_plane`.

    Attributes
    ----------
    normal : (3,) float64 unit normal, oriented so that ``normal . centroid <= 0`` (it faces
        a camera at the origin of the points' frame).
    offset : metres, ``normal . x = offset`` on the plane.
    centroid : (3,) float64 mean of the inliers, metres.
    inliers : (N,) bool (:attr:`inlier_ratio` is their fraction).
    rms : RMS distance of the inliers to the plane, metres.
    flatness : peak-to-valley of the inliers' signed distances, metres.
    distances : (N,) float64 signed distances of every point, metres.
    threshold : inlier threshold used (metres), or None when every point was used.
    """

    normal: np.ndarray
    offset: float
    centroid: np.ndarray
    inliers: np.ndarray
    rms: float
    flatness: float
    distances: np.ndarray
    threshold: float | None

    @property
    def inlier_ratio(self) -> float:
        """Fraction of inliers, 0..1 (derived from :attr:`inliers`)."""
        return float(self.inliers.mean())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary in millimetres."""
        return {
            "normal": self.normal.tolist(),
            "offset_mm": self.offset * 1e3,
            "centroid_mm": (self.centroid * 1e3).tolist(),
            "inlier_ratio": self.inlier_ratio,
            "rms_mm": self.rms * 1e3,
            "flatness_mm": self.flatness * 1e3,
            "threshold_mm": None if self.threshold is None else self.threshold * 1e3,
        }


def fit_plane(
    points: object,
    threshold: float | None = None,
    *,
    max_iterations: int = 1000,
    rng: np.random.Generator | int | None = None,
) -> PlaneFit:
    """Fit a plane to points.

    Parameters
    ----------
    points : (N, 3) float, metres, finite, N >= 3.
    threshold : inlier distance in metres; with it, MSAC on 3-point samples selects the
        inliers before the final fit; None fits every point (no outliers expected).
    max_iterations : cap on 3-point hypotheses (MSAC only).
    rng : random generator or seed for the sampling.
    """
    pts = as_points("points", points, 3)
    n = pts.shape[0]
    if n < 3:
        raise InputError("points", "at least 3 points", f"{n} points")
    max_iterations = positive_int("max_iterations", max_iterations)
    inliers = np.ones(n, dtype=bool)
    if threshold is not None:
        threshold = positive("threshold", threshold)
        inliers = _msac(pts, threshold, max_iterations, as_rng(rng))
    for _ in range(10):
        normal, centroid = _tls(pts[inliers])
        distances = (pts - centroid) @ normal
        if threshold is None:
            break
        new = np.abs(distances) <= threshold
        if np.array_equal(new, inliers) or new.sum() < 3:
            break
        inliers = new
    if normal @ centroid > 0:
        normal = -normal
        distances = -distances
    d_in = distances[inliers]
    return PlaneFit(
        normal=normal,
        offset=float(normal @ centroid),
        centroid=centroid,
        inliers=inliers,
        rms=float(np.sqrt(np.mean(d_in**2))),
        flatness=float(d_in.max() - d_in.min()),
        distances=distances,
        threshold=threshold,
    )


def _tls(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centroid = points.mean(axis=0)
    _, singular, vt = np.linalg.svd(points - centroid, full_matrices=False)
    if singular.size < 2 or singular[1] <= 1e-12 * max(singular[0], 1e-300):
        raise DegenerateData("plane fit: the points are collinear or coincident")
    return vt[-1], centroid


def _msac(pts: np.ndarray, threshold: float, max_iterations: int, gen) -> np.ndarray:
    n = pts.shape[0]
    score = pts if n <= _SCORING_POINTS else pts[gen.choice(n, _SCORING_POINTS, replace=False)]
    best_cost, best = np.inf, None
    done = 0
    while done < max_iterations:
        m = min(_BATCH, max_iterations - done)
        idx = gen.integers(0, n, size=(m, 3))
        a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
        normals = np.cross(b - a, c - a)
        norm = np.linalg.norm(normals, axis=1)
        ok = norm > 1e-15
        done += m
        if not ok.any():
            continue
        normals = normals[ok] / norm[ok, None]
        d = np.einsum("mij,mj->mi", score[None] - a[ok, None], normals)
        cost = np.minimum(d * d, threshold * threshold).sum(axis=1)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best_cost, best = float(cost[k]), (a[ok][k], normals[k])
    if best is None:
        raise DegenerateData("plane fit: every 3-point sample was degenerate (collinear points?)")
    origin, normal = best
    inliers = np.abs((pts - origin) @ normal) <= threshold
    if inliers.sum() < 3:
        raise DegenerateData("plane fit: fewer than 3 points within the threshold of any plane")
    return inliers
