"""``virtus handeye``: where the camera sits on the robot, from board captures."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.robot_scan_cmd import PackagePathOption


def handeye(
    *,
    captures: Annotated[
        list[Path],
        typer.Option(help="Board capture directories (or folders of them), one per pose."),
    ],
    robot_poses: Annotated[
        Path,
        typer.Option(help="JSON: {'hand2base': [{R, t}, ...]} or a trajectory (with --robot)."),
    ],
    board: Annotated[str, typer.Option(help="Board spec, e.g. 4x7 or circles:4x11,...")],
    out: Annotated[Path, typer.Option(help="Run directory to write.")] = Path("handeye"),
    mode: Annotated[
        str, typer.Option(help="eye_in_hand (camera on the link) or eye_to_hand.")
    ] = "eye_in_hand",
    robot: Annotated[
        Path | None, typer.Option(help="Robot file, to read joint values as poses.")
    ] = None,
    min_rotation: Annotated[
        float, typer.Option(help="Smallest useful relative rotation between poses, deg.")
    ] = 10.0,
    package_path: PackagePathOption = None,
    overwrite: OverwriteOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Hand-eye calibration from board captures and robot poses.

    Detects the board in each capture, solves the camera's pose on the link (eye-in-hand)
    or in the base (eye-to-hand) in closed form and refines it over every board point;
    prints the expected errors. Degenerate motion is refused with its reason. Writes
    OUT/handeye.json."""
    from virtus.robot import handeye_from_captures, load_robot_file, parse_package_paths

    setup = None
    if robot is not None:
        setup = load_robot_file(robot, parse_package_paths(package_path))
    result, record = handeye_from_captures(
        captures, robot_poses, board, out, mode=mode, setup=setup,
        min_rotation_deg=min_rotation, overwrite=overwrite,
    )  # fmt: skip
    summary = Summary(record, _print)
    summary.add("record", str(Path(out) / "handeye.json"), f"wrote {Path(out) / 'handeye.json'}")
    Output(json_out, quiet).emit(summary)


def _print(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    x_name = "cam2hand" if d["mode"] == "eye_in_hand" else "cam2base"
    table = Table(title=f"virtus handeye ({d['mode']})", show_header=False)
    table.add_row(f"{x_name} t (m)", ", ".join(f"{v:+.5f}" for v in d[x_name]["t"]))
    table.add_row("expected rotation error", f"{d['expected_rotation_error_deg']:.4f} deg")
    table.add_row("expected translation error", f"{d['expected_translation_error_mm']:.4f} mm")
    table.add_row("residual RMS", f"{d['residual_rms']:.4f} {d['residual_unit']}")
    table.add_row("poses", str(d["motion"]["poses"]))
    table.add_row(
        "largest relative rotation", f"{d['motion']['max_relative_rotation_deg']:.1f} deg"
    )
    if "truth" in d:
        t = d["truth"]
        table.add_row(
            "error vs truth",
            f"{t['rotation_error_deg']:.5f} deg, {t['translation_error_mm']:.4f} mm",
        )
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("handeye")(handeye)
