"""Design sweeps (virtus.design.sweep, ``virtus design``): the model's scaling laws through
the sweep, resuming, workers, and bad input that writes nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.tolerances import SWEEP_SCALING_REL
from virtus.cli import main
from virtus.design import sweep as sweep_module
from virtus.design.sweep import FIGURES, run_design
from virtus.errors import InputError, VirtusError
from virtus.scanner import Scanner
from virtus.sensor import SENSOR_PRESETS

BASE = Scanner(sensor=SENSOR_PRESETS["imx174"])


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("design")
    rows = run_design(out, BASE, vary=["steps=4,16", "period_px=18,36"], grid=24)
    return out, rows


def _row(rows, **values):
    (row,) = [r for r in rows if all(r[k] == v for k, v in values.items())]
    return row


def test_predicted_depth_noise_falls_with_sqrt_n_and_rises_with_the_period(sweep):
    _, rows = sweep
    for figure in ("sigma_depth_um_median", "sigma_depth_um_p95", "sigma_u_p_px_median"):
        for period in (18.0, 36.0):  # 4x the steps: half the noise
            ratio = (
                _row(rows, steps=4, period_px=period)[figure]
                / _row(rows, steps=16, period_px=period)[figure]
            )
            assert ratio == pytest.approx(2.0, rel=SWEEP_SCALING_REL), (figure, period, ratio)
        for steps in (4, 16):  # twice the period: twice the noise
            ratio = (
                _row(rows, steps=steps, period_px=36.0)[figure]
                / _row(rows, steps=steps, period_px=18.0)[figure]
            )
            assert ratio == pytest.approx(2.0, rel=SWEEP_SCALING_REL), (figure, steps, ratio)


def test_a_sweep_writes_its_table_json_and_a_figure_per_figure_and_key(sweep):
    out, rows = sweep
    assert len(rows) == 4 and [r["variant"] for r in rows] == [0, 1, 2, 3]
    lines = (out / "design.csv").read_text().splitlines()
    assert lines[0].startswith("steps,period_px,variant") and len(lines) == 5
    report = json.loads((out / "design.json").read_text())
    assert report["keys"] == ["steps", "period_px"] and len(report["variants"]) == 4
    for figure in FIGURES:
        for key in ("steps", "period_px"):
            assert (out / "figures" / f"{figure}__{key}.png").stat().st_size > 1000
    # all pixels of the plane are predicted: micrometres of noise, not NaN
    assert all(r["predicted_fraction"] > 0.99 for r in rows)
    assert 1.0 < rows[0]["sigma_depth_um_median"] < 1000.0


def test_a_resumed_sweep_predicts_only_the_missing_variants(tmp_path, monkeypatch):
    vary = ["steps=4,8"]
    first = run_design(tmp_path, BASE, vary=vary, grid=12)
    (tmp_path / "variants" / "0001.json").unlink()
    calls = []
    real = sweep_module.predict_variant
    monkeypatch.setattr(sweep_module, "predict_variant",
                        lambda *a: calls.append(a[1].index) or real(*a))  # fmt: skip
    again = run_design(tmp_path, BASE, vary=vary, grid=12, resume=True)
    assert calls == [1]
    assert again == first
    with pytest.raises(VirtusError, match="already holds"):
        run_design(tmp_path, BASE, vary=vary, grid=12)
    # a variant file of another configuration is not taken for this one's
    data = json.loads((tmp_path / "variants" / "0000.json").read_text())
    data["episode"] = "another"
    (tmp_path / "variants" / "0000.json").write_text(json.dumps(data))
    with pytest.raises(VirtusError, match="another design configuration"):
        run_design(tmp_path, BASE, vary=vary, grid=12, resume=True)


@pytest.mark.slow  # two spawned processes each import the renderer (~10 s on 2 cores)
def test_worker_processes_give_the_same_rows(tmp_path):
    vary = ["sensor=imx174,webcam"]
    here = run_design(tmp_path / "here", BASE, vary=vary, grid=8)
    there = run_design(tmp_path / "there", BASE, vary=vary, grid=8, workers=2)
    assert there == here


@pytest.mark.parametrize(
    ("vary", "kwargs", "message"),
    [
        (["focal_mm=8"], {}, "--vary key: expected one of"),
        (["baseline_mm=125,1000", "toe_in_deg=0"], {}, "devices not overlapping"),
        (["steps=4"], {"target": "cube"}, "--target: expected one of plane, sphere"),
        (["steps=4"], {"grid": 0}, "grid"),
        (["steps=4"], {"grid": 4096}, "at most 512"),
        (["steps=4"], {"use": "w"}, "use"),
    ],
)
def test_bad_input_writes_nothing(tmp_path, vary, kwargs, message):
    with pytest.raises(InputError, match=message):
        run_design(tmp_path / "out", BASE, vary=vary, **kwargs)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--vary", "focal=1"], "--vary key: expected one of baseline_mm"),
        (["--vary", "working_distance_m=1,0.2", "--vary", "toe_in_deg=0"],
         "devices not overlapping"),
        (["--vary", "steps=1"], "--vary steps: expected an integer in [3, 64]"),
    ],
)  # fmt: skip
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as exit_info:
        main(["design", *argv, "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("virtus: error: "), err
    assert message in err
    assert not (tmp_path / "out").exists()


def test_cli_prints_the_table_as_json(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["design", "--vary", "bit_depth=8,12", "--sensor", "imx174", "--grid", "8",
              "--out", str(tmp_path / "out"), "--json"])  # fmt: skip
    assert exit_info.value.code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["keys"] == ["bit_depth"]
    eight, twelve = data["variants"]
    # 8 bits of the same well: the signal is 16x fewer DN, quantisation adds a little
    assert eight["sigma_u_p_px_median"] >= twelve["sigma_u_p_px_median"]
    assert np.isfinite(eight["sigma_depth_um_median"])


def test_acceptance_figures_join_each_variants_row(tmp_path, monkeypatch):
    """--acceptance: each variant's rendered test runs in OUT/acceptance/NNNN with the
    variant's scanner and the given options; its maxima (mm) join the row, the table and
    the figures. (The test itself is tested in test_acceptance.py; here a stand-in.)"""
    from virtus.design import acceptance as acceptance_module

    calls = []

    def stand_in(scanner, out_dir, **options):
        calls.append((scanner.sensor.bit_depth, str(out_dir), options))
        maxima = {"P_F": {"max_abs_mm": 0.01 * scanner.sensor.bit_depth},
                  "SD": {"max_abs_mm": 0.2}}  # fmt: skip
        return acceptance_module.AcceptanceResult({"maxima": maxima, "passed": None}, out_dir)

    monkeypatch.setattr(acceptance_module, "acceptance_test", stand_in)
    options = {"calibration": "true", "positions": 2}
    rows = run_design(tmp_path / "out", BASE, vary=["bit_depth=8,12"], grid=8,
                      acceptance=True, acceptance_options=options)  # fmt: skip
    assert [c[0] for c in calls] == [8, 12]
    assert calls[1][1] == str(tmp_path / "out" / "acceptance" / "0001")
    assert calls[0][2] == {"calibration": "true", "positions": 2, "resume": False,
                           "overwrite": False}  # fmt: skip
    assert [r["P_F_mm"] for r in rows] == [0.08, 0.12]
    assert rows[0]["SD_mm"] == 0.2 and rows[0]["P_S_mm"] is None and rows[0]["F_mm"] is None
    assert "P_F_mm" in (tmp_path / "out" / "design.csv").read_text().splitlines()[0]
    assert (tmp_path / "out" / "figures" / "P_F_mm__bit_depth.png").is_file()


def test_the_acceptance_options_are_the_acceptance_tests_keywords():
    import inspect

    from virtus.design.acceptance import acceptance_test
    from virtus.design.sweep import ACCEPTANCE_OPTIONS

    assert set(ACCEPTANCE_OPTIONS) <= set(inspect.signature(acceptance_test).parameters)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"limits": "Q=1"}, "limits|Q"),
        ({"calibration": "missing.json"}, "--acceptance-calibration"),
        ({"colour": "red"}, "acceptance options"),
    ],
)
def test_bad_acceptance_options_write_nothing(tmp_path, options, message):
    with pytest.raises(InputError, match=message):
        run_design(tmp_path / "out", BASE, vary=["steps=4"], acceptance=True,
                   acceptance_options=options)  # fmt: skip
    assert not (tmp_path / "out").exists()
