"""How well a calibration is determined: per-parameter uncertainties from the Jacobian of
the reprojection at the solution, and a conditioning check that warns when the data leave
the focal lengths, principal points or lens model poorly determined (DESIGN.md section 10:
a dozen nearly face-on boards leave the focal length tens of percent uncertain while the
reprojection RMS looks fine).

**Uncertainties** (:func:`calibration_uncertainty`). OpenCV's ``stereoCalibrate`` returns
no covariance, and ``calibrateCameraExtended``'s ``stdDeviationsIntrinsics`` cannot be used
for the focal length: on twelve boards tilted 1.1-2.5 deg (0.2 px noise, the default rig)
OpenCV 5.0 reported sigma_fx = 0.10 px where 20 re-observations spread fx by 207 px (its
principal-point values agreed with ours). So the covariance is computed here, at the
solution, from the Jacobian of the reprojection that was minimised:

* residuals: every observed point in the camera and (stereo) the projector image, px;
* parameters: each device's free intrinsics (fx, fy, cx, cy and the distortion coefficients
  its model estimates), the relative pose (``cam2proj`` rotation vector and translation,
  stereo) and the six pose parameters of every board; the Jacobian comes from
  ``cv2.projectPoints`` (and ``cv2.composeRT``'s derivatives for the projector's board
  poses ``cam2proj @ board2cam``);
* the board poses are eliminated per pose (each pose's rows projected orthogonally to its
  six columns, which gives the Schur complement), so the cost grows with the number of poses,
  not its square;
* the noise is estimated per device from its residuals, ``s_d^2 = SSR_d / m_d * m / (m - n)``
  (``m`` residuals, ``n`` free parameters), and the covariance of the unweighted least
  squares the solver ran is the sandwich ``S^-1 (G^T W G) S^-1``, ``S = G^T G``, ``W`` the
  per-row variances: camera and projector points need not be equally noisy.

With ``fix_intrinsics`` the intrinsics come from each device's own calibration and their
uncertainties from that problem; the relative pose's are then conditional on them (the
intrinsics held fixed). The baseline's and the ``proj2cam`` translation's uncertainties are
propagated from ``cam2proj`` (``proj2cam.t = -R^T t``, ``proj2cam``'s rotation vector is
``-r``). All are first-order: valid while the errors are small against the nonlinearity
(measured against the spread of fx over 20 re-observations with 0.2 px noise,
``tests/calib/test_conditioning.py``: 26.1-28.4 px reported, 26.4 px measured on twelve
boards tilted 1.1-2.5 deg; 2.38-2.50 vs 2.03 px on 12 random poses; 2.40 vs 2.37 px on the
paper's 18). Parameters the data do not determine at all (e.g. the rational model's radial
coefficients, which trade numerator against denominator) are reported as None and named in
a warning. Exact (noise-free) data give vanishing uncertainties whatever the poses: the
tilt spread below still warns there.

**Conditioning check** (:func:`conditioning_report`): the largest angle between the boards'
normals and each board's tilt to each device's optical axis (from the solved poses), each
device's image coverage (the fraction of :data:`COVERAGE_GRID` x :data:`COVERAGE_GRID` cells
holding an observed point; for the projector, of the cells the camera sees on the boards'
planes, the only part of the projector image the scanner uses), and the relative focal-length
and principal-point uncertainties; one warning line for each value past its level.
"""

from __future__ import annotations

import warnings
from typing import Any

import cv2
import numpy as np

from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose

__all__ = [
    "COVERAGE_GRID",
    "COVERAGE_LEVEL",
    "FOCAL_REL_STD_LEVEL",
    "PRINCIPAL_POINT_STD_LEVEL",
    "TILT_SPREAD_LEVEL_DEG",
    "calibration_uncertainty",
    "conditioning_report",
    "coverage",
    "warn_conditioning",
]

