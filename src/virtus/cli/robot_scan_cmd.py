"""``virtus robot-scan``: scan a scene from a robot arm, merge the views by its kinematics."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import (
    OverwriteOption,
    ResumeOption,
    ScannerOptions,
    SeedOption,
    scanner_options,
)
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report

PackagePathOption = Annotated[
    list[str] | None,
    typer.Option(
        "--package-path",
        help="URDF package root, NAME=DIR: package://NAME/... resolves to DIR/... "
        "(repeat for more packages).",
    ),
]


@scanner_options(omit=("rig",))
def robot_scan(
    *,
    robot: Annotated[Path, typer.Option(help="Robot file (YAML): robot, base, mount, rig.")],
    out: Annotated[Path, typer.Option(help="Run directory to write.")] = Path("robot_scan"),
    scene: Annotated[
        str,
        typer.Option(
            help="Scene YAML (world frame, z up), or 'freeform' (the built-in "
            "free-form object, centred 0.1 m above a floor)."
        ),
    ] = "freeform",
    trajectory: Annotated[
        Path | None, typer.Option(help="Trajectory file (JSON joint values) to scan.")
    ] = None,
    plan: Annotated[
        int | None, typer.Option(help="Plan this many views for coverage instead.")
    ] = None,
    candidates: Annotated[int, typer.Option(help="Candidate views tried by --plan.")] = 48,
    joint_noise: Annotated[
        float,
        typer.Option(
            help="Std. dev. of the reported joint values' error, rad (the clouds "
            "are merged with the noisy values)."
        ),
    ] = 0.0,
    icp: Annotated[
        str,
        typer.Option(
            help="Refine the views by ICP: 'views' (each onto the merged cloud so far; "
            "no mesh needed), 'mesh' (each onto the scene's meshes; an evaluation aid) "
            "or 'none'."
        ),
    ] = "views",
    package_path: PackagePathOption = None,
    options: ScannerOptions,
    seed: SeedOption = 0,
    overwrite: OverwriteOption = False,
    resume: ResumeOption = False,
    no_report: NoReportOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Scan from a robot arm; merge the views by its kinematics.

    Each configuration (of --trajectory, or of a --plan of N views chosen for coverage)
    is captured with the robot's links in the scene, decoded and reconstructed in
    OUT/views/NNN; the clouds are mapped to the world by FK of the reported joint values,
    merged (OUT/merged.ply) and measured against the scene's meshes (C2M, coverage) in
    OUT/robot_scan.json."""
    from virtus.robot import load_robot_file, parse_package_paths
    from virtus.robot import robot_scan as run_robot_scan
    from virtus.sensor import as_seed

    packages = parse_package_paths(package_path)
    setup = load_robot_file(robot, packages)
    scanner = options.build()
    if setup.rig is not None:
        scanner = scanner.with_(rig=setup.rig)
    result = run_robot_scan(
        setup,
        scene,
        out,
        scanner=scanner,
        trajectory=trajectory,
        plan=plan,
        joint_noise_rad=joint_noise,
        icp=icp,
        seed=as_seed(seed),
        candidates=candidates,
        overwrite=overwrite,
        resume=resume,
    )
    record = result.record
    data = {
        "directory": str(out),
        "views": len(record["views"]),
        "merged_points": int(len(result.merged)),
        "joint_noise_rad": record["joint_noise_rad"],
        "c2m_kinematics": [_brief(e) for e in record["c2m_kinematics"]],
        "coverage_kinematics": record["coverage_kinematics"],
        "c2m_icp": [_brief(e) for e in record.get("c2m_icp", [])],
        "plan": record["plan"],
    }
    summary = Summary(data, _print)
    summary.add(
        "record", str(Path(out) / "robot_scan.json"), f"wrote {Path(out) / 'robot_scan.json'}"
    )
    output = Output(json_out, quiet)
    add_report(output, summary, Path(out), no_report)
    output.emit(summary)


def _brief(evaluation: dict) -> dict:
    keys = ("object", "n_points", "mae_mm", "rmse_mm", "mean_mm", "p95_abs_mm", "max_abs_mm")
    return {k: evaluation.get(k) for k in keys}


def _print(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus robot-scan -> {d['directory']}", show_header=False)
    table.add_row("views", str(d["views"]))
    table.add_row("merged points", str(d["merged_points"]))
    table.add_row("joint noise", f"{d['joint_noise_rad']:g} rad")
    for label, key in (("C2M, kinematics alone", "c2m_kinematics"), ("C2M, after ICP", "c2m_icp")):
        for e in d[key]:
            table.add_row(
                f"{label} ({e['object']})",
                f"MAE {e['mae_mm']:.4f} mm, RMSE {e['rmse_mm']:.4f} mm, {e['n_points']} points",
            )
    cov = d["coverage_kinematics"]
    table.add_row(
        "coverage",
        f"{cov['share_of_measurable']:.1%} of the measurable surface "
        f"({cov['measurable_share_of_surface']:.1%} of all), points within "
        f"{cov['radius_mm']:g} mm",
    )
    if d["plan"]:
        steps = ", ".join(f"{s:.1%}" for s in d["plan"]["coverage_after_each_view"])
        table.add_row("planned coverage", steps)
    console.print(table)


def register(app: typer.Typer) -> None:
    app.command("robot-scan")(robot_scan)
