"""``virtus acceptance``: a virtual VDI/VDE 2634-2 acceptance test of the scanner
(:func:`virtus.design.acceptance_test`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import (
    OverwriteOption,
    ResumeOption,
    ScannerOptions,
    SeedOption,
    scanner_options,
)
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report

DEFAULT_OUT = Path("virtus-acceptance")


@scanner_options()
def acceptance(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = DEFAULT_OUT,
    limits: Annotated[
        list[str] | None,
        typer.Option(
            help="Limits in mm, 'NAME=MM,...' with NAME among P_F, P_S, SD, F "
            "(e.g. P_F=0.05,SD=0.1; comma-separated or repeated): each figure's largest "
            "magnitude passes or fails."
        ),
    ] = None,
    volume: Annotated[
        list[str] | None,
        typer.Option(
            metavar="X0,Y0,Z0,X1,Y1,Z1",
            help="Measuring volume: two opposite corners in mm, camera frame (x right, y down, "
            "z forward); default: the box both devices see within the depth of field.",
        ),
    ] = None,
    positions: Annotated[
        int | None,
        typer.Option(
            help="Measure only the first N positions of each feature (1-10; a shortened "
            "test); default: all (10 spheres, 7 ball bars, 6 planes)."
        ),
    ] = None,
    true_rig: Annotated[
        bool,
        typer.Option(
            "--true-rig",
            help="Reconstruct with the scanner's true rig instead of a virtual calibration "
            "(the figures then show the sensor and decoding alone).",
        ),
    ] = False,
    calibration: Annotated[
        Path | None,
        typer.Option(help="Reconstruct with this calibration file instead of calibrating."),
    ] = None,
    board: Annotated[str, typer.Option(help="Board of the virtual calibration.")] = "7x13",
    calibration_poses: Annotated[
        str, typer.Option(help="Poses of the virtual calibration: 'paper' or 'random:N'.")
    ] = "paper",
    options: ScannerOptions,
    seed: SeedOption = 0,
    overwrite: OverwriteOption = False,
    resume: ResumeOption = False,
    no_report: NoReportOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Run a virtual VDI/VDE 2634-2 acceptance test.

    Calibrate the scanner virtually, then measure a sphere (P_F, P_S), a ball bar (SD) and a
    plane (F) at positions spanning the measuring volume, as the guideline asks; write
    OUT/acceptance.json and OUT/acceptance.csv (mm). Identical runs write identical files."""
    from virtus.cli.options import once
    from virtus.design import acceptance_test, parse_limits, volume_from_text
    from virtus.errors import InputError

    # Cheap checks first: nothing is rendered or written before they pass.
    limits_text = ",".join(limits) if limits else None
    parse_limits(limits_text)
    if true_rig and calibration is not None:
        raise InputError("--true-rig", "either --true-rig or --calibration", "both")
    volume_text = once(volume, "--volume")
    the_volume = None if volume_text is None else volume_from_text(volume_text)
    scanner = options.build()
    output = Output(json_out, quiet)

    def progress(done: int, total: int, name: str) -> None:
        if done == 0:
            output.log(f"acceptance: {name} before {total} positions")
        else:
            output.log(f"acceptance: {done}/{total} positions measured ({name})")

    result = acceptance_test(
        scanner,
        out,
        volume=the_volume,
        limits=limits_text,
        positions=positions,
        calibration="true" if true_rig else (calibration or "virtual"),
        board=board,
        calibration_poses=calibration_poses,
        rng=seed,
        overwrite=overwrite,
        resume=resume,
        progress=progress,
    )
    data = {key: result.summary[key] for key in ("complete", "maxima", "limits", "passed")}
    data["rig"] = result.summary["rig"]["kind"]
    summary = Summary(data, _print_summary)
    summary.add("acceptance", out / "acceptance.json", f"wrote {out / 'acceptance.json'}")
    add_report(output, summary, out, no_report)
    output.emit(summary)


def register(app: typer.Typer) -> None:
    app.command("acceptance")(acceptance)


def _print_summary(console: Any, data: dict[str, Any]) -> None:
    from rich.table import Table

    table = Table(title=f"VDI/VDE 2634-2 (virtual), rig: {data['rig']}, mm")
    for column in ("figure", "positions", "max |value|", "limit", "result"):
        table.add_column(column, justify="right")
    for figure, row in data["maxima"].items():
        verdict = data["limits"].get(figure)
        table.add_row(
            figure,
            str(row["n"]),
            f"{row['value_mm']:+.4f}",
            "-" if verdict is None else f"{verdict['limit_mm']:g}",
            "-" if verdict is None else ("pass" if verdict["passed"] else "FAIL"),
        )
    console.print(table)
    if not data["complete"]:
        console.print("shortened test (--positions): not a complete VDI/VDE 2634-2 test")
