"""The photometric twin: what geometry cannot give, fitted from real captures.

A calibration gives a twin its geometry; :func:`fit_photometry` gives it the light. From
captures of a rig (each a phase-shift sequence with white and black frames, decoded and
triangulated with the rig) it estimates, over the valid pixels (decoded, not flagged, not
saturated, lit above :data:`MIN_SIGNAL_FRACTION` of the white-black range):

* **projector response and blur** -- per phase set (period ``P``, ``N`` steps) the harmonic
  content of the N-step profile of every pixel: ``m1 = (2/N)|C_1| / (white - black)`` and,
  for ``N >= 4``, ``q_k = Re(C_k conj(C_1)^k) / |C_1|^(k+1)`` (``C_k`` the DFT of the N
  frames, ``k = 2 .. min(3, N/2)``; both free of the pixel's phase, albedo, vignetting and
  ambient light). The same numbers of the light the projector model emits (its 8-bit
  quantised patterns through ``g(x) = x^gamma``, its pixel aperture and a Gaussian PSF of
  ``sigma`` projector px, :meth:`~virtus.sensor.projector.ProjectorModel.spread`) are fitted
  to them: ``q_k`` mostly sets gamma (DESIGN.md section 9: the harmonics of ``g`` of a
  sinusoid), ``m1`` across the periods the blur, ``exp(-2 pi^2 sigma^2 / P^2)`` per harmonic
  (a single period gives one ``m1``, still enough with gamma from ``q``). Patterns of two
  levels (square-wave fringes) send only 0 and 255, whose light no gamma changes: then the
  prior's gamma is kept (``gamma_observable: false``) and the blur alone is fitted;
* **camera vignetting and projector fall-off** -- ``log(white - black)`` less the
  geometry's ``log(cos(theta_i) |X_p| / z_p^3)`` (the renderer's radiance of a Lambertian
  point under a white projector, :mod:`virtus.render.tracing`, normals from the point map)
  is fitted by ``log C_j + n_c log cos(theta_c) + n_p log cos(theta_p)`` (robust least
  squares, one ``C_j`` per capture): ``cos(theta_c)`` of the camera ray about the camera's
  principal point, ``cos(theta_p)`` of the triangulated point's projector pixel about the
  projector's. The exponents are stored as the models' ``cos`` vignetting and fall-off
  (``cos(theta)**k``, :data:`EXPONENT_DECIMALS` decimals; ``none`` for ``k <= 0``, capped
  at :data:`~virtus.sensor.camera.MAX_COS_EXPONENT`). If the two regressors cannot be told
  apart (correlation above :data:`SEPARABLE_MAX_CORRELATION`, a standard error above
  :data:`SEPARABLE_MAX_STDERR`, or a negative exponent: on a single flat pose the two trade
  off, e.g. +9 against -15 on a real board) one exponent of their product is fitted and the
  report says ``separable: false``;
* **exposure** -- ``C_j = exposure * albedo * (1 - black)`` with the target's stated albedo;
* **ambient light** -- the black frame over the projector's black level:
  ``A = S' ((black - offset) / (white - black) (1 - b) - b)`` with ``S'`` the white
  radiance per albedo (fall-off times geometry), ``b = 1 / contrast_ratio`` the prior
  projector's and ``offset`` the camera's black level (mean over pixels, in the units of
  :attr:`virtus.scene.model.Scene.ambient`);
* **temporal noise and gain** -- per pixel the residual ``r`` of its N frames after the
  fitted model ``a + s E(phi) + t E'(phi)`` (``E`` the model's frame vector at the pixel's
  phase): ``E[r_n^2] = sum_m Q_nm^2 sigma_m^2`` (``Q = 1 - H``, ``H`` the fit's hat
  matrix) with the EMVA 1288 variance ``sigma_m^2 = K (I_m - mu_dark) + K^2 sigma_d^2 +
  1/12`` of each frame's level ``I_m`` (DESIGN.md section 9). Over every pixel and frame
  (levels from a fringe's dark to its bright part) this is one linear fit for the system
  gain ``K`` (DN/e-) and the dark noise ``sigma_d`` (``mu_dark``: the camera's black level);
  the report bins it as a photon transfer curve.

The result (:class:`PhotometricFit`) holds a :class:`~virtus.sensor.camera.Sensor` and a
:class:`~virtus.sensor.projector.ProjectorModel` (written as the twin's ``sensor.yaml`` and
``projector.yaml``), the ambient level and a report of every fitted number (with the
relative error at the image corner that storing each exponent leaves: none but for a capped
or negative exponent).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from virtus.capture.capture import Capture
from virtus.errors import DegenerateData, InputError
from virtus.geometry.devices import Rig
from virtus.patterns.decode import PhaseSet
from virtus.reconstruct import points_from_decoded
from virtus.sensor.camera import MAX_COS_EXPONENT, Sensor
from virtus.sensor.projector import Lookup, ProjectorModel

__all__ = [
    "MIN_SIGNAL_FRACTION",
    "PhotometricFit",
    "fit_photometry",
    "frame_differences",
    "response_harmonics",
]

#: Pixels whose white - black signal is below this fraction of its 99th percentile are left
#: out (shadows, the dark background, the image's unlit rim).
MIN_SIGNAL_FRACTION = 0.15
#: Pixels within this fraction of full scale (or the sensor's saturation) in any frame used
#: are left out: a clipped profile has no harmonics of the model's.
SATURATION_FRACTION = 0.995
#: Gaussian smoothing (camera px) of the point map before normals are taken from it.
NORMAL_SMOOTH_PX = 2.0
#: Vignetting and fall-off are told apart only below this correlation of their regressors...
SEPARABLE_MAX_CORRELATION = 0.95
#: ... and with standard errors of both exponents below this.
SEPARABLE_MAX_STDERR = 0.25
#: Bins of the photon transfer curve (quantiles of the pixels' mean level).
PTC_BINS = 16
#: Most pixels per capture used by the noise fit (a regular subsample beyond).
NOISE_MAX_PIXELS = 50_000
#: Pixels per block of the noise fit (its (N, N) hat matrices per pixel stay small).
_NOISE_CHUNK = 4096
#: Highest harmonic used for gamma.
MAX_HARMONIC = 3
#: Decimals of a stored vignetting or fall-off exponent (files stay short and stable).
EXPONENT_DECIMALS = 3


@dataclass(frozen=True)
class PhotometricFit:
    """What :func:`fit_photometry` found.

    Attributes
    ----------
    sensor : the fitted camera (bit depth, fixed exposure, EMVA gain and dark noise, black
        level, vignetting), other settings from the prior.
    projector : the fitted projector (gamma, ``psf`` pixel model with the fitted blur,
        fall-off), contrast and fill factor from the prior.
    ambient : the ambient level (:attr:`virtus.scene.model.Scene.ambient` units).
    report : every fitted number (JSON-ready): ``response``, ``shading``, ``ambient``,
        ``noise``, ``pixels``, ``notes``.
    """

    sensor: Sensor
    projector: ProjectorModel
    ambient: float
    report: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the models, the ambient level and the report."""
        return {
            "sensor": self.sensor.to_dict(),
            "projector": self.projector.to_dict(),
            "ambient": self.ambient,
            **self.report,
        }


