"""Camera, projector and stereo calibration from per-pose circle observations.

Pipeline (:func:`calibrate_observations`):

1. Camera: Zhang's method (``cv2.calibrateCamera``) on the refined circle centroids, with
   the lens model ``distortion`` (:data:`DISTORTION_MODELS`; by default k1, k2, p1, p2
   estimated and k3 fixed at 0: a user does not know the true lens; the truth comparison
   shows how close the estimate gets).
2. Perspective bias (circle boards; checkerboard corners have none): the area centroid
   of a circle's image is not the image of its centre. With the calibrated camera and each
   pose's board pose, the bias is computed exactly (centroid of the projected, distorted
   outline minus the projected centre), subtracted from the centroids, and the camera
   recalibrated (:data:`BIAS_ITERATIONS` passes).
3. Projector: each circle's local camera->projector homography is evaluated at its
   corrected camera centre, and the projector calibrated like a camera.
4. Stereo: ``cv2.stereoCalibrate`` refines both devices and their relative pose jointly.
   Measured on the paper's poses (7x13 board, rendered): joint refinement gives projector
   fx errors of 0.0018 % and a rotation error of 0.0016 deg, ``CALIB_FIX_INTRINSIC``
   0.0035 % and 0.0025 deg. OpenCV's ``R, T`` map camera-frame points into the projector
   frame (``cam2proj``); the result stores ``proj2cam``.

Poses whose circles are not all observed by both devices are dropped with a warning naming
them, as are poses whose reprojection error is an outlier; fewer than
:data:`MIN_POSES` usable poses raise :class:`VirtusError`.

:func:`calibrate_correspondences` runs steps 1, 3 (with given projector points) and 4 on
saved correspondences. Every solve also reports its parameters' uncertainties and a
conditioning check (:mod:`virtus.calib.conditioning`) in ``StereoCalibration.uncertainty``
and ``.conditioning``; the jobs issue the check's warnings.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from virtus.calib.board import Board, CircleBoard
from virtus.calib.conditioning import calibration_uncertainty, conditioning_report
from virtus.calib.projector import apply_homographies
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

#: Fewest usable poses for a calibration (Zhang's method needs 3 views of a plane).
MIN_POSES = 3
#: Bias-correction passes. On exact synthetic centroids of the paper's poses, no correction
#: leaves fx off by 1.3e-4 (4x7 board) and the projector's principal point by 0.06 px, while
#: the reprojection RMS stays at 5e-5 px (poses absorb most of the bias); one pass brings
#: them to < 1e-7 and < 0.001 px, a second changes nothing measurable.
BIAS_ITERATIONS = 1
#: A pose whose RMS reprojection error exceeds this multiple of the median (and
#: :data:`OUTLIER_FLOOR_PX`) is reported as an outlier and dropped.
OUTLIER_FACTOR = 5.0
OUTLIER_FLOOR_PX = 0.1
#: OpenCV flags: estimate k1, k2, p1, p2; keep k3 = 0.
CALIB_FLAGS = cv2.CALIB_FIX_K3
#: Lens models (``distortion`` option): name -> (OpenCV flags, which of the OpenCV
#: coefficients k1, k2, p1, p2, k3[, k4, k5, k6] are estimated; the others stay 0).
#: ``k1k2p1p2`` is the default (k3 fixed at 0, the results of earlier versions); ``k3`` frees
#: k3 (wide-angle lenses); ``rational`` is OpenCV's rational model (k4-k6 too), which needs
#: many well-spread poses (watch the uncertainties).
DISTORTION_MODELS: dict[str, tuple[int, tuple[bool, ...]]] = {
    "k1k2p1p2": (CALIB_FLAGS, (True, True, True, True, False)),
    "k3": (0, (True,) * 5),
    "rational": (cv2.CALIB_RATIONAL_MODEL, (True,) * 8),
}
DEFAULT_DISTORTION = "k1k2p1p2"
#: Fewest points of a pose in :func:`calibrate_correspondences` (a homography needs 4;
#: OpenCV's initialisation wants more than the minimum).
MIN_POSE_POINTS = 6
_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-15)
#: Outline samples per circle for the perspective-bias computation (polygon centroid error
#: falls as 1/n^2: 256 samples are below 1e-6 px).
_OUTLINE_SAMPLES = 256


def check_distortion(distortion: str) -> str:
    """``distortion`` if it names a :data:`DISTORTION_MODELS` entry, else :class:`InputError`."""
    if not isinstance(distortion, str) or distortion not in DISTORTION_MODELS:
        raise InputError("distortion", f"one of {', '.join(DISTORTION_MODELS)}", distortion)
    return distortion


def distortion_setting(distortion: str) -> dict[str, str]:
    """A run's settings entry for a lens model (checked): ``{"distortion": name}``, or ``{}``
    for :data:`DEFAULT_DISTORTION`, which settings record by its absence (so the settings,
    files and resumed runs of the default stay those of earlier versions)."""
    name = check_distortion(distortion)
    return {} if name == DEFAULT_DISTORTION else {"distortion": name}


@contextlib.contextmanager
def opencv_single_thread() -> Iterator[None]:
    """Run OpenCV on one thread (reproducible sums: the result's last digits otherwise
    depend on how its thread pool splits the work)."""
    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(previous)


@dataclass
class PoseObservation:
    """What one board pose gave.

    Attributes
    ----------
    name : the pose's name.
    cam_centroids : (N, 2) float64 circle area centroids (u, v) px in the camera image,
        board order; ``None`` if the board was not detected.
    homographies : (N, 3, 3) float64 local camera px -> projector px homographies (NaN
        where the phase was not usable); ``None`` if not available.
    """

    name: str
    cam_centroids: np.ndarray | None
    homographies: np.ndarray | None

    def problem(self) -> str | None:
        """Why this pose cannot be used (``None`` if it can)."""
        if self.cam_centroids is None:
            return "the camera did not detect the whole board"
        if not np.isfinite(self.cam_centroids).all():
            missing = int((~np.isfinite(self.cam_centroids).all(axis=1)).sum())
            return f"{missing} circle centre(s) could not be refined in the camera image"
        if self.homographies is None:
            return "no decoded projector coordinates"
        bad = ~np.isfinite(self.homographies).all(axis=(1, 2))
        if bad.any():
            return f"the projector did not see {int(bad.sum())} circle(s) (phase invalid)"
        return None


@dataclass
class DeviceCalibration:
    """One device's calibration: intrinsics, RMS (px) overall and per pose, board poses."""

    intrinsics: Intrinsics
    rms_px: float
    per_pose_rms_px: np.ndarray
    board2device: list[Pose]


