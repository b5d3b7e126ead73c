"""``virtus calibrate``: capture a board in many poses, calibrate, compare with the truth
(:func:`virtus.pipeline.calibrate.calibrate_rig`); with ``--captures DIR [DIR ...]``,
calibrate a real rig from its captures (:func:`virtus.pipeline.calibrate.calibrate_captures`)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import (
    OverwriteOption,
    ScannerOptions,
    SeedOption,
    scanner_options,
)

DEFAULT_OUT = Path("virtus-calibration")
BOARD_HELP = (
    "Board: ROWSxCOLS (the paper's circle boards 4x7, 5x9, 7x13), "
    "'circles:ROWSxCOLS,spacing_mm=S,diameter_mm=D[,border_mm=B][,white_on_black]', "
    "'checker:ROWSxCOLS,square_mm=S[,border_mm=B]' (inner corners) or a board .json/.yaml."
)


@scanner_options(omit=("bounces", "projector_lens", "camera_lens"))
def calibrate(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = DEFAULT_OUT,
    board: Annotated[str, typer.Option(help=BOARD_HELP)] = "7x13",
    captures: Annotated[
        list[Path] | None,
        typer.Option(
            "--captures",
            help="Calibrate from these captures instead of rendering: capture directories "
            "(one per board pose, `virtus import`) or folders of them; more may follow "
            "as arguments (--captures DIR [DIR ...]).",
        ),
    ] = None,
    more_captures: Annotated[
        list[Path] | None, typer.Argument(help="More capture directories (with --captures).")
    ] = None,
    poses: Annotated[
        str, typer.Option(help="'paper' (18 poses) or 'random:N' (3 <= N <= 200).")
    ] = "paper",
    options: ScannerOptions,
    seed: SeedOption = 0,
    overwrite: OverwriteOption = False,
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

    from virtus.calib import board_from_spec
    from virtus.calib.result import CALIBRATION_FILE
    from virtus.errors import InputError
    from virtus.pipeline.calibrate import (
        calibrate_captures,
        calibrate_rig,
        capture_dirs,
        check_pose_spec,
    )
    from virtus.sensor import as_seed

    # Cheap checks first: nothing is read, rendered or written before they pass.
    the_board = board_from_spec(board)
    if more_captures and not captures:
        raise InputError("arguments", "capture directories only after --captures", more_captures)
    from_captures = capture_dirs([*captures, *(more_captures or [])]) if captures else None
    if from_captures is None:
        poses = check_pose_spec(poses)
        seed = as_seed(seed)
        scanner = options.build()
    console = Console()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with _progress_bar(console) as progress:
            if from_captures is not None:
                if resume:
                    raise InputError("--resume", "a rendered run (not --captures)", True)
                result = calibrate_captures(
                    from_captures,
                    board=the_board,
                    progress=progress,
                    out_dir=out,
                    overwrite=overwrite,
                )
            else:
                result = calibrate_rig(
                    scanner,
                    board=the_board,
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


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)


@contextlib.contextmanager
def _progress_bar(console: Any) -> Iterator[Callable[[int, int, str], None]]:
    """A progress bar of the captured poses, shown while the block runs; yields the
    ``progress(done, total, name)`` callback of the calibration jobs."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

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

        yield progress


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
    per_pose = Table(title="per pose (RMS, px)")
    for column in ("pose", "camera", "projector"):
        per_pose.add_column(column, justify="right")
    for item in data["per_pose"]:
        per_pose.add_row(
            item["name"], f"{item['camera_rms_px']:.4f}", f"{item['projector_rms_px']:.4f}"
        )
    console.print(per_pose)
    truth = data.get("truth_error")
    if truth is None:
        if data["dropped_poses"]:
            console.print(f"dropped poses: {', '.join(data['dropped_poses'])}")
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
