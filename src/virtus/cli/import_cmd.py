"""``virtus import IMAGES``: a folder of camera images from a real bench becomes a capture."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption, UnitsOption


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

        from virtus.calib.io import load_calibration
        from virtus.capture.capture import import_capture
        from virtus.errors import InputError
        from virtus.io.images import list_images, read_image
        from virtus.patterns import load_sequence_file
        from virtus.pipeline.scan import capture_job
        from virtus.reconstruct import check_baseline

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
        # Every input is read and checked before OUT is claimed.
        check_baseline(rig, f"calibration {calibration}")
        imported = import_capture(files, seq, rig, bit_depth=bit_depth)
        image_files = files if isinstance(files, list) else list_images(files)
        inputs: dict[str, Path] = {"sequence": sequence}
        if calibration.is_dir():
            inputs.update({f"calibration/{f.name}": f for f in sorted(calibration.iterdir())
                           if f.is_file()})  # fmt: skip
        else:
            inputs["calibration"] = calibration
        inputs.update({f"image/{i:04d}": f for i, f in enumerate(image_files)})
        config = {
            "images": [str(f) for f in image_files],
            "sequence": str(sequence),
            "calibration": str(calibration),
            "units": units and units.value,
            "bit_depth": bit_depth,
        }
        capture = capture_job(
            out, "import", config, lambda: imported, inputs=inputs, overwrite=overwrite,
            resume=resume,
        )  # fmt: skip
        table = Table(title=f"virtus import -> {out}", show_header=False)
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
    from virtus.io.images import list_images

    return list_images(folder)[0]
