"""The ablation job: every cell measured, and the effects go the way physics says."""

from __future__ import annotations

import csv
import json

import pytest

from tests.support import small_rig
from virtus.cli import main
from virtus.errors import InputError
from virtus.pipeline.ablation import COLUMNS, run_ablation
from virtus.scanner import Scanner


def test_ablation_cells_are_measured(tmp_path) -> None:
    rows = run_ablation(
        tmp_path, Scanner(rig=small_rig()), materials=["matte"], ambients=["dark"],
        realism=["ideal", "sensor", "gamma"],
    )  # fmt: skip
    by = {r["realism"]: r for r in rows}
    assert set(by) == {"ideal", "sensor", "gamma"}
    # Ideal: the DMD staircase only; the sensor adds noise; the LightCrafter-like projector
    # without gamma pre-compensation blurs the staircase away (its N = 18 gamma ripple is
    # ~1e-6 rad) and lowers the error.
    assert by["ideal"]["order_error_fraction"] == 0.0
    assert by["sensor"]["phase_error_rms_rad"] > by["ideal"]["phase_error_rms_rad"]
    assert by["gamma"]["phase_error_rms_rad"] < by["ideal"]["phase_error_rms_rad"]
    assert abs(by["ideal"]["radius_error_mm"]) < 0.1
    with (tmp_path / "ablation.csv").open() as handle:
        table = list(csv.DictReader(handle))
    assert len(table) == 3 and tuple(table[0]) == COLUMNS
    assert json.loads((tmp_path / "ablation.json").read_text())["cells"][0]["material"] == "matte"
    assert (tmp_path / "ablation.png").stat().st_size > 1000


def test_unknown_cells_are_refused(tmp_path, capsys) -> None:
    with pytest.raises(InputError, match="materials"):
        run_ablation(tmp_path, materials=["velvet"])
    with pytest.raises(SystemExit) as exit_info:
        main(["ablation", "--out", str(tmp_path / "o"), "--realism", "ideal,magic"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "realism" in err[0]
