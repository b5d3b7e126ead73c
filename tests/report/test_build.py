"""``write_report`` for every kind of run: the sections each kind must have, the same bytes
for the same run, and the size bound of the default demo's report (5 MB)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.report.conftest import run_cli
from virtus.report import REPORT_FILE, write_report
from virtus.report.viewer import MAX_POINTS

#: The issue's bound on the default demo's report.
DEMO_REPORT_MAX_BYTES = 5_000_000


def _text(report) -> str:  # noqa: ANN001
    return report.path.read_text(encoding="utf-8")


def test_same_run_same_bytes(scan_run, tmp_path) -> None:
    a = write_report(scan_run, tmp_path / "a.html")
    b = write_report(scan_run, tmp_path / "b.html")
    assert a.path.read_bytes() == b.path.read_bytes()
    assert a.n_bytes == a.path.stat().st_size and a.kind == "scan"


def test_demo_report_links_its_parts(demo_run, tmp_path) -> None:
    report = write_report(demo_run, tmp_path / "demo.html")
    text = _text(report)
    for anchor in ("#calibration", "#sphere-scan-frames", "#decode", "#sphere-fit", "#3d-view"):
        assert f"href='{anchor}'" in text
        assert f'id="{anchor[1:]}"' in text
    assert "href='calibration/calibration.json'" in text
    assert report.n_bytes < DEMO_REPORT_MAX_BYTES
    assert "99.339" in text  # the paper's radius beside ours


def test_a_sphere_scan_is_fitted_as_the_demo_fits_it(scan_run) -> None:
    from virtus.report.build import _scene_sphere_fit

    sphere, error_map = _scene_sphere_fit(scan_run)
    # the true rig reconstructs the 100 mm sphere: the fit finds it (160 px camera, 1 spp)
    assert sphere["radius_true_mm"] == 100.0
    assert abs(sphere["radius_error_mm"]) < 0.5 and sphere["inlier_ratio"] > 0.8
    assert np.isfinite(error_map).sum() >= sphere["n_points"] > 1000
    assert np.allclose(sphere["center_mm"], sphere["center_true_mm"], atol=1.0)


def test_the_scan_fit_is_the_ablation_jobs_own(scan_run, ablation_run) -> None:
    # the ablation's matte / dark / ideal cell renders the same sphere with the same rig and
    # seed and fits it itself: the report's fit of the scan must give its numbers
    from virtus.report.build import _scene_sphere_fit

    sphere, _ = _scene_sphere_fit(scan_run)
    cells = json.loads((ablation_run / "ablation.json").read_text())["cells"]
    matte = next(c for c in cells if (c["material"], c["realism"]) == ("matte", "ideal"))
    assert sphere["radius_error_mm"] == pytest.approx(matte["radius_error_mm"], abs=1e-9)
    assert sphere["fit_rms_mm"] == pytest.approx(matte["fit_rms_mm"], abs=1e-9)


def test_capture_then_decode(rig_file, tmp_path) -> None:
    out = tmp_path / "cap"
    run_cli(["capture", "--rig", rig_file, "--spp", "1", "--out", out, "--quiet"])
    first = write_report(out)
    assert first.path == out / REPORT_FILE and first.kind == "capture"
    assert "Not decoded: run `virtus decode" in _text(first)
    assert "fig-frames-frame-phase" in first.figures
    run_cli(["decode", out, "--quiet"])
    second = write_report(out)
    assert {"fig-decode-wrapped-phase-v", "fig-decode-valid-and-flagged"} <= set(second.figures)
    assert "Not reconstructed" in _text(second)


def test_evaluated_scan_and_turntable_show_c2m(rig_file, tmp_path) -> None:
    scan = tmp_path / "ff"
    run_cli(["scan", "--scene", "freeform", "--rig", rig_file, "--spp", "1", "--out", scan,
             "--no-report", "--quiet"])  # fmt: skip
    run_cli(["evaluate", scan, "--quiet"])
    report = write_report(scan)
    assert "fig-cloud-to-mesh-distance-c2m-histogram-0" in report.figures
    mae = json.loads((scan / "evaluation.json").read_text())["meshes"][0]["mae_mm"]
    assert f"{mae:.6g}" in _text(report)  # the table carries the run's number
    # the 3D view is coloured by the same distances the evaluation measured
    from virtus.io.ply import read_ply
    from virtus.report.build import _c2m_values

    evaluation = json.loads((scan / "evaluation.json").read_text())
    values = _c2m_values(scan, read_ply(scan / "points.ply").points, evaluation)
    assert np.nanmean(np.abs(values)) == pytest.approx(mae, rel=1e-9)
    assert "colour: signed distance to the mesh" in _text(report)
    turn = tmp_path / "turn"
    run_cli(["scan", "--scene", "freeform", "--rig", rig_file, "--spp", "1", "--turntable",
             "2", "--out", turn, "--no-report", "--quiet"])  # fmt: skip
    report = write_report(turn)
    assert report.kind == "turntable"
    assert {"fig-cloud-to-mesh-distance-merged-c2m-histogram-0",
            "view-3d-view-cloud"} <= set(report.figures)  # fmt: skip


def test_twin_without_validation(calibrate_run, tmp_path) -> None:
    out = tmp_path / "twin"
    run_cli(["twin", calibrate_run / "calibration.json", "--out", out])
    report = write_report(out)
    assert report.kind == "twin"
    assert "No validation: run `virtus twin" in _text(report)


@pytest.mark.slow
def test_default_demo_report_is_at_most_5_mb(tmp_path) -> None:
    """The issue's bound, on the real default demo (960 x 960 px, 18 poses, 4 spp)."""
    out = tmp_path / "demo"
    run_cli(["demo", "--out", out, "--quiet"])
    report = out / REPORT_FILE
    assert report.is_file()
    size = report.stat().st_size
    assert size <= DEMO_REPORT_MAX_BYTES, size
    text = report.read_text(encoding="utf-8")
    assert f"{MAX_POINTS:,} of " in text  # the cloud is subsampled to the viewer's bound