@dataclass
class StereoCalibration:
    """The solved rig plus its errors; ``board2cam``: the board poses of the joint
    refinement (consistent with ``rig``), in ``used_poses`` order; ``per_pose[k]["board2cam"]``
    holds the same. ``uncertainty`` and ``conditioning``:
    :func:`~virtus.calib.conditioning.calibration_uncertainty` and
    :func:`~virtus.calib.conditioning.conditioning_report` of the solve."""

    rig: Rig
    camera: DeviceCalibration
    projector: DeviceCalibration
    stereo_rms_px: float
    per_pose: list[dict]
    used_poses: list[str]
    dropped_poses: dict[str, str] = field(default_factory=dict)
    board2cam: list[Pose] = field(default_factory=list)
    uncertainty: dict[str, Any] = field(default_factory=dict)
    conditioning: dict[str, Any] = field(default_factory=dict)

    @property
    def rms_px(self) -> dict[str, float]:
        """RMS reprojection errors (px) of the camera, projector and stereo calibrations."""
        return {
            "camera": self.camera.rms_px,
            "projector": self.projector.rms_px,
            "stereo": self.stereo_rms_px,
        }


def _cv_points(points: list[np.ndarray], dim: int) -> list[np.ndarray]:
    return [np.ascontiguousarray(p, dtype=np.float32).reshape(-1, 1, dim) for p in points]


def _object_list(object_points: np.ndarray | list[np.ndarray], n: int) -> list[np.ndarray]:
    """Per-pose object points: one (N, 3) array for every pose, or a list of them."""
    return list(object_points) if isinstance(object_points, list) else [object_points] * n


