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
from virtus.cli.output import JsonOption, Output, QuietOption, Summary


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
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Render one pose of a scene into a capture.

    Render the pattern sequence for one pose; write OUT/frames/000.png ...,
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
    output = Output(json_out, quiet)
    output.emit(Summary(_summary(result.capture, out, result.timing_s), _print_capture))


def register(app: typer.Typer) -> None:
    app.command("capture")(capture)


def _summary(capture, out: Path, timing: dict[str, float]) -> dict:  # noqa: ANN001
    """The capture's summary (frames, render settings and speed, pixel classes)."""
    frames = capture.frames
    gt = capture.ground_truth
    settings = capture.render
    render_s = timing["render_s"]
    return {
        "directory": str(out),
        "frames": int(frames.shape[0]),
        "width": int(frames.shape[2]),
        "height": int(frames.shape[1]),
        "bit_depth": int(capture.bit_depth),
        "render_s": render_s,
        "frames_per_s": frames.shape[0] / render_s if render_s > 0 else None,
        "spp": settings["spp"],
        "lookup": settings["lookup"],
        "mitsuba_variant": settings["mitsuba_variant"],
        "write_s": timing["write_s"],
        "exposure_dn_per_radiance": settings["exposure_dn_per_radiance"],
        "pixels": {
            "hit": float(gt.mask_hit.mean()),
            "shadowed": float(gt.mask_shadow.mean()),
            "outside_projector": float(gt.mask_outside.mean()),
            "valid": float(gt.mask.mean()),
        },
    }


def _print_capture(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus capture -> {d['directory']}", show_header=False)
    table.add_row(
        "frames", f"{d['frames']} x {d['width']} x {d['height']} px, {d['bit_depth']}-bit"
    )
    rate = "kept, " if d["frames_per_s"] is None else f"{d['frames_per_s']:.1f} frames/s, "
    table.add_row(
        "render",
        f"{d['render_s']:.2f} s ({rate}{d['spp']} spp, {d['lookup']}, {d['mitsuba_variant']})",
    )
    table.add_row("write", f"{d['write_s']:.2f} s (PNG + ground truth)")
    table.add_row("exposure", f"{d['exposure_dn_per_radiance']:.4g} DN per unit radiance")
    px = d["pixels"]
    table.add_row(
        "pixels",
        f"hit {px['hit']:.1%}, shadowed {px['shadowed']:.1%}, "
        f"outside projector {px['outside_projector']:.1%}, valid {px['valid']:.1%}",
    )
    console.print(table)
