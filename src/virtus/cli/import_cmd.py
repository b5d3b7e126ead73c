"""``virtus import IMAGES``: a folder of camera images from a real bench becomes a capture."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import UnitsOption


def register(app: typer.Typer) -> None:
    @app.command("import")
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
        overwrite: Annotated[
            bool, typer.Option("--overwrite", help="Replace an existing capture in OUT.")
        ] = False,
    ) -> None:
        """Import IMAGES as a capture in OUT (the layout of virtus capture, without ground
        truth); then `virtus decode OUT`, `virtus reconstruct OUT` work on it."""
        from rich.console import Console
        from rich.table import Table

        from virtus.calib.io import load_calibration
        from virtus.capture import import_capture
        from virtus.errors import InputError
        from virtus.images import read_image
        from virtus.patterns import load_sequence_file

        seq, listed = load_sequence_file(sequence)
        if listed:
            base = images if images.is_dir() else sequence.parent
            files: Path | list[Path] = [base / name for name in listed]
        else:
            files = images
        # The camera size is needed to read the paper code's text files, which lack it.
        first = read_image(files[0] if isinstance(files, list) else _first_image(files))
        camera_size = (first.shape[1], first.shape[0])
        rig = load_calibration(
            calibration,
            units=units and units.value,
            camera_size=camera_size,
            projector_size=(seq.width, seq.height),
        )
        if (rig.projector.width, rig.projector.height) != (seq.width, seq.height):
            raise InputError(
                "--sequence",
                f"patterns for the calibration's {rig.projector.width}x{rig.projector.height} "
                "px projector",
                f"{seq.width}x{seq.height} px",
            )
        capture = import_capture(files, seq, rig, bit_depth=bit_depth)
        manifest = capture.save(out, overwrite=overwrite)
        table = Table(title=f"virtus import -> {manifest.parent}", show_header=False)
        frames = capture.frames
        table.add_row(
            "frames",
            f"{frames.shape[0]} x {frames.shape[2]} x {frames.shape[1]} px, "
            f"{capture.bit_depth}-bit (full scale {capture.full_scale})",
        )
        table.add_row("sequence", f"{sequence} ({len(seq)} frames)")
        table.add_row("calibration", f"{calibration} (baseline {rig.baseline_m * 1e3:.2f} mm)")
        Console().print(table)
        Console().print(f"next: virtus decode {out}")


def _first_image(folder: Path) -> Path:
    from virtus.images import list_images

    return list_images(folder)[0]
