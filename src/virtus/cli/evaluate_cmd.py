"""``virtus evaluate DIR``: cloud-to-mesh distance of a scan against its scene's meshes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

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
    ) -> None:
        """C2M (after point-to-plane ICP) of DIR/points.ply against each mesh of the scan's
        scene; writes DIR/evaluation.json (mm)."""
        from rich.console import Console
        from rich.table import Table

        from virtus.capture import scandir as layout
        from virtus.pipeline.evaluate import evaluate_scan

        results = evaluate_scan(directory, ply, register=icp)
        table = Table(title=f"cloud-to-mesh distance ({'after ICP' if icp else 'no ICP'}), mm")
        for column in (
            "mesh",
            "points",
            "MAE",
            "RMSE",
            "mean",
            "p95 |d|",
            "max |d|",
            "paper MAE",
        ):
            table.add_column(column, justify="right")
        for result in results:
            s = result.c2m.stats.to_dict()
            table.add_row(
                Path(result.path).name,
                str(result.n_points),
                f"{s['mae_mm']:.4f}",
                f"{s['rmse_mm']:.4f}",
                f"{s['mean_mm']:+.4f}",
                f"{s['p95_abs_mm']:.4f}",
                f"{s['max_abs_mm']:.3f}",
                f"{PAPER_C2M_MAE_MM:.2f}",
            )
        console = Console()
        console.print(table)
        console.print(f"wrote {directory / layout.EVALUATION_JSON}")