def calibrate_device(
    object_points: np.ndarray | list[np.ndarray],
    image_points: list[np.ndarray],
    size: tuple[int, int],
    flags: int = CALIB_FLAGS,
) -> DeviceCalibration:
    """Zhang calibration of one device (camera, or projector as an inverse camera).

    Parameters
    ----------
    object_points : (N, 3) float64 circle centres, metres, board frame (or, per pose, a list
        of (N_k, 3) arrays).
    image_points : per pose, (N, 2) float64 pixels (u, v) of the same circles.
    size : (width, height) of the device's image, px.
    flags : OpenCV calibration flags (default: k1, k2, p1, p2 estimated, k3 fixed;
        ``cv2.CALIB_RATIONAL_MODEL`` keeps 8 coefficients).
    """
    objs = _cv_points(_object_list(object_points, len(image_points)), 3)
    imgs = _cv_points(image_points, 2)
    rms, K, dist, rvecs, tvecs, _, _, per_view = cv2.calibrateCameraExtended(  # noqa: N806
        objs, imgs, size, None, None, flags=flags, criteria=_CRITERIA
    )
    n_dist = 8 if flags & cv2.CALIB_RATIONAL_MODEL else 5
    intrinsics = Intrinsics.from_opencv(K, dist.ravel()[:n_dist], size[0], size[1])
    poses = [Pose.from_rotvec(r.ravel(), t.ravel()) for r, t in zip(rvecs, tvecs, strict=True)]
    return DeviceCalibration(intrinsics, float(rms), per_view.ravel().copy(), poses)


def centroid_bias(intrinsics: Intrinsics, board: CircleBoard, board2device: Pose) -> np.ndarray:
    """Area centroid of each circle's image minus the image of its centre, (N, 2) px.

    The outline is projected with the device's distortion; the centroid is that of the
    projected polygon (shoelace formula), which is what :func:`refine_centres` measures.
    """
    outline = board.circle_outline(_OUTLINE_SAMPLES)
    n, m, _ = outline.shape
    uv = intrinsics.project(board2device.apply(outline.reshape(-1, 3))).reshape(n, m, 2)
    x, y = uv[..., 0], uv[..., 1]
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum(axis=1)
    centroid = np.stack(
        [((x + x1) * cross).sum(axis=1), ((y + y1) * cross).sum(axis=1)], axis=1
    ) / (6.0 * area[:, None])
    centre = intrinsics.project(board2device.apply(board.object_points))
    return centroid - centre


def _stereo(
    object_points: list[np.ndarray],
    cam_points: list[np.ndarray],
    proj_points: list[np.ndarray],
    camera: DeviceCalibration,
    projector: DeviceCalibration,
    fix_intrinsics: bool,
    model_flags: int = CALIB_FLAGS,
) -> tuple[Intrinsics, Intrinsics, Pose, float, np.ndarray, list[Pose]]:
    cam_k, cam_d = camera.intrinsics.to_opencv()
    proj_k, proj_d = projector.intrinsics.to_opencv()
    flags = (
        cv2.CALIB_FIX_INTRINSIC | (model_flags & cv2.CALIB_RATIONAL_MODEL)
        if fix_intrinsics
        else (cv2.CALIB_USE_INTRINSIC_GUESS | model_flags)
    )
    objs = _cv_points(object_points, 3)
    size = (camera.intrinsics.width, camera.intrinsics.height)
    result = cv2.stereoCalibrateExtended(
        objs,
        _cv_points(cam_points, 2),
        _cv_points(proj_points, 2),
        cam_k.copy(),
        cam_d.copy(),
        proj_k.copy(),
        proj_d.copy(),
        size,
        np.eye(3),
        np.zeros((3, 1)),
        flags=flags,
        criteria=_CRITERIA,
    )
    rms, k1, d1, k2, d2, R, T = result[:7]  # noqa: N806
    rvecs, tvecs, per_view = result[9:12]
    board2cam = [Pose.from_rotvec(r.ravel(), t.ravel()) for r, t in zip(rvecs, tvecs, strict=True)]
    n_dist = max(5, cam_d.size)
    cam = Intrinsics.from_opencv(
        k1, d1.ravel()[:n_dist], camera.intrinsics.width, camera.intrinsics.height
    )
    proj = Intrinsics.from_opencv(
        k2, d2.ravel()[:n_dist], projector.intrinsics.width, projector.intrinsics.height
    )
    cam2proj = Pose(R, T.ravel())
    per_view = np.asarray(per_view).reshape(-1, 2)
    return cam, proj, cam2proj.inverse(), float(rms), per_view, board2cam


