"""The calibration section: residuals recomputed from the saved observations are the
solver's own (per-pose stereo RMS of ``calibration.json``), parameters beside the truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from virtus.calib.board import board_from_dict
from virtus.geometry.devices import Rig
from virtus.report.calibration import parameter_rows, residuals

#: Residual RMS against the solver's per-pose RMS: the same formula on the same data, apart
#: from the solver's last iteration step (measured: 1.2e-4 px at 0.38 px, 0.03 %).
RMS_TOL_PX = 1e-4
RMS_TOL_REL = 1e-3


@pytest.fixture(scope="module")
def calibration(calibrate_run) -> dict:
    return json.loads((calibrate_run / "calibration.json").read_text())


def test_residuals_are_the_solvers_per_pose(calibrate_run, calibration) -> None:
    rig, board = Rig.from_dict(calibration), board_from_dict(calibration["board"])
    found = residuals(calibrate_run, calibration, rig, board)
    assert [r["name"] for r in found] == [p["name"] for p in calibration["per_pose"]]
    for item, pose in zip(found, calibration["per_pose"], strict=True):
        n = len(board.object_points)
        assert item["cam_res"].shape == item["proj_res"].shape == (n, 2)
        cam = np.sqrt(np.mean(np.sum(item["cam_res"] ** 2, axis=1)))
        proj = np.sqrt(np.mean(np.sum(item["proj_res"] ** 2, axis=1)))
        assert cam == pytest.approx(pose["stereo_camera_rms_px"], rel=RMS_TOL_REL, abs=RMS_TOL_PX)
        assert proj == pytest.approx(
            pose["stereo_projector_rms_px"], rel=RMS_TOL_REL, abs=RMS_TOL_PX
        )
        # observed points fall inside each device's image
        cam_i = rig.camera.intrinsics
        assert np.all((item["cam_uv"] > -0.5) & (item["cam_uv"] < (cam_i.width, cam_i.height)))


def test_residuals_see_a_wrong_model(calibrate_run, calibration) -> None:
    # the same observations against a camera moved by 1 px: residuals of about 1 px
    moved = json.loads(json.dumps(calibration))
    moved["camera"]["K"][0][2] += 1.0
    found = residuals(calibrate_run, moved, Rig.from_dict(moved),
                      board_from_dict(calibration["board"]))  # fmt: skip
    mean_u = np.mean(np.vstack([r["cam_res"] for r in found])[:, 0])
    assert mean_u == pytest.approx(-1.0, abs=0.05)


def test_parameters_beside_the_truth(calibration) -> None:
    header, rows = parameter_rows(calibration)
    assert header[:4] == ["parameter", "calibrated", "truth", "difference"]
    by_name = {row[0]: row for row in rows}
    fx = by_name["camera fx (px)"]
    assert fx[1] == calibration["camera"]["K"][0][0]
    assert fx[2] == calibration["true_rig"]["camera"]["K"][0][0]
    assert fx[3] == pytest.approx(fx[1] - fx[2])
    tx = by_name["proj2cam tx (mm)"]
    assert tx[1] == pytest.approx(calibration["proj2cam"]["t"][0] * 1000)
    # a real calibration has no truth: the column stays empty, the uncertainty is shown
    real = {k: v for k, v in calibration.items() if k != "true_rig"}
    header, rows = parameter_rows(real)
    assert header[2] == "-" and all(row[2] is None and row[3] is None for row in rows)
    assert rows[0][4] == calibration["uncertainty"]["camera"]["fx"]
