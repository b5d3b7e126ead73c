"""The photometric twin (:mod:`virtus.twin.photometric`), virtual to virtual: captures of a
matte plane rendered with a known projector gamma, blur, contrast and fall-off, camera
vignetting, exposure, ambient light and EMVA 1288 noise are fitted back, and the fitted
twin's frames and point noise match the original's (DESIGN.md section 9)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests import tolerances as tol
from tests.pipeline.test_calibrate_captures import scaled_rig
from virtus.errors import DegenerateData, InputError
from virtus.geometry.transforms import Pose
from virtus.metrology.plane import fit_plane
from virtus.patterns import build_sequence, default_sequence
from virtus.reconstruct import points_from_decoded
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.scene.model import Material, PlaneObject, Scene
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import Lookup, ProjectorModel
from virtus.twin.photometric import fit_photometry, frame_differences, response_harmonics

RIG = scaled_rig(0.25)  # 240 x 240 px camera, 228 x 285 px projector
ALBEDO, AMBIENT = 0.7, 0.03
#: The truth: a 10-bit camera (gain 1023 DN / 8000 e-, 8 e- dark noise, black level 8 DN,
#: cos^3 vignetting, fixed exposure) and a projector with gamma 2.2, a 0.8 px lens blur,
#: 500:1 contrast and cos^5.5 fall-off (exponents other than the ideal lens's 4: real lenses'
#: are, and the fit must find them, not round them to the nearest preset).
TRUE_SENSOR = Sensor(
    bit_depth=10,
    exposure=600.0,
    system_gain_dn_per_e=1023 / 8000,
    dark_noise_e=8.0,
    black_level_dn=8.0,
    vignetting="cos",
    vignetting_exponent=3.0,
)
TRUE_PROJECTOR = ProjectorModel(
    pixel=Lookup.psf, gamma=2.2, psf_sigma_px=0.8, falloff="cos", falloff_exponent=5.5,
    contrast_ratio=500.0,
)  # fmt: skip
#: What a bench knows without fitting: the camera's black level, the projector's contrast.
PRIOR_SENSOR = Sensor(bit_depth=10, black_level_dn=8.0)
PRIOR_PROJECTOR = ProjectorModel(contrast_ratio=500.0)
#: Three periods (the longest covers the axis), 8 steps, both directions, white and black.
SEQUENCE = build_sequence(228, 285, periods=(9.0, 16.0, 300.0), steps=8)
#: Plane poses (rotation vector, translation): three depths tell vignetting from fall-off
#: (the projector's axis crosses the camera's near 1 m, where the two look alike).
POSES = [
    ([0.15, -0.2, 0.0], [0.0, 0.0, 1.0]),
    ([-0.1, 0.2, 0.0], [0.02, 0.0, 0.75]),
    ([0.05, 0.15, 0.0], [0.0, 0.03, 1.35]),
]


def plane(rotvec, t, ambient: float = AMBIENT) -> Scene:
    surface = Material(albedo=ALBEDO, specular=0.0)
    board = PlaneObject(size_m=(2.0, 2.0), pose=Pose.from_rotvec(rotvec, t), material=surface)
    return Scene(objects=[board], ambient=ambient)


def scanner(sensor: Sensor, projector: ProjectorModel, sequence=SEQUENCE) -> Scanner:
    return Scanner(
        rig=RIG, sequence=sequence, projector=projector, sensor=sensor,
        render=RenderSettings(spp=1),
    )  # fmt: skip


def noise_free(sensor: Sensor) -> Sensor:
    return sensor.with_(system_gain_dn_per_e=None, dark_noise_e=0.0, dark_current_e_per_s=0.0)


def truths(fit) -> dict[str, tuple[float, float]]:
    """Fitted and true value of every parameter."""
    shading = fit.report["shading"]
    return {
        "gamma": (fit.projector.gamma, TRUE_PROJECTOR.gamma),
        "psf_sigma_px": (fit.projector.psf_sigma_px, TRUE_PROJECTOR.psf_sigma_px),
        "camera_exponent": (shading["camera_exponent"], TRUE_SENSOR.vignetting_exponent),
        "projector_exponent": (shading["projector_exponent"], TRUE_PROJECTOR.falloff_exponent),
        "vignetting_exponent": (fit.sensor.vignetting_exponent, TRUE_SENSOR.vignetting_exponent),
        "falloff_exponent": (fit.projector.falloff_exponent, TRUE_PROJECTOR.falloff_exponent),
        "ambient": (fit.ambient, AMBIENT),
        "exposure": (fit.sensor.exposure, TRUE_SENSOR.exposure),
        "system_gain_dn_per_e": (fit.sensor.system_gain_dn_per_e, TRUE_SENSOR.system_gain_dn_per_e),
        "dark_noise_e": (fit.sensor.dark_noise_e, TRUE_SENSOR.dark_noise_e),
    }


@pytest.fixture(scope="module")
def captures():
    truth = scanner(TRUE_SENSOR, TRUE_PROJECTOR)
    return [truth.capture(plane(*pose), rng=10 + i) for i, pose in enumerate(POSES)]


@pytest.fixture(scope="module")
def fitted(captures):
    return fit_photometry(
        captures, RIG, prior_sensor=PRIOR_SENSOR, prior_projector=PRIOR_PROJECTOR, albedo=ALBEDO
    )


def test_every_parameter_is_fitted_back(fitted):
    errors = {name: got / true - 1.0 for name, (got, true) in truths(fitted).items()}
    assert all(abs(e) <= tol.PHOTOMETRIC_FIT_REL for e in errors.values()), errors
    assert fitted.report["shading"]["separable"]
    assert fitted.sensor.vignetting == "cos" and fitted.projector.falloff == "cos"
    assert fitted.report["shading"]["camera_edge_error"] == pytest.approx(0.0, abs=1e-3)
    assert fitted.projector.contrast_ratio == PRIOR_PROJECTOR.contrast_ratio
    # the fitted models are what a --sensor/--projector file holds
    assert Sensor.from_dict(fitted.sensor.to_dict()) == fitted.sensor
    assert ProjectorModel.from_dict(fitted.projector.to_dict()) == fitted.projector


def test_fitted_twin_frames_and_point_noise_match(fitted):
    """A pose none of the fitted captures shows: noise-free frames agree to 1 % (normalised
    RMS), and the point noise of a plane (noisy frames, other seeds) to 10 %."""
    scene = plane([0.1, 0.1, 0.0], [0.0, 0.0, 0.9])
    original = scanner(noise_free(TRUE_SENSOR), TRUE_PROJECTOR).capture(scene)
    twin = scanner(noise_free(fitted.sensor), fitted.projector).capture(scene)
    mask = original.decode().mask & twin.decode().mask
    assert mask.mean() > 0.9
    differences = frame_differences(original, twin, mask)
    for kind in ("white", "black", "fringe"):
        assert differences[f"{kind}_rms"] <= tol.PHOTOMETRIC_FRAME_RMS, differences
    assert np.isnan(differences["code_rms"])  # this sequence has no code frames

    def point_noise(capture) -> float:
        decoded = capture.decode()
        points = points_from_decoded(RIG, decoded.proj_uv, decoded.mask)[decoded.mask]
        return fit_plane(points).rms

    real = point_noise(scanner(TRUE_SENSOR, TRUE_PROJECTOR).capture(scene, rng=1000))
    virtual = point_noise(scanner(fitted.sensor, fitted.projector).capture(scene, rng=2000))
    assert real / virtual == pytest.approx(1.0, abs=tol.PHOTOMETRIC_POINT_NOISE_REL)
    # without the fit the twin is far off (an ideal projector's staircase, a noise-free camera)
    ideal = point_noise(scanner(Sensor(bit_depth=10), ProjectorModel()).capture(scene))
    assert abs(np.log(real / ideal)) > np.log(2.0)


def test_one_capture_fits_the_product(captures):
    """At 1 m the projector's axis meets the camera's: the two fall-offs look alike, and
    their product is fitted (and said so)."""
    fit = fit_photometry(
        captures[:1], RIG, prior_sensor=PRIOR_SENSOR, prior_projector=PRIOR_PROJECTOR,
        albedo=ALBEDO,
    )  # fmt: skip
    shading = fit.report["shading"]
    assert not shading["separable"] and shading["regressor_correlation"] > 0.95
    assert any("cannot be told apart" in note for note in fit.report["notes"])
    assert shading["camera_exponent"] == shading["projector_exponent"]
    # where the two cosines are alike their product is cos^(3 + 5.5): each gets the mean
    mean = (TRUE_SENSOR.vignetting_exponent + TRUE_PROJECTOR.falloff_exponent) / 2
    assert shading["camera_exponent"] == pytest.approx(mean, rel=tol.PHOTOMETRIC_FIT_REL)
    assert fit.projector.gamma == pytest.approx(2.2, rel=tol.PHOTOMETRIC_FIT_REL)


def test_single_period_sequence_with_codes():
    """The paper's sequence (one 18 px period, 18 steps, Gray code) on an 8-bit camera:
    gamma and blur from one period's harmonics, and the code frames match too."""
    sequence = default_sequence(228, 285)
    sensor = Sensor(bit_depth=8, exposure=150.0, system_gain_dn_per_e=255 / 6000,
                    dark_noise_e=12.0, black_level_dn=4.0, vignetting="cos4")  # fmt: skip
    truth = scanner(sensor, TRUE_PROJECTOR, sequence)
    captures = [truth.capture(plane(*pose), rng=20 + i) for i, pose in enumerate(POSES)]
    fit = fit_photometry(
        captures, RIG, prior_sensor=Sensor(bit_depth=8, black_level_dn=4.0),
        prior_projector=PRIOR_PROJECTOR, albedo=ALBEDO,
    )  # fmt: skip
    for got, true in (
        (fit.projector.gamma, 2.2),
        (fit.projector.psf_sigma_px, 0.8),
        (fit.sensor.system_gain_dn_per_e, 255 / 6000),
        (fit.ambient, AMBIENT),
    ):
        assert got == pytest.approx(true, rel=tol.PHOTOMETRIC_FIT_REL)
    scene = plane([0.1, 0.1, 0.0], [0.0, 0.0, 0.9])
    original = scanner(noise_free(sensor), TRUE_PROJECTOR, sequence).capture(scene)
    twin = scanner(noise_free(fit.sensor), fit.projector, sequence).capture(scene)
    mask = original.decode().mask & twin.decode().mask
    differences = frame_differences(original, twin, mask)
    assert max(differences.values()) <= tol.PHOTOMETRIC_FRAME_RMS, differences


