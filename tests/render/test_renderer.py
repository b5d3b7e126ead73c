"""Renderer physics and plumbing on small images: sampling, radiometry, masks, textures,
meshes, poses, sensor, errors. Accuracy against decoders and Mitsuba: test_render_accuracy."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from tests import tolerances as tol
from tests.support import LAMBERT, plane_depth, small_rig, tilted_plane
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render, synthesize, trace
from virtus.scene.model import (
    BoxObject,
    Material,
    MeshObject,
    PlaneObject,
    Scene,
    SphereObject,
    TexturedPlaneObject,
)
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import ProjectorModel


@pytest.fixture(scope="module")
def sequence():
    return default_sequence()


def white_radiance(rig: Rig, scene: Scene, spp: int = 4) -> tuple[np.ndarray, object]:
    traced = trace(rig, scene, spp=spp)
    return traced.white, traced


def interior(mask: np.ndarray) -> np.ndarray:
    """Pixels whose 3 x 3 neighbourhood is all in ``mask`` (no mixed supersamples)."""
    padded = np.pad(mask, 1, constant_values=False)
    out = np.ones_like(mask)
    for dr in range(3):
        for dc in range(3):
            out &= padded[dr : dr + mask.shape[0], dc : dc + mask.shape[1]]
    return out


# --- radiometry ---------------------------------------------------------------------------


@pytest.mark.parametrize("distance_m", [0.8, 1.25])
def test_lambertian_plane_facing_the_projector_has_radiance_rho_over_d2(distance_m) -> None:
    # Point source with uniform irradiance on its image plane: a plane orthogonal to the
    # projector axis at distance D is lit uniformly, L = rho / D^2 (see render.tracing).
    rig = small_rig()
    proj2cam = rig.proj2cam
    pose = Pose(proj2cam.R, proj2cam.t + distance_m * proj2cam.R[:, 2])
    scene = Scene([PlaneObject((3.0, 3.0), pose, Material(albedo=0.6, specular=0.0))])
    white, traced = white_radiance(rig, scene)
    lit = interior(traced.gt.mask)
    assert lit.mean() > 0.9
    np.testing.assert_allclose(white[lit], 0.6 / distance_m**2, rtol=tol.RADIANCE_REL)


def test_shadowed_and_out_of_projector_pixels_get_only_ambient() -> None:
    rig0 = small_rig()
    k = rig0.camera.intrinsics
    # A wider camera than the projector's field, so some of the wall is outside it.
    wide = Intrinsics(k.fx / 2, k.fy / 2, k.cx, k.cy, k.width, k.height)
    rig = Rig(Camera(wide), rig0.projector, rig0.proj2cam)
    albedo, ambient = 0.5, 0.1
    matte = Material(albedo=albedo, specular=0.0)
    scene = Scene(
        objects=[SphereObject(0.1, (0.0, 0.0, 1.0), matte)],
        background=PlaneObject((4.0, 4.0), Pose(np.eye(3), (0, 0, 1.3)), matte),
        ambient=ambient,
    )
    white, traced = white_radiance(rig, scene)
    gt = traced.gt
    shadow, outside = interior(gt.mask_shadow), interior(gt.mask_outside)
    assert shadow.sum() > 50 and outside.sum() > 50
    np.testing.assert_allclose(white[shadow | outside], ambient * albedo, rtol=tol.RADIANCE_REL)
    assert np.all(white[interior(gt.mask)] > 2 * ambient * albedo)
    assert not np.any(gt.mask & (gt.mask_shadow | gt.mask_outside))


# --- ground truth -------------------------------------------------------------------------


def test_ground_truth_with_distortion_and_off_centre_principal_points() -> None:
    k, p = default_rig().camera.intrinsics, default_rig().projector.intrinsics
    camera = Intrinsics(
        k.fx / 6, k.fy / 6 * 1.01, 85.3, 71.2, 170, 150, dist=(-0.12, 0.08, 0.001, -0.0015, 0.01)
    )
    projector = Intrinsics(p.fx, p.fy, 440.0, 600.0, p.width, p.height, dist=(0.06, -0.03, 0, 0))
    rig = Rig(Camera(camera), Projector(projector), default_rig().proj2cam)
    plane = tilted_plane()
    traced = trace(rig, Scene([SphereObject(0.05, (0.03, 0.0, 0.9), LAMBERT)], background=plane))
    gt = traced.gt
    hit = gt.mask_hit
    assert hit.all()
    # proj_uv is the projector model applied to the ground-truth points.
    expected = projector.project(rig.cam2proj.apply(gt.points[hit]))
    np.testing.assert_allclose(gt.proj_uv[hit], expected, atol=tol.GT_PROJ_UV_PX)
    # Depth on the plane (where the sphere does not hide it) is the analytic ray-plane depth.
    on_plane = np.linalg.norm(gt.points - (0.03, 0.0, 0.9), axis=-1) > 0.05 + 1e-4
    np.testing.assert_allclose(
        gt.depth[on_plane], plane_depth(camera, plane)[on_plane], atol=tol.PLANE_DEPTH_M, rtol=0
    )
    np.testing.assert_array_equal(gt.depth, gt.points[..., 2])
    # Normals are unit, face the camera, and equal the plane normal on the plane.
    np.testing.assert_allclose(np.linalg.norm(gt.normals[hit], axis=-1), 1.0, atol=tol.GT_NORMAL)
    assert np.all(np.sum(gt.normals * gt.points, axis=-1)[hit] < 0)
    normal = plane.pose.R[:, 2] * -np.sign(plane.pose.R[2, 2])
    np.testing.assert_allclose(
        gt.normals[on_plane], np.broadcast_to(normal, (on_plane.sum(), 3)), atol=tol.GT_NORMAL
    )
    # Absolute phase from proj_uv.
    phase = gt.phase(18.0, "v")
    np.testing.assert_allclose(phase[gt.mask], 2 * np.pi * gt.proj_uv[..., 0][gt.mask] / 18.0)
    assert np.isnan(phase[~gt.mask]).all()


def test_nothing_hit_gives_nan_ground_truth() -> None:
    rig = small_rig()
    scene = Scene([SphereObject(0.02, (0.0, 0.0, 1.0), LAMBERT)])
    gt = trace(rig, scene).gt
    miss = ~gt.mask_hit
    assert miss.mean() > 0.5
    for name in ("depth", "points", "normals", "proj_uv"):
        assert np.isnan(getattr(gt, name)[miss]).all(), name
    assert not (gt.mask_shadow | gt.mask_outside)[miss].any()


# --- scene content ------------------------------------------------------------------------


def test_board_texture_columns_along_x_rows_along_y() -> None:
    # 2 x 3 blocks of 8 x 8 texels: bilinear texture filtering is exact inside a block.
    blocks = np.array([[0.2, 0.4, 0.5], [0.6, 0.8, 1.0]])
    texture = np.kron(blocks, np.ones((8, 8)))
    pose = Pose.from_euler("xyz", [10.0, -15.0, 5.0], t=(0.01, -0.02, 1.0))
    size = (0.3, 0.2)
    rig = small_rig()
    board = TexturedPlaneObject(size, texture, pose, Material(albedo=1.0, specular=0.0))
    blank = TexturedPlaneObject(size, np.ones((2, 3)), pose, Material(albedo=1.0, specular=0.0))
    textured, traced = white_radiance(rig, Scene([board]))
    plain, _ = white_radiance(rig, Scene([blank]))
    gt = traced.gt
    local = pose.inverse().apply(gt.points.reshape(-1, 3)).reshape(gt.points.shape)
    # Block coordinates: column along local +x, row along local +y, origin at the centre.
    col = (local[..., 0] + size[0] / 2) / size[0] * 3 - 0.5
    row = (local[..., 1] + size[1] / 2) / size[1] * 2 - 0.5
    # Away from block edges by more than half a texel plus a pixel footprint.
    centred = (
        interior(gt.mask)
        & (np.abs(col - np.round(col)) < 0.35)
        & (np.abs(row - np.round(row)) < 0.35)
        & (np.round(col) >= 0) & (np.round(col) <= 2) & (np.round(row) >= 0) & (np.round(row) <= 1)
    )  # fmt: skip
    assert centred.sum() > 300
    r_idx = np.round(row[centred]).astype(int)
    c_idx = np.round(col[centred]).astype(int)
    assert len(set(zip(r_idx, c_idx, strict=True))) == 6
    ratio = textured[centred] / plain[centred]
    np.testing.assert_allclose(ratio, blocks[r_idx, c_idx], rtol=tol.RADIANCE_REL)


def test_mesh_file_traces_like_the_same_box(tmp_path) -> None:
    pose = Pose.from_euler("xyz", [25.0, 35.0, 0.0], t=(0.0, 0.0, 1.0))
    extents = (0.12, 0.08, 0.1)
    mesh = trimesh.creation.box(extents=np.asarray(extents) * 1000.0)  # millimetres
    path = tmp_path / "box.stl"
    mesh.export(path)
    rig = small_rig()
    box = trace(rig, Scene([BoxObject(extents, pose)])).gt
    from_file = trace(rig, Scene([MeshObject(path, scale_to_m=0.001, pose=pose)])).gt
    np.testing.assert_array_equal(box.mask_hit, from_file.mask_hit)
    hit = box.mask_hit
    assert hit.sum() > 1000
    np.testing.assert_allclose(from_file.depth[hit], box.depth[hit], atol=tol.SAME_GEOMETRY_M)


def test_moving_the_camera_equals_moving_the_scene(sequence) -> None:
    rig = small_rig()
    cam2world = Pose.from_euler("xyz", [5.0, -20.0, 90.0], t=(0.3, -0.2, 0.5))
    matte = Material(specular=0.0)
    plane_pose = Pose.from_euler("xyz", [10.0, 0.0, 0.0], t=(0.0, 0.0, 1.3))
    in_camera = Scene(
        [SphereObject(0.1, (0.0, 0.02, 1.0), matte)],
        background=PlaneObject((2, 2), plane_pose, matte),
    )
    centre = cam2world.apply(np.array([[0.0, 0.02, 1.0]]))[0]
    in_world = Scene(
        [SphereObject(0.1, tuple(centre), matte)],
        background=PlaneObject((2, 2), cam2world @ plane_pose, matte),
    )
    inputs = {"projector": ProjectorModel(pixel="bilinear"), "sensor": Sensor(exposure=200.0)}
    a = render(rig, in_camera, sequence, **inputs)
    b = render(rig, in_world, sequence, **inputs, cam2world=cam2world)
    np.testing.assert_array_equal(a.gt.mask, b.gt.mask)
    np.testing.assert_allclose(
        b.gt.points[a.gt.mask_hit], a.gt.points[a.gt.mask_hit], atol=tol.SAME_GEOMETRY_M
    )
    # float32 geometry differs in the last bits: 1 DN where rounding flips, more only where
    # a supersample's shadow ray grazes an occluder (a handful of pixels).
    difference = np.abs(a.frames.astype(int) - b.frames.astype(int))
    assert (difference > 0).mean() < tol.SAME_GEOMETRY_FLIP_FRACTION
    assert (difference > 1).sum(axis=0).astype(bool).sum() < tol.SAME_GEOMETRY_GRAZING_PIXELS


def test_glossy_and_metal_materials_render() -> None:
    rig = small_rig()
    peaks = {}
    for name, material in {
        "matte": Material(),
        "glossy": Material(roughness=0.3, specular=0.9),
        "metal": Material(albedo=0.9, roughness=0.3, metal=True),
    }.items():
        white, traced = white_radiance(rig, Scene([SphereObject(0.1, (0, 0, 1.0), material)]))
        lit = traced.gt.mask
        assert np.all(np.isfinite(white)) and np.all(white >= 0)
        peaks[name] = white[lit].max() / np.median(white[lit])
    # A specular highlight makes the brightest pixel stand out from the median.
    assert peaks["glossy"] > 1.5 * peaks["matte"]
    assert peaks["metal"] > 1.5 * peaks["matte"]


# --- frames and sensor --------------------------------------------------------------------


def test_frames_follow_the_sensor_model(sequence) -> None:
    rig = small_rig()
    scene = Scene(
        [SphereObject(0.1, (0, 0, 1.0), LAMBERT)],
        background=PlaneObject((2, 2), Pose(np.eye(3), (0, 0, 1.3)), LAMBERT),
    )
    traced = trace(rig, scene)
    radiance = synthesize(traced, sequence, "bilinear")
    assert radiance.shape == (len(sequence), 160, 160) and radiance.dtype == np.float32
    white = sequence.index_of("white")
    np.testing.assert_allclose(radiance[white], traced.white, rtol=tol.SYNTHESIS_WHITE_REL)
    assert np.all(radiance[sequence.index_of("black")] == 0)

    bilinear = ProjectorModel(pixel="bilinear")
    fixed = render(
        rig, scene, sequence, projector=bilinear, sensor=Sensor(bit_depth=16, exposure=300.0)
    )
    assert fixed.frames.dtype == np.uint16 and fixed.exposure == 300.0
    expected = np.clip(np.rint(radiance * np.float32(300.0)), 0, 65535)
    assert np.abs(fixed.frames - expected).max() <= tol.FRAME_ROUNDING_DN

    auto = render(rig, scene, sequence, projector=bilinear)
    assert auto.frames.dtype == np.uint8
    level = np.percentile(auto.frames[white][traced.white > 0], 99)
    assert abs(level - 0.9 * 255) <= tol.AUTO_EXPOSURE_LEVEL_DN
    bright = render(rig, scene, sequence, sensor=Sensor(exposure=5000.0))
    assert bright.frames.max() == 255  # saturation at full scale, not wrap-around


@pytest.mark.parametrize(("lookup", "bit_depth"), [("nearest", 8), ("bilinear", 16)])
def test_jit_synthesis_gives_the_same_frames(sequence, lookup: str, bit_depth: int) -> None:
    # The Dr.Jit path (used on GPUs) against the sparse path, ambient light included.
    scene = Scene(
        [SphereObject(0.1, (0, 0, 1.0), LAMBERT)],
        background=PlaneObject((2, 2), Pose(np.eye(3), (0, 0, 1.3)), LAMBERT),
        ambient=0.05,
    )
    kwargs = {"projector": ProjectorModel(pixel=lookup), "sensor": Sensor(bit_depth=bit_depth)}
    sparse = render(small_rig(), scene, sequence, synthesis="sparse", **kwargs)
    jit = render(small_rig(), scene, sequence, synthesis="jit", **kwargs)
    assert jit.frames.dtype == sparse.frames.dtype
    # The device path sums the white frame on the device, in another float32 order.
    assert jit.exposure == pytest.approx(sparse.exposure, rel=1e-6)
    difference = np.abs(jit.frames.astype(int) - sparse.frames.astype(int))
    # float32 sums in another order: 1 DN where a value sits at a rounding midpoint.
    assert difference.max() <= tol.FRAME_ROUNDING_DN
    assert (difference > 0).mean() < tol.JIT_FLIP_FRACTION


def test_sensor_rejects_bad_settings() -> None:
    with pytest.raises(InputError, match="bit_depth"):
        Sensor(bit_depth=14)
    with pytest.raises(InputError, match="exposure"):
        Sensor(exposure=-1.0)


# --- errors -------------------------------------------------------------------------------


def test_object_behind_the_camera_is_an_error(sequence) -> None:
    scene = Scene(
        [SphereObject(0.1, (0, 0, 1.0))],
        background=PlaneObject((1, 1), Pose(np.eye(3), (0, 0, -2.0))),
    )
    with pytest.raises(InputError, match=r"scene\.background: expected an object in front"):
        render(small_rig(), scene, sequence)


def test_bad_arguments_are_errors(sequence, monkeypatch) -> None:
    rig, scene = small_rig(), Scene([SphereObject(0.1, (0, 0, 1.0))])
    with pytest.raises(InputError, match="lookup"):
        render(rig, scene, sequence, projector=ProjectorModel(pixel="cubic"))
    with pytest.raises(InputError, match="spp"):
        render(rig, scene, sequence, RenderSettings(spp=3))
    with pytest.raises(InputError, match="variant"):
        render(rig, scene, sequence, RenderSettings(variant="scalar_rgb"))
    monkeypatch.setenv("VIRTUS_MITSUBA_VARIANT", "no_such_variant")
    with pytest.raises(InputError, match="VIRTUS_MITSUBA_VARIANT"):
        trace(rig, scene)
    monkeypatch.setenv("VIRTUS_MITSUBA_VARIANT", "llvm_ad_rgb")
    assert trace(rig, scene).variant == "llvm_ad_rgb"


def test_nothing_lit_is_an_error_with_auto_exposure(sequence) -> None:
    # The sphere sits where the projector does not reach (far left of its field).
    scene = Scene([SphereObject(0.05, (-0.9, 0.0, 1.0))])
    rig0 = small_rig()
    k = rig0.camera.intrinsics
    wide = Intrinsics(k.fx / 8, k.fy / 8, k.cx, k.cy, k.width, k.height)
    rig = Rig(Camera(wide), rig0.projector, rig0.proj2cam)
    from virtus.errors import VirtusError

    with pytest.raises(VirtusError, match="no pixel receives light"):
        render(rig, scene, sequence)
