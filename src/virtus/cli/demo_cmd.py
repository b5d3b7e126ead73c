"""``virtus demo``: the paper's sphere experiment with virtually calibrated parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import OverwriteOption, ScannerOptions, scanner_options


@scanner_options(omit=("bit_depth",))
def demo(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("virtus-demo"),
    options: ScannerOptions,
    overwrite: OverwriteOption = False,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume/--no-resume",
            help="Continue an earlier demo in OUT with the same settings, keeping its "
            "finished poses and capture (default; a finished demo is re-measured in "
            "seconds). --no-resume refuses a directory that holds a run.",
        ),
    ] = True,
) -> None:
    """Calibrate the paper's rig with its 18 board poses, capture the 100 mm sphere,
    reconstruct it with the calibrated parameters, fit a sphere, and compare with the
    paper. Writes OUT/metrics.json, OUT/calibration/ (calibration.json, YAML, paper
    txt), OUT/scan/ (capture + points.ply). OUT is owned by the run (OUT/run.json):
    a demo with other settings, or another command's directory, is refused unless
    --overwrite; the same demo again continues where it stopped."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    from virtus.pipeline.demo import run_demo
    from virtus.render.settings import RenderSettings
    from virtus.scanner import Scanner

    scanner = options.build()
    console = Console()
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=console,
    ) as bar:
        task = bar.add_task("calibration", total=None)

        def progress(step: str, done: int | None = None, total: int | None = None) -> None:
            if done is None:
                bar.update(task, description=step)
            else:
                # the count lives in the description so later steps do not inherit it
                bar.update(task, description=f"{step} ({done}/{total} board poses)",
                           completed=done, total=total)  # fmt: skip

        result = run_demo(
            out,
            progress=progress,
            scanner=scanner,
            overwrite=overwrite,
            resume=resume and not overwrite,
        )
        # With realism on, the same experiment with an ideal sensor and projector is run
        # beside it (OUT/ideal/, its own run) and printed side by side.
        plain = RenderSettings(spp=scanner.render.spp, variant=scanner.render.variant)
        ideal = Scanner(rig=scanner.rig, sequence=scanner.sequence, render=plain)
        reference = None
        if scanner != ideal:
            bar.update(task, description="ideal reference")
            reference = run_demo(
                out / IDEAL_DIR, progress=progress, scanner=ideal, overwrite=overwrite,
                resume=resume and not overwrite,
            ).metrics  # fmt: skip
    _print_table(console, result.metrics, reference)
    console.print(f"wrote {out / 'metrics.json'}, {out / 'calibration' / 'calibration.json'}, "
                  f"{out / 'scan' / 'points.ply'}")  # fmt: skip
    if reference is not None:
        console.print(f"ideal reference: {out / IDEAL_DIR / 'metrics.json'}")


def register(app: typer.Typer) -> None:
    app.command("demo")(demo)


#: Sub-directory of the ideal reference run when realism is on.
IDEAL_DIR = "ideal"


def _print_table(console: Any, m: dict[str, Any], ideal: dict[str, Any] | None = None) -> None:
    """The demo's table; with ``ideal`` (the metrics of the same demo with an ideal sensor
    and projector) an extra column shows what the realism costs."""
    from rich.table import Table

    cal, sph, ref, paper = m["calibration"], m["sphere"], m["sphere_true_rig"], m["paper"]
    timing, targets = m["timing"], m["targets"]

    def fmt(value: float | None, spec: str) -> str:
        return "-" if value is None else format(value, spec)

    table = Table(title="virtus demo: 100 mm sphere reconstructed with calibrated parameters")
    columns = ["", "virtus", "paper", "target", "true rig"]
    if ideal is not None:
        columns.append("ideal sensor")
    for column in columns:
        table.add_column(column, justify="left" if not column else "right")
    i_cal = ideal["calibration"] if ideal else {}
    i_sph = ideal["sphere"] if ideal else {}
    rows = [
        ("camera reprojection RMS (px)", fmt(cal["camera_rms_px"], ".4f"),
         fmt(paper["camera_rms_px"], ".3f"), "", "", fmt(i_cal.get("camera_rms_px"), ".4f")),
        ("projector reprojection RMS (px)", fmt(cal["projector_rms_px"], ".4f"),
         fmt(paper["projector_rms_px"], ".3f"), "", "", fmt(i_cal.get("projector_rms_px"), ".4f")),
        ("stereo reprojection RMS (px)", fmt(cal["stereo_rms_px"], ".4f"),
         fmt(paper["stereo_rms_px"], ".3f"), "", "", fmt(i_cal.get("stereo_rms_px"), ".4f")),
        ("sphere radius (mm)", f"{sph['radius_mm']:.4f}", f"{paper['radius_mm']:.3f}",
         f"{sph['radius_true_mm']:.1f}", f"{ref['radius_mm']:.4f}",
         fmt(i_sph.get("radius_mm"), ".4f")),
        ("radius error (mm)", f"{sph['radius_error_mm']:+.4f}",
         f"{-paper['radius_error_mm']:+.3f}", f"<= {targets['radius_error_mm']}",
         f"{ref['radius_error_mm']:+.4f}", fmt(i_sph.get("radius_error_mm"), "+.4f")),
        ("inlier ratio", f"{sph['inlier_ratio']:.2%}", f"{paper['inlier_ratio']:.1%}",
         f">= {targets['inlier_ratio']:.0%}", f"{ref['inlier_ratio']:.2%}",
         fmt(i_sph.get("inlier_ratio"), ".2%")),
        ("fit RMS (mm)", f"{sph['fit_rms_mm']:.4f}", "-", "", f"{ref['fit_rms_mm']:.4f}",
         fmt(i_sph.get("fit_rms_mm"), ".4f")),
        ("points in the fit", str(sph["n_points"]), "-", "", "", str(i_sph.get("n_points", "-"))),
        ("total time (s)", f"{timing['total_s']:.1f}", "-", f"<= {targets['total_s']:.0f}", "",
         fmt(ideal["timing"]["total_s"] if ideal else None, ".1f")),
    ]  # fmt: skip
    for row in rows:
        table.add_row(*row[: len(columns)])
    console.print(table)
    console.print(
        f"calibration {timing['calibration_s']:.1f} s, scan {timing['scan_s']:.1f} s, "
        f"fit {timing['fit_s']:.1f} s; inlier threshold {sph['threshold_mm']:.2f} mm"
    )