@dataclass
class _View:
    """One capture's valid pixels and what the fits need of them."""

    capture: Capture
    pixels: np.ndarray  # (n,) flat indices of the valid pixels
    white: np.ndarray  # (n,) DN
    black: np.ndarray  # (n,) DN
    geometry: np.ndarray  # (n,) cos(theta_i) |X_p| / z_p^3, 1/m^2
    log_cos_camera: np.ndarray  # (n,)
    log_cos_projector: np.ndarray  # (n,)


# --- pixels and geometry ------------------------------------------------------------------


def _uniform_index(capture: Capture, kind: str) -> int:
    for index, frame in enumerate(capture.sequence.frames):
        if frame.kind == kind:
            return index
    name = capture.path or "capture"
    raise InputError(f"{name}", f"a {kind} frame in the sequence (photometric fit)", None)


def _phase_sets(capture: Capture) -> list[PhaseSet]:
    plans = capture.sequence.plans()
    return [s for d in capture.sequence.directions for s in plans[d].sets]


def _saturation(capture: Capture, sensor: Sensor | None) -> float:
    level = float(capture.full_scale)
    if sensor is not None and sensor.saturation_capacity_e is not None:
        level = min(level, float(sensor.saturation_dn))
    return SATURATION_FRACTION * level


def _normals(points: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals of a point map (NaN where the smoothed map lacks support)."""
    from scipy.ndimage import gaussian_filter

    ok = np.isfinite(points).all(axis=2)
    weight = gaussian_filter(ok.astype(np.float64), NORMAL_SMOOTH_PX)
    filled = np.where(ok[..., None], points, 0.0)
    smooth = np.stack([gaussian_filter(filled[..., i], NORMAL_SMOOTH_PX) for i in range(3)], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = smooth / weight[..., None]
    smooth[(weight < 0.99) | ~ok] = np.nan
    step = 2
    dx = np.full_like(smooth, np.nan)
    dy = np.full_like(smooth, np.nan)
    dx[:, step:-step] = smooth[:, 2 * step :] - smooth[:, : -2 * step]
    dy[step:-step] = smooth[2 * step :] - smooth[: -2 * step]
    normal = np.cross(dx, dy)
    with np.errstate(invalid="ignore", divide="ignore"):
        return normal / np.linalg.norm(normal, axis=2, keepdims=True)


def _view(
    capture: Capture, rig: Rig, sensor: Sensor | None, region: np.ndarray | None = None
) -> _View:
    """The valid pixels of one capture (inside ``region`` if given) with their white, black
    and geometry."""
    frames = capture.frames
    white = frames[_uniform_index(capture, "white")].astype(np.float64)
    black = frames[_uniform_index(capture, "black")].astype(np.float64)
    sets = _phase_sets(capture)
    if not sets:
        raise InputError(f"{capture.path or 'capture'}", "phase frames (photometric fit)", None)
    used = [i for s in sets for i in s.indices]
    brightest = np.maximum(frames[used].max(axis=0), white)
    decoded = capture.decode()
    signal = white - black
    lit = signal[decoded.mask]
    if lit.size == 0:
        raise DegenerateData("photometric fit: no decoded pixel in a capture")
    if region is not None:
        region = np.asarray(region)
        if region.dtype != bool or region.shape != signal.shape:
            raise InputError(
                f"region of {capture.path or 'capture'}",
                f"a boolean mask of shape {signal.shape}",
                f"{region.dtype} {region.shape}",
            )
    valid = (
        (decoded.mask if region is None else decoded.mask & region)
        & ~decoded.flagged
        & (brightest < _saturation(capture, sensor))
        & (signal > MIN_SIGNAL_FRACTION * np.percentile(lit, 99))
    )
    points = points_from_decoded(rig, decoded.proj_uv, valid)
    normals = _normals(points)
    valid &= np.isfinite(normals).all(axis=2)
    flat = np.flatnonzero(valid)
    x = points.reshape(-1, 3)[flat]
    n = normals.reshape(-1, 3)[flat]
    x_p = rig.cam2proj.apply(x)
    to_projector = rig.proj2cam.t - x
    distance = np.linalg.norm(to_projector, axis=1)
    cos_i = np.abs(np.sum(n * to_projector, axis=1)) / distance
    geometry = cos_i * np.linalg.norm(x_p, axis=1) / x_p[:, 2] ** 3
    proj = rig.projector.intrinsics
    uv = proj.project(x_p)
    tan2 = ((uv[:, 0] - proj.cx) / proj.fx) ** 2 + ((uv[:, 1] - proj.cy) / proj.fy) ** 2
    cam = rig.camera.intrinsics
    rays = cam.unproject(cam.pixel_grid().reshape(-1, 2)[flat])
    keep = np.isfinite(geometry) & np.isfinite(tan2) & (geometry > 0) & (rays[:, 2] > 0)
    return _View(
        capture=capture,
        pixels=flat[keep],
        white=white.reshape(-1)[flat[keep]],
        black=black.reshape(-1)[flat[keep]],
        geometry=geometry[keep],
        log_cos_camera=np.log(rays[keep, 2]),
        log_cos_projector=-0.5 * np.log1p(tan2[keep]),
    )


# --- response and blur ----------------------------------------------------------------------


def _harmonic_ratios(stack: np.ndarray, signal: np.ndarray | float) -> tuple[np.ndarray, list]:
    """``m1`` and ``[q_2, ...]`` (module docstring) of (N, n) profiles."""
    steps = stack.shape[0]
    spectrum = np.fft.fft(stack, axis=0)
    c1 = spectrum[1]
    size = np.abs(c1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.conj(c1) / size
        m1 = 2.0 * size / steps / signal
        qs = [np.real(spectrum[k] * unit**k) / size for k in _harmonics(steps)]
    return m1, qs


def _harmonics(steps: int) -> range:
    return range(2, min(MAX_HARMONIC, steps // 2) + 1)


def _robust_mean(values: np.ndarray) -> float:
    """Mean of the finite values within 6 robust standard deviations of their median."""
    values = values[np.isfinite(values)]
    median = np.median(values)
    spread = 1.4826 * np.median(np.abs(values - median)) + 1e-12
    return float(np.mean(values[np.abs(values - median) <= 6 * spread]))


def response_harmonics(
    projector: ProjectorModel, sequence: Any, phase_set: PhaseSet
) -> tuple[float, list[float]]:
    """The mean ``m1`` and ``q_k`` (module docstring) of the light ``projector`` emits for a
    phase set, over the projector positions away from the pattern's ends."""
    direction = sequence.frames[phase_set.indices[0]].direction
    length = sequence.span(direction)
    profiles = np.stack([projector.emitted_profile(sequence, i) for i in phase_set.indices], 1)
    table = projector.spread(profiles)
    margin = projector.supersampling * int(np.ceil(3 * projector.psf_sigma_px + 2))
    interior = table[margin : length * projector.supersampling - margin].T
    m1, qs = _harmonic_ratios(interior, 1.0 - projector.black)
    return float(np.mean(m1)), [float(np.mean(q)) for q in qs]


def _measured_harmonics(views: list[_View]) -> list[dict[str, Any]]:
    """Per phase set: the measured mean ``m1`` and ``q_k`` (captures of one sequence pooled,
    weighted by their pixels)."""
    out: list[dict[str, Any]] = []
    for view in views:
        frames = view.capture.frames.reshape(len(view.capture.sequence), -1)
        signal = view.white - view.black
        for phase_set in _phase_sets(view.capture):
            stack = frames[list(phase_set.indices)][:, view.pixels].astype(np.float64)
            m1, qs = _harmonic_ratios(stack, signal)
            frame = view.capture.sequence.frames[phase_set.indices[0]]
            item = {
                "sequence": view.capture.sequence,
                "set": phase_set,
                "direction": frame.direction,
                "period": float(frame.period),
                "steps": int(frame.steps),
                "m1": _robust_mean(m1),
                "q": [_robust_mean(q) for q in qs],
                "pixels": int(view.pixels.size),
            }
            same = [o for o in out if o["set"] == phase_set and o["sequence"] == item["sequence"]]
            if not same:
                out.append(item)
                continue
            pooled, total = same[0], same[0]["pixels"] + item["pixels"]
            share = item["pixels"] / total
            pooled["m1"] += share * (item["m1"] - pooled["m1"])
            pooled["q"] = [a + share * (b - a) for a, b in zip(pooled["q"], item["q"], strict=True)]
            pooled["pixels"] = total
    return out


def _response_model(prior: ProjectorModel, gamma: float, sigma: float) -> ProjectorModel:
    return prior.with_(
        pixel=Lookup.psf,
        gamma=float(gamma),
        psf_sigma_px=float(sigma),
        response_lut=None,
        precompensate=False,
    )


def _fit_response(views: list[_View], prior: ProjectorModel) -> tuple[ProjectorModel, dict]:
    """Gamma and blur from the harmonics of every phase set (module docstring)."""
    from scipy.optimize import least_squares

    measured = _measured_harmonics(views)
    if not any(item["q"] for item in measured):
        raise DegenerateData(
            "photometric fit: gamma needs a phase set of N >= 4 steps (N = 3 has no "
            "harmonic but the fundamental)"
        )

    # Patterns of two levels (square waves, codes) send only 0 and 255: g(0) and g(1) are
    # the same for every gamma, which is then neither observable nor needed; blur alone.
    binary = all(
        np.isin(np.asarray(item["sequence"].profile(i), dtype=np.float64), (0.0, 1.0)).all()
        for item in measured
        for i in item["set"].indices
    )

    def parameters(x: np.ndarray) -> tuple[float, float]:
        return (prior.gamma, x[0]) if binary else (x[0], x[1])

    def residuals(x: np.ndarray) -> np.ndarray:
        model = _response_model(prior, *parameters(x))
        out = []
        for item in measured:
            m1, qs = response_harmonics(model, item["sequence"], item["set"])
            out.append(m1 / item["m1"] - 1.0)
            out += [
                (q - q_data) / max(abs(q_data), 0.01)
                for q, q_data in zip(qs, item["q"], strict=True)
            ]
        return np.asarray(out)

    starts = [(2.0, 0.5), (1.0, 0.5), (2.5, 2.0)]
    low, high = [0.2, 0.0], [6.0, 20.0]
    if binary:
        starts, low, high = [(0.5,), (2.0,)], low[1:], high[1:]
    best = min(
        (least_squares(residuals, start, bounds=(low, high), diff_step=1e-4) for start in starts),
        key=lambda result: result.cost,
    )
    gamma, sigma = (float(v) for v in parameters(best.x))
    model = _response_model(prior, gamma, sigma)
    report = {
        "gamma": gamma,
        "gamma_observable": not binary,
        "psf_sigma_px": sigma,
        "fill_factor": prior.fill_factor,
        "rms_relative_residual": float(np.sqrt(np.mean(best.fun**2))),
        "sets": [
            {
                "direction": item["direction"],
                "period": item["period"],
                "steps": item["steps"],
                "m1": item["m1"],
                "q": item["q"],
                "m1_model": response_harmonics(model, item["sequence"], item["set"])[0],
                "q_model": response_harmonics(model, item["sequence"], item["set"])[1],
            }
            for item in measured
        ],
    }
    return model, report


# --- vignetting, fall-off, exposure, ambient ---------------------------------------------------


def _robust_lstsq(design: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least squares with Huber then Tukey weights: coefficients, covariance, residual
    scale (robust: a board's dark features or a stray reflection do not pull the fit)."""
    weights = np.ones(target.size)
    scale = 1.0
    for iteration in range(12):
        root = np.sqrt(weights)
        coef = np.linalg.lstsq(design * root[:, None], target * root, rcond=None)[0]
        residual = target - design @ coef
        scale = 1.4826 * float(np.median(np.abs(residual - np.median(residual)))) + 1e-12
        u = residual / scale
        if iteration < 6:
            weights = np.minimum(1.0, 1.345 / np.maximum(np.abs(u), 1e-12))
        else:
            weights = np.where(np.abs(u) < 4.685, (1.0 - (u / 4.685) ** 2) ** 2, 0.0)
    normal = (design * weights[:, None]).T @ design
    kept = max(float(np.sum(weights > 0)) - design.shape[1], 1.0)
    variance = float(np.sum(weights * residual**2)) / kept
    return coef, variance * np.linalg.pinv(normal), scale


def _fit_shading(views: list[_View]) -> dict[str, Any]:
    """Camera vignetting and projector fall-off exponents, and ``log C`` per capture."""
    target = np.concatenate([np.log(v.white - v.black) - np.log(v.geometry) for v in views])
    count = len(views)
    dummies = np.zeros((target.size, count))
    start = 0
    for j, view in enumerate(views):
        dummies[start : start + view.pixels.size, j] = 1.0
        start += view.pixels.size
    camera = np.concatenate([v.log_cos_camera for v in views])
    projector = np.concatenate([v.log_cos_projector for v in views])
    coef, cov, scale = _robust_lstsq(np.column_stack([dummies, camera, projector]), target)
    errors = np.sqrt(np.diag(cov))[count:]
    # Correlation of the two regressors once each capture's mean is removed.
    centred = [
        x - dummies @ np.linalg.lstsq(dummies, x, rcond=None)[0] for x in (camera, projector)
    ]
    correlation = float(abs(np.corrcoef(centred[0], centred[1])[0, 1]))
    # A lens (and a light engine) darkens toward its field's edge: a negative exponent is
    # the two regressors trading off against each other (one flat pose), not a lens.
    separable = (
        correlation < SEPARABLE_MAX_CORRELATION
        and errors.max() < SEPARABLE_MAX_STDERR
        and min(coef[count], coef[count + 1]) >= 0.0
    )
    report: dict[str, Any] = {
        "separable": bool(separable),
        "regressor_correlation": correlation,
        "residual_scale": scale,
    }
    if separable:
        n_camera, n_projector = float(coef[count]), float(coef[count + 1])
        report.update(camera_exponent_stderr=float(errors[0]))
        report.update(projector_exponent_stderr=float(errors[1]))
    else:
        coef, cov, scale = _robust_lstsq(np.column_stack([dummies, camera + projector]), target)
        n_camera = n_projector = float(coef[count])
        report.update(product_exponent_stderr=float(np.sqrt(cov[count, count])))
        report["note"] = (
            "camera vignetting and projector fall-off cannot be told apart from these "
            "captures (capture planes at several distances and tilts): one exponent of their "
            "product is fitted and given to both"
        )
    report.update(
        camera_exponent=n_camera,
        projector_exponent=n_projector,
        log_scale=[float(c) for c in coef[:count]],
        camera_cos_min=float(np.exp(camera.min())),
        projector_cos_min=float(np.exp(projector.min())),
    )
    return report


def _stored_exponent(exponent: float) -> float | None:
    """The ``cos`` model's exponent for a fitted one (rounded, capped), None for ``none``."""
    stored = round(min(exponent, MAX_COS_EXPONENT), EXPONENT_DECIMALS)
    return stored if stored > 0 else None


def _rounding_error(exponent: float, cos_min: float) -> float:
    """Relative error at the field's edge of storing ``exponent`` as the model does."""
    stored = _stored_exponent(exponent) or 0.0
    return float(cos_min ** (stored - exponent) - 1.0)


def _shading_models(shading: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The sensor's and the projector's fall-off settings for the fitted exponents."""
    camera = _stored_exponent(shading["camera_exponent"])
    projector = _stored_exponent(shading["projector_exponent"])
    return (
        {"vignetting": "none" if camera is None else "cos", "vignetting_exponent": camera},
        {"falloff": "none" if projector is None else "cos", "falloff_exponent": projector},
    )


def _fit_ambient(
    views: list[_View], projector_exponent: float, black: float, offset: float
) -> dict[str, Any]:
    """Ambient level per capture: the black frame over the projector's black level."""
    levels = []
    for view in views:
        white_per_albedo = view.geometry * np.exp(projector_exponent * view.log_cos_projector)
        ratio = (view.black - offset) / (view.white - view.black)
        # A mean, not a median: the black frame holds few DN, and the median of rounded
        # values sticks to whole DN where the mean keeps the noise's dither.
        levels.append(_robust_mean(white_per_albedo * (ratio * (1.0 - black) - black)))
    return {
        "level": float(max(np.median(levels), 0.0)),
        "per_capture": levels,
        "projector_black": black,
        "camera_offset_dn": offset,
    }


# --- temporal noise and gain ---------------------------------------------------------------

#: Harmonics of the model's frame vectors E(phi) (a series in the pixel's phase).
_SERIES_ORDER = 8


def _series(phase: np.ndarray, derivative: bool = False) -> np.ndarray:
    """(n, 2K + 1) Fourier basis (or its derivative) of the phase."""
    columns = [np.zeros_like(phase) if derivative else np.ones_like(phase)]
    for k in range(1, _SERIES_ORDER + 1):
        if derivative:
            columns += [-k * np.sin(k * phase), k * np.cos(k * phase)]
        else:
            columns += [np.cos(k * phase), np.sin(k * phase)]
    return np.stack(columns, axis=1)


def _model_series(projector: ProjectorModel, sequence: Any, phase_set: PhaseSet) -> np.ndarray:
    """(2K + 1, N) coefficients of the emitted frame vector as a series in its phase."""
    direction = sequence.frames[phase_set.indices[0]].direction
    length = sequence.span(direction)
    profiles = np.stack([projector.emitted_profile(sequence, i) for i in phase_set.indices], 1)
    table = projector.spread(profiles)
    margin = projector.supersampling * int(np.ceil(3 * projector.psf_sigma_px + 2))
    interior = table[margin : length * projector.supersampling - margin]
    basis = _series(np.angle(np.fft.fft(interior, axis=1)[:, 1]))
    return np.linalg.solve(basis.T @ basis, basis.T @ interior)


def _frame_residuals(stack: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Per pixel and frame of (N, n) frames: the squared residual ``r_n^2`` after the fit
    ``a + s E(phi) + t E'(phi)``, and what its expectation sees, ``sum_m Q_nm^2 I_m`` and
    ``sum_m Q_nm^2`` (``Q = 1 - H``, ``H`` the fit's hat matrix, so ``E[r_n^2] = sum_m
    Q_nm^2 sigma_m^2``: a frame the fit follows closely, as a bright gamma peak, shows less
    of its noise). Returns (3, n * N)."""
    out = []
    steps = stack.shape[0]
    for start in range(0, stack.shape[1], _NOISE_CHUNK):
        block = stack[:, start : start + _NOISE_CHUNK]
        phase = np.angle(np.fft.fft(block, axis=0)[1])
        model = _series(phase) @ coef  # (n, N)
        slope = _series(phase, derivative=True) @ coef
        design = np.stack([np.ones_like(model), model, slope], axis=2)  # (n, N, 3)
        inverse = np.linalg.inv(np.swapaxes(design, 1, 2) @ design + 1e-12 * np.eye(3))
        q = np.eye(steps) - (design @ inverse) @ np.swapaxes(design, 1, 2)
        values = block.T[:, :, None]
        residual = (q @ values)[..., 0]
        share = q**2
        out.append(np.stack([residual**2, (share @ values)[..., 0], share.sum(axis=2)]))
    return np.concatenate([item.reshape(3, -1) for item in out], axis=1)


def _photon_transfer(samples: np.ndarray) -> tuple[float, float]:
    """``K`` and ``c`` of ``E[r^2] = K sum Q^2 I + c sum Q^2`` (weighted least squares,
    weights from the fitted variance: ``var(r^2) = 2 E[r^2]^2``)."""
    squares, level, share = samples
    keep = share > 1e-6
    squares, level, share = squares[keep], level[keep], share[keep]
    design = np.column_stack([level, share])
    expected = np.full(squares.size, float(np.mean(squares)))
    coef = np.zeros(2)
    for _ in range(4):
        weight = np.where(squares <= 30.0 * expected, 1.0 / expected**2, 0.0)
        weighted = design * weight[:, None]
        coef = np.linalg.solve(weighted.T @ design, weighted.T @ squares)
        expected = np.maximum(design @ coef, 1e-3 * float(np.mean(squares)))
    return float(coef[0]), float(coef[1])


def _transfer_curve(samples: np.ndarray) -> list[dict[str, float]]:
    """The photon transfer curve for the report: variance against level in quantile bins."""
    squares, level, share = samples
    keep = share > 0.05
    level, variance = level[keep] / share[keep], squares[keep] / share[keep]
    edges = np.quantile(level, np.linspace(0.0, 1.0, PTC_BINS + 1))
    which = np.clip(np.searchsorted(edges, level, side="right") - 1, 0, PTC_BINS - 1)
    return [
        {
            "level_dn": float(level[which == b].mean()),
            "variance_dn2": float(variance[which == b].mean()),
            "samples": int(np.sum(which == b)),
        }
        for b in range(PTC_BINS)
        if np.any(which == b)
    ]


def _fit_noise(views: list[_View], projector: ProjectorModel, offset: float) -> dict[str, Any]:
    """System gain and dark noise from the N-step residuals (module docstring)."""
    samples = []
    for view in views:
        frames = view.capture.frames.reshape(len(view.capture.sequence), -1)
        step = max(1, int(np.ceil(view.pixels.size / NOISE_MAX_PIXELS)))
        pixels = view.pixels[::step]
        for phase_set in _phase_sets(view.capture):
            if len(phase_set.indices) < 4:
                continue
            coef = _model_series(projector, view.capture.sequence, phase_set)
            stack = frames[list(phase_set.indices)][:, pixels].astype(np.float64)
            samples.append(_frame_residuals(stack, coef))
    if not samples:
        raise DegenerateData("photometric fit: the noise needs a phase set of N >= 4 steps")
    pooled = np.concatenate(samples, axis=1)
    gain, intercept = _photon_transfer(pooled)
    # intercept = K^2 sigma_d^2 + 1/12 - K mu_dark (mu_dark: the camera's black level)
    dark = (intercept + gain * offset - 1.0 / 12.0) / gain**2 if gain > 0 else 0.0
    curve = _transfer_curve(pooled)
    return {
        "system_gain_dn_per_e": gain,
        "intercept_dn2": intercept,
        "dark_noise_e": float(np.sqrt(max(dark, 0.0))),
        "level_range_dn": [curve[0]["level_dn"], curve[-1]["level_dn"]],
        "photon_transfer": curve,
    }


# --- the fit ---------------------------------------------------------------------------------


def fit_photometry(
    captures: list[Capture],
    rig: Rig | None = None,
    *,
    prior_sensor: Sensor | None = None,
    prior_projector: ProjectorModel | None = None,
    albedo: float = 1.0,
    regions: list[np.ndarray | None] | None = None,
) -> PhotometricFit:
    """Fit the twin's camera and projector models to real captures (module docstring).

    Parameters
    ----------
    captures : captures of one rig, each with phase frames (N >= 4 for gamma and noise) and
        white and black frames, at one bit depth.
    rig : the (calibrated) rig to triangulate with (default: each capture's own).
    prior_sensor : what is known of the camera and not fitted: its black level (DN), PRNU,
        DSNU, full well, quantum efficiency (default: an ideal sensor of the captures' bit
        depth).
    prior_projector : what is known of the projector and not fitted: its contrast ratio
        (the black level the ambient light is measured above) and fill factor (default:
        infinite contrast, fill factor 1).
    albedo : diffuse albedo of the captured surface where it is lit (sets the exposure).
    regions : per capture, None or an (H, W) bool mask of the pixels showing a surface of
        that one albedo (a board's white circles, say, eroded off their edges): the fit
        assumes a uniform albedo and uses only these pixels.

    Raises
    ------
    InputError : a capture without white, black or phase frames, or of another bit depth.
    DegenerateData : too few valid pixels, or only 3-step phase sets.
    """
    if not captures:
        raise InputError("captures", "at least one capture", "none")
    depths = {int(c.bit_depth) for c in captures}  # type: ignore[arg-type]
    if len(depths) != 1:
        raise InputError("captures", "captures of one bit depth", sorted(depths))
    sensor = prior_sensor or Sensor(bit_depth=depths.pop())
    sensor = sensor.with_(bit_depth=int(captures[0].bit_depth))  # type: ignore[arg-type]
    prior = prior_projector or ProjectorModel()
    if regions is not None and len(regions) != len(captures):
        expected = f"one mask (or None) per capture ({len(captures)})"
        raise InputError("regions", expected, len(regions))
    masks = regions if regions is not None else [None] * len(captures)
    views = [
        _view(capture, rig or capture.rig, sensor, region)
        for capture, region in zip(captures, masks, strict=True)
    ]
    if sum(v.pixels.size for v in views) < 100:
        raise DegenerateData("photometric fit: fewer than 100 valid pixels in the captures")
    projector, response = _fit_response(views, prior)
    shading = _fit_shading(views)
    offset = sensor.black_level_dn
    ambient = _fit_ambient(views, shading["projector_exponent"], projector.black, offset)
    noise = _fit_noise(views, projector, offset)
    exposures = np.exp(shading["log_scale"]) / (albedo * (1.0 - projector.black))
    shading.update(
        exposure_per_capture=exposures.tolist(),
        camera_stored=_stored_exponent(shading["camera_exponent"]),
        projector_stored=_stored_exponent(shading["projector_exponent"]),
        camera_edge_error=_rounding_error(shading["camera_exponent"], shading["camera_cos_min"]),
        projector_edge_error=_rounding_error(
            shading["projector_exponent"], shading["projector_cos_min"]
        ),
    )
    vignetting, falloff = _shading_models(shading)
    notes = []
    if not response["gamma_observable"]:
        notes.append(
            "the phase frames have two levels (square waves): gamma is not observable and "
            f"not needed, the prior's {projector.gamma:g} is kept"
        )
    if noise["system_gain_dn_per_e"] <= 0:
        notes.append("no photon transfer slope: the prior sensor's noise is kept")
        gain, dark_noise = sensor.system_gain_dn_per_e, sensor.dark_noise_e
    else:
        gain, dark_noise = noise["system_gain_dn_per_e"], noise["dark_noise_e"]
    fitted_sensor = sensor.with_(
        exposure=float(np.median(exposures)),
        system_gain_dn_per_e=gain,
        dark_noise_e=dark_noise,
        dark_current_e_per_s=0.0,
        **vignetting,
        name="fitted",
    )
    fitted_projector = projector.with_(**falloff, name="fitted")
    report = {
        "response": response,
        "shading": shading,
        "ambient_fit": ambient,
        "noise": noise,
        "pixels": [int(v.pixels.size) for v in views],
        "albedo": albedo,
        "notes": notes + ([shading["note"]] if "note" in shading else []),
    }
    return PhotometricFit(fitted_sensor, fitted_projector, ambient["level"], report)


def frame_differences(real: Capture, twin: Capture, mask: np.ndarray) -> dict[str, float]:
    """RMS differences of normalised frames, real minus twin, over ``mask`` (H, W): every
    frame divided by its capture's mean white frame over the mask; per kind of frame
    (``white``, ``black``, ``fringe`` = phase frames, ``code`` = Gray/binary frames and
    complements), NaN for a kind the sequence lacks."""
    kinds = [frame.kind for frame in real.sequence.frames]
    groups = {
        "white": ("white",),
        "black": ("black",),
        "fringe": ("phase",),
        "code": ("gray", "binary", "gray_complement", "binary_complement"),
    }
    white = kinds.index("white") if "white" in kinds else None
    if white is None or not np.any(mask):
        return {f"{name}_rms": float("nan") for name in groups}
    scale_real = float(real.frames[white][mask].mean())
    scale_twin = float(twin.frames[white][mask].mean())
    out = {}
    for name, members in groups.items():
        index = [i for i, kind in enumerate(kinds) if kind in members]
        if not index:
            out[f"{name}_rms"] = float("nan")
            continue
        a = real.frames[index][:, mask].astype(np.float64) / scale_real
        b = twin.frames[index][:, mask].astype(np.float64) / scale_twin
        out[f"{name}_rms"] = float(np.sqrt(np.mean((a - b) ** 2)))
    return out
