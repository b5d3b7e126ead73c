"""The projector model held to its physics: gamma harmonics, pre-compensation, black level,
pixel aperture and lens blur, fall-off (DESIGN.md section 9)."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError
from virtus.patterns import Frame, PatternSequence, build_sequence
from virtus.patterns.phase import wrapped_phase
from virtus.render.synthesis import synthesize
from virtus.render.tracing import Trace
from virtus.sensor.projector import (
    PROJECTOR_PRESETS,
    Lookup,
    ProjectorModel,
    load_projector,
)

WIDTH, HEIGHT = 912, 1140


def line_trace(u_p: np.ndarray, v_p: float = 570.0) -> Trace:
    """A trace whose pixels each see one point of the projector at ``u_p`` (px) with unit
    weight: synthesis then returns the emitted pattern itself."""
    u = np.asarray(u_p, dtype=np.float32).reshape(-1, 1)
    return Trace(
        height=1,
        width=u.shape[0],
        spp=1,
        projector_width=WIDTH,
        projector_height=HEIGHT,
        weight=np.ones_like(u),
        u_p=u,
        v_p=np.full_like(u, v_p),
        ambient=np.zeros(u.shape[0], dtype=np.float32),
        gt=None,
        variant="none",
    )


def phase_of(sequence: PatternSequence, projector: ProjectorModel | str, u: np.ndarray) -> tuple:
    """Wrapped phase, background and modulation of the phase frames seen at ``u``."""
    frames = synthesize(line_trace(u), sequence, projector)[:, 0, :].astype(np.float64)
    phase_frames = [i for i, f in enumerate(sequence.frames) if f.kind == "phase"]
    return wrapped_phase(frames[phase_frames])


def error_rad(measured: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * (measured - truth)))


# One period spanning the axis exactly (decodable alone; whole periods keep the harmonics
# orthogonal on the pixel grid), 0.39 deg of phase per projector pixel.
LONG_PERIOD = float(WIDTH)
CENTRES = np.arange(0, WIDTH, dtype=np.float64)


def long_fringes(steps: int) -> PatternSequence:
    return build_sequence(WIDTH, HEIGHT, periods=LONG_PERIOD, steps=steps, directions=("v",),
                          white=False, black=False)  # fmt: skip


@pytest.mark.parametrize(("steps", "expected"), [(3, 0.291), (4, 1.06e-2)])
def test_gamma_error_matches_the_harmonic_theory(steps, expected) -> None:
    # Full-range fringes 0.5 + 0.5 cos through g(p) = p^2.2: the harmonics N - 1 and N + 1
    # alias onto the fundamental (DESIGN.md 9: 0.291 rad for N = 3, 1.06e-2 for N = 4).
    sequence = long_fringes(steps)
    linear, _, _ = phase_of(sequence, "nearest", CENTRES)
    gamma, _, _ = phase_of(sequence, ProjectorModel(gamma=2.2), CENTRES)
    error = error_rad(gamma, linear)
    assert np.abs(error).max() == pytest.approx(expected, rel=tol.GAMMA_ERROR_REL)
    # The ripple is at N times the fringe frequency: that harmonic holds most of the error's
    # energy, and harmonics that are not multiples of N hold none of it.
    truth = 2 * np.pi * CENTRES / LONG_PERIOD

    def energy(orders: list[int]) -> float:
        basis = np.concatenate(
            [np.stack([np.sin(k * truth), np.cos(k * truth)], axis=1) for k in orders], axis=1
        )
        coefficients, *_ = np.linalg.lstsq(basis, error, rcond=None)
        return float(np.sum((basis @ coefficients) ** 2))

    total = float(np.sum(error**2))
    assert energy([steps]) > tol.GAMMA_RIPPLE_SHARE * total
    others = [k for k in range(1, 4 * steps) if k % steps]
    assert energy(others) < (1 - tol.GAMMA_RIPPLE_SHARE) * total


def test_gamma_is_negligible_at_18_steps_and_precompensation_undoes_it() -> None:
    truth = 2 * np.pi * CENTRES / LONG_PERIOD
    sequence = long_fringes(18)
    linear, _, _ = phase_of(sequence, "nearest", CENTRES)
    gamma, _, _ = phase_of(sequence, ProjectorModel(gamma=2.2), CENTRES)
    assert np.abs(error_rad(gamma, linear)).max() < 1e-3
    three = long_fringes(3)
    plain, _, _ = phase_of(three, ProjectorModel(gamma=2.2), CENTRES)
    fixed, _, _ = phase_of(three, ProjectorModel(gamma=2.2, precompensate=True), CENTRES)
    before, after = np.abs(error_rad(plain, truth)).max(), np.abs(error_rad(fixed, truth)).max()
    assert after * tol.PRECOMPENSATION_GAIN <= before, (before, after)


def test_a_measured_response_table_acts_like_its_power_law() -> None:
    lut = tuple(np.linspace(0, 1, 256) ** 2.2)
    sequence = long_fringes(3)
    power, _, _ = phase_of(sequence, ProjectorModel(gamma=2.2), CENTRES)
    table, _, _ = phase_of(sequence, ProjectorModel(response_lut=lut), CENTRES)
    np.testing.assert_allclose(table, power, atol=1e-9)


def test_black_level_lifts_the_background_not_the_phase() -> None:
    sequence = long_fringes(4)
    ideal = phase_of(sequence, "nearest", CENTRES)
    grey = phase_of(sequence, ProjectorModel(contrast_ratio=100.0), CENTRES)
    np.testing.assert_allclose(grey[0], ideal[0], atol=1e-6)
    np.testing.assert_allclose(grey[1], 0.01 + 0.99 * ideal[1], rtol=1e-5)
    np.testing.assert_allclose(grey[2], 0.99 * ideal[2], rtol=1e-5)


def test_gaussian_psf_scales_modulation_and_shifts_no_phase() -> None:
    # exp(-2 pi^2 sigma^2 / P^2): P = 18, sigma = 3 gives 0.578 (DESIGN.md 9).
    period, sigma = 18.0, 3.0
    sequence = build_sequence(WIDTH, HEIGHT, periods=period, steps=18, gray_bits=6,
                              directions=("v",))  # fmt: skip
    u = np.random.default_rng(0).uniform(100, 800, 20_000)
    sharp = ProjectorModel(pixel=Lookup.psf)
    blurred = sharp.with_(psf_sigma_px=sigma)
    phase_sharp, _, mod_sharp = phase_of(sequence, sharp, u)
    phase_blur, _, mod_blur = phase_of(sequence, blurred, u)
    ratio = np.median(mod_blur / mod_sharp)
    expected = np.exp(-2 * np.pi**2 * sigma**2 / period**2)
    assert ratio == pytest.approx(expected, rel=tol.PSF_MODULATION_REL)
    # The blur leaves the true phase (the sharp DMD staircase, +-0.5 px, is smoothed away).
    shift = error_rad(phase_blur, 2 * np.pi * u / period)
    assert abs(shift.mean()) < tol.PSF_PHASE_SHIFT_RAD
    assert np.abs(shift).max() < tol.PSF_PHASE_SHIFT_MAX_RAD
    assert np.abs(error_rad(phase_sharp, 2 * np.pi * u / period)).max() > 0.1  # the staircase


def _predicted_binary_error(profile: np.ndarray, steps: int, fill: float, sigma: float,
                            phi: np.ndarray) -> np.ndarray:  # fmt: skip
    """Phase error of N-step decoding of a periodic pixel profile (one period, P pixels)
    shown through square pixels of ``fill`` and a Gaussian PSF, from its Fourier series:
    independent of the renderer's tables."""
    period = profile.size
    harmonics = np.arange(-8 * period, 8 * period + 1)
    dft = np.array([np.sum(profile * np.exp(-2j * np.pi * k * np.arange(period) / period))
                    for k in harmonics]) / period  # fmt: skip
    transfer = np.sinc(harmonics * fill / period) * np.exp(
        -2 * np.pi**2 * sigma**2 * harmonics**2 / period**2
    )
    coefficients = dft * transfer
    shifts = 2 * np.pi * np.arange(1, steps + 1) / steps
    # Frame n shows the profile shifted by n P / N: I_n(u) = sum_k c_k exp(2 pi i k (u/P +
    # n/N)); the estimator sum_n I_n exp(-i 2 pi n / N) keeps k = 1 mod N.
    frames = np.real(
        np.sum(
            coefficients[None, None, :]
            * np.exp(1j * harmonics[None, None, :] * (phi[None, :, None] + shifts[:, None, None])),
            axis=2,
        )
    )
    estimate, _, _ = wrapped_phase(frames)
    return error_rad(estimate, phi)


