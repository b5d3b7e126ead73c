"""``virtus calibrate``: capture a circle board in many poses, calibrate, compare with the truth
(the job is :func:`virtus.pipeline.calibrate.calibrate_rig`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import (
    BitDepthOption,
    LookupOption,
    ProjectorOption,
    RigOption,
    SeedOption,
    SensorOption,
    SequenceOption,
    SppOption,
    VariantOption,
    build_scanner,
)

DEFAULT_OUT = Path("virtus-calibration")


def register(app: typer.Typer) -> None:
    @app.command("calibrate")
    def calibrate(
        out: Annotated[Path, typer.Option(help="Output directory.")] = DEFAULT_OUT,
        rig: RigOption = None,
        sequence: SequenceOption = None,
        board: Annotated[str, typer.Option(help="Circle board ROWSxCOLS (4x7, 5x9, 7x13).")] = (
            "7x13"
        ),
        poses: Annotated[
            str, typer.Option(help="'paper' (18 poses) or 'random:N' (3 <= N <= 200).")
        ] = "paper",
        spp: SppOption = 4,
        lookup: LookupOption = None,
        projector: ProjectorOption = "ideal",
        bit_depth: BitDepthOption = None,
        sensor: SensorOption = "ideal",
        seed: SeedOption = 0,
        variant: VariantOption = None,
        overwrite: Annotated[
            bool, typer.Option("--overwrite", help="Remove an earlier run's files in OUT first.")
        ] = False,
        resume: Annotated[
            bool,
            typer.Option(
                "--resume",
                help="Continue an interrupted run in OUT (same settings) from its finished poses.",
            ),
        ] = False,
    ) -> None:
        """Render the board in every pose (the whole pattern sequence each), calibrate camera,
        projector and their pose, and write OUT/calibration.json (+ OpenCV YAML and the
        paper's txt files). Identical runs write identical files; OUT/run.json records the
        run, OUT/timing.json its timings."""
        import warnings

        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        from virtus.pipeline.calibrate import CALIBRATION_FILE, calibrate_rig, check_pose_spec
        from virtus.sensor import as_seed

        # Cheap checks first: nothing is read, rendered or written before they pass.
        poses = check_pose_spec(poses)
        seed = as_seed(seed)
        scanner = build_scanner(
            rig=rig, sequence=sequence, lookup=lookup, projector=projector, spp=spp,
            bit_depth=bit_depth,
            sensor=sensor, variant=variant,
        )  # fmt: skip
        console = Console()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with Progress(
                TextColumn("[bold]capture"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}"),
                TextColumn("{task.description}"),
                TimeElapsedColumn(),
                console=console,
            ) as bar:
                task = bar.add_task("", total=None)

                def progress(done: int, total: int, name: str) -> None:
                    bar.update(task, completed=done, total=total, description=name)

                result = calibrate_rig(
                    scanner,
                    board=board,
                    poses=poses,
                    rng=seed,
                    progress=progress,
                    out_dir=out,
                    resume=resume,
                    overwrite=overwrite,
                )
        for warning in caught:
            console.print(f"[yellow]warning:[/yellow] {warning.message}")
        _print_summary(console, result.to_dict())
        console.print(f"wrote {out / CALIBRATION_FILE}")


def _print_summary(console: Any, data: dict[str, Any]) -> None:
    from rich.table import Table

    rms = data["rms_px"]
    paper = data["paper_rms_px"]
    table = Table(title="reprojection error (RMS, px)")
    table.add_column("")
    table.add_column("virtus", justify="right")
    table.add_column("paper", justify="right")
    for key in ("camera", "projector", "stereo"):
        ref = paper.get(key)
        table.add_row(key, f"{rms[key]:.4f}", "-" if ref is None else f"{ref:.3f}")
    console.print(table)
    truth = data.get("truth_error")
    if truth is None:
        return
    table = Table(title="calibrated - true")
    for column in ("device", "fx %", "fy %", "cx px", "cy px", "k1, k2, p1, p2"):
        table.add_column(column, justify="right")
    for device in ("camera", "projector"):
        e = truth[device]
        dist = ", ".join(f"{d:+.1e}" for d in e["dist_error"][:4])
        table.add_row(
            device,
            f"{100 * e['fx_rel_error']:+.4f}",
            f"{100 * e['fy_rel_error']:+.4f}",
            f"{e['cx_error_px']:+.3f}",
            f"{e['cy_error_px']:+.3f}",
            dist,
        )
    console.print(table)
    ext = truth["proj2cam"]
    console.print(
        f"proj2cam: baseline {1000 * ext['baseline_error_m']:+.4f} mm, "
        f"translation {1000 * ext['translation_error_m']:.4f} mm, "
        f"rotation {ext['rotation_error_deg']:.5f} deg"
    )
    if data["dropped_poses"]:
        console.print(f"dropped poses: {', '.join(data['dropped_poses'])}")
