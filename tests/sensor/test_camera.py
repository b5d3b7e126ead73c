"""The camera sensor model and its counter-based noise streams."""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
from tests.support import small_rig
from virtus.errors import InputError
from virtus.patterns import default_sequence
from virtus.patterns.phase import wrapped_phase
from virtus.render import render, trace
from virtus.render.synthesis import synthesize
from virtus.scene.model import default_scene
from virtus.sensor.camera import (
    SENSOR_PRESETS,
    Sensor,
    as_seed,
    load_sensor,
    standard_normal,
)
from virtus.sensor.projector import ProjectorModel

BLOCK = 1 << 14


def test_noise_stream_does_not_depend_on_the_split() -> None:
    whole = standard_normal(5, 3, slice(0, 3 * BLOCK + 17))
    for step in (1000, BLOCK, 40_000):
        parts = [
            standard_normal(5, 3, slice(start, min(start + step, whole.size)))
            for start in range(0, whole.size, step)
        ]
        np.testing.assert_array_equal(np.concatenate(parts), whole)
    # Other frames and seeds are other streams.
    assert not np.array_equal(standard_normal(5, 4, slice(0, 100)), whole[:100])
    assert not np.array_equal(standard_normal(6, 3, slice(0, 100)), whole[:100])


def test_dark_noise_has_the_stated_deviation() -> None:
    sensor = Sensor(bit_depth=16, exposure=1.0, system_gain_dn_per_e=1.0, dark_noise_e=4.0)
    n = 4 * BLOCK
    radiance = np.full((2, n), 1000.25, dtype=np.float32)
    digital = sensor.digitize(radiance, 1.0, seed=1, frames=np.array([0, 1]), pixels=slice(0, n))
    values = digital.astype(np.float64)
    # Shot noise adds the signal (1000.25 e- at K = 1), quantisation 1/12 DN^2.
    assert values.std() == pytest.approx(np.sqrt(16 + 1000.25 + 1 / 12), rel=0.02)
    assert values.mean() == pytest.approx(1000.25, abs=0.05)
    assert abs(np.corrcoef(values[0], values[1])[0, 1]) < 0.02  # frames are independent


@pytest.fixture(scope="module")
def noisy_trace():
    rig = small_rig()
    return rig, trace(rig, default_scene())


def test_noisy_frames_are_byte_identical_whatever_the_threads_and_blocks(noisy_trace) -> None:
    _, traced = noisy_trace
    sequence = default_sequence()
    sensor = SENSOR_PRESETS["imx174"]
    exposure = sensor.exposure_for(traced.white)

    def frames(threads: int, block: int) -> np.ndarray:
        return synthesize(
            traced,
            sequence,
            transform=lambda b, f, p: sensor.digitize(b, exposure, seed=11, frames=f, pixels=p),
            dtype=sensor.dtype,
            threads=threads,
            block_pixels=block,
        )

    reference = frames(1, 1 << 14)
    assert reference.dtype == np.uint16 and reference.max() <= 4095
    for threads, block in ((2, 1 << 14), (8, 1 << 14), (8, 3001), (1, 1 << 12)):
        assert frames(threads, block).tobytes() == reference.tobytes(), (threads, block)
    # The noise is really there: another seed changes most pixels of a lit frame.
    other = synthesize(
        traced,
        sequence,
        transform=lambda b, f, p: sensor.digitize(b, exposure, seed=12, frames=f, pixels=p),
        dtype=sensor.dtype,
    )
    lit = traced.gt.mask.reshape(-1)
    assert np.mean(other[50].reshape(-1)[lit] != reference[50].reshape(-1)[lit]) > 0.5


