"""``virtus rig info``: print a rig (default: the paper's) in the rig JSON schema."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary

#: The paper's camera sensor: 20.9995 mm aperture over 960 px.
from virtus.paper import CAMERA_PIXEL_SIZE_MM as PAPER_PIXEL_SIZE_MM


def register(app: typer.Typer) -> None:
    rig_app = typer.Typer(help="Inspect camera-projector rigs.", no_args_is_help=True)
    app.add_typer(rig_app, name="rig")

    @rig_app.command("info")
    def info(
        rig: Annotated[
            Path | None, typer.Option(help="Rig or calibration JSON; default: the paper's rig.")
        ] = None,
        pixel_size_mm: Annotated[
            float, typer.Option(help="Camera pixel size for the Isaac parameters, mm.")
        ] = PAPER_PIXEL_SIZE_MM,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Print a rig, its Isaac Sim camera and projected size.

        The rig in the DESIGN schema (camera, projector, proj2cam), the Isaac Sim camera
        parameters for the pixel size and the projected size at 1 m; --json prints the
        same as one JSON object (a rig file other tools read)."""
        from virtus.cli.options import load_rig_option
        from virtus.geometry import rig_info

        the_rig = load_rig_option(rig)
        data = rig_info(the_rig, pixel_size_mm)
        Output(json_out, quiet).emit(Summary(data, _print_table))


def _print_table(console: Any, data: dict[str, Any]) -> None:
    from rich.table import Table

    table = Table(title="virtus rig", show_header=True)
    table.add_column("device")
    table.add_column("size px")
    table.add_column("fx, fy px")
    table.add_column("cx, cy px")
    table.add_column("dist (k1 k2 p1 p2 k3)")
    for name in ("camera", "projector"):
        dev = data[name]
        K = dev["K"]  # noqa: N806
        table.add_row(
            name,
            f"{dev['width']} x {dev['height']}",
            f"{K[0][0]:.3f}, {K[1][1]:.3f}",
            f"{K[0][2]:.3f}, {K[1][2]:.3f}",
            " ".join(f"{d:.4g}" for d in dev["dist"]),
        )
    console.print(table)
    t = data["proj2cam"]["t"]
    console.print(f"proj2cam t (projector centre in camera frame): {t} m")
    console.print(f"baseline: {data['baseline_m'] * 1000:.3f} mm")
    isaac = data["isaac"]
    console.print(
        f"Isaac camera (mm): focal {isaac['focal_length']:.4f}, apertures "
        f"{isaac['horizontal_aperture']:.4f} x {isaac['vertical_aperture']:.4f}, offsets "
        f"{isaac['horizontal_aperture_offset']:.4f}, {isaac['vertical_aperture_offset']:.4f}"
    )
    size = data["projected_size_m"]
    console.print(f"projected size at 1 m: {size['width']:.4f} m x {size['height']:.4f} m")