def _solve_points(
    names: list[str],
    objs: list[np.ndarray],
    cam_points: list[np.ndarray],
    proj_points: list[np.ndarray],
    camera: DeviceCalibration,
    projector_size: tuple[int, int],
    fix_intrinsics: bool,
    distortion: str,
) -> StereoCalibration:
    """Projector and stereo calibration, given the camera's; uncertainties and conditioning."""
    flags, free_dist = DISTORTION_MODELS[distortion]
    projector = calibrate_device(objs, proj_points, projector_size, flags)
    cam_i, proj_i, proj2cam, rms, per_view, board2cam = _stereo(
        objs, cam_points, proj_points, camera, projector, fix_intrinsics, flags
    )
    rig = Rig(Camera(cam_i), Projector(proj_i), proj2cam)
    per_pose = [
        {
            "name": name,
            "camera_rms_px": float(camera.per_pose_rms_px[k]),
            "projector_rms_px": float(projector.per_pose_rms_px[k]),
            "stereo_camera_rms_px": float(per_view[k, 0]),
            "stereo_projector_rms_px": float(per_view[k, 1]),
            "board2cam": board2cam[k].to_dict(),
        }
        for k, name in enumerate(names)
    ]
    single = None
    if fix_intrinsics:
        single = (
            (camera.intrinsics, camera.board2device),
            (projector.intrinsics, projector.board2device),
        )
    points = (cam_points, proj_points)
    uncertainty = calibration_uncertainty(objs, points, rig, board2cam, free_dist, single)
    return StereoCalibration(
        rig,
        camera,
        projector,
        rms,
        per_pose,
        list(names),
        {},
        board2cam,
        uncertainty,
        conditioning_report(rig, board2cam, points, uncertainty),
    )


def _solve(
    board: Board,
    observations: list[PoseObservation],
    camera_size: tuple[int, int],
    projector_size: tuple[int, int],
    fix_intrinsics: bool,
    distortion: str = DEFAULT_DISTORTION,
) -> StereoCalibration:
    flags = DISTORTION_MODELS[distortion][0]
    obj = board.object_points
    raw = [o.cam_centroids for o in observations]
    cam_points = list(raw)
    camera = calibrate_device(obj, cam_points, camera_size, flags)
    # Only the circles' area centroids are biased; checkerboard corners are points.
    for _ in range(BIAS_ITERATIONS if isinstance(board, CircleBoard) else 0):
        cam_points = [
            r - centroid_bias(camera.intrinsics, board, pose)
            for r, pose in zip(raw, camera.board2device, strict=True)
        ]
        camera = calibrate_device(obj, cam_points, camera_size, flags)
    proj_points = [
        apply_homographies(o.homographies, c) for o, c in zip(observations, cam_points, strict=True)
    ]
    names = [o.name for o in observations]
    objs = [obj] * len(observations)
    return _solve_points(
        names, objs, cam_points, proj_points, camera, projector_size, fix_intrinsics, distortion
    )


def _without_outliers(
    usable: list[Any],
    names: list[str],
    solve: Callable[[list[Any]], StereoCalibration],
    dropped: dict[str, str],
) -> StereoCalibration:
    """Solve, dropping the worst pose while its reprojection error is an outlier."""
    usable, names = list(usable), list(names)
    while True:
        if len(usable) < MIN_POSES:
            raise VirtusError(
                f"calibration needs at least {MIN_POSES} usable poses, got {len(usable)}"
                + (f" (dropped: {', '.join(dropped)})" if dropped else "")
            )
        result = solve(usable)
        errors = np.array([max(p["camera_rms_px"], p["projector_rms_px"]) for p in result.per_pose])
        limit = max(OUTLIER_FACTOR * float(np.median(errors)), OUTLIER_FLOOR_PX)
        worst = int(np.argmax(errors))
        if errors[worst] <= limit or len(usable) <= MIN_POSES:
            break
        name = names[worst]
        dropped[name] = f"outlier: reprojection error {errors[worst]:.3g} px > {limit:.3g} px"
        warnings.warn(f"calibration: pose {name!r} dropped: {dropped[name]}", stacklevel=3)
        usable.pop(worst)
        names.pop(worst)
    result.dropped_poses = dropped
    return result


