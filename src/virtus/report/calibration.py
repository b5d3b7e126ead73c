"""Report section of a calibration run (``calibration.json`` + ``poses/*.npz``): the board
poses in 3D relative to camera and projector, where the board points fell in each device's
image (coverage), per-pose RMS, residual vectors, and the parameters beside the truth
(rendered runs) or beside the file's own uncertainties (real captures).

Residuals are recomputed from the saved observations exactly as the solver formed them:
circle centroids corrected for the perspective bias of the calibrated camera
(:func:`virtus.calib.solve.centroid_bias`), projector points through each circle's local
homography (:func:`virtus.calib.projector.apply_homographies`), minus the board points
projected with the calibrated intrinsics (distortion included) at the calibrated board pose.
Frames: camera frame (OpenCV) for the 3D plot, millimetres.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import figures
from virtus.report.html import Page

__all__ = ["add_calibration", "parameter_rows", "residuals"]

#: Depth (mm) at which device frusta are drawn in the 3D plot.
_FRUSTUM_MM = 300.0


def _frustum(intrinsics: Any, device2cam: Any) -> np.ndarray:
    """(5, 3) mm: the optical centre and the image corners at :data:`_FRUSTUM_MM`."""
    w, h = intrinsics.width, intrinsics.height
    corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    k = intrinsics.K
    rays = np.column_stack([(corners[:, 0] - k[0, 2]) / k[0, 0],
                            (corners[:, 1] - k[1, 2]) / k[1, 1], np.ones(4)])  # fmt: skip
    local = np.vstack([np.zeros(3), rays * _FRUSTUM_MM / 1000.0])
    return device2cam.apply(local) * 1000.0


def _board_outline(board: Any) -> np.ndarray:
    """(4, 3) m: the rectangle around the board's points, board frame."""
    pts = board.object_points
    (x0, y0), (x1, y1) = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])


def residuals(path: Path, data: dict[str, Any], rig: Any, board: Any) -> list[dict[str, Any]]:
    """Per kept pose: ``name``, camera and projector points ``cam_uv``/``proj_uv`` (N, 2) px
    and residuals ``cam_res``/``proj_res`` (N, 2) px (observed minus model). Poses without
    an observation file are skipped."""
    from virtus.calib.board import CircleBoard
    from virtus.calib.projector import apply_homographies
    from virtus.calib.solve import centroid_bias
    from virtus.geometry.transforms import Pose
    from virtus.io.safeio import load_npz

    n = len(board.object_points)
    cam, proj = rig.camera.intrinsics, rig.projector.intrinsics
    cam2proj = rig.proj2cam.inverse()
    out = []
    for item in data.get("per_pose", []):
        file = path / "poses" / f"{item['name']}.npz"
        if not file.is_file():
            continue
        arrays = load_npz(file, f"pose {item['name']}")
        centroids = np.asarray(arrays["cam_centroids"], dtype=np.float64)
        homographies = np.asarray(arrays["homographies"], dtype=np.float64)
        if centroids.shape != (n, 2) or homographies.shape != (n, 3, 3):
            from virtus.errors import InputError

            raise InputError(str(file), f"{n} board points", f"arrays {centroids.shape}")
        board2cam = Pose.from_dict(item["board2cam"], f"{item['name']} board2cam")
        observed = centroids
        if isinstance(board, CircleBoard):
            observed = centroids - centroid_bias(cam, board, board2cam)
        proj_obs = apply_homographies(homographies, observed)
        cam_model = cam.project(board2cam.apply(board.object_points))
        proj_model = proj.project((cam2proj @ board2cam).apply(board.object_points))
        out.append({"name": item["name"], "cam_uv": observed, "cam_res": observed - cam_model,
                    "proj_uv": proj_obs, "proj_res": proj_obs - proj_model})  # fmt: skip
    return out


