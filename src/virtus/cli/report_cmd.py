"""``virtus report RUN_DIR``: one self-contained HTML page for the directory of any run.

Also the ``--no-report`` option and the call with which ``demo``, ``scan``, ``calibrate``,
``ablation``, ``acceptance``, ``robot-scan`` and ``learn eval`` write ``OUT/report.html`` after
their run (:func:`add_report`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary

#: ``--no-report``: skip the run's HTML report.
NoReportOption = Annotated[
    bool,
    typer.Option(
        "--no-report",
        help="Do not write OUT/report.html (the run's HTML report; `virtus report OUT` "
        "writes it later).",
    ),
]


def add_report(output: Output, summary: Summary, run_dir: Path, no_report: bool) -> None:
    """Write ``run_dir/report.html`` after a run (unless ``no_report``) and name it in the
    summary (``report`` key; None when skipped or refused). The run's results are written
    by then: a report that cannot be made is a one-line warning, not a failed run."""
    if no_report:
        summary.add("report", None)
        return
    from virtus.errors import VirtusError
    from virtus.report import write_report

    try:
        report = write_report(run_dir)
    except VirtusError as error:
        output.warn(f"no report: {error}")
        summary.add("report", None)
        return
    summary.add("report", str(report.path), f"report: {report.path}")


def register(app: typer.Typer) -> None:
    @app.command("report")
    def report(
        run_dir: Annotated[
            Path,
            typer.Argument(
                help="Directory of a run (demo, calibrate, capture, scan, ablation, twin, "
                "acceptance, predict, design, robot-scan, learn train) or a dataset store."
            ),  # fmt: skip
        ],
        out: Annotated[
            Path | None,
            typer.Option(help="HTML file to write; default: RUN_DIR/report.html."),
        ] = None,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Write a self-contained HTML report of a run's directory.

        One file that opens offline from disk: the run's figures (frames, phase maps,
        calibration poses and residuals, sphere and cloud-to-mesh errors, twin differences,
        a dataset's samples), an interactive 3D view of the cloud with a still image where
        WebGL is unavailable, and the run's configuration, timings and metrics. A
        directory that is not a finished run, or whose files were changed, is refused and
        nothing is written."""
        from virtus.report import describe, write_report

        output = Output(json_out, quiet)
        written = write_report(run_dir, out)
        summary = Summary(describe(written), _print_report)
        output.emit(summary)


def _print_report(console: Any, data: dict[str, Any]) -> None:
    console.print(
        f"{data['kind']} report, {data['figures']} figures, {data['bytes'] / 1e6:.1f} MB: "
        f"{data['path']}",
        markup=False,
        soft_wrap=True,
    )