def test_response_harmonics_hold_to_theory():
    """The model side of the fit against closed forms (DESIGN.md section 9): Gaussian blur
    scales a period-P fringe's modulation by exp(-2 pi^2 sigma^2 / P^2) (so going from
    sigma 1 to 3 px at P = 18 by exp(-2 pi^2 8 / 324) = 0.614); g(x) = x^gamma of
    0.5 + 0.5 cos gives the harmonics c_k / c_1 of its Fourier series."""
    sequence = build_sequence(228, 285, periods=(18.0, 300.0), steps=18, directions=("v",))
    fine, coarse = sequence.plans()["v"].sets
    sharp = ProjectorModel(pixel=Lookup.psf, psf_sigma_px=0.0)
    wide, narrow = (
        response_harmonics(sharp.with_(psf_sigma_px=sigma), sequence, fine)[0]
        for sigma in (3.0, 1.0)
    )
    expected = np.exp(-2 * np.pi**2 * (9.0 - 1.0) / 18**2)
    assert wide / narrow == pytest.approx(expected, abs=tol.HARMONIC_THEORY)
    t = np.linspace(0.0, 2 * np.pi, 20000, endpoint=False)
    profile = (0.5 + 0.5 * np.cos(t)) ** 2.2
    c1, c2, c3 = (np.mean(profile * np.cos(k * t)) for k in (1, 2, 3))
    m1, (q2, q3) = response_harmonics(sharp.with_(gamma=2.2), sequence, coarse)
    assert m1 == pytest.approx(2 * c1, abs=tol.HARMONIC_THEORY)
    assert q2 == pytest.approx(c2 / c1, abs=tol.HARMONIC_THEORY)
    assert q3 == pytest.approx(c3 / c1, abs=tol.HARMONIC_THEORY)