def test_noise_is_the_same_on_the_jit_path(noisy_trace) -> None:
    # The Dr.Jit synthesis (the GPU path, run here on the LLVM backend) draws the same streams:
    # the frames differ only where float32 radiance rounds differently (at most 1 DN, rarely).
    rig, _ = noisy_trace
    sensor = SENSOR_PRESETS["imx174"]
    kwargs = {"sensor": sensor, "rng": 3, "projector": ProjectorModel(pixel="bilinear")}
    sparse = render(rig, default_scene(), default_sequence(), synthesis="sparse", **kwargs)
    jit = render(rig, default_scene(), default_sequence(), synthesis="jit", **kwargs)
    difference = np.abs(sparse.frames.astype(np.int32) - jit.frames)
    assert difference.max() <= 1 and np.mean(difference > 0) < 1e-3


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"bit_depth": 14}, "bit_depth"),
        ({"bit_depth": True}, "bit_depth"),
        ({"system_gain_dn_per_e": 0.1, "dark_noise_e": -1.0}, "dark_noise_e"),
        ({"system_gain_dn_per_e": 0.1, "dark_noise_e": float("nan")}, "dark_noise_e"),
        ({"dark_noise_e": 2.0}, "system_gain_dn_per_e"),
        ({"system_gain_dn_per_e": 0.1, "prnu": 1.5}, "prnu"),
        ({"quantum_efficiency": 1.2}, "quantum_efficiency"),
        ({"black_level_dn": 300.0}, "black_level_dn"),
        ({"exposure": 0.0}, "exposure"),
    ],
)
def test_bad_sensor_parameters_are_refused(kwargs, name) -> None:
    with pytest.raises(InputError, match=rf"^{name}: expected"):
        Sensor(**kwargs)


def test_seeds() -> None:
    assert as_seed(None) == 0 and as_seed(42) == 42
    assert as_seed(np.random.default_rng(1)) == as_seed(np.random.default_rng(1))
    for bad in (-1, 2**63, 1.5, "3", True):
        with pytest.raises(InputError, match="^seed: expected"):
            as_seed(bad)


def test_sensor_round_trips_through_its_dict_and_files(tmp_path) -> None:
    for sensor in SENSOR_PRESETS.values():
        assert Sensor.from_dict(sensor.to_dict()) == sensor
    with pytest.raises(InputError, match="gain"):
        Sensor.from_dict({**SENSOR_PRESETS["imx174"].to_dict(), "gain": 2})
    path = tmp_path / "camera.yaml"
    path.write_text("bit_depth: 10\nsystem_gain_dn_per_e: 0.25\ndark_noise_e: 3.5\n")
    sensor = load_sensor(path)
    assert sensor.bit_depth == 10 and sensor.dark_noise_e == 3.5 and sensor.name == "camera"
    assert load_sensor("webcam") is SENSOR_PRESETS["webcam"]
    path.write_text("bit_depth: 10\nsystem_gain: 0.25\n")
    with pytest.raises(InputError, match="system_gain"):
        load_sensor(path)
    with pytest.raises(InputError, match="^sensor: expected a preset name"):
        load_sensor("no-such-camera")


def _flat_pair(sensor: Sensor, level_dn: float, n: int, seeds=(1, 2)) -> tuple[np.ndarray, ...]:
    """Two frames of a uniform field whose noise-free signal is ``level_dn`` above black."""
    radiance = np.full((1, n), level_dn, dtype=np.float32)
    return tuple(
        sensor.digitize(radiance, 1.0, seed=s, frames=np.array([0]), pixels=slice(0, n))[0].astype(
            np.float64
        )
        for s in seeds
    )