def parameter_rows(data: dict[str, Any]) -> tuple[list[str], list[list[Any]]]:
    """The calibrated parameters beside the truth (``true_rig``, rendered runs) or beside
    their one-sigma uncertainty (real captures): header and rows."""
    truth = data.get("true_rig")
    sigma = data.get("uncertainty", {})
    rows = []
    for device in ("camera", "projector"):
        k = np.asarray(data[device]["K"], dtype=np.float64)
        values = {"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]}
        true_k = np.asarray(truth[device]["K"], dtype=np.float64) if truth else None
        for name, value in values.items():
            index = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}[name]
            reference = float(true_k[index]) if true_k is not None else None
            rows.append([f"{device} {name} (px)", float(value), reference,
                         None if reference is None else float(value) - reference,
                         sigma.get(device, {}).get(name)])  # fmt: skip
    t = np.asarray(data["proj2cam"]["t"], dtype=np.float64) * 1000.0
    true_t = np.asarray(truth["proj2cam"]["t"], dtype=np.float64) * 1000.0 if truth else None
    for axis in range(3):
        reference = float(true_t[axis]) if true_t is not None else None
        rows.append([f"proj2cam t{'xyz'[axis]} (mm)", float(t[axis]), reference,
                     None if reference is None else float(t[axis]) - reference,
                     _sigma_mm(sigma, axis)])  # fmt: skip
    reference_name = "truth" if truth else "-"
    return ["parameter", "calibrated", reference_name, "difference", "1-sigma"], rows


def _sigma_mm(sigma: dict[str, Any], axis: int) -> float | None:
    values = sigma.get("proj2cam", {}).get("translation_m")
    return None if not isinstance(values, list) else float(values[axis]) * 1000.0


def add_calibration(page: Page, path: Path, title: str = "Calibration") -> dict[str, Any]:
    """The calibration section (see the module docstring); returns ``calibration.json``."""
    from virtus.calib.board import board_from_dict
    from virtus.geometry.devices import Rig
    from virtus.geometry.transforms import Pose
    from virtus.report.runs import read_run_json

    data = read_run_json(path, "calibration.json", "calibration",
                         ("camera", "projector", "proj2cam", "rms_px", "per_pose"))  # fmt: skip
    rig = Rig.from_dict(data)
    section = page.section(title)
    section.table("reprojection RMS (px)", data["rms_px"])
    board = board_from_dict(data["board"]) if isinstance(data.get("board"), dict) else None
    poses = data["per_pose"]
    names = [str(p["name"]) for p in poses]
    if board is not None:
        outline = _board_outline(board)
        boards = [(p["name"], Pose.from_dict(p["board2cam"]).apply(outline) * 1000.0)
                  for p in poses]  # fmt: skip
        devices = [("camera", _frustum(rig.camera.intrinsics, Pose.identity())),
                   ("projector", _frustum(rig.projector.intrinsics, rig.proj2cam))]  # fmt: skip
        section.figure(
            "board-poses",
            figures.poses_3d(devices, boards, f"{len(poses)} board poses, camera frame"),
            "Board poses (calibrated) relative to the camera (black) and the projector "
            f"(orange), whose viewing frusta are drawn to {_FRUSTUM_MM:.0f} mm; mm.",
        )
    section.figure(
        "per-pose-rms",
        figures.bar_chart(
            names,
            {
                "camera": [p.get("camera_rms_px") for p in poses],
                "projector": [p.get("projector_rms_px") for p in poses],
            },
            "RMS (px)",
            "reprojection RMS per pose",
        ),  # fmt: skip
        "Reprojection RMS of each board pose, camera and projector (px).",
    )
    found = residuals(path, data, rig, board) if board is not None else []
    if found:
        cam_size = (rig.camera.intrinsics.width, rig.camera.intrinsics.height)
        proj_size = (rig.projector.intrinsics.width, rig.projector.intrinsics.height)
        section.figure(
            "coverage",
            figures.scatter_fields(
                [
                    ("camera", cam_size, [(r["name"], r["cam_uv"]) for r in found]),
                    ("projector", proj_size, [(r["name"], r["proj_uv"]) for r in found]),
                ],
                "board points in each device's image (one colour per pose)",
            ),  # fmt: skip
            "Coverage: where the board's points fell in the camera and projector images.",
        )
        section.figure(
            "residual-vectors",
            figures.vector_field(
                [
                    (
                        "camera",
                        cam_size,
                        np.vstack([r["cam_uv"] for r in found]),
                        np.vstack([r["cam_res"] for r in found]),
                    ),
                    (
                        "projector",
                        proj_size,
                        np.vstack([r["proj_uv"] for r in found]),
                        np.vstack([r["proj_res"] for r in found]),
                    ),
                ],
                "reprojection residuals (observed - model), magnified",
            ),  # fmt: skip
            "Residual vectors of every board point, camera and projector, magnified by the "
            "factor in each title; colour: length (px).",
        )
    header, rows = parameter_rows(data)
    section.grid("parameters", header, rows)
    if data.get("truth_error"):
        section.table("errors against the truth", data["truth_error"])
    if data.get("conditioning"):
        section.table("conditioning", data["conditioning"])
    if data.get("dropped_poses"):
        section.note(f"dropped poses: {data['dropped_poses']}")
    return data
