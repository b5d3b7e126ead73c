"""Every CLI error is one line on stderr and a non-zero exit status, never a traceback."""

from __future__ import annotations

import pytest

from virtus.cli import main

BAD_INVOCATIONS = [
    # usage errors found by Typer
    (["no-such-command"], "No such command"),
    (["capture", "--no-such-option"], "No such option"),
    (["capture", "--spp", "four"], "Invalid value for '--spp'"),
    (["scan", "--lookup", "cubic"], "'cubic' is not one of"),
    (["decode"], "Missing argument"),
    # bad values found by the library before any rendering
    (["capture", "--spp", "3"], "spp: expected a perfect square"),
    (["capture", "--bit-depth", "14"], "bit_depth: expected one of (8, 10, 12, 16)"),
    (["calibrate", "--board", "4x6"], "cols: expected an odd number of columns"),
    (["calibrate", "--poses", "random:0"], "poses: expected 'paper' or 'random:N' with 3 <= N"),
    (["capture", "--scene", "missing.yaml"], "scene: expected an existing YAML file"),
    (["rig", "info", "--rig", "missing.json"], "rig: expected an existing JSON file"),
]


@pytest.mark.parametrize(("argv", "message"), BAD_INVOCATIONS)
def test_bad_invocation_is_one_line_on_stderr(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    if "--out" not in argv and argv[0] in ("capture", "calibrate", "scan"):
        argv = [*argv, "--out", str(tmp_path / "out")]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("virtus: error: "), err
    assert message in err
    assert not (tmp_path / "out").exists()


def test_help_exits_with_status_zero(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["rig", "info", "--help"])
    assert exit_info.value.code == 0
    assert "--rig" in capsys.readouterr().out


def test_rig_info_json_reads_back_as_the_default_rig(capsys):
    import json

    from virtus.geometry.devices import Rig, default_rig

    with pytest.raises(SystemExit) as exit_info:
        main(["rig", "info", "--json"])
    assert exit_info.value.code == 0
    data = json.loads(capsys.readouterr().out)
    assert Rig.from_dict(data) == default_rig()
    assert data["isaac"]["focal_length"] == pytest.approx(50.0)  # the paper's Isaac camera
    size = data["projected_size_m"]
    assert (size["width"], size["height"]) == pytest.approx((0.5, 0.625))


def test_patterns_writes_any_sequence_it_is_given(tmp_path, capsys) -> None:
    from pathlib import Path

    from virtus.patterns import load_sequence_file

    example = (
        Path(__file__).resolve().parents[1] / "examples" / "sequences" / "lightcrafter_lab.yaml"
    )
    with pytest.raises(SystemExit) as exit_info:
        main(["patterns", "--sequence", str(example), "--out", str(tmp_path / "p")])
    assert exit_info.value.code == 0, capsys.readouterr().err
    written, _ = load_sequence_file(tmp_path / "p" / "sequence.json")
    assert written == load_sequence_file(example)[0]
    assert len(list((tmp_path / "p").glob("*.png"))) == 52


def test_capture_takes_a_built_in_scene_as_scan_does(tmp_path, monkeypatch, capsys) -> None:
    # `virtus capture --scene freeform` renders the built-in free-form object, its mesh
    # written into (and owned by) the run's directory, as `virtus scan --scene freeform` does.
    import json

    from tests.support import small_rig
    from virtus.capture.capture import Capture

    monkeypatch.chdir(tmp_path)
    rig = small_rig().save_json(tmp_path / "rig.json")
    out = tmp_path / "cap"
    argv = ["capture", "--scene", "freeform", "--rig", str(rig), "--spp", "1", "--out", str(out)]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 0, capsys.readouterr().err
    record = json.loads((out / "run.json").read_text())
    assert record["command"] == "capture" and record["status"] == "complete"
    assert record["config"]["scene"] == "freeform" and "freeform.stl" in record["files"]
    assert (out / "freeform.stl").is_file()
    capture = Capture.load(out)
    assert capture.ground_truth.mask_hit.any()
    assert [type(o).__name__ for o in capture.scene.objects] == ["MeshObject"]


# --- how the commands print: --help, --json, --quiet -------------------------------------------


def _help_rows(argv: list[str], capsys, monkeypatch) -> list[str]:  # noqa: ANN001
    """The lines of the commands panel of ``virtus ARGV --help`` at 80 columns."""
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    panel = text[text.index("Commands") :].splitlines()[1:]
    return [line for line in panel if line.startswith("│")]


@pytest.mark.parametrize("group", [[], ["dataset"], ["rig"]], ids=["virtus", "dataset", "rig"])
def test_help_lists_each_command_on_one_line(group, capsys, monkeypatch) -> None:
    import typer

    from virtus.cli import app

    rows = _help_rows(group, capsys, monkeypatch)
    command = typer.main.get_command(app)
    for name in group:
        command = command.commands[name]
    # one row per command, each starting with its name: no continuation line
    names = [row.split()[1] for row in rows]
    assert names == list(command.commands), rows
    for row in rows:
        name = row.split()[1]
        full = command.commands[name].help or ""
        first = " ".join(row.strip("│ ").split()[1:])
        # the first sentence of the command's own help, whole
        assert first.endswith(".") and " ".join(full.split()).startswith(first), (first, full)


def test_a_commands_own_help_keeps_its_whole_text(capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "100")
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert "Run the paper's sphere experiment end to end." in text
    assert "metrics.json records whether it ran and why." in text


def test_every_command_takes_json_and_quiet() -> None:
    from tests.cli.test_options import leaf_commands

    missing = [
        " ".join(path)
        for path, command in leaf_commands()
        if not {"--json", "--quiet"} <= {o for p in command.params for o in p.opts}
    ]
    assert not missing, f"commands without --json/--quiet: {missing}"
