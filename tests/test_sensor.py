"""The camera sensor model and its counter-based noise streams."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_render_support import small_rig
from virtus.errors import InputError
from virtus.patterns import default_sequence
from virtus.render import render, trace
from virtus.render.synthesis import synthesize
from virtus.scene import default_scene
from virtus.sensor import (
    NOISE_BLOCK_PIXELS,
    Sensor,
    as_seed,
    standard_normal,
)


def test_noise_stream_does_not_depend_on_the_split() -> None:
    whole = standard_normal(5, 3, slice(0, 3 * NOISE_BLOCK_PIXELS + 17))
    for step in (1000, NOISE_BLOCK_PIXELS, 40_000):
        parts = [
            standard_normal(5, 3, slice(start, min(start + step, whole.size)))
            for start in range(0, whole.size, step)
        ]
        np.testing.assert_array_equal(np.concatenate(parts), whole)
    # Other frames and seeds are other streams.
    assert not np.array_equal(standard_normal(5, 4, slice(0, 100)), whole[:100])
    assert not np.array_equal(standard_normal(6, 3, slice(0, 100)), whole[:100])


def test_read_noise_has_the_stated_deviation() -> None:
    sensor = Sensor(bit_depth=16, exposure=1.0, read_noise_dn=4.0)
    n = 4 * NOISE_BLOCK_PIXELS
    radiance = np.full((2, n), 1000.25, dtype=np.float32)
    digital = sensor.digitize(radiance, 1.0, seed=1, frames=np.array([0, 1]), pixels=slice(0, n))
    values = digital.astype(np.float64)
    # Quantisation adds 1/12 DN^2 to the variance.
    assert values.std() == pytest.approx(np.sqrt(16 + 1 / 12), rel=0.02)
    assert values.mean() == pytest.approx(1000.25, abs=0.05)
    assert abs(np.corrcoef(values[0], values[1])[0, 1]) < 0.02  # frames are independent


@pytest.fixture(scope="module")
def noisy_trace():
    rig = small_rig()
    return rig, trace(rig, default_scene())


def test_noisy_frames_are_byte_identical_whatever_the_threads_and_blocks(noisy_trace) -> None:
    _, traced = noisy_trace
    sequence = default_sequence()
    sensor = Sensor(bit_depth=12, read_noise_dn=2.5)
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
    sensor = Sensor(bit_depth=12, read_noise_dn=2.5)
    kwargs = {"sensor": sensor, "rng": 3, "lookup": "bilinear"}
    sparse = render(rig, default_scene(), default_sequence(), synthesis="sparse", **kwargs)
    jit = render(rig, default_scene(), default_sequence(), synthesis="jit", **kwargs)
    difference = np.abs(sparse.frames.astype(np.int32) - jit.frames)
    assert difference.max() <= 1 and np.mean(difference > 0) < 1e-3


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"bit_depth": 14}, "bit_depth"),
        ({"bit_depth": True}, "bit_depth"),
        ({"read_noise_dn": -1.0}, "read_noise_dn"),
        ({"read_noise_dn": float("nan")}, "read_noise_dn"),
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


def test_sensor_round_trips_through_its_dict() -> None:
    sensor = Sensor(bit_depth=10, exposure=12.5, read_noise_dn=1.5)
    assert Sensor.from_dict(sensor.to_dict()) == sensor
    with pytest.raises(InputError, match="sensor"):
        Sensor.from_dict({**sensor.to_dict(), "gain": 2})
