"""``virtus reconstruct`` names the rig it triangulated with by its real source: the
calibration file given, the calibration an imported capture came with, or the true rig of a
rendered capture -- never "the true rig" for a real bench."""

from __future__ import annotations

import json
import shutil

import pytest

from virtus.cli import main


def _reconstruct(argv: list[str], capsys) -> dict:  # noqa: ANN001
    with pytest.raises(SystemExit) as exit_info:
        main(["reconstruct", *argv, "--json"])
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0, err
    return json.loads(out)


@pytest.fixture
def imported(tiny, tmp_path, capsys):
    """The tiny capture's frames imported as a real bench's, with tiny/rig.json."""
    out = tmp_path / "bench"
    argv = ["import", str(tiny / "cap" / "frames"), "--sequence", str(tiny / "seq.json"),
            "--calibration", str(tiny / "rig.json"), "--out", str(out), "--quiet"]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 0, capsys.readouterr().err
    return out


def test_an_imported_capture_names_its_calibration_file(imported, tiny, capsys) -> None:
    rig = _reconstruct([str(imported)], capsys)["rig"]
    assert rig.startswith(str(tiny / "rig.json")) and "true rig" not in rig


def test_a_calibration_option_names_that_file(imported, tiny, tmp_path, capsys) -> None:
    other = tmp_path / "calibration.json"
    shutil.copy(tiny / "rig.json", other)
    assert _reconstruct([str(imported), "--calibration", str(other)], capsys)["rig"] == str(other)
    # the table says the same
    with pytest.raises(SystemExit):
        main(["reconstruct", str(imported), "--calibration", str(other)])
    assert "true rig" not in capsys.readouterr().out


def test_a_rendered_capture_names_its_true_rig(tiny, tmp_path, capsys) -> None:
    shutil.copytree(tiny / "cap", tmp_path / "cap")
    rig = _reconstruct([str(tmp_path / "cap")], capsys)["rig"]
    assert rig == f"{tmp_path / 'cap' / 'capture.json'} (the true rig it was rendered with)"
