"""The uncertainty model (virtus.uncertainty): each link against its closed form or the
project's own noise, and the whole chain against Monte Carlo re-renders."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support import cropped_rig, uncertainty_scenes
from tests.tolerances import (
    EMVA_VARIANCE_VS_DRAWS,
    FLOAT64_EXACT,
    MODEL_VS_MC_DRAWS,
    MODEL_VS_MC_MEDIAN,
    MODEL_VS_MC_P95,
    MODEL_VS_MC_P95_SAMPLING,
    PHASE_SIGMA_VS_DRAWS,
)
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.patterns import DEFAULT_HETERODYNE_PERIODS, build_sequence, default_sequence
from virtus.patterns.phase import wrapped_phase
from virtus.reconstruct import triangulate
from virtus.sensor import SENSOR_PRESETS, ProjectorModel, Sensor
from virtus.uncertainty import (
    QUANTISATION_VARIANCE_DN2,
    coordinate_sigma,
    finest_phase_set,
    fringe_levels,
    intensity_variance,
    phase_sigma,
    phase_sigma_from_levels,
    point_covariance,
    point_jacobian,
    predict_uncertainty,
)

IMX174 = SENSOR_PRESETS["imx174"]
WEBCAM = SENSOR_PRESETS["webcam"]
#: "Ideal 12-bit": a shot-noise-limited sensor (no dark noise, no fixed pattern), 12 bits.
#: The ``ideal`` preset is noise-free: its captures do not change with the seed, so there
#: is no spread over re-renders to compare with.
IDEAL12 = Sensor(name="ideal12", bit_depth=12, system_gain_dn_per_e=4095 / 20000)


# --- intensity noise ------------------------------------------------------------------------


@pytest.mark.parametrize("sensor", [IMX174, WEBCAM, IDEAL12], ids=lambda s: s.name)
def test_intensity_variance_is_that_of_the_sensors_own_noise(sensor):
    signal = np.array([0.0, 5.0, 40.0, 0.3 * sensor.full_scale, 0.7 * sensor.full_scale])
    normal = np.random.default_rng(1).standard_normal((200_000, signal.size)).astype(np.float32)
    drawn = sensor.emva(signal.astype(np.float32)[None], normal, None, None, np)
    # The temporal part of the sensor's own model, before rounding; + 1/12 for rounding.
    measured = drawn.var(axis=0, dtype=np.float64) + QUANTISATION_VARIANCE_DN2
    predicted = intensity_variance(sensor, signal)
    np.testing.assert_allclose(predicted, measured, rtol=EMVA_VARIANCE_VS_DRAWS)


def test_intensity_variance_of_a_noise_free_sensor_is_the_rounding():
    assert np.all(intensity_variance(Sensor(), np.array([0.0, 100.0])) == 1.0 / 12.0)


def test_intensity_variance_counts_the_dark_current():
    dark = IMX174.with_(dark_current_e_per_s=1000.0, exposure_time_s=0.1)  # +100 e- shot
    k = IMX174.system_gain_dn_per_e
    difference = intensity_variance(dark, 50.0) - intensity_variance(IMX174, 50.0)
    assert difference == pytest.approx(k**2 * (100.0 - 0.1), rel=FLOAT64_EXACT)


# --- phase noise ----------------------------------------------------------------------------


@pytest.mark.parametrize("steps", [3, 4, 18])
def test_phase_sigma_is_surrels_for_a_constant_noise(steps):
    # A sensor whose noise does not depend on the signal: K -> 0 with a large dark noise.
    sensor = Sensor(bit_depth=16, system_gain_dn_per_e=1e-6, dark_noise_e=2e6)
    sigma_i = np.sqrt(intensity_variance(sensor, 0.0))
    a, b = 1000.0, 400.0
    phi = np.linspace(-3.0, 3.0, 7)
    shifts = 2 * np.pi * np.arange(1, steps + 1) / steps
    frames = a + b * np.cos(phi[None] + shifts[:, None])
    expected = np.sqrt(2.0 / steps) * sigma_i / b
    np.testing.assert_allclose(phase_sigma(frames, sensor), expected, rtol=1e-3)
    # shot noise is ~3e-4 of the variance here: the closed form agrees to that
    np.testing.assert_allclose(phase_sigma_from_levels(a, b, steps, sensor), expected, rtol=1e-3)


@pytest.mark.parametrize("steps", [3, 4, 5])
def test_phase_sigma_follows_the_phase_where_shot_noise_differs_between_steps(steps):
    """Shot noise makes each step's sigma differ; for N = 3 the phase's sigma then depends
    on the phase itself (a cos 3 phi term). 20,000 draws of the least-squares decoder."""
    sensor = Sensor(bit_depth=16, system_gain_dn_per_e=1.0)  # pure shot noise: var = mu
    a, b = 1000.0, 900.0
    phi = np.linspace(-2.5, 2.5, 9)  # away from the +-pi wrap
    shifts = 2 * np.pi * np.arange(1, steps + 1) / steps
    frames = a + b * np.cos(phi[None] + shifts[:, None])
    rng = np.random.default_rng(7)
    noisy = frames[None] + np.sqrt(frames)[None] * rng.standard_normal((20_000, *frames.shape))
    decoded = np.array([wrapped_phase(f)[0] for f in noisy])
    predicted = phase_sigma(frames, sensor)
    np.testing.assert_allclose(decoded.std(axis=0), predicted, rtol=PHASE_SIGMA_VS_DRAWS)
    if steps == 3:  # the phase dependence is real, and the model has it
        assert predicted.max() / predicted.min() > 1.2


def test_phase_sigma_is_nan_where_saturated_or_unmodulated():
    # (3 steps, 3 pixels): flat; one step at 252 DN; a plain fringe
    frames = np.array([[100.0, 252.0, 50.0], [100.0, 100.0, 150.0], [100.0, 100.0, 10.0]])
    sigma = phase_sigma(frames, WEBCAM)
    assert np.isnan(sigma[0])  # no modulation
    assert np.isnan(sigma[1])  # 252 + black level 4 reaches the 8-bit full scale
    assert np.isfinite(sigma[2])
    with pytest.raises(InputError, match="frames_dn"):
        phase_sigma(np.ones((2, 4)), WEBCAM)


def test_coordinate_sigma_is_phase_times_period_over_two_pi():
    assert coordinate_sigma(0.01, 18.0) == pytest.approx(0.01 * 18 / (2 * np.pi))
    with pytest.raises(InputError, match="period_px"):
        coordinate_sigma(0.01, 0.0)


# --- projector ------------------------------------------------------------------------------


def test_fringe_levels_of_an_ideal_projector_are_half_and_half():
    sequence = build_sequence(912, 1140, periods=18.0, steps=4, gray_bits=6)
    c0, c1 = fringe_levels(ProjectorModel(), sequence, "v")
    # 8-bit pattern values: within half a level
    assert c0 == pytest.approx(0.5, abs=1 / 255) and c1 == pytest.approx(0.5, abs=1 / 255)


def test_fringe_levels_blur_lowers_the_modulation_as_a_gaussian_does():
    sequence = build_sequence(912, 1140, periods=18.0, steps=18, gray_bits=6)
    blurred = ProjectorModel(pixel="psf", psf_sigma_px=3.0)
    sharp = ProjectorModel(pixel="psf")
    ratio = fringe_levels(blurred, sequence, "v")[1] / fringe_levels(sharp, sequence, "v")[1]
    assert ratio == pytest.approx(np.exp(-2 * np.pi**2 * 9 / 18**2), rel=5e-3)  # 0.578


def test_fringe_levels_gamma_without_precompensation_lowers_the_modulation():
    sequence = build_sequence(912, 1140, periods=18.0, steps=18, gray_bits=6)
    c0, c1 = fringe_levels(ProjectorModel(gamma=2.2), sequence, "v")
    # g = (0.5 + 0.5 cos)^2.2: mean 0.29, first harmonic 0.43 (quadrature, 8-bit values)
    theta = np.linspace(0, 2 * np.pi, 100_000, endpoint=False)
    g = (np.round((0.5 + 0.5 * np.cos(theta)) * 255) / 255) ** 2.2
    assert c0 == pytest.approx(g.mean(), abs=2e-3)
    assert c1 == pytest.approx(2 * np.mean(g * np.cos(theta)), abs=2e-3)
    precompensated = ProjectorModel(gamma=2.2, precompensate=True)
    assert fringe_levels(precompensated, sequence, "v")[1] == pytest.approx(0.5, abs=3e-3)


def test_finest_phase_set_is_the_decoded_period():
    periods = DEFAULT_HETERODYNE_PERIODS  # 18, 18.29, 20.57 px
    sequence = build_sequence(912, 1140, periods=periods, steps=[9, 4, 4])
    indices, period = finest_phase_set(sequence, "h")
    assert period == pytest.approx(18.0) and len(indices) == 9
    code_only = build_sequence(912, 1140, periods=18.0, steps=4, gray_bits=6, directions=("v",))
    with pytest.raises(InputError, match="direction 'h'"):
        finest_phase_set(code_only, "h")


# --- triangulation --------------------------------------------------------------------------


def _parallel_rig(baseline: float = 0.1, dist: tuple = ()) -> Rig:
    """Camera and projector with the same pinhole, parallel axes, projector ``baseline``
    to the right: u - u_p = f b / Z."""
    k = Intrinsics(1000.0, 1000.0, 100.0, 80.0, 200, 160, dist)
    return Rig(Camera(k), Projector(k), Pose(np.eye(3), (baseline, 0.0, 0.0)))


def test_depth_sigma_of_a_parallel_rig_is_z_squared_over_f_b():
    rig = _parallel_rig()
    z = np.array([0.5, 1.0, 2.0])
    cam = np.array([[120.0, 70.0]] * 3)
    u_p = cam[:, 0] - 1000.0 * 0.1 / z
    proj = np.stack([u_p, cam[:, 1]], axis=1)
    jacobian = point_jacobian(rig, cam, proj, use="u")
    sigma_u = np.stack([np.full(3, 0.02), np.full(3, np.nan)], axis=1)  # v not used
    covariance = point_covariance(jacobian, sigma_u)
    expected = z**2 / (1000.0 * 0.1) * 0.02
    # central differences: relative error (h / disparity)^2 = (0.05 / 50)^2 at 2 m
    np.testing.assert_allclose(np.sqrt(covariance[:, 2, 2]), expected, rtol=3e-6)
    assert np.all(jacobian[:, :, 1] == 0)


def test_point_jacobian_with_distortion_matches_a_smaller_step_and_moves_along_the_ray():
    rig = _parallel_rig(dist=(-0.2, 0.05, 0.001, -0.002, 0.0))
    cam = np.array([[10.0, 15.0], [180.0, 140.0], [100.0, 80.0]])
    rays = rig.camera.intrinsics.unproject(cam)
    points = rays * (0.8 / rays[:, 2:3])
    proj = rig.projector.intrinsics.project(rig.cam2proj.apply(points))
    coarse = point_jacobian(rig, cam, proj, use="u")
    fine = point_jacobian(rig, cam, proj, use="u", step_px=0.005)
    np.testing.assert_allclose(coarse, fine, rtol=1e-5)
    # with one coordinate the point slides along the camera ray
    direction = coarse[:, :, 0] / np.linalg.norm(coarse[:, :, 0], axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", direction, rays)), 1.0, atol=1e-6)
    # and the derivative predicts a finite move of the triangulation
    moved = triangulate(rig, cam, proj + [0.3, 0.0], "u")
    np.testing.assert_allclose(moved - points, 0.3 * coarse[:, :, 0], rtol=2e-2, atol=1e-9)


def test_predict_uncertainty_checks_its_maps():
    sequence = default_sequence()
    rig = _parallel_rig()
    mask = np.ones((2, 3), dtype=bool)
    frames = {"v": np.ones((18, 2, 3))}
    with pytest.raises(InputError, match="proj_uv"):
        predict_uncertainty(rig, sequence, IMX174, frames, np.zeros((3, 2, 2)), mask)
    with pytest.raises(InputError, match="direction 'h'"):
        predict_uncertainty(rig, sequence, IMX174, frames, np.zeros((2, 3, 2)), mask, use="uv")
    with pytest.raises(InputError, match=r"phase_frames_dn\['v'\]"):
        predict_uncertainty(rig, sequence, IMX174, {"v": np.ones((4, 2, 3))},
                            np.zeros((2, 3, 2)), mask, use="u")  # fmt: skip


# --- the whole chain against Monte Carlo ----------------------------------------------------

#: Noisy re-renders per case (the issue asks >= 30): enough that the raw 95th percentile's
#: sampling inflation is small (tests/tolerances.py).
DRAWS = MODEL_VS_MC_DRAWS


def run_case(scene, sensor, steps, period, draws=DRAWS, use="u"):
    """:func:`virtus.design.montecarlo.monte_carlo` of the 48 px scanner with ``steps`` x
    ``period`` phase shifting and a 7-bit Gray code."""
    from virtus.design.montecarlo import monte_carlo
    from virtus.render.settings import RenderSettings
    from virtus.scanner import Scanner

    directions = ("v",) if use == "u" else ("v", "h")
    sequence = build_sequence(912, 1140, periods=period, steps=steps, gray_bits=7,
                              directions=directions)  # fmt: skip
    # the paper's pixel footprint (0.8 projector px at 1 m, so a pixel barely averages the
    # fringes), few pixels
    scanner = Scanner(rig=cropped_rig(48), sequence=sequence, sensor=sensor,
                      render=RenderSettings(spp=4))  # fmt: skip
    return monte_carlo(scanner, scene, draws, use=use)


def assert_model_agrees(result) -> None:
    assert result.valid > 0.95, result.valid  # predicted pixels decode in every draw
    assert result.order_errors < 0.02, result.order_errors
    for quantity in ("u_p", "depth"):
        ratios = result.ratios(quantity)
        assert abs(ratios["median"] - 1) <= MODEL_VS_MC_MEDIAN, (quantity, ratios)
        assert abs(ratios["p95_raw"] - 1) <= MODEL_VS_MC_P95, (quantity, ratios)


def test_the_draws_leave_the_raw_95th_percentile_little_sampling_inflation():
    """The raw 95th percentile is held to the issue's 20 % with DRAWS draws: what sampling
    spread alone adds there is the stated 8 %, not most of the 20 % (18 % with 40 draws)."""
    from virtus.design.montecarlo import p95_sampling_inflation

    inflation = p95_sampling_inflation(DRAWS)
    assert inflation == pytest.approx(MODEL_VS_MC_P95_SAMPLING, abs=1e-3)
    assert inflation - 1 <= MODEL_VS_MC_P95 / 2


@pytest.fixture(scope="module")
def scenes():
    return uncertainty_scenes()


# CI subset of the matrix (the whole matrix: benchmarks/bench_uncertainty.py): both
# scenes, N = 3, 4, 18, both periods, all three sensors -- a case is ~0.2 s at 48 x 48 px.
CASES = [
    ("plane", IMX174, 3, 18.0),
    ("plane", WEBCAM, 18, 36.0),
    ("plane", IDEAL12, 4, 18.0),
    ("sphere", IMX174, 18, 18.0),
    ("sphere", WEBCAM, 3, 36.0),
    ("sphere", IDEAL12, 18, 36.0),
    ("sphere", WEBCAM, 4, 18.0),
]


@pytest.mark.parametrize(
    ("scene", "sensor", "steps", "period"), CASES,
    ids=[f"{c[0]}-{c[1].name}-N{c[2]}-T{c[3]:g}" for c in CASES],
)  # fmt: skip
def test_predicted_sigma_agrees_with_noisy_re_renders(scenes, scene, sensor, steps, period):
    assert_model_agrees(run_case(scenes[scene], sensor, steps, period))


def test_predicted_sigma_with_both_coordinates_agrees_with_noisy_re_renders(scenes):
    """use="uv": the ray-ray midpoint from u_p and v_p, each with its own noise."""
    assert_model_agrees(run_case(scenes["sphere"], IMX174, 4, 18.0, use="uv"))


def test_the_monte_carlo_check_can_fail(scenes):
    """A model off by sqrt(2) either way (as if the sensor's gain were doubled or halved)
    fails the check."""
    result = run_case(scenes["plane"], IMX174, 4, 18.0)
    assert_model_agrees(result)
    for factor in (np.sqrt(2), 1 / np.sqrt(2)):
        with pytest.raises(AssertionError):
            assert_model_agrees(result.scaled(factor))