def test_binary_fringes_through_a_blurring_lens_match_their_harmonics() -> None:
    # Binary stripes P = 24, N = 4, sigma = 3 px: DESIGN.md 9 quotes 2.84e-2 rad for a 50 %
    # duty square wave; the projector's symmetric stripes light 13 of 24 pixels, so the
    # prediction is computed from the profile actually shown.
    period, steps, sigma = 24, 4, 3.0
    frames = [Frame("phase", "v", float(period), step=n, steps=steps, profile="binary")
              for n in range(1, steps + 1)]  # fmt: skip
    frames += [Frame("gray", "v", float(period), bit=b, bits=6) for b in range(1, 7)]
    sequence = PatternSequence(WIDTH, HEIGHT, tuple(frames))
    projector = ProjectorModel(pixel=Lookup.psf, psf_sigma_px=sigma)
    u = np.arange(240, 720, 0.125)
    measured, _, _ = phase_of(sequence, projector, u)
    truth = 2 * np.pi * u / period
    error = error_rad(measured, truth)
    shown = sequence.profile(steps - 1)[:period]  # step N: no shift
    phi = 2 * np.pi * (u % period) / period
    predicted = _predicted_binary_error(shown, steps, 1.0, sigma, phi)
    assert np.abs(error).max() == pytest.approx(np.abs(predicted).max(), rel=tol.BINARY_BLUR_REL)
    assert np.abs(predicted).max() == pytest.approx(2.84e-2, rel=0.15)