def test_refusals():
    no_uniform = build_sequence(228, 285, periods=(9.0, 300.0), steps=8, white=False, black=False)
    capture = scanner(Sensor(bit_depth=10), ProjectorModel(), no_uniform).capture(plane(*POSES[0]))
    with pytest.raises(InputError, match="white frame"):
        fit_photometry([capture], RIG)
    three = build_sequence(228, 285, periods=(9.0, 300.0), steps=3)
    capture = scanner(Sensor(bit_depth=10), ProjectorModel(), three).capture(plane(*POSES[0]))
    with pytest.raises(DegenerateData, match="N >= 4"):
        fit_photometry([capture], RIG)
    with pytest.raises(InputError, match="at least one capture"):
        fit_photometry([], RIG)


def test_square_wave_fringes_keep_the_prior_gamma_and_fit_the_blur():
    """Two-level patterns (a LightCrafter lab's square waves) send only 0 and 255: gamma is
    neither observable nor needed, so the prior's is kept (and said so), while the blur still
    shapes the square wave's harmonics and is fitted back."""
    from virtus.patterns import PatternSequence

    blocks = [
        block
        for d in ("v", "h")
        for block in (
            {"kind": "phase", "direction": d, "period": 12, "steps": 12, "profile": "binary"},
            {"kind": "gray", "direction": d, "period": 12, "bits": 5, "align": "edge"},
        )
    ] + [{"kind": "white"}, {"kind": "black"}]
    square = PatternSequence.from_dict({"width": 228, "height": 285, "blocks": blocks})
    truth = scanner(TRUE_SENSOR, TRUE_PROJECTOR, square)
    captures = [truth.capture(plane(*pose), rng=60 + i) for i, pose in enumerate(POSES[:2])]
    prior = PRIOR_PROJECTOR.with_(gamma=1.7)
    fit = fit_photometry(
        captures, RIG, prior_sensor=PRIOR_SENSOR, prior_projector=prior, albedo=ALBEDO
    )
    assert fit.report["response"]["gamma_observable"] is False
    assert fit.projector.gamma == 1.7
    assert any("gamma is not observable" in note for note in fit.report["notes"])
    assert fit.projector.psf_sigma_px == pytest.approx(0.8, rel=tol.PHOTOMETRIC_FIT_REL)


