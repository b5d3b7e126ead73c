"""``virtus ablation``: materials x ambient light x realism settings over the sphere, measured."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    OverwriteOption,
    ScannerOptions,
    SeedOption,
    names_option,
    scanner_options,
)
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report


@scanner_options("rig", "spp")
def ablation(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("ablation"),
    materials: Annotated[
        list[str] | None,
        typer.Option(
            help="Sphere materials (matte, glossy, metal, reflective), comma-separated or "
            "repeated (--materials matte --materials metal); default: all."
        ),
    ] = None,
    ambient: Annotated[
        list[str] | None,
        typer.Option(
            help="Ambient levels (dark, ambient), comma-separated or repeated; default: all."
        ),
    ] = None,
    realism: Annotated[
        list[str] | None,
        typer.Option(
            help="Realism settings (ideal, sensor, gamma, projector, interreflection, all), "
            "comma-separated or repeated; default: all."
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
    json_out: JsonOption = False,
    quiet: QuietOption = False,
    no_report: NoReportOption = False,
) -> None:
    """Measure the sphere over materials, ambient light and realism.

    Render the 100 mm sphere for every cell, decode it, and report the phase error
    against the ground truth and the sphere-fit error: OUT/cells/*.json (one per finished
    cell), OUT/ablation.csv, ablation.json, ablation.png. OUT is owned by the run
    (OUT/run.json): another run's directory is refused unless --overwrite."""
    from virtus.pipeline.ablation import run_ablation
    from virtus.sensor import as_seed

    seed = as_seed(seed)
    scanner = options.build()
    output = Output(json_out, quiet)
    rows = run_ablation(
        out,
        scanner,
        materials=names_option(materials),
        ambients=names_option(ambient),
        realism=names_option(realism),
        seed=seed,
        progress=lambda i, n, c: output.log(
            f"[{i + 1}/{n}] {c.material}, {c.ambient}, {c.realism}"
        ),
        overwrite=overwrite,
        resume=resume,
    )
    summary = Summary({"directory": str(out), "cells": rows}, _print_ablation)
    add_report(output, summary, out, no_report)
    output.emit(summary)


#: The table's columns: (title, key in a cell's row, format).
_COLUMNS = (
    ("material", "material", "s"), ("ambient", "ambient", "s"), ("realism", "realism", "s"),
    ("valid", "valid_fraction", ".1%"), ("phase RMS (rad)", "phase_error_rms_rad", ".4f"),
    ("order errors", "order_error_fraction", ".2%"),
    ("radius error (mm)", "radius_error_mm", "+.4f"), ("fit RMS (mm)", "fit_rms_mm", ".4f"),
)  # fmt: skip


def _print_ablation(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus ablation -> {d['directory']}")
    for title, _key, _spec in _COLUMNS:
        table.add_column(title)
    for row in d["cells"]:
        table.add_row(*("-" if row.get(key) is None else format(row[key], spec)
                        for _title, key, spec in _COLUMNS))  # fmt: skip
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("ablation")(ablation)
