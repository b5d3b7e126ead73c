"""The output helper of every command: one summary dict, printed as tables or as one JSON
object; progress only on a terminal (:mod:`virtus.cli.output`)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from virtus.cli import main
from virtus.cli.output import Output, Summary, plain


def _render(console, data) -> None:  # noqa: ANN001
    console.print(f"radius {data['radius_mm']:.3f} mm")


def test_plain_gives_strict_json_data() -> None:
    data = {
        "n": np.int64(3),
        "x": np.float32(0.5),
        "nan": float("nan"),
        "inf": np.float64(np.inf),
        "path": Path("a/b.ply"),
        "pair": (1, 2),
        "array": np.arange(3),
        "nested": {"values": [np.float64(-np.inf), 1.5]},
    }
    out = plain(data)
    text = json.dumps(out, allow_nan=False)  # would raise on NaN or an unknown type
    assert json.loads(text) == {
        "n": 3, "x": 0.5, "nan": None, "inf": None, "path": "a/b.ply", "pair": [1, 2],
        "array": [0, 1, 2], "nested": {"values": [None, 1.5]},
    }  # fmt: skip


@pytest.mark.parametrize(("json_out", "quiet"), [(False, False), (True, False), (False, True)])
def test_a_summary_is_the_table_or_one_json_object_or_nothing(json_out, quiet, capsys) -> None:
    summary = Summary({"radius_mm": 99.3391}, _render)
    summary.add("report", Path("run/report.html"), "report written: run/report.html")
    Output(json_out, quiet).emit(summary)
    out, err = capsys.readouterr()
    assert err == ""
    if quiet:
        assert out == ""
    elif json_out:
        # one object, and the line added after the table is one of its keys
        assert json.loads(out) == {"radius_mm": 99.3391, "report": "run/report.html"}
    else:
        assert out.splitlines() == ["radius 99.339 mm", "report written: run/report.html"]


def test_warnings_go_to_stderr_also_with_json(capsys) -> None:
    output = Output(json=True)
    output.warn("many pixels flagged")
    output.log("[1/3] matte")  # a progress line: not with --json
    output.emit(Summary({"a": 1}))
    out, err = capsys.readouterr()
    assert json.loads(out) == {"a": 1}
    assert err == "virtus: warning: many pixels flagged\n"


@pytest.mark.parametrize(
    ("tty", "json_out", "quiet", "shown"),
    [
        ("1", False, False, True),
        ("0", False, False, False),
        ("1", True, False, False),
        ("1", False, True, False),
    ],  # fmt: skip
)
def test_progress_only_on_a_terminal(tty, json_out, quiet, shown, monkeypatch, capsys) -> None:
    monkeypatch.delenv("FORCE_COLOR", raising=False)
    monkeypatch.setenv("TTY_COMPATIBLE", tty)  # rich's own switch for is_terminal
    output = Output(json_out, quiet)
    assert output.shows_progress is shown
    with output.progress() as bar:
        assert (bar is not None) is shown
        if bar is not None:
            bar.add_task("calibration", total=2)
    out, err = capsys.readouterr()
    assert out == ""
    assert ("calibration" in err) is shown


# --- every command: the table's numbers are the JSON's ---------------------------------------


#: A number as a table prints it: not part of a word (C2M, u_p, 960x960).
_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?%?(?![\w])")


def _leaves(data: object) -> list[object]:
    if isinstance(data, dict):
        return [leaf for value in data.values() for leaf in _leaves(value)]
    if isinstance(data, list):
        return [leaf for value in data for leaf in _leaves(value)]
    return [data]


def assert_table_numbers_in_json(text: str, data: dict) -> None:
    """Every number the text shows is a number of ``data`` at the printed precision, in the
    same unit or scaled as tables do (a fraction as a percentage, metres as millimetres: x100
    or x1000; a number with a ``%`` sign must be a fraction x 100). Strings of ``data``
    (paths, names; not a unit such as "m", which would cut words) are left out first."""
    leaves = _leaves(data)
    strings = (s for s in leaves if isinstance(s, str) and len(s) > 2)
    for string in sorted(strings, key=len, reverse=True):
        text = text.replace(string, " ")
    numbers = [float(v) for v in leaves if isinstance(v, int | float) and not isinstance(v, bool)]
    tokens = _NUMBER.findall(text)
    assert tokens, text
    for token in tokens:
        percent = token.endswith("%")
        mantissa, _, exponent = token.rstrip("%").partition("e")
        decimals = len(mantissa.partition(".")[2])
        tolerance = 0.5 * 10.0 ** (int(exponent or 0) - decimals) * (1 + 1e-9)
        value = float(token.rstrip("%"))
        scales = (100.0,) if percent else (1.0, 100.0, 1000.0)
        assert any(abs(n * k - value) <= tolerance for n in numbers for k in scales), (token, text)


#: Commands whose table and JSON are compared; {r} the tiny rig, {w} a work folder, {t} the
#: tiny fixture's folder (its capture: {t}/cap, read only: decode/reconstruct use a copy).
SUMMARIES = {
    "rig": ["rig", "info", "--rig", "{r}"],
    "patterns": ["patterns", "--width", "64", "--height", "48", "--out", "{w}/p"],
    "capture": ["capture", "--scene", "sphere", "--rig", "{r}", "--spp", "1", "--out", "{w}/c"],
    "scan": ["scan", "--scene", "sphere", "--rig", "{r}", "--spp", "1", "--out", "{w}/s",
             "--no-report"],  # the report has its own tests
    "decode": ["decode", "{w}/cap"],
    "reconstruct": ["reconstruct", "{w}/cap"],
    "import": ["import", "{w}/cap/frames", "--sequence", "{t}/seq.json", "--calibration",
               "{r}", "--out", "{w}/i"],
}  # fmt: skip


@pytest.mark.parametrize("name", list(SUMMARIES))
def test_json_carries_the_numbers_the_table_shows(name, tiny, tmp_path, emitted, capsys):
    seen = emitted
    values = {"r": str(tiny / "rig.json"), "t": str(tiny)}
    for mode, flags in (("text", []), ("json", ["--json"])):
        work = tmp_path / mode
        shutil.copytree(tiny / "cap", work / "cap")
        argv = [a.format(w=work, **values) for a in SUMMARIES[name]] + flags
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        out, err = capsys.readouterr()
        assert exit_info.value.code == 0, err
        if mode == "text":
            assert_table_numbers_in_json(out, seen[-1])
            text_keys = set(seen[-1])
        else:
            data = json.loads(out)  # the whole of stdout is one JSON object
            assert isinstance(data, dict) and set(data) == text_keys
            assert data == seen[-1]


@pytest.mark.parametrize("name", ["capture", "decode", "reconstruct"])
def test_quiet_prints_nothing_and_keeps_the_exit_status(name, tiny, tmp_path, capsys) -> None:
    shutil.copytree(tiny / "cap", tmp_path / "cap")
    values = {"r": str(tiny / "rig.json"), "t": str(tiny), "w": str(tmp_path)}
    with pytest.raises(SystemExit) as exit_info:
        main([a.format(**values) for a in SUMMARIES[name]] + ["--quiet"])
    assert exit_info.value.code == 0
    assert capsys.readouterr() == ("", "")
    # an error is still one line on stderr, with its status
    with pytest.raises(SystemExit) as exit_info:
        main(["decode", str(tmp_path / "missing"), "--quiet"])
    out, err = capsys.readouterr()
    assert (exit_info.value.code, out, err.count("\n")) == (2, "", 1)
    assert err.startswith("virtus: error: ")


class _Calibrated:
    """A stand-in calibration result (what ``CalibrationResult.to_dict`` holds)."""

    def to_dict(self) -> dict:
        device = {
            "fx_rel_error": 1.2e-5,
            "fy_rel_error": -3.4e-5,
            "cx_error_px": 0.0123,
            "cy_error_px": -0.0456,
            "dist_error": [1e-4, -2e-4, 3e-6, 4e-6, 0.0],
        }
        check = {
            "focal_rel_std": 2.5e-4,
            "principal_point_std_px": 0.31,
            "coverage": 0.87,
            "tilt_deg": [4.2, 31.7],
        }
        return {
            "rms_px": {"camera": 0.0512, "projector": 0.0467, "stereo": 0.0493},
            "paper_rms_px": {"camera": None, "projector": 0.049, "stereo": 0.056},
            "per_pose": [{"name": "pose_00", "camera_rms_px": 0.0501, "projector_rms_px": 0.0444},
                         {"name": "pose_01", "camera_rms_px": 0.0523, "projector_rms_px": 0.0489}],
            "conditioning": {"tilt_spread_deg": 27.5, "camera": check, "projector": check},
            "truth_error": {"camera": device, "projector": device,
                            "proj2cam": {"baseline_error_m": 2.1e-5, "translation_error_m": 3.2e-5,
                                         "rotation_error_deg": 0.00123}},
            "dropped_poses": ["pose_07"],
        }  # fmt: skip


def _fake_calibration(monkeypatch) -> None:  # noqa: ANN001
    import virtus.pipeline.calibrate as job

    monkeypatch.setattr(job, "calibrate_rig", lambda *args, **kwargs: _Calibrated())


def _fake_ablation(monkeypatch) -> None:  # noqa: ANN001
    import virtus.pipeline.ablation as job

    rows = [
        {"material": "matte", "ambient": "dark", "realism": "ideal", "valid_fraction": 0.9132,
         "phase_error_rms_rad": 0.00412, "order_error_fraction": 0.0, "radius_error_mm": -0.0123,
         "fit_rms_mm": 0.2456},
        {"material": "metal", "ambient": "ambient", "realism": "all", "valid_fraction": 0.4419,
         "phase_error_rms_rad": 0.3127, "order_error_fraction": 0.0321,
         "radius_error_mm": float("nan"), "fit_rms_mm": 1.8765},
    ]  # fmt: skip
    monkeypatch.setattr(job, "run_ablation", lambda *args, **kwargs: rows)


#: Jobs replaced by stand-ins (their tables are made from a known summary).
FAKED = {
    "calibrate": (["calibrate", "--out", "{w}/c", "--no-report"], _fake_calibration),
    "ablation": (["ablation", "--out", "{w}/a", "--no-report"], _fake_ablation),
}


@pytest.mark.parametrize("name", list(FAKED))
def test_json_carries_the_numbers_the_table_shows_of_faked_jobs(name, tmp_path, monkeypatch,
                                                                 emitted, capsys):  # fmt: skip
    argv, fake = FAKED[name]
    fake(monkeypatch)
    seen = emitted
    for flags in ([], ["--json"]):
        with pytest.raises(SystemExit) as exit_info:
            main([a.format(w=tmp_path) for a in argv] + flags)
        out, err = capsys.readouterr()
        assert exit_info.value.code == 0, err
        if flags:
            assert json.loads(out) == seen[-1]
        else:
            assert_table_numbers_in_json(out, seen[-1])


def test_the_report_row_is_in_the_json_too(tiny, tmp_path, capsys) -> None:
    # `virtus report` adds a row to the summaries of demo, scan, calibrate and ablation:
    # with --json it is a key of the one object.
    out = tmp_path / "s"
    argv = ["scan", "--scene", "sphere", "--rig", str(tiny / "rig.json"), "--spp", "1",
            "--out", str(out), "--json"]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    stdout, err = capsys.readouterr()
    assert exit_info.value.code == 0, err
    data = json.loads(stdout)
    assert data["report"] == str(out / "report.html") and (out / "report.html").is_file()
