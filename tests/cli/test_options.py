"""Options shared by the commands (:mod:`virtus.cli.options`): a repeated list option
accumulates, a repeated option of one comma-holding value is refused by name; never
last-wins silently."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import typer

from virtus.cli import app, main
from virtus.cli.options import names_option, once, parse_lens, parse_size
from virtus.errors import InputError, VirtusError


def leaf_commands():
    """``(path, command)`` of every command the CLI has, sub-commands included."""

    def walk(command, path):  # noqa: ANN001, ANN202
        if hasattr(command, "commands"):
            for name, sub in command.commands.items():
                yield from walk(sub, (*path, name))
        else:
            yield path, command

    return list(walk(typer.main.get_command(app), ()))


#: A value with a comma in the help ('W,H', 'APERTURE_M,FOCUS_M'), not prose.
_COMMA_VALUE = re.compile(r"'[^'\s]*,[^'\s]*'")


def takes_commas(option) -> bool:  # noqa: ANN001
    help_text = option.help or ""
    return (
        "," in (option.metavar or "")
        or bool(_COMMA_VALUE.search(help_text))
        or "comma" in help_text.lower()
    )


def test_every_option_with_comma_values_sees_a_repetition() -> None:
    # Click keeps the last of a repeated single-value option; an option whose values hold
    # commas is declared multiple, so its command accumulates or refuses a repetition.
    options = [
        (" ".join(path), option)
        for path, command in leaf_commands()
        for option in command.params
        if type(option).__name__.endswith("Option") and takes_commas(option)
    ]
    assert len(options) >= 15  # the audit sees the options it is about
    single = [f"{where} {option.opts[0]}" for where, option in options if not option.multiple]
    assert not single, f"last-wins when repeated: {single}"


def test_once_refuses_a_repetition_by_name() -> None:
    assert once(None, "--camera-size") is None
    assert once([], "--camera-size") is None
    assert once(["64,48"], "--camera-size") == "64,48"
    with pytest.raises(InputError, match=r"--camera-size: expected the option once"):
        once(["64,48", "32,24"], "--camera-size")
    with pytest.raises(InputError, match="--projector-size"):
        parse_size(["1,2", "3,4"], "--projector-size")
    with pytest.raises(InputError, match="--camera-lens"):
        parse_lens(["0.01,1", "0.02,1"], "--camera-lens")
    assert parse_size(["64,48"]) == (64, 48)


def test_names_accumulate_in_order() -> None:
    assert names_option(None) is None
    assert names_option(["matte"]) == ["matte"]
    assert names_option(["matte, glossy", "metal"]) == ["matte", "glossy", "metal"]
    assert names_option([","]) == []  # the job refuses an empty list by name


def _run(argv: list[str], capsys) -> tuple[int, str, str]:  # noqa: ANN001
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out, err = capsys.readouterr()
    return exit_info.value.code, out, err


def test_ablation_list_options_accumulate(tmp_path, monkeypatch, capsys) -> None:
    import virtus.pipeline.ablation as job

    seen = {}

    def record(out, scanner, **kwargs):  # noqa: ANN001, ANN202
        seen.update(kwargs)
        return []

    monkeypatch.setattr(job, "run_ablation", record)
    argv = ["ablation", "--out", str(tmp_path / "a"), "--materials", "matte",
            "--materials", "metal,glossy", "--ambient", "dark", "--ambient", "ambient",
            "--realism", "ideal", "--realism", "sensor", "--json"]  # fmt: skip
    code, _out, err = _run(argv, capsys)
    assert code == 0, err
    assert seen["materials"] == ["matte", "metal", "glossy"]
    assert seen["ambients"] == ["dark", "ambient"]
    assert seen["realism"] == ["ideal", "sensor"]


def test_calibrate_captures_accumulate(tmp_path, monkeypatch, capsys) -> None:
    import virtus.capture.scandir as scandir

    seen = []

    def record(dirs):  # noqa: ANN001, ANN202
        seen.extend(dirs)
        raise VirtusError("stop here")

    monkeypatch.setattr(scandir, "capture_dirs", record)
    argv = ["calibrate", "--out", str(tmp_path / "c"), "--captures", "a", "--captures", "b", "c"]
    code, _out, err = _run(argv, capsys)
    assert (code, err) == (2, "virtus: error: stop here\n")
    assert seen == [Path("a"), Path("b"), Path("c")]


@pytest.mark.parametrize("option", ["--validate", "--fit"])
def test_twin_capture_lists_accumulate(option, tmp_path, monkeypatch, capsys) -> None:
    import virtus.pipeline.twin as job

    seen = []

    def check(calibration, captures, **kwargs):  # noqa: ANN001, ANN202
        seen.extend(captures)
        raise VirtusError("stop here")

    def run(calibration, out, *, fit=None, **kwargs):  # noqa: ANN001, ANN202
        seen.extend(fit or [])  # the twin job: it reads the calibration before fitting
        raise VirtusError("stop here")

    monkeypatch.setattr(job, "check_validation", check)
    monkeypatch.setattr(job, "run_twin", run)
    argv = ["twin", "cal.json", "--out", str(tmp_path / "t"), option, "a", option, "b"]
    code, _out, err = _run(argv, capsys)
    assert (code, err) == (2, "virtus: error: stop here\n")
    assert seen == [Path("a"), Path("b")]


#: A repeated option of one value that holds commas: (argv, option).
REPEATED = [
    (["capture", "--projector-lens", "0.01,1", "--projector-lens", "0.02,1"], "--projector-lens"),
    (["scan", "--camera-lens", "0.01,1", "--camera-lens", "0.02,1"], "--camera-lens"),
    (["demo", "--camera-lens", "0.01,1", "--camera-lens", "0.02,1"], "--camera-lens"),
    (["import", "{w}", "--sequence", "s.json", "--camera-size", "64,48",
      "--camera-size", "32,24"], "--camera-size"),
    (["twin", "cal.json", "--camera-size", "64,48", "--camera-size", "32,24"], "--camera-size"),
    (["twin", "cal.json", "--projector-size", "9,9", "--projector-size", "8,8"],
     "--projector-size"),
    (["twin", "cal.json", "--board", "4x7", "--board", "5x9"], "--board"),
    (["calibrate", "--board", "4x7", "--board", "5x9"], "--board"),
    (["calibrate", "--from-points", "p.csv", "--sizes", "9x9,9x9", "--sizes", "8x8,8x8"],
     "--sizes"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "option"), REPEATED, ids=[f"{a[0]} {o}" for a, o in REPEATED])
def test_a_repeated_one_value_option_is_refused(argv, option, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    argv = [a.format(w=tmp_path) for a in argv] + ["--out", str(out)]
    code, stdout, err = _run(argv, capsys)
    assert code == 2 and stdout == ""
    assert err.count("\n") == 1, err
    assert err.startswith(f"virtus: error: {option}: expected the option once"), err
    assert not out.exists()
