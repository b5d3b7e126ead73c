"""``virtus acceptance``: bad input is one line, exit 2, nothing written; a tiny run works."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from virtus.cli import main
from virtus.geometry.devices import Camera, Rig, default_rig


def _small_rig(path: Path) -> Path:
    rig = default_rig()
    small = Rig(Camera(rig.camera.intrinsics.scaled(0.25)), rig.projector, rig.proj2cam)
    return small.save_json(path)


def _snapshot(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}  # fmt: skip


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--limits", "P_F=0.05,XY=1"], "--limits"),
        (["--limits", "P_F=-0.05"], "--limits"),
        (["--limits", "P_F"], "--limits"),
        (["--volume", "-400,-50,950,-300,50,1050"], "--volume"),  # left of both fields
        (["--volume", "-300,-300,900,300,300,1100"], "--volume"),  # wider than the camera's
        (["--volume", "1,2,3"], "--volume"),
        (["--volume", "-100,-50,950,100,50,1050", "--volume", "0,0,900,1,1,901"], "--volume"),
        (["--limits", "P_F=0.05", "--limits", "P_F=0.1"], "--limits"),  # twice the same
        (["--positions", "0"], "--positions"),
        (["--positions", "11"], "--positions"),
        (["--true-rig", "--calibration", "rig.json"], "--true-rig"),
        (["--calibration", "missing.json"], "--calibration"),
        (["--calibration-poses", "random:1"], "poses"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(extra, message, tmp_path, monkeypatch,
                                                          capsys):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    _small_rig(tmp_path / "rig.json")
    before = _snapshot(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        main(["acceptance", "--rig", "rig.json", "--out", "out", *extra])
    out, err = capsys.readouterr()
    assert exit_info.value.code == 2, (out, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("virtus: error: "), err
    assert message in lines[0], err
    assert not (tmp_path / "out").exists()
    assert _snapshot(tmp_path) == before


def test_a_shortened_run_writes_the_figures_and_a_rerun_resumes(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _small_rig(tmp_path / "rig.json")
    argv = ["acceptance", "--rig", "rig.json", "--out", "out", "--true-rig", "--positions", "1",
            "--lookup", "bilinear", "--limits", "P_F=5,P_S=1", "--limits", "SD=1,F=1"]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 0
    summary = json.loads((tmp_path / "out" / "acceptance.json").read_text())
    assert summary["passed"] is True and summary["complete"] is False
    assert set(summary["maxima"]) == {"P_F", "P_S", "SD", "F"}
    csv = (tmp_path / "out" / "acceptance.csv").read_text().splitlines()
    assert csv[0] == "feature,position,figure,value_mm" and len(csv) == 1 + 4
    written = _snapshot(tmp_path / "out")
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:  # the same run again: refused, unless resumed
        main(argv)
    assert exit_info.value.code == 2 and "--resume" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--resume", "--json"])
    assert exit_info.value.code == 0
    printed = json.loads(capsys.readouterr().out)  # stdout: the summary and nothing else
    assert printed["maxima"] == summary["maxima"] and printed["passed"] is True
    assert printed["rig"] == "true"
    again = _snapshot(tmp_path / "out")
    assert {k: v for k, v in again.items() if k != "run.json"} == {
        k: v for k, v in written.items() if k != "run.json"
    }
