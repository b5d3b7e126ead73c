"""The main job, `virtus demo`, on its real default configuration (18 poses, 4 spp)."""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import CALIB_RMS_PX
from virtus.cli import main
from virtus.io.ply import read_ply
from virtus.pipeline.demo import TARGETS


@pytest.mark.slow
def test_demo_meets_the_issue_targets(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo"
    with pytest.raises(SystemExit) as done:
        main(["demo", "--out", str(out)])
    assert done.value.code == 0
    printed = capsys.readouterr().out
    assert "radius error" in printed and "99.339" in printed

    metrics = json.loads((out / "metrics.json").read_text())
    calibration, sphere = metrics["calibration"], metrics["sphere"]
    for key in ("camera_rms_px", "projector_rms_px", "stereo_rms_px"):
        assert 0 < calibration[key] <= CALIB_RMS_PX  # the calibration issue's bound
    assert calibration["n_poses"] == 18
    # The issue's claims, with the calibrated rig (timing is reported, not asserted).
    assert abs(sphere["radius_error_mm"]) <= TARGETS["radius_error_mm"]
    assert sphere["inlier_ratio"] >= TARGETS["inlier_ratio"]
    assert sphere["radius_mm"] == pytest.approx(100.0 + sphere["radius_error_mm"])
    assert metrics["timing"]["total_s"] > 0
    assert metrics["config"]["poses"] == "paper"
    assert metrics["provenance"]["versions"]["virtus"]

    # The files a user opens.
    calib = json.loads((out / "calibration" / "calibration.json").read_text())
    assert {"camera", "projector", "proj2cam", "rms_px"} <= set(calib)
    assert (out / "scan" / "capture.json").is_file()
    assert len(list((out / "scan" / "frames").glob("*.png"))) == 52
    cloud = read_ply(out / "scan" / "points.ply")
    assert cloud.units == "m" and len(cloud) > 100_000
    # The sphere's points in the cloud sit about 1 m in front of the camera.
    near = np.linalg.norm(cloud.points - (0.0, 0.0, 1.0), axis=1) < 0.11
    assert near.sum() > 100_000
    error_map = np.load(out / "scan" / "sphere_radial_error.npy")
    assert error_map.shape == (960, 960) and np.isfinite(error_map).sum() == sphere["n_points"]
