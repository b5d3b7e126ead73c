"""USD stages: the camera's Isaac/USD parameters against OpenCV (both ways, with pxr's own
frustum as the reference), scene and rig round trips, the stage's prims, and a clear line
without usd-core."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh

from tests import tolerances as tol
from virtus.geometry.devices import Camera, Projector, Rig, default_rig, projected_size
from virtus.geometry.isaac import intrinsics_from_isaac, usd_camera_params
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.pipeline.inputs import load_scene
from virtus.scene.model import (
    BoxObject,
    Material,
    MeshObject,
    PlaneObject,
    Scene,
    SphereObject,
    TexturedPlaneObject,
)

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, UsdLux  # noqa: E402

from virtus.twin.usd import CAMERA, PROJECTOR, export_usd, read_usd  # noqa: E402

#: Off-centre principal points, fx != fy, distortion on both devices.
CAMERA_INTR = Intrinsics(2010.3, 2004.9, 441.7, 512.2, 960, 800, (-0.12, 0.08, 4e-4, -6e-4, 0.01))
PROJECTOR_INTR = Intrinsics(1824.0, 1830.5, 470.1, 540.3, 912, 1140, (0.05, -0.02, 1e-4, 0, 0))
RIG = Rig(Camera(CAMERA_INTR), Projector(PROJECTOR_INTR), default_rig().proj2cam)


def _points(rng: np.random.Generator, n: int = 500) -> np.ndarray:
    """Camera-frame points spread over the image at 0.5-2 m."""
    uv = rng.uniform([0, 0], [CAMERA_INTR.width, CAMERA_INTR.height], size=(n, 2)) - 0.5
    rays = CAMERA_INTR.unproject(uv)
    return rays * rng.uniform(0.5, 2.0, size=(n, 1)) / rays[:, 2:3]


def _frustum_pixels(stage_path, points_world_m: np.ndarray, mpu: float) -> np.ndarray:
    """Pixels of world points through pxr's own camera model (Gf.Camera frustum)."""
    stage = Usd.Stage.Open(str(stage_path))
    camera = UsdGeom.Camera(stage.GetPrimAtPath(CAMERA)).GetCamera(Usd.TimeCode.Default())
    frustum = camera.frustum
    matrix = frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    out = []
    for p in points_world_m / mpu:
        ndc = matrix.Transform(Gf.Vec3d(*p))
        out.append(((ndc[0] + 1) / 2 * CAMERA_INTR.width - 0.5, (1 - ndc[1]) / 2 * 800 - 0.5))
    return np.array(out)


@pytest.mark.parametrize("mpu", [1.0, 0.01])
def test_camera_round_trip_reprojects_identically(tmp_path, mpu):
    stage = export_usd(tmp_path / "rig.usda", rig=RIG, meters_per_unit=mpu)
    back = read_usd(stage)
    assert back.meters_per_unit == mpu
    points = _points(np.random.default_rng(1))
    for device, intr in (("camera", CAMERA_INTR), ("projector", PROJECTOR_INTR)):
        read = getattr(back.rig, device).intrinsics
        np.testing.assert_allclose(
            read.project(points), intr.project(points), atol=tol.ROUND_TRIP_PX, rtol=0
        )
    np.testing.assert_allclose(back.rig.proj2cam.t, RIG.proj2cam.t, atol=tol.USD_ROUND_TRIP_M)
    np.testing.assert_allclose(back.rig.proj2cam.R, RIG.proj2cam.R, atol=tol.FLOAT64_EXACT)


