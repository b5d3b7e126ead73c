"""The projector lookup option reaches the calibration captures."""

from __future__ import annotations

import pytest

from virtus.calib.episode import calibrate_rig
from virtus.cli import main
from virtus.devices import default_rig
from virtus.errors import InputError


def test_unknown_lookup_is_refused_before_rendering(tmp_path):
    with pytest.raises(InputError, match=r"^lookup: expected one of"):
        calibrate_rig(default_rig(), lookup="cubic", out_dir=tmp_path)
    assert not (tmp_path / "poses").exists() or not any((tmp_path / "poses").iterdir())


@pytest.mark.parametrize("command", ["calibrate", "demo", "scan", "capture"])
def test_cli_lookup_choices(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--lookup", "cubic"])
    assert exit_info.value.code == 2
    assert "cubic" in capsys.readouterr().err