def test_photon_transfer_follows_emva_1288() -> None:
    # EMVA 1288's own method: from pairs of frames with different seeds, var(A - B) / 2
    # against the mean signal above dark is a line of slope K and intercept
    # K^2 sigma_d^2 + sigma_q^2 (sigma_d here includes the dark current's shot noise).
    sensor = SENSOR_PRESETS["imx174"].with_(exposure=1.0)
    gain = sensor.system_gain_dn_per_e
    n = 1 << 17
    dark = _flat_pair(sensor, 0.0, n)
    mean_dark = np.mean(dark)
    means, variances = [], []
    for level in np.linspace(0.05, 0.7, 12) * sensor.full_scale:
        a, b = _flat_pair(sensor, level, n)
        means.append(0.5 * (a.mean() + b.mean()) - mean_dark)
        variances.append(np.var(a - b) / 2)
    slope, intercept = np.polyfit(means, variances, 1)
    dark_e2 = sensor.dark_noise_e**2 + sensor.dark_current_e_per_s * sensor.exposure_time_s
    assert slope == pytest.approx(gain, rel=tol.PHOTON_TRANSFER_SLOPE_REL)
    assert intercept == pytest.approx(
        gain**2 * dark_e2 + 1 / 12, rel=tol.PHOTON_TRANSFER_INTERCEPT_REL
    )
    # The dark frame's own temporal variance is the intercept too.
    assert np.var(dark[0] - dark[1]) / 2 == pytest.approx(
        intercept, rel=tol.PHOTON_TRANSFER_INTERCEPT_REL
    )


@pytest.mark.parametrize("steps", [3, 18])
def test_phase_noise_matches_theory(steps) -> None:
    # sigma_phi = sqrt(2 / N) sigma_I / B (Surrel 1997), with sigma_I^2 the EMVA temporal
    # variance at the background level A (its mean over the N frames).
    sensor = SENSOR_PRESETS["imx174"].with_(exposure=1.0, prnu=0.0)
    gain = sensor.system_gain_dn_per_e
    n = 1 << 16
    rng = np.random.default_rng(0)
    phi = rng.uniform(-np.pi, np.pi, n)
    background, modulation = 1500.0, 900.0
    shifts = 2 * np.pi * np.arange(1, steps + 1) / steps
    radiance = (background + modulation * np.cos(phi[None] + shifts[:, None])).astype(np.float32)
    frames = sensor.digitize(radiance, 1.0, seed=5, frames=np.arange(steps), pixels=slice(0, n))
    measured, _, _ = wrapped_phase(frames.astype(np.float64) - sensor.black_level_dn)
    error = np.angle(np.exp(1j * (measured - phi)))
    dark_e2 = sensor.dark_noise_e**2 + sensor.dark_current_e_per_s * sensor.exposure_time_s
    sigma_i = np.sqrt(gain**2 * dark_e2 + 1 / 12 + gain * background)
    predicted = np.sqrt(2 / steps) * sigma_i / modulation
    assert error.std() == pytest.approx(predicted, rel=tol.PHASE_NOISE_REL)
    assert abs(error.mean()) < 0.05 * predicted  # no bias


def test_full_well_and_adc_saturate() -> None:
    sensor = SENSOR_PRESETS["webcam"].with_(exposure=1.0)
    a, _ = _flat_pair(sensor, 10 * sensor.full_scale, 1000)
    assert np.all(a == sensor.full_scale)
    well = Sensor(
        bit_depth=16, exposure=1.0, system_gain_dn_per_e=1.0, saturation_capacity_e=1000.0
    )
    b, _ = _flat_pair(well, 5000.0, 1000)
    assert np.all(b == 1000)


def test_vignetting_scales_each_pixel_by_cos4() -> None:
    from virtus.render import render

    rig = small_rig()
    sequence = default_sequence()
    white = sequence.index_of("white")
    plain = Sensor(bit_depth=16, exposure=20000.0)
    vignetted = plain.with_(vignetting="cos4")
    a = render(rig, default_scene(), sequence, sensor=plain).frames[white].astype(np.float64)
    b = render(rig, default_scene(), sequence, sensor=vignetted).frames[white].astype(np.float64)
    gain = vignetted.vignetting_gain(rig.camera.intrinsics).reshape(a.shape)
    bright = a > 1000
    np.testing.assert_allclose(b[bright], a[bright] * gain[bright], rtol=1e-3, atol=1.0)
    assert gain.min() < 0.99  # the corners really are darker
    with pytest.raises(InputError, match="^vignetting"):
        Sensor(vignetting="cos3")


