"""The noise-free signal pass (virtus.design.modulation) is the renderer's own frames."""

from __future__ import annotations

import numpy as np
import pytest

from virtus.design.modulation import predict_pass, signal_pass
from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.patterns import build_sequence
from virtus.render.settings import RenderSettings
from virtus.scanner import Scanner
from virtus.scene.model import Material, PlaneObject, Scene, SphereObject
from virtus.sensor import SENSOR_PRESETS


def _scanner(sensor, size=16, directions=("v",)):
    rig = default_rig()
    k = rig.camera.intrinsics
    camera = Intrinsics(k.fx, k.fy, (size - 1) / 2, (size - 1) / 2, size, size)
    sequence = build_sequence(912, 1140, periods=18.0, steps=4, gray_bits=7,
                              directions=directions)  # fmt: skip
    return Scanner(rig=Rig(Camera(camera), rig.projector, rig.proj2cam), sequence=sequence,
                   sensor=sensor, render=RenderSettings(spp=4))  # fmt: skip


@pytest.fixture(scope="module")
def scene():
    matte = Material(albedo=0.8, specular=0.0)
    backdrop = PlaneObject((2.0, 2.0), Pose(np.eye(3), (0, 0, 1.3)), matte)
    return Scene(objects=[SphereObject(0.005, (0.0, 0.0, 1.0), matte)], background=backdrop)


def test_noisy_frames_of_a_pass_are_the_captures_frames(scene):
    """Re-applying noise to the noise-free pass is exactly re-rendering with that seed."""
    scanner = _scanner(SENSOR_PRESETS["webcam"])
    passed = signal_pass(scanner, scene)
    capture = scanner.capture(scene, rng=5, command=[])
    np.testing.assert_array_equal(passed.digitize(5), capture.frames)
    assert not np.array_equal(passed.digitize(6), capture.frames)
    assert passed.exposure == capture.render["exposure_dn_per_radiance"]


def test_phase_frames_of_a_pass_round_to_an_ideal_capture(scene):
    scanner = _scanner(SENSOR_PRESETS["ideal"], directions=("v", "h"))
    passed = signal_pass(scanner, scene)
    capture = scanner.capture(scene, rng=0, command=[])
    frames = passed.phase_frames_dn()
    assert sorted(frames) == ["h", "v"] and frames["v"].shape == (4, 16, 16)
    indices = scanner.sequence.plan("h").sets[0].indices
    np.testing.assert_array_equal(
        np.clip(np.rint(frames["h"]), 0, 255), capture.frames[list(indices)]
    )
    prediction = predict_pass(passed)
    assert prediction.mask.sum() > 0.9 * prediction.mask.size
    assert np.all(np.isfinite(prediction.sigma_v_p[prediction.mask]))
