"""``virtus capture``: render one pose of the scanner in a scene and write a capture directory."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    BitDepthOption,
    BouncesOption,
    CameraLensOption,
    LookupOption,
    OverwriteOption,
    ProjectorLensOption,
    ProjectorOption,
    RigOption,
    SeedOption,
    SensorOption,
    SequenceOption,
    SppOption,
    VariantOption,
    build_scanner,
)


def register(app: typer.Typer) -> None:
    @app.command("capture")
    def capture(
        scene: Annotated[
            Path | None,
            typer.Option(help="Scene YAML; default: 100 mm sphere at 1 m + background plane."),
        ] = None,
        out: Annotated[Path, typer.Option(help="Capture directory to write.")] = Path("capture"),
        spp: SppOption = 4,
        bit_depth: BitDepthOption = None,
        lookup: LookupOption = None,
        projector: ProjectorOption = "ideal",
        rig: RigOption = None,
        sequence: SequenceOption = None,
        sensor: SensorOption = "ideal",
        seed: SeedOption = 0,
        variant: VariantOption = None,
        bounces: BouncesOption = 1,
        projector_lens: ProjectorLensOption = None,
        camera_lens: CameraLensOption = None,
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
        from virtus.pipeline.inputs import load_scene
        from virtus.pipeline.scan import capture_job
        from virtus.scene.model import default_scene
        from virtus.sensor.camera import as_seed

        # Every check before anything is claimed, rendered or written.
        seed = as_seed(seed)
        scanner = build_scanner(
            rig=rig, sequence=sequence, lookup=lookup, projector=projector, spp=spp,
            bit_depth=bit_depth,
            sensor=sensor, variant=variant, bounces=bounces,
            projector_lens=projector_lens, camera_lens=camera_lens,
        )  # fmt: skip
        the_scene = load_scene(scene) if scene is not None else default_scene()
        scanner.check(the_scene)
        config = {
            "scanner": scanner.to_dict(),
            "scene": str(scene) if scene is not None else "default",
            "seed": seed,
        }
        timing: dict[str, float] = {}

        def render():  # noqa: ANN202
            start = time.perf_counter()
            captured = scanner.capture(the_scene, rng=seed)
            timing["render_s"] = time.perf_counter() - start
            return captured

        start = time.perf_counter()
        captured = capture_job(
            out,
            "capture",
            config,
            render,
            inputs={"scene": scene} if scene is not None else None,
            overwrite=overwrite,
            resume=resume,
        )
        total = time.perf_counter() - start
        render_s = timing.get("render_s", 0.0)
        _summary(captured, out / "capture.json", render_s, total - render_s)


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
