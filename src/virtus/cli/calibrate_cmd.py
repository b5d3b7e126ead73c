"""``virtus calibrate``: capture a board in many poses, calibrate, compare with the truth
(:func:`virtus.pipeline.calibrate.calibrate_rig`); with ``--captures DIR [DIR ...]``,
calibrate a real rig from its captures (:func:`virtus.pipeline.calibrate.calibrate_captures`);
with ``--from-points PATH``, from saved correspondences
(:func:`virtus.pipeline.calibrate.calibrate_points`)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import (
    OverwriteOption,
    ScannerOptions,
    SeedOption,
    once,
    scanner_options,
)
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report

DEFAULT_OUT = Path("virtus-calibration")
BOARD_HELP = (
    "Board: ROWSxCOLS (the paper's circle boards 4x7, 5x9, 7x13), "
    "'circles:ROWSxCOLS,spacing_mm=S,diameter_mm=D[,border_mm=B][,white_on_black]', "
    "'checker:ROWSxCOLS,square_mm=S[,border_mm=B]' (inner corners) or a board .json/.yaml. "
    "Default 7x13 (with --from-points: the run's board, if its points need one)."
)


class Distortion(StrEnum):
    """Lens models (:data:`virtus.calib.solve.DISTORTION_MODELS`)."""

    k1k2p1p2 = "k1k2p1p2"
    k3 = "k3"
    rational = "rational"


FromPointsOption = Annotated[
    Path | None,
    typer.Option(
        "--from-points",
        help="Calibrate from saved correspondences instead of rendering: a CSV "
        "(pose,id,x_cam,y_cam,x_proj,y_proj), a folder of per-pose text files (cam/ and "
        "proj/, or *_cam.txt and *_proj.txt; 'x y' per line) or of .npz pose files (a "
        "run's poses/); see the README.",
    ),
]
SizesOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="CAMWxCAMH,PROJWxPROJH",
        help="With --from-points: camera and projector image sizes in px, "
        "'CAMWxCAMH,PROJWxPROJH' (e.g. 960x960,912x1140); a run's episode.json gives them.",
    ),
]
DistortionOption = Annotated[
    Distortion,
    typer.Option(
        help="Lens model of both devices: k1k2p1p2 (k3 fixed at 0), k3 (k3 estimated too) "
        "or rational (k1-k6, p1, p2)."
    ),
]


@scanner_options(omit=("bounces", "projector_lens", "camera_lens"))
def calibrate(
    *,
    out: Annotated[Path, typer.Option(help="Output directory.")] = DEFAULT_OUT,
    board: Annotated[list[str] | None, typer.Option(metavar="SPEC", help=BOARD_HELP)] = None,
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
    from_points: FromPointsOption = None,
    sizes: SizesOption = None,
    distortion: DistortionOption = Distortion.k1k2p1p2,
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
    json_out: JsonOption = False,
    quiet: QuietOption = False,
    no_report: NoReportOption = False,
) -> None:
    """Calibrate a camera-projector rig.

    Render the board in every pose (the whole pattern sequence each), calibrate camera,
    projector and their pose, and write OUT/calibration.json (+ OpenCV YAML and the
    paper's txt files). Identical runs write identical files; OUT/run.json records the
    run, OUT/timing.json its timings."""
    import warnings

    from virtus.calib.result import CALIBRATION_FILE
    from virtus.capture.scandir import capture_dirs
    from virtus.errors import InputError
    from virtus.pipeline.calibrate import (
        calibrate_captures,
        calibrate_points,
        calibrate_rig,
        check_pose_spec,
    )
    from virtus.sensor import as_seed

    # Cheap checks first: nothing is read, rendered or written before they pass.
    board, sizes = once(board, "--board"), once(sizes, "--sizes")
    the_board = _board_of(board, from_points, sizes, bool(captures or resume))
    if more_captures and not captures:
        raise InputError("arguments", "capture directories only after --captures", more_captures)
    if captures or from_points is not None:
        mode = "--captures" if captures else "--from-points"
        _refuse_rendering_options(options, mode, poses=poses, seed=seed)
    if captures and resume:
        raise InputError("--resume", "a rendered run (not --captures)", True)
    from_captures = capture_dirs([*captures, *(more_captures or [])]) if captures else None
    if from_captures is None and from_points is None:
        poses = check_pose_spec(poses)
        seed = as_seed(seed)
        scanner = options.build()
    output = Output(json_out, quiet)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with _progress_bar(output) as progress:
            common = {"out_dir": out, "overwrite": overwrite, "distortion": distortion.value}
            if from_points is not None:
                result = calibrate_points(from_points, board=the_board, sizes=sizes, **common)
            elif from_captures is not None:
                result = calibrate_captures(
                    from_captures, board=the_board, progress=progress, **common
                )
            else:
                result = calibrate_rig(
                    scanner, board=the_board, poses=poses, rng=seed, progress=progress,
                    resume=resume, **common,
                )  # fmt: skip
    for warning in caught:
        output.warn(str(warning.message))
    summary = Summary(result.to_dict(), _print_summary)
    summary.add("calibration_file", str(out / CALIBRATION_FILE), f"wrote {out / CALIBRATION_FILE}")
    add_report(output, summary, out, no_report)
    output.emit(summary)


def _board_of(board: str | None, from_points: Path | None, sizes: str | None, other: bool) -> Any:
    """The board (default 7x13; with --from-points only if given), after refusing
    --from-points with ``other`` modes (--captures, --resume) and --sizes without it."""
    from virtus.calib import board_from_spec
    from virtus.errors import InputError

    if from_points is not None and other:
        raise InputError("--from-points", "no --captures or --resume with it", from_points)
    if sizes is not None and from_points is None:
        raise InputError("--sizes", "--from-points (the sizes of its images)", sizes)
    if board is None and from_points is None:
        board = "7x13"
    return None if board is None else board_from_spec(board)


def register(app: typer.Typer) -> None:
    app.command("calibrate")(calibrate)


#: What each mode that renders nothing calibrates, for the refusal of a rendering option.
_WHAT_IS_CALIBRATED = {"--captures": "captures", "--from-points": "points"}


def _refuse_rendering_options(options: ScannerOptions, mode: str, **given: Any) -> None:
    """With ``mode`` (``--captures``, ``--from-points``) nothing is rendered: an option of
    the rendering given another
    value than its default (``--poses random:5``, ``--spp 9``, ``--sensor imx174``, ...) is
    refused, naming it, rather than ignored."""
    from dataclasses import fields

    from virtus.errors import InputError

    defaults = {"poses": "paper", "seed": 0}
    changed = [(name, value) for name, value in given.items() if value != defaults[name]]
    changed += [
        (f.name, getattr(options, f.name))
        for f in fields(options)
        if getattr(options, f.name) != f.default
    ]
    if changed:
        name, value = changed[0]
        raise InputError(
            f"--{name.replace('_', '-')}",
            f"no rendering option with {mode} (the {_WHAT_IS_CALIBRATED[mode]} are calibrated "
            "as they are)",
            str(getattr(value, "value", value)),
        )


@contextlib.contextmanager
def _progress_bar(output: Output) -> Iterator[Callable[[int, int, str], None]]:
    """A progress bar of the captured poses on stderr (on a terminal only), shown while the
    block runs; yields the ``progress(done, total, name)`` callback of the calibration jobs."""
    from rich.progress import BarColumn, TextColumn, TimeElapsedColumn

    with output.progress(
        TextColumn("[bold]capture"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
    ) as bar:
        if bar is None:
            yield lambda done, total, name: None
            return
        task = bar.add_task("", total=None)

        def progress(done: int, total: int, name: str) -> None:
            bar.update(task, completed=done, total=total, description=name)

        yield progress


def _print_conditioning(console: Any, check: dict[str, Any] | None) -> None:
    """How well the data determine the rig (the warnings themselves are printed above)."""
    from rich.table import Table

    if not check:
        return
    table = Table(title=f"conditioning (tilt spread {check['tilt_spread_deg']:.1f} deg)")
    for column in ("device", "sigma_f/f %", "sigma_c px", "coverage %", "tilt deg"):
        table.add_column(column, justify="right")
    for device in ("camera", "projector"):
        row = check[device]
        focal, centre = row["focal_rel_std"], row["principal_point_std_px"]
        table.add_row(
            device,
            "-" if focal is None else f"{100 * focal:.3f}",
            "-" if centre is None else f"{centre:.2f}",
            f"{100 * row['coverage']:.0f}",
            "{:.1f}-{:.1f}".format(*row["tilt_deg"]),
        )
    console.print(table)


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
    _print_conditioning(console, data.get("conditioning"))
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
