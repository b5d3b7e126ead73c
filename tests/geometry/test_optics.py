"""Tests of the device models: projection, distortion, poses, rig schema, Isaac, inverse camera."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig, projected_size
from virtus.geometry.isaac import intrinsics_from_isaac, isaac_params
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

#: A realistic 960 x 960 lens with barrel distortion, tangential terms and k3 (about 25 px of
#: displacement in the corners), and an off-centre principal point.
REALISTIC = Intrinsics(2285.0, 2290.0, 470.3, 488.9, 960, 960, (-0.21, 0.18, 8e-4, -6e-4, -0.05))
#: The rational model with k4..k6.
RATIONAL = Intrinsics(
    1800.0, 1795.0, 450.0, 570.0, 912, 1140, (-0.1, 0.05, 1e-4, 2e-4, 0.01, 0.02, -0.01, 0.005)
)


def random_points(rng: np.random.Generator, n: int, depth=(0.4, 1.5)) -> np.ndarray:
    """(n, 3) points inside a ~25 deg half-angle cone in front of the device."""
    z = rng.uniform(*depth, n)
    xy = rng.uniform(-0.2, 0.2, (n, 2)) * z[:, None]
    return np.column_stack([xy, z])


@pytest.mark.parametrize("intrinsics", [REALISTIC, RATIONAL], ids=["k5", "rational"])
def test_unproject_then_project_round_trip_over_the_full_image(intrinsics):
    pixels = intrinsics.pixel_grid().reshape(-1, 2)
    # include the outer pixel edges, where distortion is strongest
    edges = np.array([[-0.5, -0.5], [intrinsics.width - 0.5, intrinsics.height - 0.5]])
    pixels = np.vstack([pixels, edges])
    rays = intrinsics.unproject(pixels)
    assert np.isfinite(rays).all()
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=tol.FLOAT64_EXACT)
    back = intrinsics.project(rays * 0.8)
    assert np.abs(back - pixels).max() < tol.ROUND_TRIP_PX


@pytest.mark.parametrize("intrinsics", [REALISTIC, RATIONAL], ids=["k5", "rational"])
def test_project_agrees_with_opencv(intrinsics):
    points = random_points(np.random.default_rng(1), 500)
    K, dist = intrinsics.to_opencv()
    reference, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, dist)
    assert np.abs(intrinsics.project(points) - reference[:, 0]).max() < tol.OPENCV_AGREEMENT_PX


def test_undistort_agrees_with_opencv_where_opencv_converges():
    # cv2.undistortPoints (with criteria) iterates a fixed-point scheme; with enough iterations
    # it reaches the
    # same inverse, which checks our Newton solver against an independent one.
    pixels = REALISTIC.pixel_grid()[::37, ::41].reshape(-1, 2)
    K, dist = REALISTIC.to_opencv()
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    reference = cv2.undistortPoints(pixels[:, None], K, dist, None, None, None, criteria)[:, 0]
    xy = REALISTIC.undistort_normalized(
        (pixels - [REALISTIC.cx, REALISTIC.cy]) / [REALISTIC.fx, REALISTIC.fy]
    )
    assert np.abs(xy - reference).max() * REALISTIC.fx < tol.OPENCV_UNDISTORT_PX


def test_pixel_centre_convention():
    intrinsics = Intrinsics(100.0, 100.0, 1.5, 0.5, 4, 2)
    # the principal point (1.5, 0.5) lies between the two middle pixel centres: the image centre
    ray = intrinsics.unproject([[1.5, 0.5]])
    np.testing.assert_allclose(ray, [[0.0, 0.0, 1.0]])
    grid = intrinsics.pixel_grid()
    assert grid.shape == (2, 4, 2)
    np.testing.assert_array_equal(grid[1, 3], [3.0, 1.0])  # [row, col] holds (u=col, v=row)


def test_points_behind_the_device_project_to_nan():
    pixels = REALISTIC.project([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.isnan(pixels[:2]).all() and np.isfinite(pixels[2]).all()


def test_scaled_intrinsics_keep_pixel_edges():
    small = REALISTIC.scaled(0.25)
    assert (small.width, small.height) == (240, 240)
    point = [[0.05, -0.03, 1.0]]
    big_px, small_px = REALISTIC.project(point)[0], small.project(point)[0]
    np.testing.assert_allclose((big_px + 0.5) * 0.25 - 0.5, small_px, atol=tol.FLOAT64_EXACT)


def test_opencv_and_dict_round_trips():
    K, dist = RATIONAL.to_opencv()
    assert Intrinsics.from_opencv(K, dist, 912, 1140) == RATIONAL
    assert Intrinsics.from_dict(json.loads(json.dumps(REALISTIC.to_dict()))) == REALISTIC


# -- poses --------------------------------------------------------------------------------------


def test_pose_composition_inverse_and_parameterisations():
    rng = np.random.default_rng(7)
    a2b = Pose.from_rotvec(rng.normal(size=3), rng.normal(size=3))
    b2c = Pose.from_euler("xyz", rng.uniform(-90, 90, 3), t=rng.normal(size=3))
    points_a = rng.normal(size=(20, 3))
    a2c = b2c @ a2b
    np.testing.assert_allclose(
        a2c.apply(points_a), b2c.apply(a2b.apply(points_a)), atol=tol.FLOAT64_EXACT
    )
    np.testing.assert_allclose((a2b.inverse() @ a2b).matrix, np.eye(4), atol=tol.FLOAT64_EXACT)
    np.testing.assert_allclose(
        Pose.from_quat(a2b.as_quat(), a2b.t).R, a2b.R, atol=tol.FLOAT64_EXACT
    )
    np.testing.assert_allclose(Pose.from_rotvec(a2b.rotvec).R, a2b.R, atol=tol.FLOAT64_EXACT)
    R_cv, _ = cv2.Rodrigues(a2b.rotvec)
    np.testing.assert_allclose(R_cv, a2b.R, atol=tol.FLOAT64_EXACT)
    assert Pose.from_dict(json.loads(json.dumps(a2c.to_dict()))) == a2c
    np.testing.assert_allclose(Pose.from_matrix(a2c.matrix).matrix, a2c.matrix)
    np.testing.assert_allclose(
        a2c.apply_direction(points_a), a2c.apply(points_a) - a2c.t, atol=tol.FLOAT64_EXACT
    )


def test_look_at_points_the_device_axes():
    eye, target = np.array([0.3, -0.2, 0.1]), np.array([0.0, 0.1, 1.2])
    device2world = Pose.look_at(eye, target, image_down=(0, 1, 0))
    z_world = device2world.apply_direction([[0, 0, 1.0]])[0]
    np.testing.assert_allclose(z_world, (target - eye) / np.linalg.norm(target - eye))
    y_world = device2world.apply_direction([[0, 1.0, 0]])[0]
    assert y_world[1] > 0.9  # image-down stays (almost) world-down
    np.testing.assert_allclose(device2world.t, eye)


# -- rig ----------------------------------------------------------------------------------------


def test_default_rig_reproduces_the_paper():
    rig = default_rig()
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    assert (cam.width, cam.height, proj.width, proj.height) == (960, 960, 912, 1140)
    assert cam.fx == pytest.approx(2285.77, abs=tol.PAPER_FOCAL_PX) and cam.fx == cam.fy
    assert (cam.cx, cam.cy) == (479.5, 479.5)
    assert (proj.fx, proj.fy, proj.cx, proj.cy) == (1824.0, 1824.0, 455.5, 569.5)
    np.testing.assert_allclose(rig.proj2cam.t, [-0.125, 0.1, 0.0])
    # toe-in: the projector's optical axis passes through the camera axis at 1 m
    centre_in_proj = rig.cam2proj.apply([[0.0, 0.0, 1.0]])[0]
    np.testing.assert_allclose(centre_in_proj[:2], 0.0, atol=tol.FLOAT64_EXACT)
    np.testing.assert_allclose(proj.project(centre_in_proj[None])[0], [455.5, 569.5])
    # coverage: every camera pixel of a fronto-parallel plane at 1 m is lit by the projector
    corners = cam.unproject([[-0.5, -0.5], [959.5, -0.5], [-0.5, 959.5], [959.5, 959.5]])
    on_plane = corners / corners[:, 2:3]
    proj_px = proj.project(rig.cam2proj.apply(on_plane))
    assert np.all((proj_px > 0) & (proj_px < [proj.width - 1, proj.height - 1]))


def test_rig_json_round_trip_and_schema(tmp_path):
    rig = default_rig()
    path = rig.save_json(tmp_path / "rig.json")
    data = json.loads(path.read_text())
    assert set(data) == {"units", "camera", "projector", "proj2cam"}
    assert data["units"] == "m"
    assert set(data["camera"]) == {"width", "height", "K", "dist"}
    assert set(data["proj2cam"]) == {"R", "t"}
    loaded = Rig.load_json(path)
    assert loaded == rig
    # calibration results add fields; readers ignore them
    data["rms_px"] = {"camera": 0.01}
    assert Rig.from_dict(data) == rig


def test_isaac_parameters_round_trip():
    rig = default_rig()
    pixel = 20.9995 / 960
    params = isaac_params(rig.camera.intrinsics, pixel)
    assert params.focal_length == pytest.approx(50.0)
    assert params.horizontal_aperture == pytest.approx(20.9995)
    assert params.horizontal_aperture_offset == pytest.approx(0.0)
    shifted = Intrinsics(2000.0, 2000.0, 500.25, 430.0, 960, 720)
    p = isaac_params(shifted, 0.01)
    back = intrinsics_from_isaac(
        p.focal_length,
        p.horizontal_aperture,
        960,
        720,
        p.vertical_aperture,
        p.horizontal_aperture_offset,
        p.vertical_aperture_offset,
    )
    for name in ("fx", "fy", "cx", "cy"):
        assert getattr(back, name) == pytest.approx(
            getattr(shifted, name), abs=tol.ISAAC_ROUND_TRIP_PX
        )


def test_inverse_camera_model_of_the_default_projector():
    projector = default_rig().projector.intrinsics
    width, height = projected_size(projector, 1.0)
    assert abs(width - 0.500) < tol.PROJECTED_SIZE_M
    assert abs(height - 0.625) < tol.PROJECTED_SIZE_M
    distances = np.linspace(0.4, 1.0, 7)
    sizes = np.array([projected_size(projector, z) for z in distances])
    # exactly linear in Z: size / Z is the same at every distance
    np.testing.assert_allclose(
        sizes / distances[:, None], [[0.5, 0.625]] * 7, rtol=tol.FLOAT64_EXACT
    )


# -- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"fx": 0.0}, "fx"),
        ({"fy": -5.0}, "fy"),
        ({"cx": float("nan")}, "cx"),
        ({"width": 0}, "width"),
        ({"height": 10.5}, "height"),
        ({"dist": (0.1, 0.2, 0.3)}, "dist"),
        ({"dist": (0.1, float("nan"), 0.0, 0.0)}, "dist"),
        ({"fx": 10**400}, "fx"),
        ({"cy": float("inf")}, "cy"),
    ],
)
def test_bad_intrinsics_name_the_argument(kwargs, name):
    args = {"fx": 100.0, "fy": 100.0, "cx": 5.0, "cy": 5.0, "width": 10, "height": 10}
    args.update(kwargs)
    with pytest.raises(InputError, match=rf"^{name}: expected"):
        Intrinsics(**args)


def test_bad_arrays_and_rotations_are_refused():
    with pytest.raises(InputError, match=r"^points: expected an array of shape \(N, 3\)"):
        REALISTIC.project(np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"^pixels: expected"):
        REALISTIC.unproject(np.zeros(2))
    with pytest.raises(InputError, match=r"^points: expected finite values"):
        REALISTIC.project([[0.0, np.inf, 1.0]])
    with pytest.raises(InputError, match=r"^R: expected an orthonormal rotation"):
        Pose(np.diag([1.0, 1.0, 1.01]), np.zeros(3))
    with pytest.raises(InputError, match=r"^R: expected an orthonormal rotation"):
        Pose(np.diag([1.0, 1.0, -1.0]), np.zeros(3))  # a reflection
    with pytest.raises(InputError, match=r"^t: expected"):
        Pose(np.eye(3), [1.0, 2.0])
    with pytest.raises(InputError, match=r"^rig.units: expected"):
        Rig.from_dict({**default_rig().to_dict(), "units": "mm"})
    with pytest.raises(InputError, match=r"^proj2cam.R: expected"):
        Rig.from_dict({**default_rig().to_dict(), "proj2cam": {"R": np.eye(3) * 2, "t": [0, 0, 0]}})
    with pytest.raises(InputError, match=r"^distance_m: expected a positive number"):
        projected_size(REALISTIC, -1.0)


def test_devices_expose_their_size():
    rig = Rig(Camera(REALISTIC), Projector(RATIONAL), Pose.identity())
    assert (rig.camera.width, rig.projector.height) == (960, 1140)
    assert rig.baseline_m == 0.0


# -- rig files: misspelt keys and garbage -------------------------------------------------------


def test_misspelt_device_and_pose_keys_are_refused_by_name():
    data = default_rig().to_dict()
    data["camera"]["distortion"] = data["camera"].pop("dist")
    with pytest.raises(InputError) as error:
        Rig.from_dict(data)
    assert str(error.value) == (
        "camera: expected only the keys width, height, K, dist, "
        "got \"unknown key 'distortion' (did you mean 'dist'?)\""
    )
    data = default_rig().to_dict()
    data["projector"]["k"] = data["projector"].pop("K")
    with pytest.raises(InputError, match=r"^projector: .*unknown key 'k' \(did you mean 'K'\?\)"):
        Rig.from_dict(data)
    data = default_rig().to_dict()
    data["proj2cam"]["T"] = data["proj2cam"].pop("t")
    with pytest.raises(InputError, match=r"^proj2cam: .*unknown key 'T' \(did you mean 't'\?\)"):
        Rig.from_dict(data)
    data = default_rig().to_dict()
    data["projecter"] = data.pop("projector")
    with pytest.raises(InputError, match=r"^rig: .*missing 'projector' \(is 'projecter' misspelt"):
        Rig.from_dict(data)
    with pytest.raises(InputError, match=r"^proj2cam: expected an object with the keys R, t"):
        Rig.from_dict({**default_rig().to_dict(), "proj2cam": [[1, 0, 0]]})


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[1, 2, 3]", r"expected a JSON object, got 'a JSON array'"),
        ('{"camera": {"fx": NaN}}', r"expected finite numbers \(JSON has no NaN"),
        ('{"units": "m",\n "camera": }', r"expected valid JSON, got 'Expecting value at line 2"),
        ("[" * 50_000, r"expected JSON nested at most 64 deep"),
    ],
    ids=["list", "nan", "syntax", "deep"],
)
def test_malformed_rig_files_give_one_line(tmp_path, text, message):
    path = tmp_path / "rig.json"
    path.write_text(text)
    with pytest.raises(InputError, match=rf"^rig .*rig\.json: {message}") as error:
        Rig.load_json(path)
    assert "\n" not in str(error.value)
    path.write_bytes(b"\x93NUMPY\x01\x00")
    with pytest.raises(InputError, match=r"^rig .*rig\.json: expected UTF-8 text"):
        Rig.load_json(path)
    with pytest.raises(InputError, match=r"^rig: expected an existing JSON file"):
        Rig.load_json(tmp_path / "missing.json")


def test_absurd_image_sizes_are_refused_before_allocating():
    with pytest.raises(InputError, match=r"^width: expected at most 32768 pixels, got '100000'"):
        Intrinsics(1e5, 1e5, 5e4, 5e4, 100_000, 100_000)
    with pytest.raises(InputError, match=r"^width x height: expected at most 268,435,456 pixels"):
        Intrinsics(1e4, 1e4, 10000.0, 10000.0, 20_000, 20_000)
    assert Intrinsics(1e4, 1e4, 5000.0, 100.0, 32768, 200).width == 32768