def test_fill_factor_keeps_power_and_darkens_the_gaps() -> None:
    projector = ProjectorModel(pixel=Lookup.psf, fill_factor=0.5)
    sequence = build_sequence(WIDTH, HEIGHT, periods=1000.0, steps=3, directions=("v",))
    white = sequence.index_of("white")
    u = np.arange(100, 200, 1 / 64)
    light = synthesize(line_trace(u), sequence, projector)[white, 0]
    assert light.mean() == pytest.approx(1.0, rel=1e-3)  # power per pixel is kept
    gap = np.abs(u - np.rint(u)) > 0.3
    assert np.all(light[gap] < 1e-6) and np.all(light[np.abs(u - np.rint(u)) < 0.2] > 1.99)


def test_cos4_falloff() -> None:
    from virtus.geometry.devices import default_rig

    intrinsics = default_rig().projector.intrinsics
    sequence = build_sequence(WIDTH, HEIGHT, periods=1000.0, steps=3, directions=("v",))
    u = np.array([intrinsics.cx, 0.0, WIDTH - 1.0])
    projector = ProjectorModel(falloff="cos4")
    frames = synthesize(line_trace(u, v_p=intrinsics.cy), sequence, projector,
                        projector_intrinsics=intrinsics)  # fmt: skip
    white = frames[sequence.index_of("white"), 0]
    x = (u - intrinsics.cx) / intrinsics.fx
    np.testing.assert_allclose(white, 1 / (1 + x**2) ** 2, rtol=1e-6)


def test_cos_k_falloff() -> None:
    """``falloff: cos`` with ``falloff_exponent: k``: cos(theta_p)**k; k = 4 is ``cos4``."""
    from virtus.geometry.devices import default_rig

    intrinsics = default_rig().projector.intrinsics
    sequence = build_sequence(WIDTH, HEIGHT, periods=1000.0, steps=3, directions=("v",))
    u = np.array([intrinsics.cx, 0.0, WIDTH - 1.0])
    x = (u - intrinsics.cx) / intrinsics.fx
    for k in (3.1, 5.5):
        projector = ProjectorModel(falloff="cos", falloff_exponent=k)
        frames = synthesize(line_trace(u, v_p=intrinsics.cy), sequence, projector,
                            projector_intrinsics=intrinsics)  # fmt: skip
        white = frames[sequence.index_of("white"), 0]
        np.testing.assert_allclose(white, (1 + x**2) ** (-k / 2), rtol=1e-6)
        assert ProjectorModel.from_dict(projector.to_dict()) == projector
        assert projector.falloff_power == k
    four = ProjectorModel(falloff="cos", falloff_exponent=4.0)
    np.testing.assert_allclose(
        four.falloff_factor(u, np.full(3, intrinsics.cy), intrinsics),
        ProjectorModel(falloff="cos4").falloff_factor(u, np.full(3, intrinsics.cy), intrinsics),
        rtol=1e-6,
    )
    assert "falloff_exponent" not in ProjectorModel(falloff="cos4").to_dict()
    for bad in ({"falloff": "cos"}, {"falloff": "cos", "falloff_exponent": -1.0},
                {"falloff": "none", "falloff_exponent": 2.0}):  # fmt: skip
        with pytest.raises(InputError, match="^falloff_exponent"):
            ProjectorModel(**bad)


