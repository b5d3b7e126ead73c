"""``virtus twin`` of a calibration that states no image size (the paper code's text
folders): refused in one line without ``--camera-size``/``--projector-size``, written with
them; ``--pixel-size-um``
sets the USD lens and film values (focalLength = 10 fx p in a metre stage, DESIGN.md §10)."""

from __future__ import annotations

import json

import pytest

from virtus.calib.io import save_paper_txt
from virtus.cli import main
from virtus.geometry.devices import default_rig

#: The image sizes the paper code's text files do not state.
SIZES = ["--camera-size", "960,960", "--projector-size", "912,1140"]


def _twin(argv: list[str], capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as exit_info:
        main([str(a) for a in argv])
    return exit_info.value.code, capsys.readouterr().err


@pytest.fixture
def folder(tmp_path):
    return save_paper_txt(default_rig(), tmp_path / "lab")


def test_a_folder_without_a_camera_size_needs_camera_size(folder, tmp_path, capsys) -> None:
    out = tmp_path / "twin"
    code, err = _twin(["twin", folder, "--out", out], capsys)
    assert code == 2 and err.count("\n") == 1 and "size" in err, err
    assert not out.exists() or not any(out.iterdir())  # nothing written
    code, err = _twin(["twin", folder, "--out", out, *SIZES], capsys)
    assert code in (0, None), err
    rig = json.loads((out / "rig.json").read_text())
    assert (rig["camera"]["width"], rig["camera"]["height"]) == (960, 960)
    assert (rig["projector"]["width"], rig["projector"]["height"]) == (912, 1140)


def test_the_pixel_size_sets_the_usd_focal_length(folder, tmp_path, capsys) -> None:
    out = tmp_path / "twin"
    argv = ["twin", folder, "--out", out, *SIZES, "--pixel-size-um", "3.45"]
    code, err = _twin(argv, capsys)
    assert code in (0, None), err
    usd = json.loads((out / "isaac.json").read_text())["camera"]["usd"]
    fx = default_rig().camera.intrinsics.fx
    assert usd["focalLength"] == pytest.approx(10 * fx * 3.45e-6, rel=1e-12)


@pytest.mark.parametrize("value", ["0", "-3", "nan"])
def test_a_bad_pixel_size_is_one_line_and_writes_nothing(folder, tmp_path, capsys, value):
    out = tmp_path / "twin"
    argv = ["twin", folder, "--out", out, *SIZES, "--pixel-size-um", value]
    code, err = _twin(argv, capsys)
    assert code == 2 and err.count("\n") == 1 and "--pixel-size-um" in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("option", "value"),
    [("--camera-size", "0,960"), ("--camera-size", "960"), ("--projector-size", "abc,1140")],
)
def test_a_bad_size_is_one_line_and_writes_nothing(folder, tmp_path, capsys, option, value):
    out = tmp_path / "twin"
    argv = ["twin", folder, "--out", out, *SIZES, option, value]
    code, err = _twin(argv, capsys)
    assert code == 2 and err.count("\n") == 1 and option in err, err
    assert not out.exists()