def test_regions_restrict_the_fit_to_one_albedo(captures):
    """A region mask keeps the fit on pixels of the stated albedo: half of each plane
    painted darker biases the exposure without it and not with it."""
    darker = []
    for capture in captures[:2]:
        frames = capture.frames.copy()
        half = frames.shape[2] // 2
        frames[:, :, half:] = np.rint(
            TRUE_SENSOR.black_level_dn + 0.5 * (frames[:, :, half:] - TRUE_SENSOR.black_level_dn)
        ).astype(frames.dtype)
        darker.append(dataclasses.replace(capture, frame_data=frames, frame_files=()))
    region = np.zeros(captures[0].frames.shape[1:], dtype=bool)
    region[:, : captures[0].frames.shape[2] // 2 - 4] = True
    options = {"prior_sensor": PRIOR_SENSOR, "prior_projector": PRIOR_PROJECTOR, "albedo": ALBEDO}
    whole = fit_photometry(darker, RIG, **options)
    masked = fit_photometry(darker, RIG, regions=[region] * len(darker), **options)
    assert abs(whole.sensor.exposure / TRUE_SENSOR.exposure - 1) > 0.1
    true = TRUE_SENSOR.exposure
    assert masked.sensor.exposure == pytest.approx(true, rel=tol.PHOTOMETRIC_FIT_REL)
    with pytest.raises(InputError, match="region"):
        fit_photometry(darker[:1], RIG, regions=[region[:10]], **options)
    with pytest.raises(InputError, match="one mask"):
        fit_photometry(darker[:1], RIG, regions=[], **options)