def calibrate_observations(
    board: Board,
    observations: list[PoseObservation],
    camera_size: tuple[int, int],
    projector_size: tuple[int, int],
    *,
    fix_intrinsics: bool = False,
    distortion: str = DEFAULT_DISTORTION,
) -> StereoCalibration:
    """Calibrate camera, projector and their relative pose from per-pose observations.

    Parameters
    ----------
    board : the board (circles or checkerboard) whose ``object_points`` were observed.
    observations : one per pose; unusable ones are dropped with a warning naming them.
    camera_size, projector_size : (width, height) px.
    fix_intrinsics : keep the single-device intrinsics in the stereo step
        (``CALIB_FIX_INTRINSIC``) instead of refining everything jointly.
    distortion : the lens model of both devices, a :data:`DISTORTION_MODELS` name.

    Raises
    ------
    VirtusError : fewer than :data:`MIN_POSES` usable poses.
    """
    distortion = check_distortion(distortion)
    dropped: dict[str, str] = {}
    usable = []
    for obs in observations:
        problem = obs.problem()
        if problem is None:
            usable.append(obs)
        else:
            dropped[obs.name] = problem
            warnings.warn(f"calibration: pose {obs.name!r} dropped: {problem}", stacklevel=2)

    def solve(kept: list[PoseObservation]) -> StereoCalibration:
        return _solve(board, kept, camera_size, projector_size, fix_intrinsics, distortion)

    return _without_outliers(usable, [o.name for o in usable], solve, dropped)


def calibrate_correspondences(
    names: list[str],
    object_points: list[np.ndarray],
    cam_points: list[np.ndarray],
    proj_points: list[np.ndarray],
    camera_size: tuple[int, int],
    projector_size: tuple[int, int],
    *,
    fix_intrinsics: bool = False,
    distortion: str = DEFAULT_DISTORTION,
) -> StereoCalibration:
    """Calibrate from saved correspondences: per pose, board points and their camera and
    projector pixels (:mod:`virtus.calib.points` reads them from files).

    The points are taken as the exact images of the object points: no perspective-bias
    correction (correct circle centroids before saving them). A point that is not finite in
    both images is left out of its pose; a pose left with fewer than
    :data:`MIN_POSE_POINTS` points is dropped with a warning naming it, as are outlier
    poses (as :func:`calibrate_observations`).

    Parameters
    ----------
    names : one per pose.
    object_points : per pose, (N_k, 3) board-frame points, metres (z = 0 for a plane).
    cam_points, proj_points : per pose, (N_k, 2) pixels (u, v) in the camera and projector.
    camera_size, projector_size : (width, height) px.
    fix_intrinsics, distortion : as :func:`calibrate_observations`.

    Raises
    ------
    VirtusError : fewer than :data:`MIN_POSES` usable poses.
    """
    distortion = check_distortion(distortion)
    flags = DISTORTION_MODELS[distortion][0]
    dropped: dict[str, str] = {}
    usable = []
    for name, obj, cam, proj in zip(names, object_points, cam_points, proj_points, strict=True):
        obj, cam, proj = (np.asarray(a, dtype=np.float64) for a in (obj, cam, proj))
        ok = np.isfinite(obj).all(axis=1) & np.isfinite(cam).all(axis=1)
        ok &= np.isfinite(proj).all(axis=1)
        if ok.sum() < MIN_POSE_POINTS:
            dropped[name] = f"{int(ok.sum())} points seen by both devices (< {MIN_POSE_POINTS})"
            warnings.warn(f"calibration: pose {name!r} dropped: {dropped[name]}", stacklevel=2)
            continue
        usable.append((str(name), obj[ok], cam[ok], proj[ok]))

    def solve(kept: list[tuple[Any, ...]]) -> StereoCalibration:
        kept_names, objs, cams, projs = (list(column) for column in zip(*kept, strict=True))
        camera = calibrate_device(objs, cams, camera_size, flags)
        return _solve_points(
            kept_names, objs, cams, projs, camera, projector_size, fix_intrinsics, distortion
        )

    return _without_outliers(usable, [u[0] for u in usable], solve, dropped)