#: Warn above this relative standard deviation of a focal length. A relative focal error
#: scales the reconstructed lengths and depths by about as much: 0.5 % is 0.5 mm on the
#: paper's 100 mm sphere, the size of the error the paper reports for it (0.661 mm).
FOCAL_REL_STD_LEVEL = 0.005
#: Warn above this standard deviation of a principal-point coordinate, as a fraction of the
#: image's larger side. A principal-point error c turns the rays by about c / f: 1 % of the
#: side is 0.24 deg for the paper's camera (f = 2.4 widths), ten times the rig rotation
#: errors of its well-posed calibrations.
PRINCIPAL_POINT_STD_LEVEL = 0.01
#: Warn below this largest angle between the boards' normals (deg). Zhang's method sees the
#: focal length through the boards' tilts; :data:`virtus.calib.poses.MIN_POSE_SPREAD_DEG`
#: (5 deg) refuses what cannot be solved at all. Measured with this module's covariance
#: (default rig, 12 poses of the 7x13 board, 0.1 px noise, stereo solve): sigma_f / f 1.0 %
#: at a 2.7 deg spread, 0.6 % at 4.5 deg, 0.34 % at 9 deg, 0.19 % at 18 deg, 0.12 % at
#: 27 deg: below 10 deg the 0.5 % level is reached at noise levels real benches have.
TILT_SPREAD_LEVEL_DEG = 10.0
#: Warn below this fraction of covered image cells: the distortion polynomials are fitted
#: where the points are and extrapolated elsewhere. The paper's 18 poses of the 7x13 board
#: cover 52 % of the camera image (cells of :data:`COVERAGE_GRID`).
COVERAGE_LEVEL = 0.5
#: Cells per image side of the coverage grid (each cell a tenth of the width and height).
COVERAGE_GRID = 10
#: Significant digits of the reported uncertainties (they are estimates; fewer digits also
#: keep identical runs' files identical whatever the BLAS's summation order).
_DIGITS = 4
#: Directions of the (unit-diagonal) normal matrix whose eigenvalue is below this fraction of
#: the largest are taken as not determined by the data (a standard deviation a million times
#: a well-determined parameter's): parameters with a share in them are reported as None. The
#: rational model on an undistorted lens is one (numerator = denominator: eigenvalues
#: measured 3e-17 of the largest); the default model's smallest are 1e-4 to 1e-7.
_SINGULAR = 1e-12
#: Share of a parameter in a not-determined direction above which it is not determined.
_NULL_SHARE = 1e-6

DEVICES = ("camera", "projector")
#: OpenCV's distortion coefficients, in order.
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


def _round(value: float) -> float | None:
    """``value`` to :data:`_DIGITS` significant digits; None if not finite (not determined)."""
    return float(f"{value:.{_DIGITS}g}") if np.isfinite(value) else None


