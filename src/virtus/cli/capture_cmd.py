"""``virtus capture``: render one pose of the rig in a scene and write a capture directory."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import LOOKUP_HELP, Lookup


def register(app: typer.Typer) -> None:
    @app.command("capture")
    def capture(
        scene: Annotated[
            Path | None,
            typer.Option(help="Scene YAML; default: 100 mm sphere at 1 m + background plane."),
        ] = None,
        out: Annotated[Path, typer.Option(help="Capture directory to write.")] = Path("capture"),
        spp: Annotated[
            int, typer.Option(help="Supersamples per pixel (a square: 1, 4, 9...).")
        ] = 4,
        bit_depth: Annotated[int, typer.Option(help="Frame bit depth: 8 or 16.")] = 8,
        lookup: Annotated[Lookup, typer.Option(help=LOOKUP_HELP)] = Lookup.nearest,
        rig: Annotated[
            Path | None, typer.Option(help="Rig or calibration JSON; default: the paper's rig.")
        ] = None,
        variant: Annotated[
            str | None, typer.Option(help="Mitsuba variant (default: CUDA if it works, else LLVM).")
        ] = None,
        overwrite: Annotated[
            bool, typer.Option("--overwrite", help="Replace an existing capture in OUT.")
        ] = False,
    ) -> None:
        """Render the paper's 52-frame sequence for one pose; write OUT/frames/000.png ...,
        OUT/capture.json (rig, patterns, scene, settings) and OUT/gt/*.npy ground truth."""
        from virtus.capture import save_capture
        from virtus.devices import Rig, default_rig
        from virtus.patterns import default_sequence
        from virtus.render import render
        from virtus.scene import default_scene, load_scene

        the_rig = Rig.load_json(rig) if rig is not None else default_rig()
        the_scene = load_scene(scene) if scene is not None else default_scene()
        projector = the_rig.projector.intrinsics
        sequence = default_sequence(projector.width, projector.height)
        start = time.perf_counter()
        rendering = render(
            the_rig,
            the_scene,
            sequence,
            spp=spp,
            lookup=lookup.value,
            bit_depth=bit_depth,
            variant=variant,
        )
        rendered = time.perf_counter()
        manifest = save_capture(
            out, rendering, rig=the_rig, sequence=sequence, scene=the_scene, overwrite=overwrite
        )
        written = time.perf_counter()
        _summary(rendering, manifest, rendered - start, written - rendered)


def _summary(rendering, manifest: Path, render_s: float, write_s: float) -> None:  # noqa: ANN001
    from rich.console import Console
    from rich.table import Table

    frames = rendering.frames
    gt = rendering.gt
    table = Table(title=f"virtus capture -> {manifest.parent}", show_header=False)
    table.add_row(
        "frames",
        f"{frames.shape[0]} x {frames.shape[2]} x {frames.shape[1]} px, {rendering.bit_depth}-bit",
    )
    table.add_row(
        "render",
        f"{render_s:.2f} s ({frames.shape[0] / render_s:.1f} frames/s, "
        f"{rendering.spp} spp, {rendering.lookup}, {rendering.variant})",
    )
    table.add_row("write", f"{write_s:.2f} s (PNG + ground truth)")
    table.add_row("exposure", f"{rendering.exposure:.4g} DN per unit radiance")
    table.add_row(
        "pixels",
        f"hit {gt.mask_hit.mean():.1%}, shadowed {gt.mask_shadow.mean():.1%}, "
        f"outside projector {gt.mask_outside.mean():.1%}, valid {gt.mask.mean():.1%}",
    )
    Console().print(table)
