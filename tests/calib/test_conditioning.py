"""Tests of the conditioning check and the parameter uncertainties
(:mod:`virtus.calib.conditioning`) and of the lens-model option (:mod:`virtus.calib.solve`),
on synthetic correspondences: board points projected through a known rig with Gaussian pixel
noise (no rendering)."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from tests import tolerances as tol
from virtus.calib.board import board_from_spec
from virtus.calib.conditioning import (
    COVERAGE_GRID,
    FOCAL_REL_STD_LEVEL,
    TILT_SPREAD_LEVEL_DEG,
    coverage,
    warn_conditioning,
)
from virtus.calib.poses import pose_problem, random_poses
from virtus.calib.solve import (
    DISTORTION_MODELS,
    StereoCalibration,
    calibrate_correspondences,
    opencv_single_thread,
)
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

RIG = default_rig()
BOARD = board_from_spec("7x13")
#: Pixel noise of the re-observations (a real bench's centroids: a few 0.1 px).
NOISE_PX = 0.2
REPEATS = 20


def observe(rig: Rig, poses: list[Pose], obj: np.ndarray, noise: float, seed: int):
    """Camera and projector pixels of ``obj`` in every pose, with Gaussian noise."""
    rng = np.random.default_rng(seed)
    cam = [rig.camera.intrinsics.project(p.apply(obj)) for p in poses]
    proj = [rig.projector.intrinsics.project(rig.cam2proj.apply(p.apply(obj))) for p in poses]
    return (
        [c + rng.normal(0.0, noise, c.shape) for c in cam],
        [q + rng.normal(0.0, noise, q.shape) for q in proj],
    )


def solve(rig, poses, obj, noise, seed, **options) -> StereoCalibration:
    cam, proj = observe(rig, poses, obj, noise, seed)
    names = [f"pose_{k:02d}" for k in range(len(poses))]
    sizes = (rig.camera.intrinsics.size, rig.projector.intrinsics.size)
    with opencv_single_thread():
        return calibrate_correspondences(names, [obj] * len(poses), cam, proj, *sizes, **options)


def face_on_poses(n: int = 12, seed: int = 1) -> list[Pose]:
    """``n`` boards tilted 1.1-2.5 deg (random directions) near the working distance."""
    rng = np.random.default_rng(seed)
    poses = []
    while len(poses) < n:
        axis = rng.uniform(0, 2 * np.pi)
        tilt = np.radians(rng.uniform(1.1, 2.5))
        t = (rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08), rng.uniform(0.9, 1.1))
        pose = Pose.from_rotvec(tilt * np.array([np.cos(axis), np.sin(axis), 0.0]), t)
        if pose_problem(RIG, BOARD, pose) is None:
            poses.append(pose)
    return poses


def spread_poses() -> list[Pose]:
    """12 seeded random poses (tilts up to 35 deg, rolls up to 45 deg)."""
    return [p.board2cam for p in random_poses(RIG, BOARD, 12, 3)]


@pytest.mark.parametrize("kind", ["face_on", "spread"])
def test_reported_focal_uncertainty_matches_the_spread_of_re_observations(kind):
    """The camera's reported sigma_fx against the standard deviation of fx over 20 noisy
    re-observations of the same poses (measured 26.6 vs 23.3 px face-on, 2.46 vs 2.03 px
    spread); a face-on set warns, a well-spread one does not."""
    poses = face_on_poses() if kind == "face_on" else spread_poses()
    results = [solve(RIG, poses, BOARD.object_points, NOISE_PX, 100 + i) for i in range(REPEATS)]
    fx = np.array([r.rig.camera.intrinsics.fx for r in results])
    measured = float(np.std(fx, ddof=1))
    reported = np.array([r.uncertainty["camera"]["fx"] for r in results])
    factor = tol.CONDITIONING_SIGMA_FACTOR
    assert measured / factor <= reported.min() and reported.max() <= measured * factor, (
        measured,
        reported,
    )
    # the baseline's reported uncertainty too (first-order propagation from cam2proj)
    baselines = np.array([r.rig.baseline_m for r in results])
    sigma_b = np.array([r.uncertainty["proj2cam"]["baseline_m"] for r in results])
    spread_b = float(np.std(baselines, ddof=1))
    assert spread_b / factor <= np.median(sigma_b) <= spread_b * factor, (spread_b, sigma_b)
    check = results[0].conditioning
    if kind == "face_on":
        assert check["tilt_spread_deg"] < TILT_SPREAD_LEVEL_DEG
        assert check["camera"]["focal_rel_std"] > FOCAL_REL_STD_LEVEL
        assert any("tilt little" in w for w in check["warnings"])
        assert any("camera's focal length is uncertain" in w for w in check["warnings"])
        assert check["camera"]["tilt_deg"][1] < 3.0
    else:
        assert check["warnings"] == [], check["warnings"]
        assert check["tilt_spread_deg"] > 30.0
    assert check["levels"]["focal_rel_std"] == FOCAL_REL_STD_LEVEL


def test_warnings_are_one_line_each_and_issued_as_user_warnings():
    check = solve(RIG, face_on_poses(), BOARD.object_points, NOISE_PX, 7).conditioning
    assert check["warnings"] and all("\n" not in w for w in check["warnings"])
    with pytest.warns(UserWarning) as record:
        warn_conditioning(check)
    assert [str(w.message) for w in record] == check["warnings"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_conditioning(None)  # nothing to say


def test_coverage_counts_grid_cells_holding_points():
    size = (1000, 500)
    corner = [np.array([[10.0, 10.0], [20.0, 30.0]])]  # one cell
    assert coverage(corner, size) == pytest.approx(1 / COVERAGE_GRID**2)
    centres = (np.arange(COVERAGE_GRID) + 0.5) / COVERAGE_GRID
    uu, vv = np.meshgrid(centres * 1000 - 0.5, centres * 500 - 0.5)
    everywhere = [np.column_stack([uu.ravel(), vv.ravel()])]
    assert coverage(everywhere, size) == 1.0
    region = np.zeros((COVERAGE_GRID, COVERAGE_GRID), dtype=bool)
    region[0, :2] = True  # coverage of a region: the corner point's cell is one of two
    assert coverage(corner, size, region) == pytest.approx(0.5)
    assert coverage([np.array([[np.nan, 1.0], [-50.0, 3.0]]), *corner], size) > 0


def wide_rig(k3: float) -> Rig:
    """A wide-angle camera (fx = 480 px on 960 px: rays up to 45 deg) with k3 = ``k3``, and
    a projector that sees the same boards."""
    cam = Intrinsics.from_opencv(
        np.array([[480.0, 0, 479.5], [0, 480.0, 479.5], [0, 0, 1]]),
        [-0.2, 0.05, 0, 0, k3],
        960,
        960,
    )
    proj = Intrinsics.from_opencv(
        np.array([[700.0, 0, 455.5], [0, 700.0, 569.5], [0, 0, 1]]), [], 912, 1140
    )
    return Rig(Camera(cam), Projector(proj), Pose.look_at((-0.125, 0.1, 0.0), (0, 0, 0.6)))


def wide_views(rig: Rig, n: int = 12) -> tuple[np.ndarray, list[Pose]]:
    """A 0.6 m grid of 13 x 13 points and ``n`` poses filling both images."""
    g = np.linspace(-0.3, 0.3, 13)
    xx, yy = np.meshgrid(g, g)
    obj = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    rng = np.random.default_rng(0)
    poses: list[Pose] = []

    def inside(intrinsics: Intrinsics, points: np.ndarray) -> bool:
        uv = intrinsics.project(points)
        high = np.array([intrinsics.width, intrinsics.height]) - 5
        return bool(np.isfinite(uv).all() and (uv > 5).all() and (uv < high).all())

    while len(poses) < n:
        angles = (rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(-30, 30))
        t = (rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.35, 0.6))
        pose = Pose.from_euler("xyz", angles, degrees=True, t=t)
        points = pose.apply(obj)
        if inside(rig.camera.intrinsics, points) and inside(
            rig.projector.intrinsics, rig.cam2proj.apply(points)
        ):
            poses.append(pose)
    return obj, poses


def test_k3_free_recovers_k3_that_k3_fixed_cannot():
    """k3 = 0.3 on a wide-angle camera (0.1 px noise): the k3 model recovers it (measured
    0.3007 +- 0.0009), the default model keeps k3 = 0 and pays with a camera RMS six times
    the noise (0.84 px), fx off by 1.3 % and 48 px across the image."""
    rig = wide_rig(0.3)
    obj, poses = wide_views(rig)
    fixed = solve(rig, poses, obj, 0.1, 4)
    free = solve(rig, poses, obj, 0.1, 4, distortion="k3")
    true_cam = rig.camera.intrinsics
    k3_free = free.rig.camera.intrinsics.dist_array[4]
    assert abs(k3_free - 0.3) < tol.CALIB_K3_ABS
    sigma_k3 = free.uncertainty["camera"]["dist"][4]
    assert sigma_k3 is not None and abs(k3_free - 0.3) < 5 * sigma_k3 + tol.FLOAT64_EXACT
    assert fixed.rig.camera.intrinsics.dist_array[4] == 0.0
    assert fixed.uncertainty["camera"]["dist"][4] is None  # fixed, not estimated
    assert fixed.camera.rms_px > 3 * free.camera.rms_px
    assert abs(free.rig.camera.intrinsics.fx / true_cam.fx - 1) < tol.CALIB_K3_FOCAL_REL
    assert abs(fixed.rig.camera.intrinsics.fx / true_cam.fx - 1) > 10 * tol.CALIB_K3_FOCAL_REL


def test_rational_model_reports_what_the_data_leave_open():
    """k1-k6 of the rational model trade off (numerator against denominator): the mapping,
    the focal length and the principal point stay determined, the radial coefficients
    individually do not, and the check says so."""
    rig = wide_rig(0.3)
    obj, poses = wide_views(rig)
    result = solve(rig, poses, obj, 0.1, 4, distortion="rational")
    assert len(result.rig.camera.intrinsics.dist) == 8
    camera = result.uncertainty["camera"]
    assert camera["fx"] is not None and camera["cx"] is not None
    assert len(camera["dist"]) == 8 and "k4" in camera["not_determined"]
    assert any("do not determine the camera's" in w for w in result.conditioning["warnings"])
    assert abs(result.rig.camera.intrinsics.fx / rig.camera.intrinsics.fx - 1) < 1e-3


def test_fixed_intrinsics_take_their_uncertainties_from_each_device():
    result = solve(RIG, spread_poses(), BOARD.object_points, NOISE_PX, 5, fix_intrinsics=True)
    for device in ("camera", "projector"):
        assert all(result.uncertainty[device][k] > 0 for k in ("fx", "fy", "cx", "cy"))
    assert result.uncertainty["proj2cam"]["rotation_angle_deg"] > 0


def test_distortion_models_and_bad_names():
    assert set(DISTORTION_MODELS) == {"k1k2p1p2", "k3", "rational"}
    assert DISTORTION_MODELS["k1k2p1p2"][0] == cv2.CALIB_FIX_K3  # today's default
    with pytest.raises(InputError, match="distortion: expected one of k1k2p1p2, k3, rational"):
        solve(RIG, spread_poses()[:4], BOARD.object_points, 0.1, 1, distortion="k4")