@pytest.mark.parametrize("mpu", [1.0, 0.01])
def test_usd_pinhole_attributes_follow_pxr_frustum(tmp_path, mpu):
    """USD's own projection (Gf.Camera's frustum) of the pinhole attributes we write lands on
    OpenCV's pixels; an off-axis point tells the aperture offsets' sign."""
    pinhole = Intrinsics(2010.3, 2004.9, 441.7 - 60.0, 512.2 + 45.0, 960, 800)
    rig = Rig(Camera(pinhole), Projector(PROJECTOR_INTR), RIG.proj2cam)
    stage = export_usd(tmp_path / "pinhole.usda", rig=rig, meters_per_unit=mpu)
    back = read_usd(stage)
    points = _points(np.random.default_rng(2), 50)
    points[0] = (0.3, -0.25, 1.0)  # off-axis: right and up
    world = back.cam2stage.apply(points)
    through_usd = _frustum_pixels(stage, world, mpu)
    error = np.abs(through_usd - pinhole.project(points)).max()
    assert error <= tol.USD_FLOAT32_PX  # USD stores lens values as float32
    # with either offset's sign flipped the point is 2 x 60 or 2 x 45 px away
    flipped = Intrinsics(pinhole.fx, pinhole.fy, 2 * 479.5 - pinhole.cx, pinhole.cy, 960, 800)
    assert np.abs(through_usd[0] - flipped.project(points[:1])[0]).max() > 100
    # the pinhole attributes alone (as Isaac reads them) give the intrinsics back
    params = usd_camera_params(pinhole, 3e-6, mpu)
    again = intrinsics_from_isaac(
        params.focal_length,
        params.horizontal_aperture,
        960,
        800,
        params.vertical_aperture,
        params.horizontal_aperture_offset,
        params.vertical_aperture_offset,
    )
    np.testing.assert_allclose(again.K, pinhole.K, atol=tol.ISAAC_ROUND_TRIP_PX)


