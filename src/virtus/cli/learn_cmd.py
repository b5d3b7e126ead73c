"""``virtus learn train|eval``: learning-based fringe analysis on virtus data (virtus.learn)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import OverwriteOption
from virtus.cli.output import JsonOption, Output, QuietOption, Summary
from virtus.cli.report_cmd import NoReportOption, add_report

DeviceOption = Annotated[
    str | None, typer.Option(help="torch device (default: cuda when available, else cpu).")
]


def _emit(
    summary: dict, json_out: bool, quiet: bool, report: tuple[Path, bool] | None = None
) -> None:
    """Print ``summary``; with ``report = (run, no_report)`` write the run's report first."""
    lines = []
    for key, value in summary.items():
        if isinstance(value, float):
            value = f"{value:.4g}"
        if not isinstance(value, list | dict):
            lines.append(f"{key}: {value}")
    output, result = Output(json_out, quiet), Summary(summary, lines=lines)
    if report is not None:
        add_report(output, result, *report)
    output.emit(result)


def train(
    config: Annotated[
        Path, typer.Option(help="Training configuration YAML (virtus.learn.config).")
    ],
    store: Annotated[Path, typer.Option(help="The dataset store (virtus dataset generate).")],
    out: Annotated[Path, typer.Option(help="The run directory (checkpoint, metrics).")],
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the run in OUT from its last checkpoint.")
    ] = False,
    overwrite: OverwriteOption = False,
    device: DeviceOption = None,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train CONFIG's model (unet or phase) on STORE's train split; test metrics go to
    OUT/metrics.json. Rerun with --resume after an interruption: the weights equal an
    uninterrupted run's."""
    from virtus.learn import load_train_config
    from virtus.learn import train as train_run

    metrics = train_run(
        load_train_config(config), store, out, resume=resume, overwrite=overwrite, device=device
    )
    test = metrics.get("test") or {}
    _emit({"run": str(out), "steps": metrics["steps"], **test}, json_out, quiet)


def evaluate(
    run: Annotated[Path, typer.Argument(help="A run directory of virtus learn train.")],
    store: Annotated[Path | None, typer.Option(help="A dataset store to evaluate on.")] = None,
    split: Annotated[str | None, typer.Option(help="The store's split (default: all).")] = None,
    captures: Annotated[
        list[Path] | None,
        typer.Option(
            "--captures",
            help="Capture directories (virtus import / capture), evaluated against their own "
            "multi-step phase; repeat the option for more.",
        ),
    ] = None,
    unwrap: Annotated[
        str,
        typer.Option(
            help="Phase model on a store: fringe orders from the stored labels ('label': a "
            "perfect Gray-code decode) or decoded from each sample's frames ('decode')."
        ),
    ] = "label",
    device: DeviceOption = None,
    no_report: NoReportOption = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Evaluate a trained run on a store (--store) or on captures (--captures); the metrics
    go to RUN/evaluations/*.json and the run's report to RUN/report.html."""
    from virtus.errors import InputError
    from virtus.learn import evaluate as evaluate_store
    from virtus.learn import evaluate_captures

    if (store is None) == (not captures):
        raise InputError("--store/--captures", "exactly one of them", "both" if store else "none")
    if store is not None:
        summary = evaluate_store(run, store, split, device=device, unwrap=unwrap)
    else:
        summary = evaluate_captures(run, list(captures or []), device=device)
    _emit(summary, json_out, quiet, (run, no_report))


def register(app: typer.Typer) -> None:
    learn_app = typer.Typer(
        help="Train and evaluate fringe-analysis networks on virtus datasets.",
        no_args_is_help=True,
    )
    app.add_typer(learn_app, name="learn")
    learn_app.command("train")(train)
    learn_app.command("eval")(evaluate)