def test_vignetting_cos_k_takes_its_exponent() -> None:
    """``vignetting: cos`` with ``vignetting_exponent: k`` scales by cos(theta)**k (a real
    lens's k, fitted by ``twin --fit``); k = 4 is ``cos4``; files without the key (and every
    sensor without "cos") are read and written as before."""
    rig = small_rig()
    intrinsics = rig.camera.intrinsics
    rays = intrinsics.unproject(intrinsics.pixel_grid().reshape(-1, 2))
    for k in (2.7, 4.0, 6.3):
        sensor = Sensor(vignetting="cos", vignetting_exponent=k)
        np.testing.assert_allclose(sensor.vignetting_gain(intrinsics), rays[:, 2] ** k, rtol=1e-6)
        assert sensor.vignetting_power == k
        assert Sensor.from_dict(sensor.to_dict()) == sensor
    four = Sensor(vignetting="cos", vignetting_exponent=4.0).vignetting_gain(intrinsics)
    np.testing.assert_allclose(four, Sensor(vignetting="cos4").vignetting_gain(intrinsics),
                               rtol=1e-6)  # fmt: skip
    assert (Sensor().vignetting_power, Sensor(vignetting="cos4").vignetting_power) == (0.0, 4.0)
    assert "vignetting_exponent" not in Sensor(vignetting="cos4").to_dict()
    for bad in ({"vignetting": "cos"}, {"vignetting": "cos", "vignetting_exponent": 0.0},
                {"vignetting": "cos", "vignetting_exponent": 40.0},
                {"vignetting": "cos", "vignetting_exponent": "4"},
                {"vignetting": "cos4", "vignetting_exponent": 3.0}):  # fmt: skip
        with pytest.raises(InputError, match="^vignetting_exponent"):
            Sensor(**bad)


def test_saturated_pixels_are_in_the_ground_truth(tmp_path) -> None:
    from virtus.capture.capture import Capture
    from virtus.render import render

    rig = small_rig()
    sequence = default_sequence()
    too_bright = Sensor(exposure=400.0)  # the white frame's radiance is ~1 on the sphere
    rendering = render(rig, default_scene(), sequence, sensor=too_bright)
    expected = (rendering.frames >= 255).any(axis=0)
    assert 0 < expected.mean() < 1
    np.testing.assert_array_equal(rendering.gt.mask_saturated, expected)
    # A full well below the ADC's range saturates there instead.
    well = Sensor(bit_depth=12, system_gain_dn_per_e=0.1, saturation_capacity_e=20000.0)
    assert well.saturation_dn == 2000
    # It travels with the capture.
    capture = Capture(sequence, rig, frame_data=rendering.frames, gt_data=rendering.gt)
    loaded = Capture.load(capture.save(tmp_path / "c").parent)
    np.testing.assert_array_equal(loaded.ground_truth.mask_saturated, expected)


@pytest.mark.parametrize("black", [0.0, 64.0, 100.5])
def test_saturation_level_of_a_well_below_the_adc_range_includes_the_black_level(black) -> None:
    # K * well + black: 0.1 DN/e- x 20,000 e- = 2000 DN above a black level of ``black`` DN,
    # well below the 12-bit full scale. A flat field ten times brighter than the well reads
    # exactly that level, and nothing below it is saturated.
    sensor = Sensor(
        bit_depth=12, exposure=1.0, system_gain_dn_per_e=0.1, saturation_capacity_e=20000.0,
        black_level_dn=black,
    )  # fmt: skip
    assert sensor.saturation_dn == int(np.floor(2000.0 + black))
    bright, _ = _flat_pair(sensor, 20000.0, 1000)
    assert np.all(bright == sensor.saturation_dn)
    # 100 DN below the well (7 standard deviations of its ~14 DN shot noise): not saturated.
    below, _ = _flat_pair(sensor, 1900.0, 1000)
    assert np.all(below < sensor.saturation_dn)
    # A well above the ADC range saturates at full scale whatever the black level.
    deep = sensor.with_(saturation_capacity_e=50000.0)
    assert deep.saturation_dn == deep.full_scale == 4095
