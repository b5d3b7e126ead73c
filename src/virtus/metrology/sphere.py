"""Robust sphere fit: MSAC on 4-point minimal sets, then geometric least squares.

1. **Hypotheses.** Random 4-point samples give spheres in closed form: a sphere is
   ``|x|^2 + D x + E y + F z + G = 0``, linear in ``(D, E, F, G)``. The data are centred and
   scaled first so the 4x4 systems stay well conditioned for small spheres far from the
   origin (a 50 mm radius at 1 m).
2. **Scoring.** With a ``threshold`` (metres), MSAC: the cost of a point is
   ``min(r^2, threshold^2)`` with ``r`` its radial distance to the sphere surface (Torr and
   Zisserman, 2000). Without one, LMedS: the median of ``r^2``; the threshold is then
   2.5 robust standard deviations, ``sigma = 1.4826 (1 + 5 / (n - 4)) sqrt(median r^2)``
   (Rousseeuw and Leroy, 1987). The number of samples adapts to the inlier ratio found so far
   (confidence 0.999 by default).
3. **Refinement.** ``scipy.optimize.least_squares`` on the geometric residuals
   ``|p - c| - r`` of the inliers; inliers are re-selected and the fit repeated until the set
   no longer changes.

:func:`sphere_roi_fit` fits the points of an organised point map near a nominal sphere (an
operator's crop) and maps the radial errors back to the pixels.

All lengths in metres, points in any Cartesian frame (the centre comes back in the same one).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from virtus.checks import as_points, as_rng, positive, positive_int
from virtus.errors import InputError, VirtusError
from virtus.metrology.stats import Histogram, histogram

__all__ = ["SphereFit", "fit_sphere", "sphere_from_4_points", "sphere_roi_fit"]

#: Points used to rank hypotheses (a random subset when there are more): ranking needs only
#: a consistent estimate of each hypothesis' cost, not every point.
_SCORING_POINTS = 4000
#: Hypotheses per vectorised round.
_BATCH = 256
#: Rousseeuw's cut-off in robust standard deviations when no threshold is given.
_AUTO_THRESHOLD_SIGMAS = 2.5
_MAX_REFINEMENTS = 10


@dataclass(frozen=True)
class SphereFit:
    """Result of :func:`fit_sphere`.

    Attributes
    ----------
    center : (3,) float64, metres, the frame of the input points.
    radius : metres.
    radius_std : standard uncertainty of the radius from the least-squares covariance
        (metres); it reflects noise only, not systematic errors.
    inliers : (N,) bool, points within ``threshold`` of the fitted surface
        (:attr:`inlier_ratio` is their fraction).
    rms : RMS of the radial errors of the inliers, metres.
    radial_errors : (N,) float64 signed radial errors ``|p - c| - r`` of every point, metres
        (positive outside the sphere).
    threshold : inlier threshold used, metres.
    hist : histogram of the inliers' radial errors (metres).
    iterations : number of 4-point hypotheses evaluated.
    """

    center: np.ndarray
    radius: float
    radius_std: float
    inliers: np.ndarray
    rms: float
    radial_errors: np.ndarray
    threshold: float
    hist: Histogram
    iterations: int

    @property
    def inlier_ratio(self) -> float:
        """Fraction of inliers, 0..1 (derived from :attr:`inliers`)."""
        return float(self.inliers.mean())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary in millimetres (per-point arrays left out)."""
        mm = 1e3
        return {
            "center_mm": (self.center * mm).tolist(),
            "radius_mm": self.radius * mm,
            "radius_std_mm": self.radius_std * mm,
            "inlier_ratio": self.inlier_ratio,
            "fit_rms_mm": self.rms * mm,
            "threshold_mm": self.threshold * mm,
            "n_points": int(self.inliers.size),
            "n_inliers": int(self.inliers.sum()),
            "iterations": self.iterations,
            "radial_error_histogram_mm": self.hist.to_dict(mm),
        }


