"""``virtus ablation``: materials x ambient light x realism settings over the sphere, measured."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption, ScannerOptions, SeedOption, scanner_options


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [part.strip() for part in text.split(",") if part.strip()]


@scanner_options("rig", "spp")
def ablation(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("ablation"),
    materials: Annotated[
        str | None,
        typer.Option(help="Comma-separated sphere materials (matte,glossy,metal,reflective)."),
    ] = None,
    ambient: Annotated[
        str | None, typer.Option(help="Comma-separated ambient levels (dark,ambient).")
    ] = None,
    realism: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated realism settings "
            "(ideal,sensor,gamma,projector,interreflection,all)."
        ),
    ] = None,
    options: ScannerOptions,
    seed: SeedOption = 0,
    overwrite: OverwriteOption = False,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume",
            help="Continue an interrupted run in OUT (same settings): finished cells are kept.",
        ),
    ] = False,
) -> None:
    """Render the 100 mm sphere for every cell, decode it, and report the phase error
    against the ground truth and the sphere-fit error: OUT/cells/*.json (one per finished
    cell), OUT/ablation.csv, ablation.json, ablation.png. OUT is owned by the run
    (OUT/run.json): another run's directory is refused unless --overwrite."""
    from rich.console import Console
    from rich.table import Table

    from virtus.pipeline.ablation import run_ablation
    from virtus.sensor import as_seed

    seed = as_seed(seed)
    scanner = options.build()
    console = Console(stderr=True)
    rows = run_ablation(
        out,
        scanner,
        materials=_names(materials),
        ambients=_names(ambient),
        realism=_names(realism),
        seed=seed,
        progress=lambda i, n, c: console.print(
            f"[{i + 1}/{n}] {c.material}, {c.ambient}, {c.realism}", highlight=False
        ),
        overwrite=overwrite,
        resume=resume,
    )
    table = Table(title=f"virtus ablation -> {out}")
    for column in ("material", "ambient", "realism", "valid", "phase RMS (rad)",
                   "order errors", "radius error (mm)", "fit RMS (mm)"):  # fmt: skip
        table.add_column(column)
    for r in rows:
        table.add_row(
            r["material"], r["ambient"], r["realism"], f"{r['valid_fraction']:.1%}",
            f"{r['phase_error_rms_rad']:.4f}", f"{r['order_error_fraction']:.2%}",
            f"{r['radius_error_mm']:+.4f}", f"{r['fit_rms_mm']:.4f}",
        )  # fmt: skip
    Console().print(table)


def register(app: typer.Typer) -> None:
    app.command("ablation")(ablation)
