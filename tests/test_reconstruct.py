"""Triangulation against exact correspondences built from known 3D points."""

import numpy as np
import pytest

from tests.tolerances import NORMALS_EXACT, TRIANGULATION_M
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.reconstruct import (
    depth_edge_mask,
    depth_map,
    normals_from_points,
    points_from_decoded,
    triangulate,
    valid_points,
)


def _distorted_rig() -> Rig:
    """The default rig with realistic lens distortion and off-centre principal points."""
    rig = default_rig()
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    cam = Intrinsics(cam.fx, cam.fy, cam.cx + 3.0, cam.cy - 2.0, cam.width, cam.height,
                     (-0.2, 0.15, 0.001, -0.0008, 0.02))  # fmt: skip
    proj = Intrinsics(proj.fx, proj.fy, proj.cx - 4.0, proj.cy + 5.0, proj.width, proj.height,
                      (0.1, -0.05, -0.0005, 0.0007))  # fmt: skip
    return Rig(Camera(cam), Projector(proj), rig.proj2cam)


def _random_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Points in the camera frame inside the rig's working volume (0.7-1.3 m)."""
    return np.stack(
        [rng.uniform(-0.15, 0.15, n), rng.uniform(-0.15, 0.15, n), rng.uniform(0.7, 1.3, n)],
        axis=1,
    )


