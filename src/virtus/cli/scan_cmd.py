"""``virtus scan``: capture a scene with the virtual sensor, decode, reconstruct."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    OverwriteOption,
    ScannerOptions,
    SeedOption,
    UnitsOption,
    scanner_options,
)
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report
from virtus.paper import C2M_MAE_MM


@scanner_options()
def scan(
    *,
    out: Annotated[Path, typer.Option(help="Scan directory to write.")] = Path("scan"),
    scene: Annotated[
        str,
        typer.Option(
            help="Scene YAML, or a built-in scene: 'sphere' (100 mm sphere, the paper's) "
            "or 'freeform' (the procedural free-form object)."
        ),
    ] = "sphere",
    calibration: Annotated[
        Path | None,
        typer.Option(help="Calibration file to reconstruct with; default: the true rig."),
    ] = None,
    units: UnitsOption = None,
    options: ScannerOptions,
    seed: SeedOption = 0,
    turntable: Annotated[
        int,
        typer.Option(
            help="Scan N turntable views of the scene's mesh object (vertical axis through "
            "its origin), merge them in the object frame and report C2M; 0 = one view."
        ),
    ] = 0,
    refine: Annotated[
        bool, typer.Option("--refine", help="Turntable: refine each view's pose by ICP.")
    ] = False,
    overwrite: OverwriteOption = False,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume",
            help="Continue an interrupted run in OUT (same settings): finished turntable "
            "views and a complete capture are kept.",
        ),
    ] = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
    no_report: NoReportOption = False,
) -> None:
    """Scan a scene: capture, decode and reconstruct it.

    Render the scene with the true rig (52 frames), save the capture in OUT (layout of
    virtus capture), decode it and write OUT/points.ply (metres, camera frame). OUT is
    owned by the run (OUT/run.json): another run's directory is refused unless
    --overwrite."""
    from virtus.calib import load_rig_file
    from virtus.pipeline.inputs import resolve_scene
    from virtus.pipeline.scan import ScanSettings
    from virtus.pipeline.scan import scan as run_scan
    from virtus.pipeline.turntable import check_views
    from virtus.scene.builtin import BUILTIN_SCENES
    from virtus.sensor import as_seed

    # Every check before anything is claimed, rendered or written.
    settings = ScanSettings(seed=as_seed(seed))
    if turntable:
        check_views(turntable)
    scanner = options.build()
    used = (
        None
        if calibration is None
        else load_rig_file(calibration, scanner.rig, units=units and units.value)
    )
    builtin = scene in BUILTIN_SCENES and not Path(scene).is_file()
    the_scene = scene if builtin else resolve_scene(scene, out)  # a YAML file: read only
    output = Output(json_out, quiet)
    if turntable:
        summary = _turntable(the_scene, out, turntable, scanner, used, settings,
                             refine, overwrite, resume)  # fmt: skip
        add_report(output, summary, out, no_report)
        output.emit(summary)
        return
    result = run_scan(
        the_scene,
        out,
        scanner=scanner,
        calibration=used,
        settings=settings,
        overwrite=overwrite,
        resume=resume,
    )
    recon = result.reconstruction
    data = {
        "directory": str(out),
        "scene": scene,
        "reconstructed_with": str(calibration) if calibration else "the true rig",
        "decoded_fraction": float(result.decoded.mask.mean()),
        "points": int(recon.mask.sum()),
        "ply": str(result.ply_path),
        "timing_s": dict(result.timing_s),
    }
    summary = Summary(data, _print_scan)
    summary.lines.append(f"next: virtus evaluate {out}  (C2M against the scene's meshes)")
    add_report(output, summary, out, no_report)
    output.emit(summary)


def _print_scan(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus scan -> {d['directory']}", show_header=False)
    table.add_row("scene", d["scene"])
    table.add_row("reconstructed with", d["reconstructed_with"])
    table.add_row("decoded pixels", f"{d['decoded_fraction']:.1%}")
    table.add_row("points", f"{d['points']} -> {d['ply']}")
    table.add_row(
        "time",
        ", ".join(f"{k.removesuffix('_s')} {v:.2f} s" for k, v in d["timing_s"].items()),
    )
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("scan")(scan)


def _turntable(scene, out, n_views, scanner, calibration, settings, refine, overwrite,  # noqa: ANN001
               resume) -> Summary:  # fmt: skip
    from virtus.pipeline.turntable import turntable_scan_scene

    result = turntable_scan_scene(
        scene,
        out,
        n_views=n_views,
        scanner=scanner,
        calibration=calibration,
        settings=settings,
        refine=refine,
        overwrite=overwrite,
        resume=resume,
    )
    data = {
        "directory": str(out),
        "views": n_views,
        "ply": str(result.ply_path),
        "points_per_view": [int(n) for n in result.view_counts],
        "merged_points": int(result.merged.shape[0]),
        "c2m": result.c2m.stats.to_dict(),
        "paper_c2m_mae_mm": C2M_MAE_MM,
        "timing_s": dict(result.timing_s),
        "turntable": str(Path(out) / "turntable.json"),
    }
    summary = Summary(data, _print_turntable)
    summary.lines.append(f"wrote {data['turntable']}")
    return summary


def _print_turntable(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    s = d["c2m"]
    title = f"turntable scan, {d['views']} views -> {d['ply']}"
    table = Table(title=title, show_header=False)
    table.add_row("points per view", ", ".join(map(str, d["points_per_view"])))
    table.add_row("merged points", str(d["merged_points"]))
    table.add_row("C2M MAE", f"{s['mae_mm']:.4f} mm (paper, one view: {d['paper_c2m_mae_mm']} mm)")
    table.add_row("C2M RMSE", f"{s['rmse_mm']:.4f} mm")
    table.add_row("C2M p95 |d|", f"{s['p95_abs_mm']:.4f} mm")
    table.add_row(
        "time", ", ".join(f"{k.removesuffix('_s')} {v:.1f} s" for k, v in d["timing_s"].items())
    )
    console.print(table)
