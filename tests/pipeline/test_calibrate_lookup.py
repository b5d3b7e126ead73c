"""The scanner's projector model reaches the calibration captures."""

from __future__ import annotations

import pytest

import virtus.pipeline.calibrate as job
from tests.pipeline.test_calibrate_resume import quarter_rig
from virtus.cli import main
from virtus.render import RenderSettings
from virtus.scanner import Scanner
from virtus.sensor.projector import Lookup, ProjectorModel


@pytest.mark.slow
def test_the_scanners_lookup_makes_every_calibration_capture(tmp_path, monkeypatch):
    seen = []
    capture = Scanner.capture

    def recording(self, *args, **kwargs):
        made = capture(self, *args, **kwargs)
        seen.append(made.render["lookup"])
        return made

    monkeypatch.setattr(Scanner, "capture", recording)
    projector = ProjectorModel(pixel=Lookup.bilinear)
    scanner = Scanner(rig=quarter_rig(), projector=projector, render=RenderSettings(spp=1))
    result = job.calibrate_rig(scanner, board="4x7", poses="random:3", rng=1, out_dir=tmp_path)
    assert seen == ["bilinear"] * 3
    assert result.settings["lookup"] == "bilinear"
    assert result.settings["projector"] == projector.to_dict()


@pytest.mark.parametrize("command", ["calibrate", "demo", "scan", "capture"])
def test_cli_lookup_choices(command, capsys, tmp_path):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--lookup", "cubic", "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    assert "cubic" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before anything is written
