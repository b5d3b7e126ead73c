"""``virtus twin``: the digital twin of a calibrated rig for Isaac Sim, and its validation
against the real captures (:mod:`virtus.pipeline.twin`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import UnitsOption


def register(app: typer.Typer) -> None:
    @app.command("twin")
    def twin(
        calibration: Annotated[
            Path,
            typer.Argument(help="Calibration file (calibration.json, OpenCV YAML, txt folder)."),
        ],
        out: Annotated[Path, typer.Option(help="Output directory.")] = Path("virtus-twin"),
        validate: Annotated[
            list[Path] | None,
            typer.Option(
                "--validate",
                help="Real calibration captures (directories or folders of them) to re-render "
                "with the twin and compare; more may follow as arguments.",
            ),
        ] = None,
        more_captures: Annotated[
            list[Path] | None, typer.Argument(help="More captures (with --validate).")
        ] = None,
        board: Annotated[
            str | None, typer.Option(help="Board spec (default: the calibration file's).")
        ] = None,
        meters_per_unit: Annotated[
            float, typer.Option(help="The stage's metersPerUnit (1 = metres, 0.01 = cm).")
        ] = 1.0,
        spp: Annotated[int, typer.Option(help="Supersamples of the twin renders.")] = 1,
        units: UnitsOption = None,
    ) -> None:
        """Write OUT/rig.json, OUT/isaac.json (Isaac Sim parameters in USD's convention:
        lens and film values in tenths of a scene unit, metersPerUnit, lens distortion,
        projector RectLight size at 1 m, poses in Isaac's world) and, with usd-core,
        OUT/twin.usda. With --validate, re-render every captured pose with the twin and
        write OUT/validation.json."""
        from rich.console import Console
        from rich.table import Table

        from virtus.errors import InputError
        from virtus.pipeline.twin import VALIDATION_FILE, validate_twin, write_twin

        if more_captures and not validate:
            raise InputError("arguments", "captures after --validate", more_captures)
        unit = None if units is None else units.value
        console = Console()
        written = write_twin(calibration, out, meters_per_unit=meters_per_unit, units=unit)
        for path in written.values():
            console.print(f"wrote {path}")
        if not validate:
            return
        result = validate_twin(
            calibration,
            [*validate, *(more_captures or [])],
            board=board,
            spp=spp,
            out=out / VALIDATION_FILE,
            units=unit,
        )
        table = Table(title="real - twin")
        columns = ("centre_diff_mean_px", "centre_diff_max_px", "proj_uv_rms_px")
        columns += ("cloud_mae_mm", "cloud_rmse_mm")
        table.add_column("pose")
        for column in columns:
            table.add_column(column, justify="right")
        for row in [*result.per_pose, {"name": "overall", **result.overall}]:
            table.add_row(row["name"], *(f"{row.get(c, float('nan')):.4f}" for c in columns))
        console.print(table)
        console.print(
            f"paper: real-to-virtual MAE {result.overall['paper_cloud_mae_mm']} mm; "
            f"wrote {out / VALIDATION_FILE}"
        )
        for name, reason in result.dropped.items():
            console.print(f"[yellow]dropped {name}:[/yellow] {reason}")
