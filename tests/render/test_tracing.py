"""Compiled kernels are reused from pose to pose (:mod:`virtus.render.tracing` and the
device path of :mod:`virtus.render.jit`).

A calibration moves the board, a dataset the camera, and the auto exposure changes with
every pose: if any such value were baked into a kernel's source as a literal, every pose
would compile its kernels again (0.1-0.6 s a pose on 2 CPU cores, more than the pose's
whole render). Dr.Jit names a kernel by the hash of its source, so the same hashes for
two different poses prove the kernels are reused, whatever the on-disk cache holds. And the
camera rays' traversal setting (coherent rays) changes no tap and no ground truth.
"""

from __future__ import annotations

import gc

import numpy as np
import pytest

from tests.support import small_rig
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render, render_device
from virtus.render.backend import mitsuba
from virtus.render.mitsuba_scene import _cached_scene
from virtus.scene.model import Scene, SphereObject, default_scene
from virtus.sensor.camera import SENSOR_PRESETS, Sensor
from virtus.sensor.projector import ProjectorModel

VARIANT = "llvm_ad_rgb"
SETTINGS = RenderSettings(variant=VARIANT)
#: Three camera poses about the sphere 1 m ahead, each seeing it differently (and so
#: getting a different auto exposure).
POSES = (
    Pose.from_euler("xyz", [0.5, -1.0, 0.3], t=(0.004, 0.0, 0.0)),
    Pose.from_euler("xyz", [-1.5, 0.7, -0.4], t=(-0.01, 0.006, 0.02)),
    Pose.from_euler("xyz", [2.0, 1.5, 1.0], t=(0.015, -0.01, -0.03)),
)


def kernel_hashes(function) -> list[str]:  # noqa: ANN001
    """Hashes of the JIT kernels ``function()`` launches, in launch order."""
    _, dr, _ = mitsuba(VARIANT)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.kernel_history_clear()
        function()
        dr.sync_thread()
        history = dr.kernel_history()
    return [k["hash"] for k in history if k["type"] == dr.KernelType.JIT]


def device_pose(cam2world: Pose, scene: Scene, sensor: Sensor):  # noqa: ANN201
    def run():  # noqa: ANN202
        rendering = render_device(
            small_rig(), scene, default_sequence(), SETTINGS, projector=ProjectorModel(),
            sensor=sensor, seed=3, cam2world=cam2world,
        )  # fmt: skip
        rendering.trace.ground_truth()  # the pixel-centre rays' kernel too
        return rendering

    return run


@pytest.mark.parametrize("sensor", ["ideal", "imx174"])
def test_a_new_pose_reuses_the_device_paths_kernels(sensor: str) -> None:
    scene, model = default_scene(), SENSOR_PRESETS[sensor]
    kernel_hashes(device_pose(POSES[0], scene, model))  # the first pose compiles
    second = kernel_hashes(device_pose(POSES[1], scene, model))
    third = kernel_hashes(device_pose(POSES[2], scene, model))
    assert len(second) >= 3  # trace, synthesis, ground truth at least
    assert second == third


def test_the_poses_really_differ() -> None:
    # Guards the test above: the poses see different images, with different exposures.
    runs = [device_pose(pose, default_scene(), Sensor())() for pose in POSES[1:]]
    assert runs[0].exposure != runs[1].exposure
    assert not np.array_equal(runs[0].frames.numpy(), runs[1].frames.numpy())


def host_pose(cam2world: Pose):  # noqa: ANN201
    """A host-path render of the small rig's default scene from ``cam2world``."""
    return lambda: render(
        small_rig(), default_scene(), default_sequence(), SETTINGS, cam2world=cam2world,
        synthesis="sparse",
    )  # fmt: skip


def test_a_new_pose_reuses_the_host_paths_kernels() -> None:
    kernel_hashes(host_pose(POSES[0]))
    second, third = (kernel_hashes(host_pose(pose)) for pose in POSES[1:])
    assert len(second) >= 2  # the pixel-centre rays and the supersamples
    assert second == third


def test_the_kernels_do_not_depend_on_where_the_rays_sit_in_memory() -> None:
    # Dr.Jit reads the numpy ray arrays in place and compiles aligned loads only for aligned
    # addresses: rays made anew for every pose (at whatever address numpy's allocator gives)
    # must give the same kernels. Before the rays' rows were aligned, the pixel-centre rays
    # were copied for each pose and the host path's first kernel changed from pose to pose
    # now and then (seen in CI).
    from virtus.render.rays import camera_rays

    hashes = []
    for pose in POSES:
        camera_rays.cache_clear()
        hashes.append(kernel_hashes(host_pose(pose)))
    assert hashes[0] == hashes[1] == hashes[2]


def test_a_scene_with_another_ambient_level_reuses_the_kernels() -> None:
    def scene(ambient: float) -> Scene:
        return Scene(
            objects=(SphereObject(radius_m=0.1, center_m=(0.0, 0.0, 1.0)),),
            background=default_scene().background,
            ambient=ambient,
        )

    def fresh(ambient: float) -> list[str]:
        # Each scene loaded alone: Mitsuba's BSDF registry (which the trace kernel's calls
        # dispatch over) then looks the same to every one, as to a calibration's poses.
        _cached_scene.cache_clear()
        gc.collect()
        return kernel_hashes(device_pose(POSES[0], scene(ambient), Sensor()))

    fresh(0.05)
    assert fresh(0.1) == fresh(0.2)


def test_coherent_camera_rays_find_the_same_hits(monkeypatch, tmp_path) -> None:
    # Camera rays are cast as coherent rays (Embree traverses them in packets): a hint for
    # the traversal only. Every tap, the ambient light and the ground truth equal those of
    # the plain call bit for bit, for analytic shapes and for a triangle mesh.
    from virtus.render import tracing
    from virtus.scene.model import MeshObject
    from virtus.scene.procedural import write_freeform_object

    mesh = write_freeform_object(tmp_path / "freeform.stl", subdivisions=3)
    placed = Pose(np.eye(3), (0.0, 0.0, 0.9))
    scene = Scene(
        objects=(*default_scene().objects, MeshObject(path=mesh, scale_to_m=1.0, pose=placed)),
        background=default_scene().background,
        ambient=0.05,
    )
    coherent = tracing.trace(small_rig(), scene, variant=VARIANT)
    monkeypatch.setattr(
        tracing._Tracer, "_camera_intersect", lambda self, ray: self.mscene.ray_intersect(ray)
    )
    plain = tracing.trace(small_rig(), scene, variant=VARIANT)
    assert (coherent.weight > 0).mean() > 0.5  # most taps lit: a test of real hits
    for name in ("weight", "u_p", "v_p", "ambient"):
        np.testing.assert_array_equal(getattr(coherent, name), getattr(plain, name), name)
    expected = plain.gt.arrays()
    for name, array in coherent.gt.arrays().items():
        np.testing.assert_array_equal(array, expected[name], name)


def test_camera_rays_carry_the_coherent_hint_on_llvm_only() -> None:
    # Embree (LLVM) traverses coherent rays in packets; Mitsuba's CUDA path drops the hint,
    # so CUDA takes the plain call (the same OptiX kernel, and the code says what runs).
    from virtus.render.tracing import coherent_camera_rays

    assert coherent_camera_rays("llvm_ad_rgb") and coherent_camera_rays("llvm_ad_mono")
    assert not coherent_camera_rays("cuda_ad_rgb")
