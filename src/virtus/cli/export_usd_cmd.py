"""``virtus export-usd``: write a scene and/or a rig as a USD stage for Isaac Sim
(:func:`virtus.twin.usd.export_usd`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary


def register(app: typer.Typer) -> None:
    @app.command("export-usd")
    def export_usd_command(
        out: Annotated[Path, typer.Option(help="The stage to write (.usda, .usdc or .usd).")],
        scene: Annotated[
            Path | None, typer.Option(help="Scene YAML (or USD) to write; default: none.")
        ] = None,
        rig: Annotated[
            Path | None,
            typer.Option(
                help="Rig or calibration file (any format `virtus twin` reads) whose camera "
                "and projector are written; default: the paper's rig."
            ),
        ] = None,
        meters_per_unit: Annotated[
            float, typer.Option(help="The stage's metersPerUnit (1 = metres, 0.01 = cm).")
        ] = 1.0,
        pattern: Annotated[
            Path | None,
            typer.Option(help="Image the projector shows (its size); default: full white."),
        ] = None,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Write a scene and a rig as a USD stage for Isaac Sim.

        Write a USD stage: the camera (USD lens values in tenths of a scene unit, OpenCV
        distortion in Omniverse's lens-distortion attributes), the projector as a RectLight
        (isProjector) and the scene's objects with UsdPreviewSurface materials, in Isaac's
        world (camera looking along +X, +Z up)."""
        from virtus.twin.usd import require_usd

        require_usd()  # one line without usd-core, before anything is read
        from virtus.calib import load_rig_file
        from virtus.geometry import default_rig
        from virtus.io import read_image
        from virtus.pipeline.inputs import load_scene
        from virtus.twin.usd import export_usd

        the_rig = load_rig_file(rig) if rig is not None else default_rig()
        the_scene = load_scene(scene) if scene is not None else None
        image = read_image(pattern) if pattern is not None else None
        path = export_usd(
            out, scene=the_scene, rig=the_rig, meters_per_unit=meters_per_unit, pattern=image
        )
        summary = Summary({"stage": str(path), "meters_per_unit": meters_per_unit})
        summary.lines.append(f"wrote {path} (metersPerUnit {meters_per_unit:g})")
        Output(json_out, quiet).emit(summary)
