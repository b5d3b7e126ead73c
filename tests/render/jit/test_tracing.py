"""The device-resident path (trace, synthesis, sensor on Dr.Jit arrays) against the host path.

CI has no GPU: these run the same code on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.support import small_rig
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics, ThinLens
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render
from virtus.render.backend import mitsuba
from virtus.render.jit.noise import frame_keys, standard_normal_jit
from virtus.render.jit.tracing import DeviceFrames, percentile_of_positive, trace_device
from virtus.render.renderer import render_device
from virtus.render.tracing import trace
from virtus.scene.model import default_scene
from virtus.sensor.camera import SENSOR_PRESETS, Sensor
from virtus.sensor.noise import standard_normal
from virtus.sensor.projector import PROJECTOR_PRESETS, ProjectorModel

VARIANT = "llvm_ad_rgb"
#: The default render settings on that variant.
SETTINGS = RenderSettings(variant=VARIANT)
#: Frames may differ by 1 DN where a value sits on a rounding edge: float32 sums in another
#: order (the white frame's 99th percentile, so the exposure, moves by ~1e-8 relative) and
#: an ulp of log/cos in the noise. Measured: at most 8e-5 of the values.
MAX_OFF_BY_ONE_FRACTION = 1e-3
GT_ARRAYS = ("depth", "points", "normals", "proj_uv", "mask_hit", "mask_shadow",
             "mask_outside", "mask_multibounce", "mask_saturated")  # fmt: skip


def distorted_rig() -> Rig:
    k, p = default_rig().camera.intrinsics, default_rig().projector.intrinsics
    camera = Intrinsics(k.fx / 6, k.fy / 6, 85.3, 71.2, 170, 150, dist=(-0.12, 0.08, 0.001, 0, 0))
    projector = Intrinsics(p.fx, p.fy, 440.0, 600.0, p.width, p.height, dist=(0.06, -0.03, 0, 0))
    return Rig(Camera(camera), Projector(projector), default_rig().proj2cam)


def assert_same_rendering(host, device) -> None:
    assert device.frames.dtype == host.frames.dtype and device.frames.shape == host.frames.shape
    off = np.abs(host.frames.astype(np.int64) - device.frames.astype(np.int64))
    assert off.max() <= 1
    assert np.count_nonzero(off) <= MAX_OFF_BY_ONE_FRACTION * off.size
    assert device.exposure == pytest.approx(host.exposure, rel=1e-6)
    for name in GT_ARRAYS:
        np.testing.assert_array_equal(getattr(device.gt, name), getattr(host.gt, name), name)


CASES = {
    "ideal nearest": {},
    "bilinear": {"projector": ProjectorModel(pixel="bilinear")},
    "noisy sensor, lightcrafter projector (psf, gamma, fall-off)": {
        "sensor": SENSOR_PRESETS["imx174"],
        "projector": PROJECTOR_PRESETS["lightcrafter"],
    },
    "vignetting, 12 bit": {"sensor": Sensor(bit_depth=12, vignetting="cos4")},
    "interreflections": {"settings": {"bounces": 2, "spp": 1}},
    "projector defocus": {
        "settings": {
            "projector_lens": ThinLens(aperture_m=0.01, focus_distance_m=0.6),
            "aperture_samples": 3,
            "spp": 1,
        }
    },
    "camera depth of field": {
        "settings": {"camera_lens": ThinLens(aperture_m=0.01, focus_distance_m=0.8), "spp": 4}
    },
}


@pytest.mark.parametrize("options", CASES.values(), ids=CASES.keys())
def test_device_path_renders_the_host_frames(options) -> None:
    rig, scene, sequence = small_rig(), default_scene(), default_sequence()
    options = dict(options)
    settings = RenderSettings(variant=VARIANT, **options.pop("settings", {}))
    host = render(rig, scene, sequence, settings, synthesis="sparse", rng=3, **options)
    device = render(rig, scene, sequence, settings, synthesis="jit", rng=3, **options)
    assert_same_rendering(host, device)


def test_device_path_with_lens_distortion_and_off_centre_principal_points() -> None:
    rig, scene, sequence = distorted_rig(), default_scene(), default_sequence()
    options = {"rng": 5, "sensor": SENSOR_PRESETS["webcam"]}
    host = render(rig, scene, sequence, SETTINGS, synthesis="sparse", **options)
    device = render(rig, scene, sequence, SETTINGS, synthesis="jit", **options)
    assert_same_rendering(host, device)


def test_device_taps_equal_the_host_taps() -> None:
    rig, scene = distorted_rig(), default_scene()
    lens = ThinLens(aperture_m=0.01, focus_distance_m=0.6)
    options = {"variant": VARIANT, "bounces": 2, "projector_lens": lens, "aperture_samples": 2}
    host = trace(rig, scene, **options)
    device = trace_device(rig, scene, **options)
    shape = host.weight.shape
    for name in ("weight", "u_p", "v_p"):
        values = getattr(device, name).numpy().reshape(shape)
        np.testing.assert_allclose(values, getattr(host, name), rtol=1e-6, atol=1e-5, err_msg=name)
    np.testing.assert_allclose(device.white().numpy(), host.white.ravel(), rtol=1e-5)


def test_frames_stay_on_the_device_until_asked() -> None:
    mi, dr, _ = mitsuba(VARIANT)
    sequence = default_sequence()
    result = render_device(
        small_rig(), default_scene(), sequence, SETTINGS, projector=ProjectorModel(),
        sensor=Sensor(),
    )  # fmt: skip
    assert isinstance(result.frames.data, mi.UInt8)
    assert dr.width(result.frames.data) == len(sequence) * 160 * 160
    assert result.frames.numpy().shape == (len(sequence), 160, 160)


def test_device_noise_streams_equal_the_host_streams() -> None:
    mi, dr, _ = mitsuba(VARIANT)
    n = 50_000
    for seed, frame in ((0, 0), (7, 3), (2**62 + 5, 51), (1, 1 << 40)):
        k0, k1 = frame_keys(mi, seed, np.array([frame]))
        device = standard_normal_jit(mi, dr, k0, k1, dr.arange(mi.UInt32, 1000, 1000 + n))
        host = standard_normal(seed, frame, slice(1000, 1000 + n))
        # Integer hashing is exact; only float32 log/cos may differ by an ulp or so.
        np.testing.assert_allclose(device.numpy(), host, rtol=0, atol=2e-6)


def test_host_noise_is_standard_normal_and_uncorrelated() -> None:
    values = standard_normal(11, 2, slice(0, 1 << 20)).astype(np.float64)
    assert abs(values.mean()) < 5 / 2**10  # 5 standard errors
    assert values.std() == pytest.approx(1.0, abs=5 / 2**10 / np.sqrt(2))
    assert abs(np.corrcoef(values[:-1], values[1:])[0, 1]) < 5e-3
    other = standard_normal(11, 3, slice(0, 1 << 20))
    assert abs(np.corrcoef(values, other)[0, 1]) < 5e-3
    # Tails of a normal: P(|z| > 3) = 0.0027.
    assert np.mean(np.abs(values) > 3) == pytest.approx(0.0027, rel=0.1)


@pytest.mark.parametrize("size", [1, 2, 3, 1001, 100_000])
def test_white_frame_percentile_on_the_device_is_numpys(size) -> None:
    mi, _, _ = mitsuba(VARIANT)
    rng = np.random.default_rng(size)
    values = (rng.random(size) * 3).astype(np.float32)
    values[rng.random(size) < 0.3] = 0.0
    values[0] = 1.5  # at least one lit pixel
    for q in (0.5, 50.0, 99.0, 100.0):
        expected = np.percentile(values[values > 0], q)
        assert percentile_of_positive(mi.Float(values), q) == pytest.approx(expected, rel=1e-7)
    assert percentile_of_positive(mi.Float(np.zeros(size, np.float32)), 99.0) is None


@pytest.mark.parametrize("shape", [(1, 3, 5), (2, 2, 2)])
def test_16_bit_frames_come_back_whole_and_in_order(shape) -> None:
    mi, dr, _ = mitsuba(VARIANT)
    values = np.arange(np.prod(shape), dtype=np.uint32) * 4099 % 65536
    frames = DeviceFrames(
        data=mi.UInt32(values), n_frames=shape[0], height=shape[1], width=shape[2],
        dtype=np.uint16, saturated=dr.zeros(mi.Bool, shape[1] * shape[2]), variant=VARIANT,
    )  # fmt: skip
    host = frames.numpy()
    assert host.dtype == np.uint16
    np.testing.assert_array_equal(host, values.reshape(shape))


def test_a_pose_decoded_on_the_device_is_the_capture_decoded_on_the_host() -> None:
    from virtus.scanner import Scanner

    scanner = Scanner(rig=small_rig(), sensor=SENSOR_PRESETS["imx174"], render=SETTINGS)
    scene = default_scene()
    host = scanner.decoded_view(scene, rng=4, on_device=False)
    device = scanner.decoded_view(scene, rng=4, on_device=True)
    off = np.abs(device.white.astype(np.int64) - host.white.astype(np.int64))
    assert off.max() <= 1 and np.count_nonzero(off) <= MAX_OFF_BY_ONE_FRACTION * off.size
    # Frames agree to 1 DN at rounding edges (above), so decodes agree closely, not bitwise.
    both = host.decoded.mask & device.decoded.mask
    assert np.count_nonzero(host.decoded.mask ^ device.decoded.mask) <= 1e-3 * both.size
    difference = device.decoded.proj_uv[both] - host.decoded.proj_uv[both]
    assert np.sqrt(np.mean(difference**2)) < 1e-3  # px
    orders = np.abs(difference) > 0.5
    assert not orders.any()


def test_a_texture_is_reused_only_while_its_image_is_unchanged() -> None:
    from virtus.render.mitsuba_scene import _texture

    mi, _, _ = mitsuba(VARIANT)
    image = np.full((8, 8), 0.5)
    first = _texture(mi, image)
    assert _texture(mi, image) is first
    assert _texture(mi, image.copy()) is not first  # another array: its own texture
    image[2, 3] = 0.25  # the same array, changed in place
    assert _texture(mi, image) is not first


def test_frames_split_over_several_kernels_are_the_same_frames(monkeypatch) -> None:
    import virtus.render.jit.synthesis as synthesis_jit

    rig, scene, sequence = small_rig(), default_scene(), default_sequence()
    options = {"rng": 2, "sensor": SENSOR_PRESETS["imx174"]}
    whole = render(rig, scene, sequence, SETTINGS, synthesis="jit", **options)
    monkeypatch.setattr(synthesis_jit, "_MAX_LANES", 5 * 160 * 160)  # 5 frames per kernel
    split = render(rig, scene, sequence, SETTINGS, synthesis="jit", **options)
    np.testing.assert_array_equal(split.frames, whole.frames)
    np.testing.assert_array_equal(split.gt.mask_saturated, whole.gt.mask_saturated)


def test_frames_are_handed_to_pytorch_without_a_copy() -> None:
    torch = pytest.importorskip("torch")
    result = render_device(
        small_rig(), default_scene(), default_sequence(), SETTINGS, projector=ProjectorModel(),
        sensor=Sensor(),
    )  # fmt: skip
    tensor = result.frames.torch()
    assert tensor.dtype == torch.uint8 and tuple(tensor.shape) == (52, 160, 160)
    np.testing.assert_array_equal(tensor.numpy(), result.frames.numpy())
    # The same memory: a change through the tensor shows in the device array.
    tensor[0, 0, 0] = 77
    assert int(result.frames.data[0]) == 77


def test_scenes_that_read_files_are_not_cached(tmp_path) -> None:
    import trimesh

    from virtus.render.tracing import _reads_files
    from virtus.scene.model import MeshObject, Scene

    path = tmp_path / "box.stl"
    trimesh.creation.box((0.1, 0.1, 0.1)).export(path)
    mesh = MeshObject(path=path, pose=Pose(np.eye(3), (0.0, 0.0, 1.0)))
    assert _reads_files(Scene([mesh]))
    assert not _reads_files(default_scene())