def test_ideal_models_are_the_old_renderer() -> None:
    sequence = build_sequence(WIDTH, HEIGHT, periods=18.0, steps=18, gray_bits=6)
    u = np.random.default_rng(1).uniform(-0.5, WIDTH - 0.5, 5000)
    for pixel in ("nearest", "bilinear"):
        a = synthesize(line_trace(u), sequence, pixel)
        b = synthesize(line_trace(u), sequence, ProjectorModel(pixel=pixel, gamma=1.0))
        assert a.tobytes() == b.tobytes()
    # psf with a full fill factor and no blur is the DMD staircase away from pixel edges.
    psf = synthesize(line_trace(u), sequence, ProjectorModel(pixel=Lookup.psf))
    nearest = synthesize(line_trace(u), sequence, "nearest")
    inside = np.abs(u - np.rint(u)) < 0.5 - 1 / 8
    np.testing.assert_allclose(psf[:, 0, inside], nearest[:, 0, inside], atol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"gamma": 0.0}, "gamma"),
        ({"gamma": float("nan")}, "gamma"),
        ({"contrast_ratio": 0.5}, "contrast_ratio"),
        ({"pixel": "psf", "fill_factor": 0.0}, "fill_factor"),
        ({"pixel": "psf", "psf_sigma_px": -1.0}, "psf_sigma_px"),
        ({"psf_sigma_px": 1.0}, "pixel"),
        ({"pixel": "cubic"}, "lookup"),
        ({"falloff": "cos3"}, "falloff"),
        ({"response_lut": (0.0, 1.0)}, "response_lut"),
        ({"response_lut": tuple(np.linspace(1, 0, 256))}, "response_lut"),
    ],
)
def test_bad_projector_parameters_are_refused(kwargs, name) -> None:
    with pytest.raises(InputError, match=rf"^{name}: expected"):
        ProjectorModel(**kwargs)


def test_presets_and_files(tmp_path) -> None:
    for projector in PROJECTOR_PRESETS.values():
        assert ProjectorModel.from_dict(projector.to_dict()) == projector
    path = tmp_path / "dlp.yaml"
    path.write_text("pixel: psf\ngamma: 2.4\npsf_sigma_px: 0.7\n")
    assert load_projector(path).psf_sigma_px == 0.7
    path.write_text("pixel: psf\ngama: 2.4\n")
    with pytest.raises(InputError, match="gama"):
        load_projector(path)


def test_the_device_synthesis_agrees_with_the_host_one() -> None:
    # The Dr.Jit path (the GPU's, run here on the LLVM backend) with a full projector model.
    from tests.support import small_rig
    from virtus.patterns import default_sequence
    from virtus.render import render
    from virtus.scene.model import default_scene
    from virtus.sensor.camera import Sensor

    kwargs = {"projector": PROJECTOR_PRESETS["lightcrafter"], "sensor": Sensor(bit_depth=12)}
    sparse = render(small_rig(), default_scene(), default_sequence(), synthesis="sparse", **kwargs)
    jit = render(small_rig(), default_scene(), default_sequence(), synthesis="jit", **kwargs)
    difference = np.abs(sparse.frames.astype(np.int32) - jit.frames)
    assert difference.max() <= 1 and np.mean(difference > 0) < 1e-3


@pytest.mark.parametrize("gamma", [1.0, 2.2])
def test_precompensated_values_are_sent_on_the_8_bit_grid(gamma: float) -> None:
    # The projector is sent quantise(g^-1(p)): whole levels k / 255, then its response.
    # Undo the response here (p**gamma, no black level) and the sent values must be k / 255,
    # the levels round(255 (p)^(1 / gamma)) of the ideal pattern p (not its 8-bit profile).
    sequence = build_sequence(WIDTH, HEIGHT, periods=18.0, steps=3, gray_bits=6,
                              directions=("v",))  # fmt: skip
    model = ProjectorModel(gamma=gamma, precompensate=True)
    j = np.arange(WIDTH, dtype=np.float64)
    for index, frame in enumerate(sequence.frames):
        light = model.emitted_profile(sequence, index)
        sent = light ** (1.0 / gamma) * 255
        np.testing.assert_allclose(sent, np.rint(sent), rtol=0, atol=1e-9, err_msg=str(index))
        if frame.kind == "phase":
            ideal = 0.5 + 0.5 * np.cos(2 * np.pi * j / 18.0 + 2 * np.pi * frame.step / 3)
            np.testing.assert_allclose(sent, np.rint(255 * ideal ** (1 / gamma)), atol=1e-9)
    if gamma == 1.0:  # a linear projector: pre-compensation sends the plain 8-bit profile
        for index in range(len(sequence)):
            np.testing.assert_array_equal(
                model.emitted_profile(sequence, index), sequence.profile(index)
            )
