"""``virtus design``: predicted noise over variants of the rig, fringes, sensor, projector."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption, ResumeOption, ScannerOptions, scanner_options
from virtus.cli.output import JsonOption, Output, QuietOption, Summary

_VARY_HELP = (
    "KEY=V1,V2,... (repeat for more keys: their product is swept). Keys: baseline_mm, "
    "toe_in_deg, working_distance_m, period_px, steps, coding (gray, heterodyne), sensor, "
    "exposure (fraction of full scale), bit_depth, projector, blur_px."
)
#: The table's columns: (title, key, format).
_COLUMNS = (
    ("u_p median (px)", "sigma_u_p_px_median", ".4f"),
    ("depth median (um)", "sigma_depth_um_median", ".2f"),
    ("depth p95 (um)", "sigma_depth_um_p95", ".2f"),
)


@scanner_options("rig", "sequence", "lookup", "projector", "bit_depth", "sensor", "variant")
def design(
    *,
    vary: Annotated[list[str], typer.Option(help=_VARY_HELP)],
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("design"),
    target: Annotated[
        str, typer.Option(help="Target: plane (facing the camera) or sphere (100 mm).")
    ] = "plane",
    grid: Annotated[
        int, typer.Option(help="Camera samples along the longer side for the prediction.")
    ] = 64,
    use: Annotated[
        str, typer.Option(help="Decoded coordinates that triangulate: uv, u or v.")
    ] = "uv",
    workers: Annotated[int, typer.Option(help="Worker processes for the variants.")] = 1,
    ray: Annotated[
        str | None,
        typer.Option(help="Run the variants as Ray tasks: auto, local or HOST:PORT."),
    ] = None,
    acceptance: Annotated[
        bool,
        typer.Option(
            "--acceptance",
            help="Also render each variant's VDI/VDE 2634-2 acceptance test (slow): its "
            "largest P_F, P_S, SD and F join the table.",
        ),
    ] = False,
    acceptance_calibration: Annotated[
        str,
        typer.Option(help="Rig of the acceptance tests: virtual (calibrate), true, or a file."),
    ] = "virtual",
    acceptance_positions: Annotated[
        int | None,
        typer.Option(help="Measure only the first N positions of each acceptance feature."),
    ] = None,
    options: ScannerOptions,
    overwrite: OverwriteOption = False,
    resume: ResumeOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Sweep scanner designs by their predicted noise.

    Each variant of the varied keys is the scanner with the keys applied, looking at the
    target at the working distance; its noise is predicted from one noise-free pass (no
    noisy render): OUT/variants/NNNN.json (one per finished variant), OUT/design.csv,
    design.json and OUT/figures/FIGURE__KEY.png; with --acceptance also each variant's
    rendered acceptance test (OUT/acceptance/NNNN/). An impossible rig (devices not
    overlapping) is refused before anything is written."""
    from virtus.design import run_design

    output = Output(json_out, quiet)
    rows = run_design(
        out, options.build(), vary=vary, target=target, grid=grid, use=use, workers=workers,
        ray_address=ray, acceptance=acceptance,
        acceptance_options={"calibration": acceptance_calibration,
                            "positions": acceptance_positions},
        overwrite=overwrite, resume=resume,
        progress=lambda i, n, row: output.log(f"[{i}/{n}] variant {row['variant']}"),
    )  # fmt: skip
    keys = [k for k in rows[0] if k not in _NOT_KEYS] if rows else []
    result = Summary({"directory": str(out), "keys": keys, "variants": rows}, _print_table)
    result.lines.append(f"wrote {out}/design.csv, design.json, figures/")
    output.emit(result)


_NOT_KEYS = {
    "variant", "exposure_dn_per_radiance", "predicted_fraction", "sigma_point_um_median",
    "sigma_depth_um_median", "sigma_depth_um_p95", "sigma_u_p_px_median", "sigma_u_p_px_p95",
    "P_F_mm", "P_S_mm", "SD_mm", "F_mm",
}  # fmt: skip


def _print_table(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus design -> {d['directory']} (predicted)")
    for key in d["keys"]:
        table.add_column(key, justify="right")
    columns = list(_COLUMNS)
    if d["variants"] and "P_F_mm" in d["variants"][0]:
        columns += [(f"{n} (mm)", f"{n}_mm", ".4f") for n in ("P_F", "P_S", "SD", "F")]
    for title, _key, _spec in columns:
        table.add_column(title, justify="right")
    for row in d["variants"]:
        cells = [str(row[k]) for k in d["keys"]]
        cells += ["-" if row.get(k) is None else format(row[k], s) for _t, k, s in columns]
        table.add_row(*cells)
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("design")(design)