def test_stage_has_the_expected_prims_and_attributes(tmp_path):
    pattern = np.zeros((1140, 912), np.uint8)
    pattern[0, 0] = 255
    stage_path = export_usd(tmp_path / "s.usda", rig=RIG, meters_per_unit=0.01, pattern=pattern)
    stage = Usd.Stage.Open(str(stage_path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    camera = stage.GetPrimAtPath(CAMERA)
    assert camera.IsA(UsdGeom.Camera)
    # usd-core does not know Omniverse's schema: it is in the prim's apiSchemas list
    assert (
        "OmniLensDistortionOpenCvPinholeAPI"
        in camera.GetMetadata("apiSchemas").GetAddedOrExplicitItems()
    )
    assert camera.GetAttribute("omni:lensdistortion:model").Get() == "opencvPinhole"
    assert camera.GetAttribute("omni:lensdistortion:opencvPinhole:k1").Get() == pytest.approx(-0.12)
    # Isaac's world: the camera looks along +X with +Z up
    l2w = np.array(UsdGeom.Xformable(camera).ComputeLocalToWorldTransform(0)).T
    np.testing.assert_allclose(l2w[:3, :3] @ [0, 0, -1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(l2w[:3, :3] @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    light = stage.GetPrimAtPath(PROJECTOR)
    assert light.IsA(UsdLux.RectLight) and light.GetAttribute("isProjector").Get() is True
    assert "ShapingAPI" in light.GetMetadata("apiSchemas").GetAddedOrExplicitItems()
    rect = UsdLux.RectLight(light)
    width, height = projected_size(PROJECTOR_INTR, 1.0)
    assert rect.GetWidthAttr().Get() == pytest.approx(width / 0.01, rel=1e-6)
    assert rect.GetHeightAttr().Get() == pytest.approx(height / 0.01, rel=1e-6)
    texture = tmp_path / rect.GetTextureFileAttr().Get().path
    import cv2

    image = cv2.imread(str(texture), cv2.IMREAD_UNCHANGED)
    # the pattern's pixel (0, 0) is the texture's last column (texture min at +X)
    assert image.shape == (1140, 912) and image[0, -1] == 255 and image.sum() == 255
    # the projector sits 12.5 cm left of (+Y) and 10 cm below (-Z) the camera
    position = np.array(UsdGeom.Xformable(light).ComputeLocalToWorldTransform(0)).T[:3, 3]
    np.testing.assert_allclose(position, [0.0, 12.5, -10.0], atol=1e-12)


def _scene(tmp_path) -> Scene:
    mesh_file = tmp_path / "part.stl"
    trimesh.creation.icosphere(subdivisions=2, radius=40.0).export(mesh_file)  # mm, float32
    texture = np.random.default_rng(0).uniform(0, 1, size=(20, 30))
    return Scene(
        objects=(
            SphereObject(0.05, (0.02, -0.01, 0.9), Material(0.7, 0.5, 0.3)),
            BoxObject((0.05, 0.08, 0.03), Pose.from_euler("xyz", (10, 20, 30), t=(0.1, 0, 1))),
            MeshObject(
                mesh_file,
                0.001,
                Pose.from_euler("xyz", (5, -15, 40), t=(-0.1, 0.05, 1.05)),
                Material(0.9, 0.2, 0.5, metal=True),
            ),
            TexturedPlaneObject(
                (0.3, 0.2), texture, Pose.from_euler("xyz", (0, 30, 0), t=(0, 0.1, 1.1))
            ),
        ),
        background=PlaneObject((2.0, 1.5), Pose(np.eye(3), (0, 0, 1.3))),
        ambient=0.05,
    )


@pytest.mark.parametrize("mpu", [1.0, 0.01])
def test_scene_round_trip_keeps_geometry(tmp_path, mpu):
    scene = _scene(tmp_path)
    stage = export_usd(tmp_path / "scene.usda", scene=scene, rig=RIG, meters_per_unit=mpu)
    back = load_scene(stage)  # load_scene dispatches on .usda
    assert len(back.objects) == 4 and back.ambient == 0.05
    sphere, box, mesh, board = back.objects
    assert sphere.radius_m == pytest.approx(0.05, abs=tol.USD_ROUND_TRIP_M)
    np.testing.assert_allclose(sphere.center_m, (0.02, -0.01, 0.9), atol=tol.USD_ROUND_TRIP_M)
    assert sphere.material == Material(0.7, 0.5, 0.3)
    np.testing.assert_allclose(box.size_m, (0.05, 0.08, 0.03), atol=tol.USD_ROUND_TRIP_M)
    for got, want in ((box, scene.objects[1]), (board, scene.objects[3])):
        np.testing.assert_allclose(got.pose.t, want.pose.t, atol=tol.USD_ROUND_TRIP_M)
        np.testing.assert_allclose(got.pose.R, want.pose.R, atol=tol.FLOAT64_EXACT)
    np.testing.assert_allclose(
        mesh.load()[0], scene.objects[2].load()[0], atol=tol.USD_ROUND_TRIP_M, rtol=0
    )
    assert mesh.material.metal and mesh.material.roughness == 0.2
    assert mesh.material.specular == 0.5
    np.testing.assert_allclose(board.size_m, (0.3, 0.2), atol=tol.USD_ROUND_TRIP_M)
    np.testing.assert_allclose(  # 16-bit PNG texture
        board.texture_image(), scene.objects[3].texture, atol=1 / 65535
    )
    assert back.background.size_m == pytest.approx((2.0, 1.5), abs=tol.USD_ROUND_TRIP_M)


def test_scene_is_read_in_the_stage_cameras_frame(tmp_path):
    """A stage made elsewhere: a camera 2 m up the +Y axis looking down -Y; a sphere at the
    world origin is 2 m in front of it."""
    path = tmp_path / "other.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    camera = UsdGeom.Camera.Define(stage, "/cam")
    camera.CreateFocalLengthAttr(50.0)
    camera.CreateHorizontalApertureAttr(20.0)
    camera.CreateVerticalApertureAttr(20.0)
    # look along -Y: local -Z -> -Y (local +Y, its image up, -> -Z)
    camera.AddTranslateOp().Set(Gf.Vec3d(0, 200, 0))
    camera.AddRotateXOp().Set(-90.0)
    UsdGeom.Sphere.Define(stage, "/ball").CreateRadiusAttr(10.0)
    stage.Save()
    contents = read_usd(path)
    assert contents.camera is None  # pinhole attributes alone need an image size
    (ball,) = contents.scene.objects
    np.testing.assert_allclose(ball.center_m, (0.0, 0.0, 2.0), atol=1e-12)
    assert ball.radius_m == pytest.approx(0.1)
    from virtus.twin.usd import usd_camera_intrinsics

    opened = Usd.Stage.Open(str(path))
    intr = usd_camera_intrinsics(opened.GetPrimAtPath("/cam"), (100, 100))
    assert intr.fx == pytest.approx(250.0) and intr.cx == pytest.approx(49.5)


def test_without_usd_core_the_commands_say_how_to_install_it(tmp_path, monkeypatch, capsys):
    from virtus.cli import main

    monkeypatch.setitem(sys.modules, "pxr", None)
    for argv in (
        ["export-usd", "--out", str(tmp_path / "s.usda")],
        ["capture", "--scene", str(tmp_path / "s.usda"), "--out", str(tmp_path / "c")],
    ):
        (tmp_path / "s.usda").write_text("#usda 1.0\n")
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2
        err = capsys.readouterr().err.strip()
        assert err == "virtus: error: USD support needs usd-core: pip install 'virtus-fpp[usd]'"
