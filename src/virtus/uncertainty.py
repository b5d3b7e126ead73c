"""Predicted per-pixel uncertainty of a fringe projection scan, without rendering noise.

The chain, one function per link (DESIGN.md §9 and §12):

1. **Intensity noise** (:func:`intensity_variance`): the EMVA 1288 linear model of the
   camera (:class:`virtus.sensor.camera.Sensor`) at the pixel's noise-free signal ``mu``
   (DN above the black level): ``sigma_I^2 = K mu + K^2 (sigma_d^2 + I_dark t_exp) + 1/12``
   DN^2 (photon shot noise, dark noise and the dark current's shot noise, quantisation).
   PRNU and DSNU are fixed patterns -- the same in every capture -- so they add no temporal
   noise (they move a pixel's signal by a fixed fraction, a bias the model neglects).
2. **Phase noise** (:func:`phase_sigma`): the least-squares N-step phase
   ``phi = atan2(-S, C)``, ``S = sum I_n sin d_n``, ``C = sum I_n cos d_n``,
   ``d_n = 2 pi n / N`` (:func:`virtus.patterns.phase.wrapped_phase`), to first order:
   ``sigma_phi^2 = sum_n (dphi/dI_n)^2 sigma_n^2`` with
   ``dphi/dI_n = (S cos d_n - C sin d_n) / (S^2 + C^2)``, evaluated on the noise-free
   frames and each frame's own ``sigma_n`` (shot noise differs between the steps). For
   ``I_n = A + B cos(phi + d_n)`` and one ``sigma_I`` this is Surrel's
   ``sigma_phi = sqrt(2 / N) sigma_I / B`` (:func:`phase_sigma_from_levels`). Whatever the
   frames hold -- the projector's gamma and black level, its pixel shape and blur, the
   camera pixel's footprint, ambient light -- is in ``A`` and ``B`` (and so in the answer)
   when the frames come from a ground-truth pass (:mod:`virtus.design.modulation`); for a
   given albedo or white-level map :func:`fringe_levels` gives the fraction of the white
   light that becomes ``A`` and ``B`` for a projector model.
3. **Projector coordinate** (:func:`coordinate_sigma`): ``sigma_u = sigma_phi T / (2 pi)``
   projector px for the finest period ``T`` (the coordinate is that period's unwrapped
   phase; the code or the coarser periods only pick the order and, when they pick it
   right, add no noise).
4. **Point** (:func:`point_jacobian`, :func:`point_covariance`): ``Sigma_X = J Sigma_u J^T``
   with ``J = dX / d(u_p, v_p)`` of the project's own triangulation
   (:func:`virtus.reconstruct.triangulate`, central differences: both devices' distortion
   included); the depth's sigma is ``sqrt(Sigma_zz)`` (camera-frame z, what depth maps
   hold), the range's along the camera ray ``sqrt(a^T Sigma a)``.

:func:`predict_uncertainty` runs the chain on whole maps into a :class:`Prediction`.

Conventions: maps indexed ``[row, col]``; signals in digital numbers (DN) above the black
level; phases in radians; projector coordinates in projector px; points in metres in the
camera frame. Pixels the model cannot answer for (no signal, saturated, no modulation,
not triangulated) are NaN and False in the mask; nothing is clamped.

This module is numpy only and never imports the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.patterns import PatternSequence
from virtus.reconstruct import DEFAULT_MIN_MODULATION, Use, as_use, triangulate
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import ProjectorModel

__all__ = [
    "JACOBIAN_STEP_PX",
    "QUANTISATION_VARIANCE_DN2",
    "Prediction",
    "coordinate_sigma",
    "finest_phase_set",
    "fringe_levels",
    "intensity_variance",
    "phase_sigma",
    "phase_sigma_from_levels",
    "point_covariance",
    "point_jacobian",
    "predict_uncertainty",
    "summarize",
]

#: Variance of rounding to whole digital numbers, DN^2 (a uniform error of one DN width).
QUANTISATION_VARIANCE_DN2 = 1.0 / 12.0
#: Central-difference step of the triangulation Jacobian, projector px: the relative error
#: is ~(h / d)^2 for a disparity of d px (depth ~ 1 / d), below 1e-6 from d = 50 px.
JACOBIAN_STEP_PX = 0.05


def intensity_variance(sensor: Sensor, signal_dn: Any) -> np.ndarray:
    """Temporal variance (DN^2) of a pixel whose noise-free signal is ``signal_dn``.

    Parameters
    ----------
    sensor : the camera model.
    signal_dn : (...) float, noise-free signal in DN above the black level
        (``exposure x radiance``).

    Returns
    -------
    (...) float64 variance in DN^2: ``K mu + K^2 (sigma_d^2 + I_dark t_exp) + 1/12`` for an
    EMVA sensor. A noise-free (ideal) sensor has only the rounding, ``1/12``: there it is
    not a temporal noise (the same in every capture) but the spread over pixels of a
    rounding error that is uncorrelated between them.
    """
    signal = np.asarray(signal_dn, dtype=np.float64)
    if not sensor.noisy:
        return np.full(signal.shape, QUANTISATION_VARIANCE_DN2)
    gain = float(sensor.system_gain_dn_per_e)  # type: ignore[arg-type]
    dark_e2 = sensor.dark_noise_e**2 + sensor.dark_current_e_per_s * sensor.exposure_time_s
    return gain * np.maximum(signal, 0.0) + gain**2 * dark_e2 + QUANTISATION_VARIANCE_DN2


def _check_frames(frames_dn: Any) -> np.ndarray:
    frames = np.asarray(frames_dn, dtype=np.float64)
    if frames.ndim < 1 or frames.shape[0] < 3:
        raise InputError("frames_dn", "an array of shape (N, ...) with N >= 3", frames.shape)
    return frames


def phase_sigma(frames_dn: Any, sensor: Sensor, min_modulation_dn: float = 0.0) -> np.ndarray:
    """Standard deviation (rad) of the least-squares N-step phase of noise-free frames.

    Parameters
    ----------
    frames_dn : (N, ...) float, the noise-free signals (DN above the black level) of one
        phase set's steps 1..N, in order (``I_n = A + B cos(phi + 2 pi n / N)``).
    sensor : the camera model (:func:`intensity_variance`).
    min_modulation_dn : pixels whose modulation ``B`` is below this are not decoded (the
        decoder's ``min_modulation`` times the full scale); a ``B`` within float rounding
        of zero never is.

    Returns
    -------
    (...) float64 radians; NaN where the frames have too little modulation or a step
    reaches the sensor's saturation (its phase is clipped, not noisy).
    """
    frames = _check_frames(frames_dn)
    steps = frames.shape[0]
    shifts = 2.0 * np.pi * np.arange(1, steps + 1) / steps
    cos, sin = np.cos(shifts), np.sin(shifts)
    flat = frames.reshape(steps, -1)
    c = cos @ flat
    s = sin @ flat
    power = s * s + c * c
    variance = intensity_variance(sensor, flat)
    with np.errstate(invalid="ignore", divide="ignore"):
        derivative = (s[None] * cos[:, None] - c[None] * sin[:, None]) / power[None]
        sigma = np.sqrt(np.sum(derivative**2 * variance, axis=0))
    saturated = (flat + sensor.black_level_dn >= sensor.saturation_dn).any(axis=0)
    modulation = 2.0 / steps * np.sqrt(power)
    floor = np.maximum(min_modulation_dn, 1e-9 * (np.abs(flat).mean(axis=0) + 1.0))
    sigma[saturated | ~(modulation >= floor)] = np.nan
    return sigma.reshape(frames.shape[1:])


def phase_sigma_from_levels(
    mean_dn: Any, modulation_dn: Any, steps: int, sensor: Sensor
) -> np.ndarray:
    """Surrel's ``sqrt(2 / N) sigma_I(A) / B`` (rad): :func:`phase_sigma` averaged over the
    phase, for maps of the background ``A`` and modulation ``B`` (DN above the black level);
    NaN where ``B <= 0`` or ``A + B`` reaches saturation."""
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 3:
        raise InputError("steps", "an integer >= 3", steps)
    mean = np.asarray(mean_dn, dtype=np.float64)
    modulation = np.asarray(modulation_dn, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.sqrt(2.0 / steps * intensity_variance(sensor, mean)) / modulation
    bad = ~(modulation > 0) | (mean + modulation + sensor.black_level_dn >= sensor.saturation_dn)
    return np.where(bad, np.nan, sigma)


def coordinate_sigma(sigma_phase: Any, period_px: float) -> np.ndarray:
    """``sigma_u = sigma_phi T / (2 pi)``: projector px of a phase sigma (rad) at period
    ``period_px`` (projector px)."""
    if not (isinstance(period_px, int | float | np.number) and period_px > 0):
        raise InputError("period_px", "a period > 0 (projector px)", period_px)
    return np.asarray(sigma_phase, dtype=np.float64) * float(period_px) / (2.0 * np.pi)


def finest_phase_set(sequence: PatternSequence, direction: str) -> tuple[tuple[int, ...], float]:
    """The frame indices (steps 1..N) and period (projector px) of the phase set that gives
    ``direction``'s decoded coordinate: its finest period. :class:`InputError` when the
    direction has no phase frames (a code alone: its noise is not a phase's)."""
    plan = sequence.plan(direction)
    if plan is None or not plan.sets:
        raise InputError(
            "sequence", f"phase frames in direction {direction!r} to predict its noise", "none"
        )
    finest = plan.sets[0]
    return finest.indices, finest.coding.period / sequence.axis_scale(direction)


def fringe_levels(
    projector: ProjectorModel, sequence: PatternSequence, direction: str
) -> tuple[float, float]:
    """``(c0, c1)``: the background ``A`` and modulation ``B`` of ``direction``'s finest
    phase set as fractions of the light of a full-on projector pixel (so ``A = c0 W`` and
    ``B = c1 W`` for a white-level map ``W``, plus any ambient light in ``A``).

    Fitted over the emitted profiles the renderer uses (8-bit pattern values, response and
    pre-compensation, black level, the ``psf`` pixel model's fill factor and blur): an ideal
    projector gives (0.5, 0.5); gamma without pre-compensation and blur lower ``c1`` (blur
    by ``exp(-2 pi^2 sigma^2 / T^2)``, DESIGN.md §9).
    """
    indices, _ = finest_phase_set(sequence, direction)
    profiles = np.stack([projector.emitted_profile(sequence, i) for i in indices], axis=1)
    table = np.asarray(projector.spread(profiles), dtype=np.float64)
    steps = len(indices)
    shifts = 2.0 * np.pi * np.arange(1, steps + 1) / steps
    mean = table.mean(axis=1)
    modulation = 2.0 / steps * np.hypot(table @ np.cos(shifts), table @ np.sin(shifts))
    # The outer pixels see the profile's clamped edge: the medians describe the interior.
    return float(np.median(mean)), float(np.median(modulation))


def point_jacobian(
    rig: Rig,
    cam_px: Any,
    proj_uv: Any,
    use: Use | str = Use.uv,
    step_px: float = JACOBIAN_STEP_PX,
) -> np.ndarray:
    """``dX / d(u_p, v_p)`` of :func:`virtus.reconstruct.triangulate` by central differences.

    Parameters
    ----------
    rig : the rig that triangulates.
    cam_px : (P, 2) float camera pixel coordinates ``(u, v)``.
    proj_uv : (P, 2) float projector coordinates ``(u_p, v_p)`` at those pixels.
    use : which coordinates constrain the point (the column of an unused one is 0).
    step_px : difference step, projector px.

    Returns
    -------
    (P, 3, 2) float64, metres per projector px, camera frame; NaN where a point is not
    triangulated.
    """
    use = as_use(use)
    cam = np.asarray(cam_px, dtype=np.float64).reshape(-1, 2)
    base = np.asarray(proj_uv, dtype=np.float64).reshape(-1, 2)
    jacobian = np.zeros((cam.shape[0], 3, 2))
    for axis, name in ((0, Use.u), (1, Use.v)):
        if use not in (Use.uv, name):
            continue
        plus, minus = base.copy(), base.copy()
        plus[:, axis] += step_px
        minus[:, axis] -= step_px
        jacobian[:, :, axis] = (
            triangulate(rig, cam, plus, use) - triangulate(rig, cam, minus, use)
        ) / (2.0 * step_px)
    return jacobian


def point_covariance(jacobian: np.ndarray, sigma_uv: np.ndarray) -> np.ndarray:
    """``J diag(sigma_u^2, sigma_v^2) J^T``: (P, 3, 3) m^2 from (P, 3, 2) ``jacobian`` and
    (P, 2) ``sigma_uv`` (projector px; the decoded ``u_p`` and ``v_p`` come from different
    frames, so their noise is independent). An unused coordinate's sigma may be NaN."""
    sigma = np.nan_to_num(np.asarray(sigma_uv, dtype=np.float64), nan=0.0)
    unused = ~np.any(jacobian != 0, axis=1)  # (P, 2): columns of coordinates not used
    missing = ~np.isfinite(np.asarray(sigma_uv)) & ~unused
    scaled = jacobian * sigma[:, None, :]
    covariance = scaled @ scaled.transpose(0, 2, 1)
    covariance[missing.any(axis=1)] = np.nan
    return covariance


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted per-pixel standard deviations of one pose (NaN where not predicted).

    Attributes
    ----------
    sigma_u_p, sigma_v_p : (H, W) float64 projector px, of the decoded coordinates (NaN
        for a direction the sequence does not code).
    sigma_phase_v, sigma_phase_h : (H, W) float64 radians, of the finest phase.
    sigma_depth : (H, W) float64 metres, of the camera-frame z of the point.
    sigma_range : (H, W) float64 metres, along the camera ray.
    sigma_point : (H, W) float64 metres, ``sqrt(trace Sigma_X)``.
    covariance : (H, W, 3, 3) float64 m^2, camera frame.
    mask : (H, W) bool, pixels with a predicted depth sigma.
    """

    sigma_u_p: np.ndarray
    sigma_v_p: np.ndarray
    sigma_phase_v: np.ndarray
    sigma_phase_h: np.ndarray
    sigma_depth: np.ndarray
    sigma_range: np.ndarray
    sigma_point: np.ndarray
    covariance: np.ndarray
    mask: np.ndarray

    #: The maps :meth:`maps` returns (and a predict run writes as ``NAME.npy``).
    MAP_NAMES = ("sigma_u_p", "sigma_v_p", "sigma_depth", "sigma_range", "sigma_point")

    def maps(self) -> dict[str, np.ndarray]:
        """The per-pixel sigma maps by name (:attr:`MAP_NAMES`)."""
        return {name: getattr(self, name) for name in self.MAP_NAMES}

    def summary(self) -> dict[str, Any]:
        """Median and 95th percentile of each map over its finite pixels, in human units:
        ``*_px`` projector px, ``*_um`` micrometres; and the count of predicted pixels."""
        out: dict[str, Any] = {"pixels": int(self.mask.sum())}
        for name, scale, unit in (
            ("sigma_u_p", 1.0, "px"), ("sigma_v_p", 1.0, "px"), ("sigma_depth", 1e6, "um"),
            ("sigma_range", 1e6, "um"), ("sigma_point", 1e6, "um"),
        ):  # fmt: skip
            out.update(summarize(getattr(self, name) * scale, f"{name}_{unit}"))
        return out


def summarize(values: np.ndarray, name: str) -> dict[str, float | None]:
    """``{name_median, name_p95}`` over the finite entries of ``values`` (None if none)."""
    finite = np.asarray(values)[np.isfinite(values)]
    if finite.size == 0:
        return {f"{name}_median": None, f"{name}_p95": None}
    median, p95 = np.percentile(finite, [50.0, 95.0])
    return {f"{name}_median": float(median), f"{name}_p95": float(p95)}


def predict_uncertainty(
    rig: Rig,
    sequence: PatternSequence,
    sensor: Sensor,
    phase_frames_dn: dict[str, np.ndarray],
    proj_uv: np.ndarray,
    mask: np.ndarray,
    use: Use | str = Use.uv,
    min_modulation: float = DEFAULT_MIN_MODULATION,
) -> Prediction:
    """The whole chain on maps (module docstring).

    Parameters
    ----------
    rig : the rig that triangulates (true or calibrated).
    sequence : the projected patterns (which phase sets decode each direction).
    sensor : the camera model.
    phase_frames_dn : direction (``"v"``, ``"h"``) -> (N, H, W) noise-free signals (DN
        above the black level) of that direction's finest phase set
        (:func:`finest_phase_set`), e.g. from :func:`virtus.design.modulation.signal_pass`.
    proj_uv : (H, W, 2) float64 true projector coordinates ``(u_p, v_p)`` of each pixel.
    mask : (H, W) bool, pixels that see a lit surface.
    use : which decoded coordinates triangulate (:func:`virtus.reconstruct.triangulate`);
        a coordinate ``use`` needs must be in ``phase_frames_dn``.
    min_modulation : the decoder's threshold, a fraction of full scale: pixels below it
        are not decoded, so not predicted.
    """
    use = as_use(use)
    proj_uv = np.asarray(proj_uv, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool)
    height, width = mask.shape
    if proj_uv.shape != (height, width, 2):
        raise InputError("proj_uv", f"shape ({height}, {width}, 2)", proj_uv.shape)
    sigma_phase = {d: np.full((height, width), np.nan) for d in ("v", "h")}
    sigma_coord = {d: np.full((height, width), np.nan) for d in ("v", "h")}
    for direction, frames in phase_frames_dn.items():
        indices, period = finest_phase_set(sequence, direction)
        frames = _check_frames(frames)
        if frames.shape != (len(indices), height, width):
            raise InputError(
                f"phase_frames_dn[{direction!r}]", f"shape ({len(indices)}, {height}, {width})",
                frames.shape,
            )  # fmt: skip
        sigma = phase_sigma(frames, sensor, min_modulation * sensor.full_scale)
        sigma_phase[direction] = np.where(mask, sigma, np.nan)
        sigma_coord[direction] = coordinate_sigma(sigma_phase[direction], period)
    needed = {Use.uv: ("v", "h"), Use.u: ("v",), Use.v: ("h",)}[use]
    for direction in needed:
        if direction not in phase_frames_dn:
            raise InputError("phase_frames_dn", f"direction {direction!r} for use={use.value}",
                             sorted(phase_frames_dn))  # fmt: skip
    rows, cols = np.nonzero(mask)
    cam_px = np.stack([cols, rows], axis=1).astype(np.float64)
    jacobian = point_jacobian(rig, cam_px, proj_uv[rows, cols], use)
    sigma_uv = np.stack([sigma_coord["v"][rows, cols], sigma_coord["h"][rows, cols]], axis=1)
    covariance = np.full((height, width, 3, 3), np.nan)
    covariance[rows, cols] = point_covariance(jacobian, sigma_uv)
    rays = rig.camera.intrinsics.unproject(cam_px) if cam_px.size else np.zeros((0, 3))
    rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    sigma_range = np.full((height, width), np.nan)
    with np.errstate(invalid="ignore"):
        sigma_range[rows, cols] = np.sqrt(
            np.einsum("pi,pij,pj->p", rays, covariance[rows, cols], rays)
        )
        sigma_depth = np.sqrt(covariance[..., 2, 2])
        sigma_point = np.sqrt(np.trace(covariance, axis1=-2, axis2=-1))
    return Prediction(
        sigma_u_p=sigma_coord["v"], sigma_v_p=sigma_coord["h"],
        sigma_phase_v=sigma_phase["v"], sigma_phase_h=sigma_phase["h"],
        sigma_depth=sigma_depth, sigma_range=sigma_range, sigma_point=sigma_point,
        covariance=covariance, mask=np.isfinite(sigma_depth),
    )  # fmt: skip
