"""``virtus robot-scan``: a tiny run end to end, and bad input as one line, exit 2, nothing
written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from virtus.cli import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "robots"
#: One configuration of the example robot that sees the free-form object (from a plan).
VIEW_Q = [-0.2061, -0.4796, -0.5141, -1.6275, 0.1334, 1.23, 0.9]


def _run(argv: list[str], capsys) -> tuple[int, str, str]:  # noqa: ANN001
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out, err = capsys.readouterr()
    return exit_info.value.code, out, err


def _robot_file(folder: Path, tiny: Path, link: str = "panda_hand", robot: str = "panda") -> Path:
    path = folder / "robot.yaml"
    text = (EXAMPLES / "panda_wrist.yaml").read_text()
    text = text.replace("rig: null", f"rig: {tiny / 'rig.json'}")
    text = text.replace("link: panda_hand", f"link: {link}").replace(
        "robot: panda", f"robot: {robot}"
    )
    path.write_text(text)
    return path


def _trajectory(folder: Path, rows: list[list[float]]) -> Path:
    path = folder / "trajectory.json"
    path.write_text(json.dumps({"q": rows}))
    return path


def test_robot_scan_of_one_view(tiny, tmp_path, capsys) -> None:
    out = tmp_path / "scan"
    argv = [
        "robot-scan",
        "--robot",
        str(_robot_file(tmp_path, tiny)),
        "--trajectory",
        str(_trajectory(tmp_path, [VIEW_Q])),
        "--spp",
        "1",
        "--out",
        str(out),
        "--json",
    ]
    code, stdout, err = _run(argv, capsys)
    assert code == 0, err
    data = json.loads(stdout)
    assert data["views"] == 1 and data["merged_points"] > 50
    # a 64 x 64 px camera (~7 mm pixels on the object): the cloud lies on the mesh within a
    # millimetre or two; a wrong frame or mount would put it centimetres away
    assert data["c2m_kinematics"][0]["mae_mm"] < 2.0
    assert (out / "views" / "000" / "capture.json").is_file()
    record = json.loads((out / "views" / "000" / "capture.json").read_text())
    assert record["provenance"]["robot"]["q"] == VIEW_Q


def _urdf_missing_mesh(folder: Path) -> Path:
    path = folder / "arm.urdf"
    path.write_text("""<robot name="arm"><link name="base"><visual><geometry>
<mesh filename="package://arm/meshes/base.stl"/></geometry></visual></link><link name="tool"/>
<joint name="j" type="revolute"><parent link="base"/><child link="tool"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>""")
    (folder / "arm").mkdir()
    return path


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("unknown link", "mount.link: expected a link of panda"),
        ("missing mesh", "link base mesh package://arm/meshes/base.stl: expected an existing"),
        ("outside limits", "trajectory q joint panda_joint4: expected a value within"),
        ("joint count", r"trajectory q\[0\]: expected 7 joint values, got 6"),
        ("both", "--trajectory/--plan: expected exactly one of them"),
        ("plan zero", "--plan: expected 1 to 10000 views, got 0"),
    ],
)
def test_bad_input_is_one_line_exit_2_nothing_written(
    case, message, tiny, tmp_path, capsys
) -> None:
    import re

    rows = [VIEW_Q]
    robot = _robot_file(tmp_path, tiny)
    extra: list[str] = []
    if case == "unknown link":
        robot = _robot_file(tmp_path, tiny, link="tool0")
    elif case == "missing mesh":
        urdf = _urdf_missing_mesh(tmp_path)
        robot = _robot_file(tmp_path, tiny, link="tool", robot=str(urdf))
        extra = ["--package-path", f"arm={tmp_path / 'arm'}"]
    elif case == "outside limits":
        rows = [[0.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0]]
    elif case == "joint count":
        rows = [VIEW_Q[:6]]
    elif case == "both":
        extra = ["--plan", "2"]
    elif case == "plan zero":
        extra = ["--plan", "0"]
    out = tmp_path / "scan"
    argv = [
        "robot-scan",
        "--robot",
        str(robot),
        "--trajectory",
        str(_trajectory(tmp_path, rows)),
        "--spp",
        "1",
        "--out",
        str(out),
        *extra,
    ]
    if case == "plan zero":  # --plan alone
        argv = [a for a in argv if a != "--trajectory" and not a.endswith("trajectory.json")]
    code, stdout, err = _run(argv, capsys)
    assert code == 2 and stdout == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert re.search(message, err), err
    assert not out.exists()
