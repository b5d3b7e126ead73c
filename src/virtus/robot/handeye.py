"""Hand-eye calibration: where the camera sits on the robot (or where a fixed camera stands).

Inputs, one per robot pose ``i``: the hand's pose ``hand2base_i`` (forward kinematics of the
mount link) and the calibration board's pose ``board2cam_i`` seen by the camera (from a board
observation), optionally with the board's pixel observations.

* **Eye-in-hand** (camera on the link): unknowns ``cam2hand`` (X) and ``board2base`` (Z),
  with ``hand2base_i @ X @ board2cam_i = Z`` for every ``i``.
* **Eye-to-hand** (fixed camera, board on the link): unknowns ``cam2base`` (X) and
  ``board2hand`` (Z), with ``hand2base_i^-1 @ X @ board2cam_i = Z``; the same equations with
  ``hand2base_i`` inverted.

Solution: (1) the closed form of Park & Martin (IEEE T-RA 10(5), 1994) on all pose pairs:
``A_ij = H_j^-1 H_i``, ``B_ij = C_j C_i^-1``, ``A X = X B``; the rotation from the axes
``log(R_A) = R_X log(R_B)`` (orthogonal Procrustes), the translation by linear least squares
on ``(R_A - I) t_X = R_X t_B - t_A``; (2) nonlinear refinement of X and Z together over every
board observation (robot-world-hand-eye, the board pose free): pixel residuals when pixel
observations are given, else the board poses (rotation and translation weighted by their
variances). Expected errors are 1-sigma, root-sum-square over the three axes, from the
covariance of the board-pose residuals (errors shared by all points of one observation
count once per pose; with pixels, the larger of that and the pixel-noise covariance).

Degenerate motion is refused before anything is solved (:func:`check_motion`, raising
:class:`~virtus.errors.DegenerateData` with the reason): fewer than :data:`MIN_POSES`
poses; no pair of hand poses rotated by at least ``min_rotation_deg`` relative to each other;
relative rotation axes all (nearly) parallel. Two non-parallel axes determine X uniquely
(Tsai & Lenz, IEEE T-RA 5(3), 1989): axes in one plane are accepted, and the spread of the
axes out of that plane is reported (``axes_spread``) -- it shows in the expected errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from virtus.errors import DegenerateData, InputError
from virtus.geometry.transforms import Pose

__all__ = [
    "HAND_EYE_MODES",
    "MIN_POSES",
    "HandEyeResult",
    "check_motion",
    "park_martin",
    "solve_handeye",
]

HAND_EYE_MODES = ("eye_in_hand", "eye_to_hand")
#: Fewest robot poses accepted (two motions with non-parallel axes need three poses).
MIN_POSES = 3
#: Default smallest relative rotation (deg) between some pair of poses.
MIN_ROTATION_DEG = 10.0
#: Axes count as parallel when the second singular value of the stacked unit axes is below
#: this share of the first (about 3 deg of spread).
MIN_AXES_SPREAD = 0.05


@dataclass(frozen=True)
class HandEyeResult:
    """A hand-eye solution.

    Attributes
    ----------
    mode : ``"eye_in_hand"`` or ``"eye_to_hand"``.
    cam2hand : eye-in-hand: the camera in the hand (link) frame; eye-to-hand: ``cam2base``.
    board2base : eye-in-hand: the board in the base frame; eye-to-hand: ``board2hand``.
    closed_form : the closed-form X before refinement.
    rotation_error_deg, translation_error_mm : expected 1-sigma errors of X (RSS of axes).
    residual_rms : RMS of the refined residuals, in ``residual_unit`` (``px`` or ``mm``).
    motion : the motion check's numbers (:func:`check_motion`).
    per_pose_rms : RMS residual per pose, ``residual_unit``.
    """

    mode: str
    cam2hand: Pose
    board2base: Pose
    closed_form: Pose
    rotation_error_deg: float
    translation_error_mm: float
    residual_rms: float
    residual_unit: str
    motion: dict[str, Any] = field(default_factory=dict)
    per_pose_rms: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (poses as ``{R, t}`` in metres)."""
        x_name, z_name = (
            ("cam2hand", "board2base") if self.mode == "eye_in_hand" else ("cam2base", "board2hand")
        )
        return {
            "mode": self.mode,
            "units": "m",
            x_name: self.cam2hand.to_dict(),
            z_name: self.board2base.to_dict(),
            "closed_form": self.closed_form.to_dict(),
            "expected_rotation_error_deg": self.rotation_error_deg,
            "expected_translation_error_mm": self.translation_error_mm,
            "residual_rms": self.residual_rms,
            "residual_unit": self.residual_unit,
            "per_pose_rms": list(self.per_pose_rms),
            "motion": self.motion,
        }