def sphere_from_4_points(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spheres through sets of 4 points.

    Parameters
    ----------
    samples : (M, 4, 3) float64 points.

    Returns
    -------
    centres : (M, 3) float64; NaN for degenerate (coplanar or repeated) samples.
    radii : (M,) float64; NaN for degenerate samples.
    """
    samples = np.asarray(samples, dtype=np.float64)
    if samples.ndim != 3 or samples.shape[1:] != (4, 3):
        raise InputError("samples", "an array of shape (M, 4, 3)", f"shape {samples.shape}")
    # Centre and scale each sample so the system is well conditioned; undo afterwards.
    mean = samples.mean(axis=1, keepdims=True)
    local = samples - mean
    scale = np.sqrt(np.mean(np.sum(local * local, axis=2), axis=1))[:, None, None]
    scale = np.where(scale > 0, scale, 1.0)
    local = local / scale
    A = np.concatenate([local, np.ones(local.shape[:2] + (1,))], axis=2)  # noqa: N806
    b = -np.sum(local * local, axis=2)
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-9  # coplanar samples: the 4x4 system is singular
    centres = np.full((samples.shape[0], 3), np.nan)
    radii = np.full(samples.shape[0], np.nan)
    if ok.any():
        sol = np.linalg.solve(A[ok], b[ok][:, :, None])[..., 0]
        c = -0.5 * sol[:, :3]
        r2 = np.sum(c * c, axis=1) - sol[:, 3]
        good = r2 > 0
        idx = np.flatnonzero(ok)
        s = scale[ok, 0, 0]
        centres[idx[good]] = c[good] * s[good, None] + mean[ok, 0][good]
        radii[idx[good]] = np.sqrt(r2[good]) * s[good]
    return centres, radii


def fit_sphere(
    points: object,
    threshold: float | None = None,
    *,
    confidence: float = 0.999,
    max_iterations: int = 5000,
    min_inlier_ratio: float = 0.1,
    bins: int = 50,
    rng: np.random.Generator | int | None = None,
) -> SphereFit:
    """Fit a sphere robustly to points with noise and outliers.

    Parameters
    ----------
    points : (N, 3) float, metres, finite, N >= 4.
    threshold : inlier distance to the sphere surface in metres (MSAC); None estimates it
        from the data (LMedS, 2.5 robust sigmas), which assumes at least half are inliers.
    confidence : probability that at least one all-inlier sample was drawn (adaptive
        stopping), in (0, 1).
    max_iterations : cap on the number of 4-point hypotheses.
    min_inlier_ratio : below this fraction of inliers the fit is refused.
    bins : bins of the radial-error histogram.
    rng : random generator or seed for the sampling.

    Returns
    -------
    :class:`SphereFit`.

    Raises
    ------
    VirtusError
        No sphere with at least ``min_inlier_ratio`` inliers was found.
    """
    pts = as_points("points", points, 3)
    n = pts.shape[0]
    if n < 4:
        raise InputError("points", "at least 4 points", f"{n} points")
    if threshold is not None:
        threshold = positive("threshold", threshold)
    if not 0.0 < confidence < 1.0:
        raise InputError("confidence", "a probability in (0, 1)", confidence)
    max_iterations = positive_int("max_iterations", max_iterations)
    if not 0.0 < min_inlier_ratio <= 1.0:
        raise InputError("min_inlier_ratio", "a fraction in (0, 1]", min_inlier_ratio)
    gen = as_rng(rng)

    score_pts = pts if n <= _SCORING_POINTS else pts[gen.choice(n, _SCORING_POINTS, replace=False)]
    best_cost = np.inf
    best: tuple[np.ndarray, float] | None = None
    needed = max_iterations
    done = 0
    while done < min(needed, max_iterations):
        m = min(_BATCH, max_iterations - done)
        idx = _draw_samples(gen, n, m)
        centres, radii = sphere_from_4_points(pts[idx])
        done += m
        ok = np.isfinite(radii)
        if not ok.any():
            continue
        r = np.linalg.norm(score_pts[None, :, :] - centres[ok, None, :], axis=2) - radii[ok, None]
        r2 = r * r
        if threshold is None:
            cost = np.median(r2, axis=1)
        else:
            cost = np.minimum(r2, threshold * threshold).sum(axis=1)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best_cost = float(cost[k])
            best = (centres[ok][k], float(radii[ok][k]))
            thr = threshold if threshold is not None else _auto_threshold(cost[k], n)
            w = float(np.mean(np.abs(r[k]) <= thr))
            needed = _required_samples(w, confidence)
    if best is None:
        raise VirtusError("sphere fit: every 4-point sample was degenerate (coplanar points?)")

    centre, radius = best
    thr = threshold if threshold is not None else _auto_threshold(best_cost, n)
    inliers = np.abs(np.linalg.norm(pts - centre, axis=1) - radius) <= thr
    radius_std = np.nan
    for _ in range(_MAX_REFINEMENTS):
        if inliers.sum() < 4:
            break
        centre, radius, radius_std = _refine(pts[inliers], centre, radius)
        residual = np.linalg.norm(pts - centre, axis=1) - radius
        if threshold is None:
            thr = _auto_threshold(float(np.median(residual**2)), n)
        new_inliers = np.abs(residual) <= thr
        if np.array_equal(new_inliers, inliers):
            break
        inliers = new_inliers

    residual = np.linalg.norm(pts - centre, axis=1) - radius
    ratio = float(inliers.mean())
    if ratio < min_inlier_ratio or inliers.sum() < 4:
        raise VirtusError(
            f"sphere fit: only {ratio:.1%} of {n} points within {thr * 1e3:.3g} mm of the best "
            f"sphere (need {min_inlier_ratio:.0%}); are these points on a sphere?"
        )
    inlier_res = residual[inliers]
    return SphereFit(
        center=centre,
        radius=float(radius),
        radius_std=float(radius_std),
        inliers=inliers,
        rms=float(np.sqrt(np.mean(inlier_res**2))),
        radial_errors=residual,
        threshold=float(thr),
        hist=histogram(inlier_res, bins, (-thr, thr)),
        iterations=done,
    )


def sphere_roi_fit(
    point_map: np.ndarray,
    centre_m: object,
    radius_m: float,
    *,
    roi_margin: float = 0.1,
    threshold_m: float = 1e-3,
    rng: np.random.Generator | int | None = 0,
) -> tuple[SphereFit, np.ndarray]:
    """Fit a sphere to the reconstructed points near a nominal sphere.

    Parameters
    ----------
    point_map : (H, W, 3) float, reconstructed points (camera frame, metres), NaN where
        there is none (:attr:`virtus.reconstruct.Reconstruction.points`).
    centre_m : (3,) nominal centre, camera frame, metres.
    radius_m : nominal radius, metres.
    roi_margin : keep points within ``(1 + roi_margin) * radius_m`` of the nominal centre.
    threshold_m : MSAC inlier threshold, metres.
    rng : RANSAC sampling.

    Returns
    -------
    fit : the sphere fit.
    error_map : (H, W) float64 signed radial error per pixel (m), NaN outside the ROI.
    """
    centre = np.asarray(centre_m, dtype=np.float64)
    points = np.asarray(point_map, dtype=np.float64)
    dist = np.linalg.norm(points - centre, axis=-1)
    with np.errstate(invalid="ignore"):
        roi = dist <= (1.0 + roi_margin) * radius_m
    if roi.sum() < 4:
        raise VirtusError(f"sphere fit: {int(roi.sum())} points near the sphere; is it in view?")
    fit = fit_sphere(points[roi], threshold_m, rng=rng)
    error_map = np.full(points.shape[:2], np.nan)
    error_map[roi] = fit.radial_errors
    return fit, error_map


def _draw_samples(gen: np.random.Generator, n: int, m: int) -> np.ndarray:
    """(m, 4) indices of 4 distinct points each."""
    idx = np.stack([gen.choice(n, 4, replace=False) for _ in range(m)]) if n < 64 else None
    if idx is None:
        idx = gen.integers(0, n, size=(m, 4))
        # Redraw the rare samples with a repeated index.
        for _ in range(10):
            s = np.sort(idx, axis=1)
            dup = (s[:, 1:] == s[:, :-1]).any(axis=1)
            if not dup.any():
                break
            idx[dup] = gen.integers(0, n, size=(int(dup.sum()), 4))
    return idx


def _required_samples(inlier_ratio: float, confidence: float) -> int:
    """Samples needed to draw one all-inlier 4-point set with probability ``confidence``."""
    p_good = inlier_ratio**4
    if p_good <= 0:
        return np.iinfo(np.int64).max
    if p_good >= 1:
        return 1
    return int(np.ceil(np.log(1 - confidence) / np.log(1 - p_good)))


def _auto_threshold(median_r2: float, n: int) -> float:
    sigma = 1.4826 * (1 + 5 / max(n - 4, 1)) * np.sqrt(median_r2)
    # A perfect fit (noise-free data) has sigma = 0: keep a threshold at float64 resolution.
    return max(_AUTO_THRESHOLD_SIGMAS * sigma, 1e-12)


def _refine(
    points: np.ndarray, centre: np.ndarray, radius: float
) -> tuple[np.ndarray, float, float]:
    """Geometric least squares on inliers; returns (centre, radius, radius_std)."""
    origin = points.mean(axis=0)
    local = points - origin

    def residuals(p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(local - p[:3], axis=1) - p[3]

    def jacobian(p: np.ndarray) -> np.ndarray:
        d = local - p[:3]
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        return np.concatenate([-d / dist, -np.ones((local.shape[0], 1))], axis=1)

    x0 = np.concatenate([centre - origin, [radius]])
    sol = least_squares(residuals, x0, jac=jacobian, method="lm", xtol=1e-15, ftol=1e-15)
    m = local.shape[0]
    radius_std = np.nan
    if m > 4:
        sigma2 = float(np.sum(sol.fun**2)) / (m - 4)
        try:
            cov = np.linalg.inv(sol.jac.T @ sol.jac) * sigma2
            radius_std = float(np.sqrt(max(cov[3, 3], 0.0)))
        except np.linalg.LinAlgError:
            pass
    return sol.x[:3] + origin, float(sol.x[3]), radius_std
