"""``virtus capture``: render one pose of the scanner in a scene and write a capture directory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    OverwriteOption,
    ScannerOptions,
    SeedOption,
    scanner_options,
)


@scanner_options()
def capture(
    *,
    scene: Annotated[
        Path | None,
        typer.Option(
            help="Scene YAML, or a built-in scene: 'sphere' (100 mm sphere, the paper's) or "
            "'freeform' (the procedural free-form object); default: 100 mm sphere at 1 m + "
            "background plane."
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Capture directory to write.")] = Path("capture"),
    options: ScannerOptions,
    seed: SeedOption = 0,
    overwrite: OverwriteOption = False,
    resume: Annotated[
        bool,
        typer.Option("--resume", help="Finish an interrupted run in OUT (same settings)."),
    ] = False,
) -> None:
    """Render the pattern sequence for one pose; write OUT/frames/000.png ...,
    OUT/capture.json (rig, pose, patterns, sensor, seed, scene, settings) and OUT/gt/*.npy
    ground truth. OUT is owned by the run (OUT/run.json): another run's directory is
    refused unless --overwrite."""
    from virtus.pipeline.capture import capture_scene
    from virtus.sensor import as_seed

    # Every check before anything is claimed, rendered or written.
    seed = as_seed(seed)
    result = capture_scene(
        options.build(), scene, out, seed=seed, overwrite=overwrite, resume=resume
    )
    timing = result.timing_s
    _summary(result.capture, out / "capture.json", timing["render_s"], timing["write_s"])


def register(app: typer.Typer) -> None:
    app.command("capture")(capture)


def _summary(capture, manifest: Path, render_s: float, write_s: float) -> None:  # noqa: ANN001
    from rich.console import Console
    from rich.table import Table

    frames = capture.frames
    gt = capture.ground_truth
    settings = capture.render
    table = Table(title=f"virtus capture -> {manifest.parent}", show_header=False)
    table.add_row(
        "frames",
        f"{frames.shape[0]} x {frames.shape[2]} x {frames.shape[1]} px, {capture.bit_depth}-bit",
    )
    rate = f"{frames.shape[0] / render_s:.1f} frames/s, " if render_s > 0 else "kept, "
    table.add_row(
        "render",
        f"{render_s:.2f} s ({rate}"
        f"{settings['spp']} spp, {settings['lookup']}, {settings['mitsuba_variant']})",
    )
    table.add_row("write", f"{write_s:.2f} s (PNG + ground truth)")
    table.add_row("exposure", f"{settings['exposure_dn_per_radiance']:.4g} DN per unit radiance")
    table.add_row(
        "pixels",
        f"hit {gt.mask_hit.mean():.1%}, shadowed {gt.mask_shadow.mean():.1%}, "
        f"outside projector {gt.mask_outside.mean():.1%}, valid {gt.mask.mean():.1%}",
    )
    Console().print(table)