def _rvec(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    return cv2.Rodrigues(np.asarray(pose.R, dtype=np.float64))[0], pose.t.reshape(3, 1)


def _project(
    obj: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, intrinsics: Intrinsics
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projected points (2n,), d/d(intrinsics) (2n, 4 + nd) and d/d(rvec, tvec) (2n, 6)."""
    K, dist = intrinsics.to_opencv()  # noqa: N806
    uv, jac = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return uv.reshape(-1), jac[:, 6 : 10 + dist.size], jac[:, :6]


def _pose_rows(
    obj: np.ndarray,
    board2cam: Pose,
    intrinsics: list[Intrinsics],
    observed: list[np.ndarray],
    cam2proj: Pose | None,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per device ``(A, B, r)``: d/d(global parameters), d/d(board pose), residuals (px).

    Global parameters: each device's intrinsics (fx, fy, cx, cy, dist), then (two devices)
    ``cam2proj``'s rotation vector and translation.
    """
    widths = [4 + i.to_opencv()[1].size for i in intrinsics]
    n_global = sum(widths) + (6 if len(intrinsics) == 2 else 0)
    r1, t1 = _rvec(board2cam)
    rows = []
    for index, (intr, seen) in enumerate(zip(intrinsics, observed, strict=True)):
        A = np.zeros((2 * len(obj), n_global))  # noqa: N806
        start = sum(widths[:index])
        if index == 0:
            uv, d_intr, B = _project(obj, r1, t1, intr)  # noqa: N806
        else:
            assert cam2proj is not None
            r2, t2 = _rvec(cam2proj)
            r3, t3, dr3dr1, _, dr3dr2, _, dt3dr1, dt3dt1, dt3dr2, dt3dt2 = cv2.composeRT(
                r1, t1, r2, t2
            )
            uv, d_intr, d_pose = _project(obj, r3, t3, intr)
            a_r, a_t = d_pose[:, :3], d_pose[:, 3:]
            B = np.hstack([a_r @ dr3dr1 + a_t @ dt3dr1, a_t @ dt3dt1])  # noqa: N806
            A[:, -6:] = np.hstack([a_r @ dr3dr2 + a_t @ dt3dr2, a_t @ dt3dt2])
        A[:, start : start + widths[index]] = d_intr
        rows.append((A, B, uv - np.asarray(seen, dtype=np.float64).reshape(-1)))
    return rows


def _covariance(
    views: list[tuple[np.ndarray, Pose, list[np.ndarray]]],
    intrinsics: list[Intrinsics],
    cam2proj: Pose | None,
    free: np.ndarray,
) -> tuple[np.ndarray, list[float]]:
    """Covariance of the free global parameters (module docstring; NaN rows and columns for
    parameters the data do not determine) and each device's residual standard deviation."""
    blocks: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in intrinsics]
    for obj, board2cam, observed in views:
        rows = _pose_rows(obj, board2cam, intrinsics, observed, cam2proj)
        A = np.vstack([a[:, free] for a, _, _ in rows])  # noqa: N806
        B = np.vstack([b for _, b, _ in rows])  # noqa: N806
        # Eliminate this pose's six parameters: project onto the complement of B's columns.
        G = A - B @ np.linalg.lstsq(B, A, rcond=None)[0]  # noqa: N806
        start = 0
        for device, (_, _, residual) in enumerate(rows):
            blocks[device].append((G[start : start + residual.size], residual))
            start += residual.size
    m = sum(r.size for device in blocks for _, r in device)
    n = int(free.sum()) + 6 * len(views)
    scale = m / max(m - n, 1)
    normal = np.zeros((int(free.sum()),) * 2)
    middle = np.zeros_like(normal)
    sigmas = []
    for device in blocks:
        residuals = np.concatenate([r for _, r in device])
        variance = float(residuals @ residuals) / residuals.size * scale
        sigmas.append(float(np.sqrt(variance)))
        for g, _ in device:
            normal += g.T @ g
            middle += variance * (g.T @ g)
    # Invert in scaled units (fx ~ 1e3 px, k ~ 1, t ~ 0.1 m), on the determined directions.
    d = 1.0 / np.sqrt(np.maximum(np.diag(normal), np.finfo(float).tiny))
    values, vectors = np.linalg.eigh(normal * np.outer(d, d))
    null = values <= _SINGULAR * values[-1]
    kept = vectors[:, ~null]
    inverse = (kept / values[~null]) @ kept.T * np.outer(d, d)
    cov = inverse @ middle @ inverse
    undetermined = (np.abs(vectors[:, null]) > _NULL_SHARE).any(axis=1)
    cov[undetermined, :] = np.nan
    cov[:, undetermined] = np.nan
    return cov, sigmas


def _intrinsics_std(std: np.ndarray, intrinsics: Intrinsics, free: np.ndarray) -> dict:
    """``{fx, fy, cx, cy, dist}`` standard deviations (px; None where fixed or not
    determined), and ``not_determined``: the names of the free ones the data leave open."""
    n_dist = intrinsics.to_opencv()[1].size
    values: list[float | None] = [None] * (4 + n_dist)
    names = ("fx", "fy", "cx", "cy", *_DIST_NAMES[:n_dist])
    for index, value in zip(np.flatnonzero(free), std, strict=True):
        values[index] = _round(value)
    open_ = [
        names[i] for i, value in zip(np.flatnonzero(free), std, strict=True) if np.isnan(value)
    ]
    result = {**dict(zip(names[:4], values[:4], strict=True)), "dist": values[4:]}
    return {**result, "not_determined": open_} if open_ else result


def _extrinsic_std(cov: np.ndarray, cam2proj: Pose) -> dict[str, Any]:
    """``proj2cam`` uncertainties from the covariance of ``cam2proj``'s (r, t)."""
    r, t = _rvec(cam2proj)

    def translation(x: np.ndarray) -> np.ndarray:  # proj2cam.t = -R(r)^T t
        return -cv2.Rodrigues(x[:3].reshape(3, 1))[0].T @ x[3:]

    x0 = np.concatenate([r.ravel(), t.ravel()])
    step = 1e-7
    jac = np.column_stack(
        [(translation(x0 + step * e) - translation(x0 - step * e)) / (2 * step) for e in np.eye(6)]
    )
    t_cov = jac @ cov @ jac.T
    unit = t.ravel() / np.linalg.norm(t)
    baseline = float(np.sqrt(unit @ cov[3:, 3:] @ unit))
    rotation = np.degrees(np.sqrt(np.diag(cov[:3, :3])))
    return {
        "translation_m": [_round(v) for v in np.sqrt(np.diag(t_cov))],
        "baseline_m": _round(baseline),
        "rotation_deg": [_round(v) for v in rotation],
        "rotation_angle_deg": _round(float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))),
    }


