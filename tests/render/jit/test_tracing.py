"""The device-resident path (trace, synthesis, sensor on Dr.Jit arrays) against the host path.

CI has no GPU: these run the same code on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests import tolerances as tol
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
    "fitted cos^k vignetting and fall-off": {
        "sensor": Sensor(bit_depth=12, vignetting="cos", vignetting_exponent=3.2),
        "projector": ProjectorModel(falloff="cos", falloff_exponent=5.7),
    },
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

    from virtus.render.mitsuba_scene import reads_files as _reads_files
    from virtus.scene.model import MeshObject, Scene

    path = tmp_path / "box.stl"
    trimesh.creation.box((0.1, 0.1, 0.1)).export(path)
    mesh = MeshObject(path=path, pose=Pose(np.eye(3), (0.0, 0.0, 1.0)))
    assert _reads_files(Scene([mesh]))
    assert not _reads_files(default_scene())


# --- synthesis against the analytic pattern values ----------------------------------------
# A mistake made in both synthesis paths passes the host-vs-device comparisons above; here
# both are held to frame values computed from the pattern formulas at known taps.


def known_taps(lookup: str):
    """A one-row host Trace whose pixel i has two taps: weight 1 at (u_i, v_i) and weight 2
    at (u_i + 3, v_i + 2), ambient 0.25; u_i, v_i sweep the projector with sub-pixel
    offsets (nearest: -0.4, 0, 0.3 px from a centre; bilinear: quarter pixels)."""
    from virtus.render.tracing import Trace

    fractions = (-0.4, 0.0, 0.3) if lookup == "nearest" else (0.0, 0.25, 0.5, 0.75)
    j = np.repeat(np.arange(1, 900), len(fractions))
    u = j + np.tile(fractions, 899)
    v = (np.arange(u.size) % 1130 + 1) + np.tile(fractions[::-1], 899)
    n = u.size
    taps = {
        "u_p": np.stack([u, u + 3], axis=1).astype(np.float32),
        "v_p": np.stack([v, v + 2], axis=1).astype(np.float32),
        "weight": np.tile(np.array([1.0, 2.0], np.float32), (n, 1)),
    }
    trace = Trace(
        height=1, width=n, spp=2, projector_width=912, projector_height=1140,
        ambient=np.full(n, 0.25, np.float32), gt=None, variant=VARIANT, **taps,
    )  # fmt: skip
    return trace, taps


def analytic_value(sequence, index: int, x: np.ndarray, lookup: str) -> np.ndarray:
    """The projected value of frame ``index`` at projector coordinates ``x`` along its axis:
    the 8-bit level of the frame formula at a pixel centre (phase frames; codes read from
    the profile, which tests/patterns checks against the Gray code), the pixel containing
    ``x`` (nearest) or the linear interpolation between the two nearest centres."""
    frame = sequence.frames[index]
    if frame.kind in ("white", "black"):
        return np.full(x.shape, 1.0 if frame.kind == "white" else 0.0)

    def level(pixel: np.ndarray) -> np.ndarray:
        if frame.kind == "phase":
            x = 2 * np.pi * pixel / frame.period + 2 * np.pi * frame.step / frame.steps
            return np.rint(255 * (0.5 + 0.5 * np.cos(x))) / 255
        return sequence.profile(index)[pixel]

    if lookup == "nearest":
        return level(np.floor(x + 0.5).astype(np.int64))
    left = np.floor(x).astype(np.int64)
    fraction = x - left
    return (1 - fraction) * level(left) + fraction * level(left + 1)


@pytest.mark.parametrize("lookup", ["nearest", "bilinear"])
def test_synthesised_frames_are_the_pattern_values_at_the_taps(lookup: str) -> None:
    from virtus.render.jit.synthesis import synthesize_digital
    from virtus.render.synthesis import synthesize

    sequence = default_sequence()
    trace, taps = known_taps(lookup)
    # 4 x 255 DN per unit radiance on a 16-bit ideal sensor: every expected frame value is a
    # whole number of DN (quarter-pixel fractions of 8-bit levels), far from rounding edges.
    exposure, sensor = 1020.0, Sensor(bit_depth=16)
    expected = np.empty((len(sequence), trace.width))
    for index, frame in enumerate(sequence.frames):
        axis = "v_p" if frame.direction == "h" else "u_p"
        values = [analytic_value(sequence, index, taps[axis][:, k].astype(float), lookup)
                  for k in (0, 1)]  # fmt: skip
        expected[index] = exposure * (values[0] + 2.0 * values[1] + 0.25)
    assert np.allclose(expected, np.rint(expected), atol=1e-6)
    device = synthesize_digital(trace, sequence, lookup, sensor, exposure)[:, 0, :]
    np.testing.assert_array_equal(device, np.rint(expected))
    host = synthesize(trace, sequence, lookup)[:, 0, :]
    np.testing.assert_array_equal(sensor.digitize(host, exposure), np.rint(expected))


def test_device_taps_are_the_analytic_taps_of_a_tilted_plane() -> None:
    # One pixel-centre sample per pixel on a tilted Lambertian plane (camera = world frame),
    # with lens distortion on both devices: each tap is the projector pixel of the ray's
    # hit and the point-source radiance rho cos(theta_i) |X_p| / z_p^3 (module docstring of
    # virtus.render.tracing), computed here in float64.
    from tests.support import LAMBERT, tilted_plane
    from virtus.scene.model import PlaneObject, Scene

    rig = distorted_rig()
    plane = PlaneObject(tilted_plane().size_m, tilted_plane().pose, LAMBERT)
    camera, projector = rig.camera.intrinsics, rig.projector.intrinsics
    device = trace_device(rig, Scene([plane]), variant=VARIANT, spp=1)
    rays = camera.unproject(camera.pixel_grid().reshape(-1, 2))
    normal, origin = plane.pose.R[:, 2], plane.pose.t
    points = rays * ((normal @ origin) / (rays @ normal))[:, None]
    x_p = rig.cam2proj.apply(points)
    uv = projector.project(x_p)
    centre = rig.proj2cam.t  # the projector's centre in the camera frame
    to_projector = centre - points
    cos_i = np.abs(to_projector @ normal) / np.linalg.norm(to_projector, axis=1)
    radiance = LAMBERT.albedo * cos_i * np.linalg.norm(x_p, axis=1) / x_p[:, 2] ** 3
    inside = (uv[:, 0] > 1) & (uv[:, 0] < projector.width - 2)
    inside &= (uv[:, 1] > 1) & (uv[:, 1] < projector.height - 2)
    assert inside.mean() > 0.5
    u_p, v_p = device.u_p.numpy(), device.v_p.numpy()
    np.testing.assert_allclose(u_p[inside], uv[inside, 0], atol=tol.DEVICE_TAP_PX)
    np.testing.assert_allclose(v_p[inside], uv[inside, 1], atol=tol.DEVICE_TAP_PX)
    weight = device.weight.numpy()
    np.testing.assert_allclose(weight[inside], radiance[inside], rtol=tol.RADIANCE_REL)
