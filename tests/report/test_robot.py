"""The report of a robot scan (:mod:`virtus.report.robot`) and its refusals."""

from __future__ import annotations

import json

from tests.report.conftest import copy_run
from tests.report.test_runs import _refused
from virtus.report import build_page
from virtus.report.html import format_value


def test_a_robot_scan_shows_c2m_its_first_view_and_the_merged_cloud(robot_scan_run) -> None:
    page, info = build_page(robot_scan_run)
    assert info.kind == "robot-scan"
    figures = set(page.figures)
    assert "fig-cloud-to-mesh-distance-kinematics-alone-c2m-histogram-0" in figures
    assert "fig-first-view-000-decode-wrapped-phase-v" in figures
    assert "view-3d-view-cloud" in figures
    data = json.loads((robot_scan_run / "robot_scan.json").read_text())
    html = page.render()
    assert "kinematics alone (no registration)" in html
    assert format_value(data["c2m_kinematics"][0]["mae_mm"]) in html  # the C2M table


def test_a_view_whose_frames_changed_is_refused(robot_scan_run, tmp_path, capsys) -> None:
    run = copy_run(robot_scan_run, tmp_path)
    frames = run / "views" / "000" / "frames"
    (frames / "000.png").write_bytes((frames / "001.png").read_bytes())
    assert "decoded/ is stale" in _refused(run, capsys)


def test_a_half_finished_robot_scan_is_refused(robot_scan_run, tmp_path, capsys) -> None:
    run = copy_run(robot_scan_run, tmp_path)
    record = json.loads((run / "run.json").read_text())
    record.update(status="failed", error="KeyboardInterrupt: ")
    (run / "run.json").write_text(json.dumps(record))
    assert "half-finished `virtus robot-scan` run (status failed" in _refused(run, capsys)