def calibration_uncertainty(
    object_points: list[np.ndarray],
    image_points: tuple[list[np.ndarray], list[np.ndarray]],
    rig: Rig,
    board2cam: list[Pose],
    free_dist: tuple[bool, ...],
    single: tuple[tuple[Intrinsics, list[Pose]], tuple[Intrinsics, list[Pose]]] | None = None,
) -> dict[str, Any]:
    """Standard deviations of the calibrated parameters (method: module docstring).

    Parameters
    ----------
    object_points : per pose, (n_k, 3) board points (metres).
    image_points : (camera, projector) per pose, (n_k, 2) observed pixels.
    rig : the solved rig; ``board2cam`` its solved board poses (same order).
    free_dist : which distortion coefficients the model estimated (OpenCV order).
    single : with ``fix_intrinsics``: each device's own calibration (intrinsics, board
        poses), whose problems give the intrinsics' uncertainties; the relative pose's are
        then conditional on them.

    Returns
    -------
    ``{"method", "residual_std_px": {camera, projector}, "camera": {fx, fy, cx, cy, dist},
    "projector": {...}, "proj2cam": {translation_m, baseline_m, rotation_deg,
    rotation_angle_deg}}`` (rotations: of the rotation vector's components and its
    norm); ``None`` for fixed coefficients and for parameters the data do not determine.
    """
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    masks = [
        np.r_[
            np.ones(4, dtype=bool), np.resize(np.asarray(free_dist, dtype=bool), i.dist_array.size)
        ]
        for i in (cam, proj)
    ]
    views = [
        (obj, pose, [c, p])
        for obj, pose, c, p in zip(object_points, board2cam, *image_points, strict=True)
    ]
    cam2proj = rig.cam2proj
    fixed = single is not None
    free = np.r_[masks[0] & (not fixed), masks[1] & (not fixed), np.ones(6, dtype=bool)]
    cov, sigmas = _covariance(views, [cam, proj], cam2proj, free)
    std = np.sqrt(np.diag(cov))
    result: dict[str, Any] = {
        "method": "first-order covariance from the reprojection Jacobian at the solution "
        "(board poses eliminated, per-device noise from the residuals)",
        "residual_std_px": {d: _round(s) for d, s in zip(DEVICES, sigmas, strict=True)},
    }
    if single is None:
        split = int(masks[0].sum())
        parts = [std[:split], std[split : split + masks[1].sum()]]
        for device, intr, mask, part in zip(DEVICES, (cam, proj), masks, parts, strict=True):
            result[device] = _intrinsics_std(part, intr, mask)
    else:
        for device, (intr, poses), mask, points in zip(
            DEVICES, single, masks, image_points, strict=True
        ):
            views_1 = [
                (o, pose, [p]) for o, pose, p in zip(object_points, poses, points, strict=True)
            ]
            cov_1, _ = _covariance(views_1, [intr], None, mask)
            result[device] = _intrinsics_std(np.sqrt(np.diag(cov_1)), intr, mask)
    result["proj2cam"] = _extrinsic_std(cov[-6:, -6:], cam2proj)
    return result