def _matrices(name: str, poses: list[Any]) -> np.ndarray:
    out = []
    for i, pose in enumerate(poses):
        if isinstance(pose, Pose):
            out.append(pose.matrix)
        else:
            try:
                out.append(Pose.from_matrix(pose).matrix)
            except InputError as error:
                raise InputError(f"{name}[{i}]", error.expected, error.got) from None
    return np.array(out, dtype=np.float64).reshape(-1, 4, 4)


def _pairs(n: int) -> list[tuple[int, int]]:
    return list(combinations(range(n), 2))


def check_motion(hand2base: list[Any], min_rotation_deg: float = MIN_ROTATION_DEG) -> dict:
    """Refuse motion that cannot determine a hand-eye transform (see the module docs).

    Returns the numbers it looked at: ``poses``, ``max_relative_rotation_deg``,
    ``informative_pairs`` (pairs rotated by at least ``min_rotation_deg``) and
    ``axes_singular_values`` of their stacked unit rotation axes (relative to the largest).
    """
    H = _matrices("hand2base", hand2base)  # noqa: N806
    n = len(H)
    if n < MIN_POSES:
        raise DegenerateData(
            f"hand-eye needs at least {MIN_POSES} robot poses (two motions); got {n}"
        )
    axes, angles = [], []
    for i, j in _pairs(n):
        rel = np.linalg.inv(H[j]) @ H[i]
        rotvec = Rotation.from_matrix(rel[:3, :3]).as_rotvec()
        angle = float(np.degrees(np.linalg.norm(rotvec)))
        angles.append(angle)
        if angle >= min_rotation_deg:
            axes.append(rotvec / np.linalg.norm(rotvec))
    largest = max(angles)
    if not axes:
        raise DegenerateData(
            f"hand-eye: the robot poses rotate too little relative to each other (largest "
            f"relative rotation {largest:.2f} deg, need >= {min_rotation_deg:g} deg): vary "
            "the hand's orientation"
        )
    s = np.linalg.svd(np.array(axes), compute_uv=False)
    s = np.pad(s, (0, 3 - len(s))) / s[0]
    record = {
        "poses": n,
        "max_relative_rotation_deg": largest,
        "informative_pairs": len(axes),
        "axes_singular_values": s.tolist(),
        "axes_spread": float(s[2]),
    }
    if s[1] < MIN_AXES_SPREAD:
        raise DegenerateData(
            "hand-eye: all relative rotations are about (nearly) parallel axes (axis spread "
            f"{s[1]:.3g} < {MIN_AXES_SPREAD}): the rotation about that axis and the "
            "translation along it are undetermined; rotate the hand about a second axis"
        )
    return record


def park_martin(A: np.ndarray, B: np.ndarray) -> np.ndarray:  # noqa: N803
    """Closed-form X (4, 4) of ``A_k X = X B_k`` from motions A, B (K, 4, 4), Park-Martin."""
    alpha = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    beta = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    M = alpha.T @ beta  # sum alpha_k beta_k^T  # noqa: N806
    U, _, Vt = np.linalg.svd(M)  # noqa: N806
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])  # noqa: N806
    R = U @ D @ Vt  # noqa: N806
    lhs = (A[:, :3, :3] - np.eye(3)).reshape(-1, 3)
    rhs = (np.einsum("ij,kj->ki", R, B[:, :3, 3]) - A[:, :3, 3]).reshape(-1)
    t = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    X = np.eye(4)  # noqa: N806
    X[:3, :3], X[:3, 3] = R, t
    return X


