"""``virtus import IMAGES``: a folder of camera images from a real bench becomes a capture."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption, UnitsOption


def import_(
    images: Annotated[
        Path,
        typer.Argument(
            help="Folder of 8/10/12/16-bit PNG, TIFF or BMP frames (natural order: img2 "
            "before img10), or a sequence file's own image list when it has one."
        ),
    ],
    sequence: Annotated[
        Path, typer.Option(help="Pattern sequence file (YAML/JSON) describing the frames.")
    ],
    calibration: Annotated[
        Path,
        typer.Option(
            help="Calibration: rig JSON, OpenCV YAML/XML, or a folder of the paper code's "
            "text files."
        ),
    ],
    out: Annotated[Path, typer.Option(help="Capture directory to write.")],
    units: UnitsOption = None,
    bit_depth: Annotated[
        int | None,
        typer.Option(
            help="Camera ADC bits (8, 10, 12, 16); default: the smallest that holds the data."
        ),
    ] = None,
    overwrite: OverwriteOption = False,
    resume: Annotated[
        bool,
        typer.Option("--resume", help="Finish an interrupted import into OUT (same inputs)."),
    ] = False,
) -> None:
    """Import IMAGES as a capture in OUT (the layout of virtus capture, without ground
    truth); then `virtus decode OUT`, `virtus reconstruct OUT` work on it. OUT is owned
    by the run (OUT/run.json, with the inputs' checksums): another run's directory is
    refused unless --overwrite."""
    from rich.console import Console
    from rich.table import Table

    from virtus.pipeline.capture import import_images

    result = import_images(
        images, sequence, calibration, out, units=units and units.value, bit_depth=bit_depth,
        overwrite=overwrite, resume=resume,
    )  # fmt: skip
    table = Table(title=f"virtus import -> {out}", show_header=False)
    capture = result.capture
    frames = capture.frames
    table.add_row(
        "frames",
        f"{frames.shape[0]} x {frames.shape[2]} x {frames.shape[1]} px, "
        f"{capture.bit_depth}-bit (full scale {capture.full_scale})",
    )
    table.add_row("sequence", f"{sequence} ({len(result.sequence)} frames)")
    table.add_row("calibration", f"{calibration} (baseline {result.rig.baseline_m * 1e3:.2f} mm)")
    Console().print(table)
    Console().print(f"next: virtus decode {out}")


def register(app: typer.Typer) -> None:
    app.command("import")(import_)