def _correspondences(rig: Rig, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cam_px = rig.camera.intrinsics.project(points)
    proj_uv = rig.projector.intrinsics.project(rig.cam2proj.apply(points))
    return cam_px, proj_uv


@pytest.mark.parametrize("distorted", [False, True], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("use", ["uv", "u", "v"])
def test_exact_correspondences_return_the_points(distorted: bool, use: str) -> None:
    rig = _distorted_rig() if distorted else default_rig()
    points = _random_points(np.random.default_rng(1), 5_000)
    cam_px, proj_uv = _correspondences(rig, points)
    out = triangulate(rig, cam_px, proj_uv, use=use)
    assert np.isfinite(out).all()
    assert np.max(np.abs(out - points)) < TRIANGULATION_M


def test_single_coordinate_ignores_the_other() -> None:
    rig = _distorted_rig()
    points = _random_points(np.random.default_rng(2), 1000)
    cam_px, proj_uv = _correspondences(rig, points)
    only_u = proj_uv.copy()
    only_u[:, 1] = np.nan
    assert np.max(np.abs(triangulate(rig, cam_px, only_u, use="u") - points)) < TRIANGULATION_M
    assert np.isnan(triangulate(rig, cam_px, only_u, use="uv")).all()
    assert np.isnan(triangulate(rig, cam_px, only_u, use="v")).all()


def test_nan_rows_stay_nan_and_others_are_exact() -> None:
    rig = default_rig()
    points = _random_points(np.random.default_rng(3), 100)
    cam_px, proj_uv = _correspondences(rig, points)
    proj_uv[::3] = np.nan
    out = triangulate(rig, cam_px, proj_uv)
    assert np.isnan(out[::3]).all()
    keep = np.ones(100, dtype=bool)
    keep[::3] = False
    assert np.max(np.abs(out[keep] - points[keep])) < TRIANGULATION_M


def test_point_behind_the_devices_is_nan() -> None:
    rig = default_rig()
    # The camera ray through the image centre and a projector ray that diverge in front of
    # both devices: their closest approach lies behind the projector.
    cam_px = np.array([[479.5, 479.5]])
    proj_uv = np.array([[0.0, 569.5]])  # far left edge: the ray heads away from the camera ray
    out = triangulate(rig, cam_px, proj_uv)
    assert np.isnan(out).all()


def _seen_from_behind(rig: Rig, point_cam: np.ndarray, behind: str) -> tuple[np.ndarray, ...]:
    """The correspondence of a point that lies behind one device (camera or projector).

    That device's pixel is the one of the point mirrored through its centre: the same line
    of sight, so the two rays (or the ray and the projector's plane) meet exactly at the
    point, which is where triangulation must refuse to put it.
    """
    point_proj = rig.cam2proj.apply(point_cam[None])[0]
    assert (point_cam[2] < 0) == (behind == "camera") and (point_proj[2] < 0) == (
        behind == "projector"
    )
    cam_px = rig.camera.intrinsics.project(np.sign(point_cam[2]) * point_cam[None])
    proj_uv = rig.projector.intrinsics.project(np.sign(point_proj[2]) * point_proj[None])
    return cam_px, proj_uv


@pytest.mark.parametrize("use", ["uv", "u", "v"])
def test_points_behind_either_device_are_nan(use: str) -> None:
    # Pinhole devices: far off-axis lines of sight stay exactly invertible (with distortion
    # they would be NaN for another reason, an undistortion that does not converge).
    rig = default_rig()
    # (3, 0, 0.2) m in the projector frame lies behind the camera's centre plane; (-3, 0, 0.2)
    # m in the camera frame lies behind the projector's (toe-in: its axis turns towards +x).
    behind_camera = rig.proj2cam.apply(np.array([[3.0, 0.0, 0.2]]))[0]
    behind_projector = np.array([-3.0, 0.0, 0.2])
    in_front = np.array([0.05, -0.03, 0.9])
    for point, behind in ((behind_camera, "camera"), (behind_projector, "projector")):
        cam_px, proj_uv = _seen_from_behind(rig, point, behind)
        assert np.isnan(triangulate(rig, cam_px, proj_uv, use=use)).all(), behind
    # The control: the same construction for a visible point gives it back.
    cam_px, proj_uv = _correspondences(rig, in_front[None])
    np.testing.assert_allclose(triangulate(rig, cam_px, proj_uv, use=use)[0], in_front,
                               atol=TRIANGULATION_M)  # fmt: skip


def test_image_functions_on_a_plane() -> None:
    """A fronto-parallel plane at 0.9 m: depth map is 0.9 everywhere it is lit."""
    full = _distorted_rig()
    # A quarter-resolution camera keeps the test fast; the maths is per pixel.
    rig = Rig(Camera(full.camera.intrinsics.scaled(0.25)), full.projector, full.proj2cam)
    intr = rig.camera.intrinsics
    rays = intr.unproject(intr.pixel_grid().reshape(-1, 2))
    points = rays * (0.9 / rays[:, 2:3])
    proj_uv = rig.projector.intrinsics.project(rig.cam2proj.apply(points))
    proj_uv = proj_uv.reshape(intr.height, intr.width, 2)
    mask = np.zeros((intr.height, intr.width), dtype=bool)
    mask[25:-25, 12:-12] = True
    depth = depth_map(rig, proj_uv, mask)
    assert np.isnan(depth[~mask]).all()
    assert np.max(np.abs(depth[mask] - 0.9)) < TRIANGULATION_M
    point_map = points_from_decoded(rig, proj_uv, mask, use="u")
    flat, pixels = valid_points(point_map)
    assert flat.shape == (int(mask.sum()), 3)
    assert np.array_equal(point_map[pixels[:, 0], pixels[:, 1]], flat)
    normals = normals_from_points(point_map)
    inner = normals[mask]
    assert np.max(np.abs(inner - (0.0, 0.0, -1.0))) < NORMALS_EXACT


def test_bad_input_names_the_argument() -> None:
    rig = default_rig()
    with pytest.raises(InputError, match="cam_px"):
        triangulate(rig, np.zeros((3, 3)), np.zeros((3, 2)))
    with pytest.raises(InputError, match="cam_px"):
        triangulate(rig, np.full((3, 2), np.nan), np.zeros((3, 2)))
    with pytest.raises(InputError, match="proj_uv"):
        triangulate(rig, np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(InputError, match="use"):
        triangulate(rig, np.zeros((3, 2)), np.zeros((3, 2)), use="w")
    with pytest.raises(InputError, match="proj_uv"):
        points_from_decoded(rig, np.zeros((10, 10, 2)))
    with pytest.raises(InputError, match="mask"):
        points_from_decoded(rig, np.zeros((960, 960, 2)), mask=np.ones((960, 960)))


def test_depth_edge_mask_flags_both_sides_of_a_jump() -> None:
    rig = default_rig()
    fx = rig.camera.intrinsics.fx
    intr = rig.camera.intrinsics
    rays = intr.unproject(intr.pixel_grid().reshape(-1, 2)).reshape(intr.height, intr.width, 3)
    depth = np.where(np.arange(intr.width)[None, :] < 400, 1.0, 1.3)  # a step at column 400
    points = rays * (depth / rays[..., 2])[..., None]
    # A steep but continuous slope (80 deg from the view direction) is not an edge.
    slope = rays * ((1.0 + np.arange(intr.width)[None, :] * 5.7 / fx) / rays[..., 2])[..., None]
    edges = depth_edge_mask(points, fx)
    assert edges[:, 399].all() and edges[:, 400].all()
    assert edges.sum() == 2 * intr.height
    assert not depth_edge_mask(slope, fx).any()
    points[10, 10] = np.nan  # invalid neighbours are not edges
    assert not depth_edge_mask(points, fx)[9:12, 9:12].any()
    with pytest.raises(InputError, match="focal_px"):
        depth_edge_mask(points, 0.0)
