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
from virtus.cli.output import JsonOption, Output, QuietOption, Summary


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
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Import a real bench's images as a capture.

    Import IMAGES as a capture in OUT (the layout of virtus capture, without ground
    truth); then `virtus decode OUT`, `virtus reconstruct OUT` work on it. OUT is owned
    by the run (OUT/run.json, with the inputs' checksums): another run's directory is
    refused unless --overwrite."""
    from virtus.pipeline.capture import import_images

    output = Output(json_out, quiet)
    size = parse_size(camera_size)
    result = import_images(
        images, sequence, calibration, out, units=units and units.value, bit_depth=bit_depth,
        camera_size=size, pixel_size_um=pixel_size_um, overwrite=overwrite, resume=resume,
    )  # fmt: skip
    capture = result.capture
    frames = capture.frames
    calibrated = result.sources.calibrated
    data = {
        "directory": str(out),
        "frames": int(frames.shape[0]),
        "width": int(frames.shape[2]),
        "height": int(frames.shape[1]),
        "bit_depth": int(capture.bit_depth),
        "full_scale": int(capture.full_scale),
        "sequence": str(sequence),
        "sequence_frames": len(result.sequence),
        "calibration": str(calibration) if calibrated else None,
        "calibration_format": result.sources.format if calibrated else None,
        "baseline_mm": result.rig.baseline_m * 1e3 if calibrated else None,
        # where each rig parameter came from, as the lines print it
        "sources": [[label, text] for label, text in result.sources.lines()],
        "pixel_size_um": pixel_size_um,
    }
    summary = Summary(data, _print_import)
    summary.lines += [f"{label}: {text}" for label, text in data["sources"]]
    if pixel_size_um is not None:
        summary.lines.append(
            f"camera pixel size: {pixel_size_um:g} um (recorded for a digital twin)"
        )
    summary.lines.append(f"next: virtus decode {out}")
    output.emit(summary)


def _print_import(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus import -> {d['directory']}", show_header=False)
    table.add_row(
        "frames",
        f"{d['frames']} x {d['width']} x {d['height']} px, "
        f"{d['bit_depth']}-bit (full scale {d['full_scale']})",
    )
    table.add_row("sequence", f"{d['sequence']} ({d['sequence_frames']} frames)")
    if d["calibration"] is not None:
        baseline = f"baseline {d['baseline_mm']:.2f} mm"
        table.add_row("calibration", f"{d['calibration']} ({baseline}, {d['calibration_format']})")
    else:
        table.add_row("calibration", "none: a placeholder rig (decode, calibrate --captures)")
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("import")(import_)
