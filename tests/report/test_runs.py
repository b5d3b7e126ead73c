"""``virtus report`` refuses what is not a finished, unchanged run: one line naming the
problem, exit status 2, nothing written (:mod:`virtus.report.runs`)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from virtus.cli import main
from virtus.report import KINDS, check_run


def _mark_running(run_dir: Path) -> str:
    """Turn ``run_dir`` into a half-finished run (its record's status "running"); returns the
    run's command."""
    record = json.loads((run_dir / "run.json").read_text())
    record["status"] = "running"
    (run_dir / "run.json").write_text(json.dumps(record))
    return record["command"]


def _refused(run_dir: Path, capsys, out: Path | None = None) -> str:
    """Run ``virtus report``; assert exit 2, one line on stderr, no report written."""
    argv = ["report", str(run_dir)] + (["--out", str(out)] if out else [])
    with pytest.raises(SystemExit) as done:
        main(argv)
    captured = capsys.readouterr()
    assert done.value.code == 2
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("virtus: error: "), captured.err
    target = out or run_dir / "report.html"
    assert not target.exists()
    assert not (target.parent / ".virtus-tmp").exists()
    return lines[0]


def test_a_finished_scan_is_recognised(scan_run) -> None:
    info = check_run(scan_run)
    assert info.kind == "scan" and info.kind in KINDS and info.command == "scan"


def test_a_directory_that_is_not_a_run(tmp_path, capsys) -> None:
    (tmp_path / "notes.txt").write_text("not a run")
    line = _refused(tmp_path, capsys)
    assert "not a virtus run" in line and str(tmp_path) in line


def test_a_missing_directory(tmp_path, capsys) -> None:
    line = _refused(tmp_path / "nowhere", capsys, out=tmp_path / "r.html")
    assert "not a directory" in line


def test_a_half_finished_run(scan_copy, capsys) -> None:
    _mark_running(scan_copy)
    line = _refused(scan_copy, capsys)
    assert "half-finished `virtus scan` run (status running)" in line


def test_a_failed_run_names_its_error(scan_copy, capsys) -> None:
    record = json.loads((scan_copy / "run.json").read_text())
    record.update(status="failed", error="KeyboardInterrupt: ")
    (scan_copy / "run.json").write_text(json.dumps(record))
    assert "status failed (KeyboardInterrupt" in _refused(scan_copy, capsys)


def test_frames_changed_after_decoding(scan_copy, capsys) -> None:
    frame = scan_copy / "frames" / "000.png"
    other = scan_copy / "frames" / "001.png"
    frame.write_bytes(other.read_bytes())
    assert "decoded/ is stale" in _refused(scan_copy, capsys)


def test_a_cloud_replaced_after_reconstruction(scan_copy, capsys) -> None:
    ply = scan_copy / "points.ply"
    ply.write_bytes(ply.read_bytes()[:-12])
    assert "points.ply" in _refused(scan_copy, capsys)


def test_a_file_the_record_lists_removed(scan_copy, capsys) -> None:
    (scan_copy / "frames" / "005.png").unlink()
    assert "005.png: missing" in _refused(scan_copy, capsys)


def test_a_decoded_map_of_the_wrong_shape(scan_copy, capsys) -> None:
    np.save(scan_copy / "decoded" / "modulation.npy", np.zeros((3, 3)))
    assert "modulation" in _refused(scan_copy, capsys)


def test_a_demo_whose_metrics_were_edited(demo_run, tmp_path, capsys) -> None:
    run = Path(shutil.copytree(demo_run, tmp_path / "demo"))
    metrics = json.loads((run / "metrics.json").read_text())
    del metrics["calibration"]
    (run / "metrics.json").write_text(json.dumps(metrics))
    assert "demo metrics without calibration" in _refused(run, capsys)


def test_a_demo_whose_calibration_was_removed(demo_run, tmp_path, capsys) -> None:
    run = Path(shutil.copytree(demo_run, tmp_path / "demo"))
    (run / "calibration" / "calibration.json").unlink()
    assert "calibration.json: missing" in _refused(run, capsys)


def test_a_foreign_npy_where_the_error_map_was(demo_run, tmp_path, capsys) -> None:
    run = Path(shutil.copytree(demo_run, tmp_path / "demo"))
    np.save(run / "scan" / "sphere_radial_error.npy", np.zeros((4, 4)))
    assert "sphere_radial_error.npy" in _refused(run, capsys)


def test_out_must_be_html_in_an_existing_folder(scan_run, tmp_path, capsys) -> None:
    assert "a .html file" in _refused(scan_run, capsys, out=tmp_path / "report.txt")
    assert "existing directory" in _refused(scan_run, capsys, out=tmp_path / "no" / "r.html")
