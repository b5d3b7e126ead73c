"""``virtus evaluate DIR``: cloud-to-mesh distance of a scan against its scene's meshes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary

#: The paper's virtual C2M mean absolute error (astronaut figurine), mm.
from virtus.paper import C2M_MAE_MM as PAPER_C2M_MAE_MM


def register(app: typer.Typer) -> None:
    @app.command("evaluate")
    def evaluate(
        directory: Annotated[Path, typer.Argument(help="Scan directory (from virtus scan).")],
        ply: Annotated[
            Path | None, typer.Option(help="Point cloud to evaluate; default: DIR/points.ply.")
        ] = None,
        icp: Annotated[
            bool, typer.Option("--icp/--no-icp", help="Register by ICP before measuring.")
        ] = True,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Measure a scan's cloud-to-mesh distance (C2M, mm).

        C2M (after point-to-plane ICP) of DIR/points.ply against each mesh of the scan's
        scene; writes DIR/evaluation.json (mm)."""
        from virtus.capture import scandir as layout
        from virtus.pipeline.evaluate import evaluate_scan

        output = Output(json_out, quiet)
        results = evaluate_scan(directory, ply, register=icp)
        meshes = [
            {"mesh": Path(result.path).name, "points": int(result.n_points),
             **result.c2m.stats.to_dict()}
            for result in results
        ]  # fmt: skip
        data = {
            "icp": icp,
            "meshes": meshes,
            "paper_mae_mm": PAPER_C2M_MAE_MM,
            "evaluation": str(directory / layout.EVALUATION_JSON),
        }
        summary = Summary(data, _print_evaluation)
        summary.lines.append(f"wrote {data['evaluation']}")
        output.emit(summary)


def _print_evaluation(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"cloud-to-mesh distance ({'after ICP' if d['icp'] else 'no ICP'}), mm")
    for column in ("mesh", "points", "MAE", "RMSE", "mean", "p95 |d|", "max |d|", "paper MAE"):
        table.add_column(column, justify="right")
    for s in d["meshes"]:
        table.add_row(
            s["mesh"],
            str(s["points"]),
            f"{s['mae_mm']:.4f}",
            f"{s['rmse_mm']:.4f}",
            f"{s['mean_mm']:+.4f}",
            f"{s['p95_abs_mm']:.4f}",
            f"{s['max_abs_mm']:.3f}",
            f"{d['paper_mae_mm']:.2f}",
        )
    console.print(table)
