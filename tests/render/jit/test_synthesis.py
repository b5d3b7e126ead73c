"""The device synthesis kernel (:mod:`virtus.render.jit.synthesis`): the host's frames for
every kind of sequence, one kernel a pose, and one compiled kernel whatever the sequence --
in both kernel layouts, which give the same bits.

CI has no GPU: these run the same code on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``;
the GPU's layout (a lane per frame and pixel) is forced there through ``layout``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.support import small_rig
from virtus.errors import InputError
from virtus.patterns import build_sequence, default_sequence
from virtus.render.backend import mitsuba
from virtus.render.jit import synthesis as synthesis_jit
from virtus.render.jit.synthesis import (
    LAYOUT_FRAME_PIXEL,
    LAYOUT_PIXEL,
    LAYOUTS,
    layout_for,
    synthesize_digital,
    synthesize_on_device,
)
from virtus.render.jit.tracing import trace_device
from virtus.render.synthesis import synthesize
from virtus.render.tracing import trace
from virtus.scene.model import default_scene
from virtus.sensor.camera import SENSOR_PRESETS, Sensor
from virtus.sensor.projector import ProjectorModel

VARIANT = "llvm_ad_rgb"
#: As in test_tracing: float32 sums in another order may move a value on a rounding edge by
#: 1 DN; measured: none here.
MAX_OFF_BY_ONE_FRACTION = 1e-3


@pytest.mark.parametrize("pixel", ["nearest", "bilinear", "psf"])
@pytest.mark.parametrize("directions", [("v",), ("h",)])
def test_sequences_of_one_fringe_direction_give_the_host_frames(pixel, directions) -> None:
    # Fringes of one direction and uniform frames only: the kernel reads one coordinate of
    # each tap (with psf the uniform frames join the fringes' table); each value is the host's.
    sequence = build_sequence(912, 1140, steps=4, gray_bits=6, directions=directions)
    traced = trace(small_rig(), default_scene(), variant=VARIANT)
    projector, sensor = ProjectorModel(pixel=pixel), Sensor(bit_depth=12)
    exposure = sensor.exposure_for(traced.white)
    host = synthesize(
        traced, sequence, projector, dtype=sensor.dtype,
        transform=lambda block, frames, pixels: sensor.digitize(block, exposure),
    )  # fmt: skip
    device = synthesize_digital(traced, sequence, projector, sensor, exposure)
    assert device.shape == host.shape == (len(sequence), 160, 160)
    off = np.abs(host.astype(np.int64) - device.astype(np.int64))
    assert off.max() <= 1 and np.count_nonzero(off) <= MAX_OFF_BY_ONE_FRACTION * off.size
    assert np.ptp(device[:4], axis=0).max() > 100  # the phase-shift frames differ


def jit_kernels(dr, function) -> list[dict]:  # noqa: ANN001
    """The JIT kernels that ``function()`` launches (Dr.Jit's kernel history)."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.kernel_history_clear()
        function()
        dr.sync_thread()
        history = dr.kernel_history()
    return [k for k in history if k["type"] == dr.KernelType.JIT]


@pytest.fixture(scope="module")
def device_trace():  # noqa: ANN201
    """The small rig's default scene traced on ``VARIANT``, shared by this module's tests."""
    return trace_device(small_rig(), default_scene(), variant=VARIANT)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_pose_is_one_kernel_compiled_once_for_every_sequence(device_trace, layout) -> None:
    # Frames, sensor noise and the saturation mask come out of one kernel launch, and a
    # sequence of another length and frame order reuses the compiled kernel (its frame
    # count, rows and noise keys are data, not the kernel's source).
    mi, dr, _ = mitsuba(VARIANT)
    device, sensor = device_trace, SENSOR_PRESETS["imx174"]

    def synthesized(sequence):  # noqa: ANN001, ANN202
        return synthesize_on_device(device, sequence, "nearest", sensor, 900.0, layout=layout)

    first = jit_kernels(dr, lambda: synthesized(default_sequence()))
    assert len(first) == 1
    lanes = {LAYOUT_PIXEL: 160 * 160, LAYOUT_FRAME_PIXEL: len(default_sequence()) * 160 * 160}
    assert first[0]["size"] == lanes[layout]  # a lane per pixel, or per frame and pixel
    other = build_sequence(912, 1140, steps=5, gray_bits=6, complementary=False)
    assert len(other) != len(default_sequence())
    result: list = []
    second = jit_kernels(dr, lambda: result.append(synthesized(other)))
    assert len(second) == 1 and second[0]["cache_hit"]
    frames = result[0].numpy()
    assert frames.shape == (len(other), 160, 160)
    reference = synthesized(other)
    np.testing.assert_array_equal(frames, reference.numpy())  # same seed, same bytes
    saturated = frames >= sensor.saturation_dn
    np.testing.assert_array_equal(result[0].saturated_mask(), saturated.any(axis=0))


#: Sequences of fringes along both projector axes, along its columns only, its rows only.
SEQUENCES = {
    "both": default_sequence,
    "v": lambda: build_sequence(912, 1140, steps=4, gray_bits=6, directions=("v",)),
    "h": lambda: build_sequence(912, 1140, steps=4, gray_bits=6, directions=("h",)),
}


def both_layouts(device, sequence, projector, sensor, exposure) -> list:  # noqa: ANN001
    """The DeviceFrames of :data:`LAYOUT_PIXEL` and :data:`LAYOUT_FRAME_PIXEL` for the same
    inputs (seed 3)."""
    return [
        synthesize_on_device(device, sequence, projector, sensor, exposure, 3, layout=layout)
        for layout in (LAYOUT_PIXEL, LAYOUT_FRAME_PIXEL)
    ]


@pytest.mark.parametrize("pixel", ["nearest", "bilinear", "psf"])
@pytest.mark.parametrize("sequence", list(SEQUENCES))
def test_both_kernel_layouts_give_the_same_bits(device_trace, pixel, sequence) -> None:
    # The CPU's layout (a lane per pixel looping over the frames) and the GPU's (a lane per
    # frame and pixel) do the same float32 operations per value: the same frames and the
    # same saturation mask, bit for bit, with a noisy sensor and pixels that saturate.
    sensor = SENSOR_PRESETS["imx174"]
    exposure = 1.5 * sensor.exposure_for(np.asarray(device_trace.white()))  # some saturate
    pixel_loop, lanes = both_layouts(
        device_trace, SEQUENCES[sequence](), ProjectorModel(pixel=pixel), sensor, exposure
    )
    frames = pixel_loop.numpy()
    np.testing.assert_array_equal(lanes.numpy(), frames)
    mask = pixel_loop.saturated_mask()
    np.testing.assert_array_equal(lanes.saturated_mask(), mask)
    np.testing.assert_array_equal(mask, (frames >= sensor.saturation_dn).any(axis=0))
    assert 0.0 < mask.mean() < 1.0  # a test of both values of the mask
    assert np.ptp(frames[:4], axis=0).max() > 100  # the phase-shift frames differ


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_pose_split_over_several_kernels_gives_the_same_bits(
    device_trace, layout, monkeypatch
) -> None:
    # Past _MAX_LANES pixels x frames a pose takes several kernels: the same frames and the
    # same mask (each kernel adds its frames' saturated pixels to the mask).
    sensor = SENSOR_PRESETS["imx174"]
    exposure = 1.5 * sensor.exposure_for(np.asarray(device_trace.white()))
    _, dr, _ = mitsuba(VARIANT)

    def synthesized():  # noqa: ANN202
        return synthesize_on_device(
            device_trace, default_sequence(), "bilinear", sensor, exposure, 1, layout=layout
        )

    whole = synthesized()
    monkeypatch.setattr(synthesis_jit, "_MAX_LANES", 5 * 160 * 160)  # 5 frames per kernel
    result: list = []
    kernels = jit_kernels(dr, lambda: result.append(synthesized()))
    assert len(kernels) == -(-len(default_sequence()) // 5)
    np.testing.assert_array_equal(result[0].numpy(), whole.numpy())
    np.testing.assert_array_equal(result[0].saturated_mask(), whole.saturated_mask())
    assert whole.saturated_mask().any()


def test_a_sequence_table_is_made_once_per_sequence_and_projector(
    device_trace, monkeypatch
) -> None:
    # The poses of a dataset share the sequence's table: made once for a sequence and
    # projector (an equal sequence made anew included), again for another projector or
    # sequence -- whose frames are theirs, not the cached ones.
    made: list = []
    profile_table = synthesis_jit._profile_table
    monkeypatch.setattr(
        synthesis_jit, "_profile_table", lambda *a: (made.append(a), profile_table(*a))[1]
    )
    synthesis_jit._table_cache.cache_clear()
    sensor = SENSOR_PRESETS["ideal"]

    def frames(sequence, projector="nearest"):  # noqa: ANN001, ANN202
        return synthesize_on_device(device_trace, sequence, projector, sensor, 900.0).numpy()

    first = frames(default_sequence())
    np.testing.assert_array_equal(frames(default_sequence()), first)
    assert len(made) == 1
    gamma = frames(default_sequence(), ProjectorModel(gamma=2.2))
    other = build_sequence(912, 1140, steps=5, gray_bits=6, complementary=False)
    shifted = frames(other)
    assert len(made) == 3
    assert not np.array_equal(gamma, first)
    assert shifted.shape[0] == len(other) != first.shape[0]
    synthesis_jit._table_cache.cache_clear()  # made afresh: the same frames
    np.testing.assert_array_equal(frames(default_sequence(), ProjectorModel(gamma=2.2)), gamma)
    np.testing.assert_array_equal(frames(other), shifted)


def test_the_layout_follows_the_backend(device_trace, monkeypatch) -> None:
    # A lane per pixel on LLVM (the CPU), a lane per frame and pixel on CUDA (the GPU); an
    # unknown layout is refused before any work.
    assert layout_for("llvm_ad_rgb") == LAYOUT_PIXEL
    assert layout_for("cuda_ad_rgb") == LAYOUT_FRAME_PIXEL
    used: list[str] = []
    for name in ("_pixel_kernel", "_frame_pixel_kernel"):
        kernel = getattr(synthesis_jit, name)
        monkeypatch.setattr(
            synthesis_jit,
            name,
            lambda *a, kernel=kernel, name=name: (used.append(name), kernel(*a)),
        )
    sensor = SENSOR_PRESETS["ideal"]
    synthesize_on_device(device_trace, default_sequence(), "nearest", sensor, 900.0)
    assert used == ["_pixel_kernel"]
    with pytest.raises(InputError, match="layout"):
        synthesize_on_device(
            device_trace, default_sequence(), "nearest", sensor, 900.0, layout="per_frame"
        )
