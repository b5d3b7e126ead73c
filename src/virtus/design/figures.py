"""The VDI/VDE 2634-2 figures from a reconstructed point map, and what the sensor model
predicts for them.

Measured (each fit is least squares; VDI/VDE 2634-2 lets up to 0.3 % of the points,
:data:`EXCLUDED_FRACTION`, be left out, and the points farthest from the first fit are):

* :func:`measure_sphere`: geometric least-squares sphere (algebraic start, then
  ``scipy.optimize.least_squares`` on ``|p - c| - r``); **P_F** = range of the radial
  residuals, **P_S** = fitted minus calibrated diameter. Points within
  ``(1 + ROI_MARGIN) r`` of the nominal centre are the sphere's (a ball bar's two spheres
  are told apart this way).
* :func:`measure_plane`: total least-squares plane (:func:`virtus.metrology.fit_plane`);
  **F** = range of the signed distances.
* **SD** = distance of a ball bar's two fitted centres minus the calibrated distance.

Predicted (for design studies and for the tests that hold the job to physics):

* :func:`projector_jacobian`: ``J = dX / d(u_p, v_p)`` of the triangulation at each pixel, by
  central differences of :func:`virtus.reconstruct.triangulate` (both devices' distortion
  included).
* :func:`staircase_form_bound`: nearest-pixel (DMD) lookup shifts a decoded projector
  coordinate by at most half a projector pixel in each direction, so a point's radial error
  is at most ``b = 0.5 (|J_u . n| + |J_v . n|)`` (``n`` the sphere's normal); the residual
  range to the fitted sphere is then at most ``2 max b`` (the largest 0.3 % of ``b`` left out
  as the fit leaves out points) plus twice the fit's centre and radius error
  (``| |p - c'| - r' - (|p - c| - r) | <= |c' - c| + |r' - r|``).
* :func:`coordinate_sigma_px`: the projector coordinate's noise,
  ``sigma_u = sqrt(2 / N) sigma_I / B * T / (2 pi)`` with ``sigma_I`` the EMVA 1288 temporal
  noise at the pixel's mean signal ``A`` (``sigma_y^2 = K^2 sigma_d^2 + 1/12 + K (A - dark)``,
  DESIGN §9; for shot noise the variance at ``A +- B cos`` averages to that at ``A``).
* :func:`expected_form_range`: P_F of pure noise: the mean over Monte Carlo trials of the
  range of independent normal radial errors of the given per-point sigma, after leaving out
  the same 0.3 % (for one sigma and many points, about ``2 sigma sqrt(2 ln n)``, DESIGN §12).
* :func:`expected_fit_bias`: P_S (and the centre's shift) that zero-mean projector-coordinate
  errors alone give the least-squares sphere fit: the mean over Monte Carlo trials of fits to
  the exact points of the sphere re-triangulated from their true projector coordinates plus
  independent normal errors of the given sigma.

**The sphere fit is biased by large point errors (errors in variables).** A triangulated
point's error runs along the triangulation's direction ``J``, not along the sphere's normal:
its tangential part tilts the direction from the centre to the point in step with its radial
part, and the geometric fit (minimising ``sum (|p - c| - r)^2``) trades that for a smaller
sphere whose centre is nearer the camera. The bias grows as the errors' variance, does not
average away with more points (it depends on how far toward its outline the cap is kept: with
0.19 px errors -0.088 mm at a 480 px camera, -0.062 mm at 960 px), and is there whatever makes
the errors (noise or the DMD staircase). Measured with the paper's rig and the guideline's
sphere (82.6 mm at 1 m, 9-step heterodyne, ideal sensor, true rig, ``use="uv"``, ``nearest``
lookup, the sphere moved by 12 / 6 sub-pixel steps): the DMD staircase leaves no offset in the
decoded coordinates (decoded minus true: |mean| < 0.004 px, so no half-pixel rounding shift)
but 0.19 px RMS in ``u_p`` and ``v_p`` at a 480 px camera and 0.14 px at 960 px, and P_S is
-0.091 +- 0.008 mm (480 px) and -0.041 +- 0.003 mm (960 px, mean +- its standard error); this
function with those RMS gives -0.088 and -0.042 mm. Bilinear lookup (0.01-0.02 px RMS) leaves
-0.006 mm at 480 px. Each ball-bar sphere's centre moves toward the camera along its own line
of sight (0.8 of its P_S), so their distance shrinks by about that shift times the angle
between the lines of sight: over the 7 bar positions at 960 px SD is -0.016 mm measured, -0.014
mm predicted (the 10 sphere positions: P_S -0.044 measured, -0.043 predicted;
``benchmarks/bench_acceptance.py --fit-bias``).
A real scanner with the same coordinate errors shows the same figures (VDI/VDE 2634-2
prescribes this fit). Leaving out the outline pixels (:func:`virtus.design.acceptance.interior`)
makes P_S more negative (-0.091 against -0.022 mm with them, 480 px) because the outline's
partly covered pixels err outward and so offset part of the bias by accident.

Units: metres and projector pixels inside; the JSON summaries in millimetres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import least_squares

from virtus.errors import VirtusError
from virtus.metrology import fit_plane
from virtus.reconstruct import triangulate

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig
    from virtus.geometry.transforms import Pose
    from virtus.patterns import DecodeResult, PatternSequence
    from virtus.sensor.camera import Sensor

__all__ = [
    "EXCLUDED_FRACTION",
    "MIN_POINTS",
    "ROI_MARGIN",
    "PlaneMeasurement",
    "SphereMeasurement",
    "coordinate_sigma_px",
    "expected_fit_bias",
    "expected_form_range",
    "measure_plane",
    "measure_sphere",
    "projector_jacobian",
    "radial_sigma",
    "sphere_normals",
    "staircase_form_bound",
]

#: Largest share of points VDI/VDE 2634-2 lets an evaluation leave out.
EXCLUDED_FRACTION = 0.003
#: A sphere's points lie within (1 + ROI_MARGIN) r of its nominal centre.
ROI_MARGIN = 0.25
#: Fewest points a fit accepts (below, the artefact was not seen).
MIN_POINTS = 50
#: Step of the central differences of the triangulation, projector px: small against the
#: curvature of the rays (exact for a pinhole), large against float64 rounding.
_JACOBIAN_STEP_PX = 0.05


def _excluded(n: int) -> int:
    return int(math.floor(EXCLUDED_FRACTION * n))


@dataclass(frozen=True)
class SphereMeasurement:
    """A sphere's fit: ``centre_m`` (3,), ``diameter_m``, ``form_m`` (P_F), the points kept
    (``n_points``, after ``n_excluded`` were left out), and ``pixels`` (K, 2) int ``(row,
    col)`` of the kept points (not saved)."""

    centre_m: np.ndarray
    diameter_m: float
    form_m: float
    n_points: int
    n_excluded: int
    pixels: np.ndarray

    def to_dict(self, calibrated_diameter_m: float) -> dict[str, Any]:
        """JSON-ready figures in millimetres: ``P_F_mm``, ``P_S_mm`` and the fit."""
        return {
            "P_F_mm": 1e3 * self.form_m,
            "P_S_mm": 1e3 * (self.diameter_m - calibrated_diameter_m),
            "diameter_mm": 1e3 * self.diameter_m,
            "centre_mm": (1e3 * self.centre_m).tolist(),
            "n_points": self.n_points,
            "n_excluded": self.n_excluded,
        }


@dataclass(frozen=True)
class PlaneMeasurement:
    """A plane's fit: ``flatness_m`` (F), ``normal`` (3,), the points kept and left out."""

    flatness_m: float
    normal: np.ndarray
    n_points: int
    n_excluded: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures in millimetres."""
        return {
            "F_mm": 1e3 * self.flatness_m,
            "normal": self.normal.tolist(),
            "n_points": self.n_points,
            "n_excluded": self.n_excluded,
        }


def _lsq_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Geometric least-squares sphere: algebraic (Kasa) start, then Gauss-Newton."""
    mean = points.mean(axis=0)
    p = points - mean
    a = np.concatenate([2 * p, np.ones((p.shape[0], 1))], axis=1)
    solution = np.linalg.lstsq(a, (p * p).sum(axis=1), rcond=None)[0]
    start = np.append(solution[:3], math.sqrt(max(solution[3] + solution[:3] @ solution[:3], 0)))

    def residuals(x: np.ndarray) -> np.ndarray:
        return np.linalg.norm(p - x[:3], axis=1) - x[3]

    def jacobian(x: np.ndarray) -> np.ndarray:
        d = p - x[:3]
        unit = d / np.linalg.norm(d, axis=1, keepdims=True)
        return np.concatenate([-unit, -np.ones((p.shape[0], 1))], axis=1)

    fit = least_squares(residuals, start, jac=jacobian, method="lm", xtol=1e-15, ftol=1e-15)
    return fit.x[:3] + mean, float(fit.x[3])


