"""``virtus report`` and ``--no-report``: the report's summary as JSON, the path printed after
a run, no report when told (:mod:`virtus.cli.report_cmd`)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.report import conftest as runs
from tests.report.conftest import run_cli

#: The report tests' session runs (fixtures), shared here.
rig_file = runs.rig_file
scan_run = runs.scan_run


def test_report_json_names_the_file_it_wrote(scan_run, tmp_path, capsys) -> None:
    target = tmp_path / "r.html"
    run_cli(["report", scan_run, "--out", target, "--json"])
    data = json.loads(capsys.readouterr().out)
    assert data["path"] == str(target) and data["kind"] == "scan"
    assert data["bytes"] == Path(target).stat().st_size and data["figures"] >= 7


def test_report_prints_one_line_and_quiet_nothing(scan_run, tmp_path, capsys) -> None:
    run_cli(["report", scan_run, "--out", tmp_path / "a.html"])
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("scan report, ") and out[0].endswith("a.html")
    run_cli(["report", scan_run, "--out", tmp_path / "b.html", "--quiet"])
    assert capsys.readouterr().out == "" and (tmp_path / "b.html").is_file()


def test_a_run_writes_its_report_unless_told_not_to(rig_file, tmp_path, capsys) -> None:
    out = tmp_path / "scan"
    run_cli(["scan", "--rig", rig_file, "--spp", "1", "--out", out, "--json"])
    data = json.loads(capsys.readouterr().out)
    assert data["report"] == str(out / "report.html") and (out / "report.html").is_file()
    skipped = tmp_path / "skipped"
    run_cli(["scan", "--rig", rig_file, "--spp", "1", "--out", skipped, "--json", "--no-report"])
    assert json.loads(capsys.readouterr().out)["report"] is None
    assert not (skipped / "report.html").exists()
