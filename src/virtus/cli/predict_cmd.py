"""``virtus predict``: per-pixel predicted noise of the scanner on a scene (no noisy render)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption, ScannerOptions, scanner_options
from virtus.cli.output import JsonOption, Output, QuietOption, Summary

#: The summary's rows: (title, key, format).
_ROWS = (
    ("sigma u_p (projector px)", "sigma_u_p_px", ".4f"),
    ("sigma v_p (projector px)", "sigma_v_p_px", ".4f"),
    ("sigma depth z (um)", "sigma_depth_um", ".2f"),
    ("sigma along the ray (um)", "sigma_range_um", ".2f"),
    ("sigma of the point (um)", "sigma_point_um", ".2f"),
)


@scanner_options()
def predict(
    *,
    scene: Annotated[
        str, typer.Option(help="Scene: a built-in name (sphere, freeform) or a scene file.")
    ] = "sphere",
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("predict"),
    use: Annotated[
        str, typer.Option(help="Decoded coordinates that triangulate: uv, u or v.")
    ] = "uv",
    options: ScannerOptions,
    overwrite: OverwriteOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Predict each pixel's noise on a scene, without noisy renders.

    One noise-free ground-truth pass, then the EMVA sensor model, the phase-shifting noise
    and the triangulation Jacobian: OUT/sigma_u_p.npy, sigma_v_p.npy (projector px),
    sigma_depth.npy, sigma_range.npy, sigma_point.npy (metres), mask.npy and
    OUT/summary.json (median and 95th percentile)."""
    from virtus.design import predict_scene

    output = Output(json_out, quiet)
    summary = predict_scene(out, scene, options.build(), use=use, overwrite=overwrite)
    result = Summary({"directory": str(out), **summary}, _print_summary)
    result.lines.append(f"wrote {out}")
    output.emit(result)


def _print_summary(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"predicted noise, {d['pixels']} pixels ({d['sensor']}, {d['scene']})")
    for column in ("", "median", "95th percentile"):
        table.add_column(column, justify="right")
    for title, key, spec in _ROWS:
        cells = (d.get(f"{key}_median"), d.get(f"{key}_p95"))
        table.add_row(title, *("-" if c is None else format(c, spec) for c in cells))
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("predict")(predict)
