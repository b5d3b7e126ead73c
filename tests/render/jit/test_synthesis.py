"""The device synthesis kernel (:mod:`virtus.render.jit.synthesis`): the host's frames for
every kind of sequence, one kernel a pose, and one compiled kernel whatever the sequence.

CI has no GPU: these run the same code on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.support import small_rig
from virtus.patterns import build_sequence, default_sequence
from virtus.render.backend import mitsuba
from virtus.render.jit.synthesis import synthesize_digital, synthesize_on_device
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


def test_a_pose_is_one_kernel_compiled_once_for_every_sequence() -> None:
    # Frames, sensor noise and the saturation mask come out of one kernel launch, and a
    # sequence of another length and frame order reuses the compiled kernel (its frame
    # count, rows and noise keys are data, not the kernel's source).
    mi, dr, _ = mitsuba(VARIANT)
    device = trace_device(small_rig(), default_scene(), variant=VARIANT)
    sensor = SENSOR_PRESETS["imx174"]
    first = jit_kernels(
        dr, lambda: synthesize_on_device(device, default_sequence(), "nearest", sensor, 900.0)
    )
    assert len(first) == 1
    other = build_sequence(912, 1140, steps=5, gray_bits=6, complementary=False)
    assert len(other) != len(default_sequence())
    result: list = []
    second = jit_kernels(
        dr, lambda: result.append(synthesize_on_device(device, other, "nearest", sensor, 900.0))
    )
    assert len(second) == 1 and second[0]["cache_hit"]
    frames = result[0].numpy()
    assert frames.shape == (len(other), 160, 160)
    reference = synthesize_on_device(device, other, "nearest", sensor, 900.0)
    np.testing.assert_array_equal(frames, reference.numpy())  # same seed, same bytes
    saturated = frames >= sensor.saturation_dn
    np.testing.assert_array_equal(result[0].saturated_mask(), saturated.any(axis=0))