def coverage(
    points: list[np.ndarray], size: tuple[int, int], region: np.ndarray | None = None
) -> float:
    """Fraction of the :data:`COVERAGE_GRID` x :data:`COVERAGE_GRID` cells of an image of
    ``size`` (width, height) px holding at least one of ``points`` (per pose, (n, 2) px);
    with ``region`` (a boolean grid, row = v), of the cells of that region."""
    cells = np.zeros((COVERAGE_GRID, COVERAGE_GRID), dtype=bool)
    uv = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in points])
    uv = uv[np.isfinite(uv).all(axis=1)]
    index = np.floor((uv + 0.5) / np.asarray(size, dtype=np.float64) * COVERAGE_GRID).astype(int)
    inside = ((index >= 0) & (index < COVERAGE_GRID)).all(axis=1)
    cells[index[inside, 1], index[inside, 0]] = True
    region = np.ones_like(cells) if region is None else region | cells
    return float(cells.sum() / region.sum())


def _projector_field(rig: Rig, board2cam: list[Pose]) -> np.ndarray:
    """Coverage cells of the projector image whose centre the camera sees on some board's
    plane (the plane unbounded): the part of the projector image the scanner uses."""
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    centres = (np.arange(COVERAGE_GRID) + 0.5) / COVERAGE_GRID
    uu, vv = np.meshgrid(centres * proj.width - 0.5, centres * proj.height - 0.5)
    rays = rig.proj2cam.apply_direction(proj.unproject(np.column_stack([uu.ravel(), vv.ravel()])))
    origin = rig.proj2cam.t
    seen = np.zeros(rays.shape[0], dtype=bool)
    for pose in board2cam:
        normal = pose.R[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (normal @ (pose.t - origin)) / (rays @ normal)
        hits = origin + rays * np.where(s > 0, s, np.nan)[:, None]
        uv = cam.project(np.nan_to_num(hits, nan=-1.0))
        ok = np.isfinite(s) & (s > 0) & np.isfinite(uv).all(axis=1)
        ok &= (uv >= -0.5).all(axis=1) & (uv <= np.array([cam.width, cam.height]) - 0.5).all(axis=1)
        seen |= ok
    return seen.reshape(COVERAGE_GRID, COVERAGE_GRID)


def _tilts(board2cam: list[Pose], rotation: np.ndarray) -> np.ndarray:
    """Angle (deg) between each board's normal and a device's optical axis."""
    normals = np.array([rotation @ pose.R[:, 2] for pose in board2cam])
    return np.degrees(np.arccos(np.clip(np.abs(normals[:, 2]), 0.0, 1.0)))


def conditioning_report(
    rig: Rig,
    board2cam: list[Pose],
    image_points: tuple[list[np.ndarray], list[np.ndarray]],
    uncertainty: dict[str, Any],
) -> dict[str, Any]:
    """The conditioning check of a solved calibration (module docstring).

    Parameters
    ----------
    rig, board2cam : the solved rig and board poses.
    image_points : (camera, projector) per pose, (n_k, 2) observed pixels.
    uncertainty : :func:`calibration_uncertainty` of the same solve.

    Returns
    -------
    ``{"tilt_spread_deg", "camera": {tilt_deg: [min, max], coverage, focal_rel_std,
    principal_point_std_px}, "projector": {...}, "levels": {...}, "warnings": [...]}``
    (one line per value past its level, as :func:`warn_conditioning` issues them).
    """
    normals = np.array([pose.R[:, 2] for pose in board2cam])
    spread = float(np.degrees(np.arccos(np.clip(normals @ normals.T, -1.0, 1.0)).max()))
    levels = {
        "focal_rel_std": FOCAL_REL_STD_LEVEL,
        "principal_point_std_fraction": PRINCIPAL_POINT_STD_LEVEL,
        "tilt_spread_deg": TILT_SPREAD_LEVEL_DEG,
        "coverage": COVERAGE_LEVEL,
        "coverage_grid": COVERAGE_GRID,
    }
    report: dict[str, Any] = {"tilt_spread_deg": _round(spread)}
    messages = []
    if spread < TILT_SPREAD_LEVEL_DEG:
        messages.append(
            f"calibration: the boards tilt little (largest angle between their normals "
            f"{spread:.1f} deg < {TILT_SPREAD_LEVEL_DEG:g} deg), so the focal lengths are "
            "poorly determined; add poses tilted by 10-30 deg"
        )
    rotations = (np.eye(3), rig.cam2proj.R)
    fields = (None, _projector_field(rig, board2cam))
    for device, intr, rotation, points, field in zip(
        DEVICES,
        (rig.camera.intrinsics, rig.projector.intrinsics),
        rotations,
        image_points,
        fields,
        strict=True,
    ):
        tilt = _tilts(board2cam, rotation)
        std = uncertainty[device]
        focal = None
        if std["fx"] is not None and std["fy"] is not None:
            focal = max(std["fx"] / intr.fx, std["fy"] / intr.fy)
        centre = None
        if std["cx"] is not None and std["cy"] is not None:
            centre = max(std["cx"], std["cy"])
        covered = coverage(points, (intr.width, intr.height), field)
        report[device] = {
            "tilt_deg": [_round(float(tilt.min())), _round(float(tilt.max()))],
            "coverage": _round(covered),
            "focal_rel_std": None if focal is None else _round(focal),
            "principal_point_std_px": None if centre is None else _round(centre),
        }
        centre_level = PRINCIPAL_POINT_STD_LEVEL * max(intr.width, intr.height)
        undetermined = std.get("not_determined", [])
        if undetermined:
            messages.append(
                f"calibration: the data do not determine the {device}'s "
                f"{', '.join(undetermined)}: choose a simpler lens model (distortion)"
            )
        elif focal is None or centre is None:
            messages.append(
                f"calibration: the {device}'s focal length or principal point is not "
                "determined by the data"
            )
        else:
            if focal > FOCAL_REL_STD_LEVEL:
                messages.append(
                    f"calibration: the {device}'s focal length is uncertain (standard "
                    f"deviation {100 * focal:.2g} % > {100 * FOCAL_REL_STD_LEVEL:g} %); add "
                    "poses tilted by 10-30 deg"
                )
            if centre > centre_level:
                messages.append(
                    f"calibration: the {device}'s principal point is uncertain (standard "
                    f"deviation {centre:.2g} px > {centre_level:.3g} px, "
                    f"{100 * PRINCIPAL_POINT_STD_LEVEL:g} % of the image)"
                )
        if covered < COVERAGE_LEVEL:
            where = "image" if field is None else "image seen by the camera"
            messages.append(
                f"calibration: the {device}'s points cover {100 * covered:.0f} % of its "
                f"{where} ({COVERAGE_GRID}x{COVERAGE_GRID} cells) < {100 * COVERAGE_LEVEL:g} %; "
                "the lens model is extrapolated elsewhere: place boards towards the corners"
            )
    report["levels"] = levels
    report["warnings"] = messages
    return report


def warn_conditioning(report: dict[str, Any] | None) -> None:
    """Issue each of a :func:`conditioning_report`'s warnings (``UserWarning``, one line)."""
    for message in (report or {}).get("warnings", []):
        warnings.warn(message, stacklevel=2)
