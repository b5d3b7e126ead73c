"""``virtus demo``: one experiment with default options, the ideal reference only for a
scanner that differs physically from the ideal one, and its summary as table or JSON. The
experiment itself is replaced by a stand-in that records its scanner (the real one is the
slow test in tests/pipeline/test_demo.py)."""

from __future__ import annotations

import json

import pytest

import virtus.pipeline.demo as job
from tests.cli.test_output import assert_table_numbers_in_json
from virtus.cli import main


def _metrics(scanner) -> dict:  # noqa: ANN001
    noisy = scanner.sensor.dark_noise_e > 0
    return {
        "calibration": {"camera_rms_px": 0.0412, "projector_rms_px": 0.0377,
                        "stereo_rms_px": 0.0395 + 0.01 * noisy},
        "sphere": {"radius_true_mm": 100.0, "radius_mm": 99.9871, "radius_error_mm": -0.0129,
                   "inlier_ratio": 0.9931, "fit_rms_mm": 0.2764 + 0.1 * noisy,
                   "n_points": 183214, "threshold_mm": 1.0},
        "sphere_true_rig": {"radius_mm": 99.9962, "radius_error_mm": -0.0038,
                            "fit_rms_mm": 0.2711, "inlier_ratio": 0.9944},
        "paper": job.PAPER,
        "targets": job.TARGETS,
        "timing": {"calibration_s": 3.21, "scan_s": 1.43, "fit_s": 0.52, "total_s": 5.26},
    }  # fmt: skip


@pytest.fixture
def experiments(monkeypatch) -> list:
    """The scanners the demo's experiment ran with (a stand-in experiment)."""
    ran = []

    def experiment(run, config, scanner, progress):  # noqa: ANN001, ANN202
        ran.append(scanner)
        if progress is not None:
            progress("calibration", 1, 18)
        return job.DemoResult(run.path, _metrics(scanner), None, None)

    monkeypatch.setattr(job, "_run", experiment)
    return ran


def _demo(argv: list[str], capsys) -> tuple[str, str]:  # noqa: ANN001
    with pytest.raises(SystemExit) as exit_info:
        main(["demo", *argv, "--no-report"])  # the report has its own tests
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0, err
    return out, err


def test_the_default_demo_runs_one_experiment(experiments, tmp_path, capsys) -> None:
    out, _ = _demo(["--out", str(tmp_path / "d"), "--json"], capsys)
    assert len(experiments) == 1
    record = json.loads((tmp_path / "d" / "metrics.json").read_text())["ideal_reference"]
    assert record["ran"] is False and record["differences"] == [] and record["metrics"] is None
    assert "physically the ideal one" in record["reason"]
    summary = json.loads(out)
    assert summary["ideal_reference"] == record and summary["ideal"] is None
    assert not (tmp_path / "d" / job.IDEAL_DIR).exists()


def test_a_renamed_ideal_sensor_is_still_one_experiment(experiments, tmp_path, capsys) -> None:
    # the same parameters under another name: physically ideal, so no reference
    (tmp_path / "cam.yaml").write_text("name: my-lab-camera\nbit_depth: 8\n")
    (tmp_path / "proj.yaml").write_text("name: my-projector\ngamma: 1.0\n")
    argv = ["--out", str(tmp_path / "d"), "--sensor", str(tmp_path / "cam.yaml"),
            "--projector", str(tmp_path / "proj.yaml"), "--quiet"]  # fmt: skip
    assert _demo(argv, capsys) == ("", "")
    assert len(experiments) == 1


def test_a_realistic_demo_runs_the_ideal_reference_beside_it(experiments, tmp_path, capsys):
    out, _ = _demo(["--out", str(tmp_path / "d"), "--sensor", "imx174", "--json"], capsys)
    assert [s.sensor.name for s in experiments] == ["imx174", "custom"]
    assert experiments[1].sensor.dark_noise_e == 0 and experiments[1].rig == experiments[0].rig
    metrics = json.loads((tmp_path / "d" / "metrics.json").read_text())
    record = metrics["ideal_reference"]
    assert record["ran"] is True and record["metrics"] == "ideal/metrics.json"
    assert any(d.startswith("sensor.dark_noise_e: 6.8") for d in record["differences"])
    ideal = json.loads((tmp_path / "d" / "ideal" / "metrics.json").read_text())
    assert ideal["ideal_reference"]["ran"] is False  # the reference has no reference
    summary = json.loads(out)
    assert summary["ideal"]["sphere"]["fit_rms_mm"] == pytest.approx(0.2764)
    assert summary["sphere"]["fit_rms_mm"] == pytest.approx(0.3764)


def test_the_demo_table_shows_the_numbers_of_its_json(experiments, tmp_path, emitted,
                                                      capsys) -> None:  # fmt: skip
    seen = emitted
    out, err = _demo(["--out", str(tmp_path / "d"), "--sensor", "imx174"], capsys)
    assert "ideal sensor" in out and "0.3764" in out and "0.2764" in out
    assert_table_numbers_in_json(out, seen[-1])


@pytest.mark.parametrize(("tty", "shown"), [("0", False), ("1", True)])
def test_progress_only_on_a_terminal(tty, shown, experiments, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("FORCE_COLOR", raising=False)
    monkeypatch.setenv("TTY_COMPATIBLE", tty)
    _out, err = _demo(["--out", str(tmp_path / "d")], capsys)
    assert ("board poses" in err) is shown
    if not shown:
        assert err == ""