def solve_handeye(
    hand2base: list[Any],
    board2cam: list[Any],
    *,
    mode: str = "eye_in_hand",
    board_points: np.ndarray | None = None,
    image_points: list[np.ndarray] | None = None,
    intrinsics: Any = None,
    min_rotation_deg: float = MIN_ROTATION_DEG,
) -> HandEyeResult:
    """Solve hand-eye calibration (see the module docs).

    Parameters
    ----------
    hand2base : N poses of the mount link in the base frame (Pose or (4, 4)).
    board2cam : N board poses in the camera frame (from the board observations).
    mode : ``"eye_in_hand"`` or ``"eye_to_hand"``.
    board_points, image_points, intrinsics : (K, 3) board points (metres, board frame), N
        arrays (K, 2) of their observed pixels (OpenCV convention) and the camera's
        :class:`~virtus.geometry.optics.Intrinsics`: the refinement then minimises
        reprojection errors (px); the expected errors are the larger of ``s^2 (J^T J)^-1``
        (independent pixel noise) and the board-pose covariance below (errors shared by the
        points of one observation, which pixel residuals hide). Without them
        it minimises the board-pose errors (rotation and translation weighted by their
        variances, estimated from the residuals in two rounds).
    min_rotation_deg : smallest informative relative rotation.

    Raises
    ------
    DegenerateData : degenerate motion (the reason is in the message).
    InputError : mismatched or malformed inputs.
    """
    if mode not in HAND_EYE_MODES:
        raise InputError("mode", f"one of {HAND_EYE_MODES}", mode)
    H = _matrices("hand2base", hand2base)  # noqa: N806
    C = _matrices("board2cam", board2cam)  # noqa: N806
    if len(H) != len(C):
        raise InputError("board2cam", f"one board pose per robot pose ({len(H)})", len(C))
    if mode == "eye_to_hand":
        H = np.linalg.inv(H)  # noqa: N806
    motion = check_motion([Pose.from_matrix(h) for h in H], min_rotation_deg)
    pairs = _pairs(len(H))
    A = np.array([np.linalg.inv(H[j]) @ H[i] for i, j in pairs])  # noqa: N806
    B = np.array([C[j] @ np.linalg.inv(C[i]) for i, j in pairs])  # noqa: N806
    X0 = park_martin(A, B)  # noqa: N806
    Zs = H @ X0 @ C  # noqa: N806
    Z0 = np.eye(4)  # noqa: N806
    Z0[:3, :3] = Rotation.from_matrix(Zs[:, :3, :3]).mean().as_matrix()
    Z0[:3, 3] = Zs[:, :3, 3].mean(axis=0)

    def compose(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X, Z = X0.copy(), Z0.copy()  # noqa: N806
        X[:3, :3] = X0[:3, :3] @ Rotation.from_rotvec(params[0:3]).as_matrix()
        X[:3, 3] = X0[:3, 3] + params[3:6]
        Z[:3, :3] = Z0[:3, :3] @ Rotation.from_rotvec(params[6:9]).as_matrix()
        Z[:3, 3] = Z0[:3, 3] + params[9:12]
        return X, Z

    tight = {"xtol": 1e-15, "ftol": 1e-15, "gtol": 1e-15, "max_nfev": 2000}
    if image_points is not None:
        params, cov, r, unit = _refine_pixels(
            compose, H, board_points, image_points, intrinsics, tight
        )
    else:
        params, cov, r, unit = _refine_poses(compose, H, C, tight)
    if image_points is not None:  # the larger of pixel noise and board-pose scatter
        cov = np.maximum(cov, _pose_covariance(params, compose, H, C))
    X, Z = compose(params)  # noqa: N806
    per_pose = np.sqrt(np.mean(r.reshape(len(H), -1) ** 2, axis=1))
    return HandEyeResult(
        mode=mode,
        cam2hand=Pose.from_matrix(X),
        board2base=Pose.from_matrix(Z),
        closed_form=Pose.from_matrix(X0),
        rotation_error_deg=float(np.degrees(np.sqrt(max(np.trace(cov[0:3, 0:3]), 0.0)))),
        translation_error_mm=float(1e3 * np.sqrt(max(np.trace(cov[3:6, 3:6]), 0.0))),
        residual_rms=float(np.sqrt(np.mean(r**2))),
        residual_unit=unit,
        motion=motion,
        per_pose_rms=tuple(float(v) for v in per_pose),
    )


def _inverse_or_inf(matrix: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.inv(matrix)
    except np.linalg.LinAlgError:
        return np.full(matrix.shape, np.inf)


def _refine_pixels(compose, H, board_points, image_points, intrinsics, tight):  # noqa: ANN001, ANN202, N803
    """Reprojection refinement: (params, covariance, residuals px, "px")."""
    if intrinsics is None or board_points is None:
        raise InputError("image_points", "board_points and intrinsics with them", None)
    points = np.asarray(board_points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 3:
        raise InputError("board_points", "(K >= 3, 3) points", np.shape(points))
    if len(image_points) != len(H):
        raise InputError("image_points", f"one array per pose ({len(H)})", len(image_points))
    try:
        observed = np.array(
            [np.asarray(p, np.float64).reshape(len(points), 2) for p in image_points]
        )
    except ValueError:
        raise InputError("image_points", f"({len(points)}, 2) pixels per pose", "other") from None

    def residuals(params: np.ndarray) -> np.ndarray:
        X, Z = compose(params)  # noqa: N806
        predicted = np.linalg.inv(X) @ np.linalg.inv(H) @ Z
        cam = np.einsum("nij,kj->nki", predicted[:, :3, :3], points) + predicted[:, None, :3, 3]
        return (intrinsics.project(cam.reshape(-1, 3)).reshape(observed.shape) - observed).ravel()

    fit = least_squares(residuals, np.zeros(12), method="lm", **tight)
    r = fit.fun
    sigma2 = float(r @ r) / max(r.size - 12, 1)
    return fit.x, _inverse_or_inf(fit.jac.T @ fit.jac) * sigma2, r, "px"


def _refine_poses(compose, H, C, tight):  # noqa: ANN001, ANN202, N803
    """Board-pose refinement: (params, covariance, residuals in mrad and mm, "mrad|mm")."""
    n = len(H)
    params = np.zeros(12)
    share = 6 * n / max(6 * n - 12, 1)
    weights = np.ones(6)
    for _ in range(3):  # variances from the residuals, then refit with them
        r0 = _pose_residuals(params, compose, H, C)
        var_rot = max(float(np.mean(r0[:, :3] ** 2)) * share, 1e-30)
        var_t = max(float(np.mean(r0[:, 3:] ** 2)) * share, 1e-30)
        weights = np.r_[np.full(3, var_rot**-0.5), np.full(3, var_t**-0.5)]

        def residuals(p: np.ndarray, w: np.ndarray = weights) -> np.ndarray:
            return (_pose_residuals(p, compose, H, C) * w).ravel()

        params = least_squares(residuals, params, method="lm", **tight).x
    r0 = _pose_residuals(params, compose, H, C)
    return params, _pose_covariance(params, compose, H, C), (r0 * 1e3).ravel(), "mrad|mm"


def _pose_covariance(params, compose, H, C) -> np.ndarray:  # noqa: ANN001, N803
    """Covariance (12, 12) of the parameters from the board-pose residuals: one variance for
    the rotation and one for the translation components, ``6N - 12`` degrees of freedom,
    ``(J^T W J)^-1`` -- errors every point of one observation shares (a pose's detection
    bias) are seen here, not in pixel residuals treated as independent."""
    n = len(H)
    share = 6 * n / max(6 * n - 12, 1)
    r0 = _pose_residuals(params, compose, H, C)
    var_rot = max(float(np.mean(r0[:, :3] ** 2)) * share, 1e-30)
    var_t = max(float(np.mean(r0[:, 3:] ** 2)) * share, 1e-30)
    step = 1e-7
    J = np.empty((n * 6, 12))  # noqa: N806
    for k in range(12):
        dp = np.zeros(12)
        dp[k] = step
        plus = _pose_residuals(params + dp, compose, H, C)
        minus = _pose_residuals(params - dp, compose, H, C)
        J[:, k] = ((plus - minus) / (2 * step)).ravel()
    w = np.tile(np.r_[np.full(3, 1 / var_rot), np.full(3, 1 / var_t)], n)
    return _inverse_or_inf(J.T @ (J * w[:, None]))


def _pose_residuals(params: np.ndarray, compose: Any, H: np.ndarray, C: np.ndarray) -> np.ndarray:  # noqa: N803
    """(N, 6) rotation vector (rad) and translation (m) of ``predicted @ observed^-1`` per
    board pose."""
    X, Z = compose(params)  # noqa: N806
    predicted = np.linalg.inv(X) @ np.linalg.inv(H) @ Z
    delta = predicted @ np.linalg.inv(C)
    rot = Rotation.from_matrix(delta[:, :3, :3]).as_rotvec()
    return np.concatenate([rot, predicted[:, :3, 3] - C[:, :3, 3]], axis=1)
