"""``virtus import IMAGES``: a folder of camera images from a real bench becomes a capture."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    CameraSizeOption,
    OverwriteOption,
    PixelSizeOption,
    UnitsOption,
    parse_size,
)


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
    out: Annotated[Path, typer.Option(help="Capture directory to write.")],
    calibration: Annotated[
        Path | None,
        typer.Option(
            help="Calibration: rig JSON, OpenCV YAML/XML, NumPy .npz, a mapping .yaml, or a "
            "folder of calibration text files. Omit it for captures of a board to calibrate "
            "the bench from (virtus calibrate --captures): they decode, and reconstruct asks "
            "for --calibration."
        ),
    ] = None,
    units: UnitsOption = None,
    camera_size: CameraSizeOption = None,
    pixel_size_um: PixelSizeOption = None,
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

    size = parse_size(camera_size)
    result = import_images(
        images, sequence, calibration, out, units=units and units.value, bit_depth=bit_depth,
        camera_size=size, pixel_size_um=pixel_size_um, overwrite=overwrite, resume=resume,
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
    if result.sources.calibrated:
        baseline = f"baseline {result.rig.baseline_m * 1e3:.2f} mm"
        table.add_row("calibration", f"{calibration} ({baseline}, {result.sources.format})")
    else:
        table.add_row("calibration", "none: a placeholder rig (decode, calibrate --captures)")
    Console().print(table)
    # One plain line per parameter source (never wrapped: paths stay whole).
    for label, text in result.sources.lines():
        typer.echo(f"{label}: {text}")
    if pixel_size_um is not None:
        typer.echo(f"camera pixel size: {pixel_size_um:g} um (recorded for a digital twin)")
    Console().print(f"next: virtus decode {out}")


def register(app: typer.Typer) -> None:
    app.command("import")(import_)
