"""``virtus reconstruct DIR``: triangulate a decoded capture into a point cloud."""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import UnitsOption
from virtus.cli.output import JsonOption, Output, QuietOption, Summary


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
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Triangulate a decoded capture into a point cloud.

        Triangulate DIR (decoding it first if needed or stale) into DIR/points.ply (binary
        PLY, metres, camera frame, with normals) and DIR/reconstruction/{points,depth,mask}.npy
        with source.json tying them to the frames and the rig. A rig without baseline, no
        decoded pixel or no point is an error (exit 2). Holds DIR's lock while writing."""
        import numpy as np

        from virtus.capture import scandir as layout
        from virtus.pipeline.scan import reconstruct_capture, rig_source

        output = Output(json_out, quiet)
        start = time.perf_counter()
        recon = reconstruct_capture(
            directory, calibration, out, use=use.value, units=units and units.value
        )
        elapsed = time.perf_counter() - start
        depth = recon.depth[recon.mask]
        data = {
            "ply": str(out if out is not None else directory / layout.POINTS_PLY),
            "rig": rig_source(directory, calibration),
            "points": int(recon.mask.sum()),
            "points_fraction": float(recon.mask.mean()),
            "depth_edge_pixels_dropped": int(recon.edges.sum()),
            "depth_min_m": float(np.min(depth)) if depth.size else None,
            "depth_max_m": float(np.max(depth)) if depth.size else None,
            "time_s": elapsed,
        }
        output.emit(Summary(data, _print_reconstruction))


def _print_reconstruction(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus reconstruct -> {d['ply']}", show_header=False)
    table.add_row("rig", d["rig"])
    table.add_row("points", f"{d['points']} ({d['points_fraction']:.1%} of pixels)")
    table.add_row("depth-edge pixels dropped", str(d["depth_edge_pixels_dropped"]))
    if d["depth_min_m"] is not None:
        table.add_row("depth range", f"{d['depth_min_m']:.4f} .. {d['depth_max_m']:.4f} m")
    table.add_row("time", f"{d['time_s']:.2f} s")
    console.print(table)