def _resume_argv(kind: str, session, run_dir) -> list:  # noqa: ANN001
    """The session run's own command line again, resumed in ``run_dir`` (a copy of the
    session's run; its inputs stay where they are): nothing is rendered again."""
    folder = session.parent
    if kind == "acceptance":
        return ["acceptance", "--rig", folder / "rig240.json", "--out", run_dir, "--true-rig",
                "--positions", "1", "--lookup", "bilinear", "--limits",
                "P_F=5,P_S=1,SD=1,F=1", "--resume", "--quiet"]  # fmt: skip
    return ["robot-scan", "--robot", folder / "robot.yaml", "--trajectory",
            folder / "trajectory.json", "--spp", "1", "--out", run_dir, "--resume",
            "--quiet"]  # fmt: skip


@pytest.mark.parametrize("kind", ["acceptance", "robot-scan"])
def test_acceptance_and_robot_scan_write_their_report(kind, request, tmp_path) -> None:
    import shutil

    session = request.getfixturevalue(f"{kind.replace('-', '_')}_run")
    run_dir = Path(shutil.copytree(session, tmp_path / session.name))
    run_cli([*_resume_argv(kind, session, run_dir), "--no-report"])
    assert not (run_dir / REPORT_FILE).exists()
    run_cli(_resume_argv(kind, session, run_dir))
    assert (run_dir / REPORT_FILE).stat().st_size > 10_000


def test_learn_eval_writes_the_runs_report(learn_run, learn_store_small, tmp_path) -> None:
    import shutil

    run_dir = Path(shutil.copytree(learn_run, tmp_path / "learn"))
    run_cli(["learn", "eval", run_dir, "--store", learn_store_small, "--split", "test",
             "--quiet"])  # fmt: skip
    text = (run_dir / REPORT_FILE).read_text()
    assert "Evaluation store-test" in text and "Evaluation store-all" in text