def _fit_sphere(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Least-squares sphere of ``points`` (N, 3) after leaving out the
    :data:`EXCLUDED_FRACTION` farthest from a first fit: ``(centre, radius, kept indices)``."""
    c, r = _lsq_sphere(points)
    keep = np.arange(points.shape[0])
    k = _excluded(points.shape[0])
    if k:
        keep = np.sort(np.argsort(-np.abs(np.linalg.norm(points - c, axis=1) - r))[k:])
        c, r = _lsq_sphere(points[keep])
    return c, r, keep


def measure_sphere(
    point_map: np.ndarray, centre_m: object, radius_m: float, name: str = "sphere"
) -> SphereMeasurement:
    """Fit the sphere near ``centre_m`` (nominal, camera frame, metres) in a point map
    ``(H, W, 3)`` (metres, NaN where none) and give its figures (module docstring).

    Raises
    ------
    VirtusError : fewer than :data:`MIN_POINTS` points near the sphere (``name`` says which).
    """
    centre = np.asarray(centre_m, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        near = np.linalg.norm(point_map - centre, axis=-1) <= (1 + ROI_MARGIN) * radius_m
    pixels = np.argwhere(near)
    points = point_map[near]
    if points.shape[0] < MIN_POINTS:
        raise VirtusError(
            f"acceptance: {points.shape[0]} points on {name} (need {MIN_POINTS}); is it seen?"
        )
    c, r, keep = _fit_sphere(points)
    k = points.shape[0] - keep.size
    points, pixels = points[keep], pixels[keep]
    residual = np.linalg.norm(points - c, axis=1) - r
    return SphereMeasurement(
        c, 2 * r, float(residual.max() - residual.min()), int(points.shape[0]), k, pixels
    )


def measure_plane(point_map: np.ndarray, plane2cam: Pose, size_m: tuple[float, float],
                  name: str = "plane") -> PlaneMeasurement:  # fmt: skip
    """Fit the plane of nominal pose ``plane2cam`` and ``size_m`` in a point map and give its
    flatness (module docstring); points farther than 5 % of its length from the nominal
    plane or outside its outline (+5 %) are not its.

    Raises
    ------
    VirtusError : fewer than :data:`MIN_POINTS` points on the plane.
    """
    valid = np.isfinite(point_map).all(axis=-1)
    local = plane2cam.inverse().apply(point_map[valid])
    length, width = size_m
    slack = 0.05 * length
    mine = (np.abs(local[:, 2]) <= slack) & (np.abs(local[:, 0]) <= length / 2 + slack)
    mine &= np.abs(local[:, 1]) <= width / 2 + slack
    points = point_map[valid][mine]
    if points.shape[0] < MIN_POINTS:
        raise VirtusError(
            f"acceptance: {points.shape[0]} points on {name} (need {MIN_POINTS}); is it seen?"
        )
    fit = fit_plane(points)
    k = _excluded(points.shape[0])
    if k:
        keep = np.sort(np.argsort(-np.abs(fit.distances))[k:])
        points = points[keep]
        fit = fit_plane(points)
    return PlaneMeasurement(float(fit.flatness), fit.normal, int(points.shape[0]), k)


# --- predictions ---------------------------------------------------------------------------


def projector_jacobian(rig: Rig, cam_px: np.ndarray, proj_uv: np.ndarray) -> np.ndarray:
    """``(N, 3, 2)`` float64 ``dX / d(u_p, v_p)`` (metres per projector px) of the ray-ray
    triangulation at camera pixels ``cam_px`` (N, 2) ``(u, v)`` and projector coordinates
    ``proj_uv`` (N, 2), by central differences."""
    h = _JACOBIAN_STEP_PX
    columns = []
    for axis in (0, 1):
        step = np.zeros(2)
        step[axis] = h
        plus = triangulate(rig, cam_px, proj_uv + step)
        minus = triangulate(rig, cam_px, proj_uv - step)
        columns.append((plus - minus) / (2 * h))
    return np.stack(columns, axis=2)


def sphere_normals(
    rig: Rig, cam_px: np.ndarray, centre_m: object, radius_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where camera pixels ``cam_px`` (N, 2) see a sphere: ``(points (N, 3), normals (N, 3),
    proj_uv (N, 2))`` -- the first intersection of each pixel's ray, the outward unit normal
    and the true projector coordinates there (NaN rows for rays that miss)."""
    rays = rig.camera.intrinsics.unproject(cam_px)
    centre = np.asarray(centre_m, dtype=np.float64)
    b = rays @ centre
    disc = b * b - (centre @ centre - radius_m**2)
    with np.errstate(invalid="ignore"):
        s = b - np.sqrt(disc)
    points = rays * s[:, None]
    normals = (points - centre) / radius_m
    proj_uv = rig.projector.intrinsics.project(rig.cam2proj.apply(points))
    return points, normals, proj_uv


def staircase_form_bound(
    rig: Rig, cam_px: np.ndarray, centre_m: object, radius_m: float, fit_error_m: float = 0.0
) -> float:
    """The largest P_F (metres) nearest-pixel projector lookup alone can cause on a sphere
    seen at camera pixels ``cam_px`` (N, 2) ``(u, v)``: ``2 max b + 2 fit_error_m`` (module
    docstring), ``fit_error_m`` the fit's ``|c' - c| + |r' - r|``."""
    _, normals, proj_uv = sphere_normals(rig, cam_px, centre_m, radius_m)
    jac = projector_jacobian(rig, cam_px, proj_uv)
    bound = 0.5 * np.abs(np.einsum("nij,ni->nj", jac, normals)).sum(axis=1)
    bound = np.sort(bound[np.isfinite(bound)])
    k = _excluded(bound.size)
    return float(2 * bound[bound.size - 1 - k] + 2 * fit_error_m)


def _finest(sequence: PatternSequence, direction: str) -> tuple[int, float]:
    """Steps and period (projector px) of the phase set that gives ``direction``'s coordinate."""
    plan = sequence.plan(direction)
    if plan is None or not plan.sets:
        raise VirtusError(f"acceptance: no phase frames in direction {direction!r}")
    finest = plan.sets[0]
    return len(finest.indices), finest.coding.period / sequence.axis_scale(direction)


def coordinate_sigma_px(sensor: Sensor, sequence: PatternSequence, decoded: DecodeResult,
                        pixels: np.ndarray) -> np.ndarray:  # fmt: skip
    """``(K, 2)`` predicted standard deviation (projector px) of ``(u_p, v_p)`` at camera
    pixels ``pixels`` (K, 2) int ``(row, col)``, from the sensor's EMVA 1288 model at each
    pixel's decoded background and modulation (module docstring)."""
    rows, cols = pixels[:, 0], pixels[:, 1]
    gain = sensor.system_gain_dn_per_e
    background = decoded.background[rows, cols]
    if gain is None:  # an ideal sensor: only its rounding to whole DN
        variance = np.full(background.shape, 1 / 12)
    else:
        dark = sensor.black_level_dn + gain * sensor.dark_current_e_per_s * sensor.exposure_time_s
        variance = gain**2 * sensor.dark_noise_e**2 + 1 / 12 + gain * (background - dark)
        variance += gain**2 * sensor.dark_current_e_per_s * sensor.exposure_time_s
    sigma_i = np.sqrt(np.maximum(variance, 0.0))
    out = []
    for direction, modulation in (("v", decoded.modulation_v), ("h", decoded.modulation_h)):
        steps, period = _finest(sequence, direction)
        sigma_phi = math.sqrt(2 / steps) * sigma_i / modulation[rows, cols]
        out.append(sigma_phi * period / (2 * math.pi))
    return np.stack(out, axis=1)


def radial_sigma(
    rig: Rig, cam_px: np.ndarray, proj_uv: np.ndarray, normals: np.ndarray, sigma_uv: np.ndarray
) -> np.ndarray:
    """``(N,)`` standard deviation (metres) of the points' errors along ``normals`` (N, 3)
    for independent projector-coordinate noise ``sigma_uv`` (N, 2) px: ``sqrt(sum_j (J_j .
    n)^2 sigma_j^2)`` with ``J`` from :func:`projector_jacobian`."""
    jac = projector_jacobian(rig, cam_px, proj_uv)
    along = np.einsum("nij,ni->nj", jac, normals)
    return np.sqrt(((along * sigma_uv) ** 2).sum(axis=1))


def expected_form_range(sigma_m: np.ndarray, trials: int = 400, seed: int = 0) -> float:
    """Mean over ``trials`` of the range of independent normal errors of per-point standard
    deviations ``sigma_m`` (N,), after leaving out the :data:`EXCLUDED_FRACTION` of points
    farthest from zero (as the fits do): P_F of noise alone, metres."""
    sigma = np.asarray(sigma_m, dtype=np.float64)
    gen = np.random.default_rng(seed)
    k = _excluded(sigma.size)
    ranges = np.empty(trials)
    for t in range(trials):
        draws = gen.standard_normal(sigma.size) * sigma
        kept = np.sort(np.argsort(-np.abs(draws))[k:])
        ranges[t] = draws[kept].max() - draws[kept].min()
    return float(ranges.mean())


def expected_fit_bias(
    rig: Rig, cam_px: np.ndarray, centre_m: object, radius_m: float, sigma_uv: object,
    *, use: str = "uv", trials: int = 20, seed: int = 0,
) -> tuple[float, np.ndarray]:  # fmt: skip
    """The fit's own bias (module docstring): mean over ``trials`` of the fitted minus true
    diameter (metres, P_S) and centre ``(3,)`` of a sphere seen at camera pixels ``cam_px``
    (N, 2) ``(u, v)`` whose points are triangulated (``use``) from their true projector
    coordinates plus independent normal errors of ``sigma_uv`` px (scalar, (2,) or (N, 2)),
    fitted as :func:`measure_sphere` fits (0.3 % left out)."""
    centre = np.asarray(centre_m, dtype=np.float64)
    _, _, proj_uv = sphere_normals(rig, cam_px, centre, radius_m)
    hit = np.isfinite(proj_uv).all(axis=1)
    cam, proj = cam_px[hit], proj_uv[hit]
    sigma = np.broadcast_to(np.asarray(sigma_uv, dtype=np.float64), proj_uv.shape)[hit]
    gen = np.random.default_rng(seed)
    sizes, centres = [], []
    for _ in range(trials):
        points = triangulate(rig, cam, proj + sigma * gen.standard_normal(proj.shape), use)
        c, r, _ = _fit_sphere(points[np.isfinite(points).all(axis=1)])
        sizes.append(2 * (r - radius_m))
        centres.append(c - centre)
    return float(np.mean(sizes)), np.mean(centres, axis=0)
