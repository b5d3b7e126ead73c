"""``virtus reconstruct DIR``: triangulate a decoded capture into a point cloud."""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import UnitsOption


class UseCoordinates(StrEnum):
    uv = "uv"
    u = "u"
    v = "v"


def register(app: typer.Typer) -> None:
    @app.command("reconstruct")
    def reconstruct(
        directory: Annotated[Path, typer.Argument(help="Capture directory (decoded or not).")],
        calibration: Annotated[
            Path | None,
            typer.Option(
                help="Calibration file (rig-schema JSON, e.g. calibration.json; OpenCV YAML/XML; "
                "or a folder of the paper code's text files); default: the rig in "
                "DIR/capture.json."
            ),
        ] = None,
        units: UnitsOption = None,
        out: Annotated[
            Path | None,
            typer.Option(
                help="Output PLY; default: DIR/points.ply (with DIR/reconstruction/); another "
                "path gets only the PLY."
            ),
        ] = None,
        use: Annotated[
            UseCoordinates,
            typer.Option(help="Projector coordinates to triangulate with: uv (both), u or v."),
        ] = UseCoordinates.uv,
    ) -> None:
        """Triangulate DIR (decoding it first if needed or stale) into DIR/points.ply (binary
        PLY, metres, camera frame, with normals) and DIR/reconstruction/{points,depth,mask}.npy
        with source.json tying them to the frames and the rig. A rig without baseline, no
        decoded pixel or no point is an error (exit 2). Holds DIR's lock while writing."""
        import numpy as np
        from rich.console import Console
        from rich.table import Table

        from virtus.capture import scandir as layout
        from virtus.pipeline.scan import reconstruct_capture

        start = time.perf_counter()
        recon = reconstruct_capture(
            directory, calibration, out, use=use.value, units=units and units.value
        )
        elapsed = time.perf_counter() - start
        depth = recon.depth[recon.mask]
        ply = out if out is not None else directory / layout.POINTS_PLY
        table = Table(title=f"virtus reconstruct -> {ply}", show_header=False)
        table.add_row("rig", str(calibration) if calibration else "capture.json (true rig)")
        table.add_row("points", f"{int(recon.mask.sum())} ({recon.mask.mean():.1%} of pixels)")
        table.add_row("depth-edge pixels dropped", str(int(recon.edges.sum())))
        if depth.size:
            table.add_row("depth range", f"{np.min(depth):.4f} .. {np.max(depth):.4f} m")
        table.add_row("time", f"{elapsed:.2f} s")
        Console().print(table)
