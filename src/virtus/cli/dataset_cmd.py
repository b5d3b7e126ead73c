"""``virtus dataset generate|info|verify|export``: synthetic FPP datasets (virtus.data)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary


class StorageFormat(StrEnum):
    """How samples are stored."""

    zarr = "zarr"
    png = "png"


def generate(
    config: Annotated[Path, typer.Option(help="Dataset configuration YAML.")],
    out: Annotated[Path, typer.Option(help="The store folder (new, or the same config's).")],
    num: Annotated[
        int | None, typer.Option(help="Samples (default: the config's num_samples).")
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Local worker processes in all (default: one per GPU x --workers-per-gpu, "
            "or 1 without GPUs). On a CPU one uses every core; on a GPU the cores checksum "
            "and compress what it renders, so use about 3/4 of them (12 of 16 gave the most)."
        ),
    ] = None,
    gpus: Annotated[
        str | None,
        typer.Option(
            help="GPUs to render on: a number or 'all' (default: all visible, from "
            "CUDA_VISIBLE_DEVICES or nvidia-smi; with --ray, the cluster's). Each worker is "
            "pinned to one."
        ),
    ] = None,
    workers_per_gpu: Annotated[
        int | None,
        typer.Option(help="Worker processes per GPU (with --ray: actors of 1/N GPU each)."),
    ] = None,
    ray: Annotated[
        str | None,
        typer.Option(help="Render on Ray: 'auto' (running cluster), 'local' or an address."),
    ] = None,
    ray_timeout: Annotated[
        float,
        typer.Option(help="Seconds a --ray cluster has to answer before the run gives up."),
    ] = 15.0,
    storage: Annotated[
        StorageFormat, typer.Option("--format", help="zarr (sharded Zarr v3) or png.")
    ] = StorageFormat.zarr,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Render the samples of CONFIG that OUT lacks. Rerun the same command after an
    interruption to complete the store; the result equals an uninterrupted run's."""
    from virtus.data import generate as generate_dataset
    from virtus.data import load_config
    from virtus.data.generate import wait_for_workers

    the_config = load_config(config)
    output = Output(json_out, quiet)
    with _samples_bar(output) as progress:
        report = generate_dataset(
            the_config, out, num=num, workers=workers, gpus=gpus,
            workers_per_gpu=workers_per_gpu, ray=ray, storage=storage.value,
            progress=progress, ray_timeout=ray_timeout,
        )  # fmt: skip
    data = {
        "path": str(report.path),
        "complete": report.complete,
        "num_samples": report.num_samples,
        "rendered": report.rendered,
        "seconds": report.seconds,
    }
    summary = Summary(data)
    summary.lines.append(
        f"{report.path}: {report.complete}/{report.num_samples} samples complete "
        f"({report.rendered} rendered in {report.seconds:.1f} s)"
    )
    output.emit(summary)
    # The run's workers exit after it, the report printed: the command ends once they
    # have, here, where an interrupt is handled as the command's (not at the interpreter's
    # exit, which would wait for them too).
    wait_for_workers()


@contextlib.contextmanager
def _samples_bar(output: Output) -> Iterator[Callable[[int, int, int], None]]:
    """The samples' progress bar on stderr (on a terminal only) while the block runs;
    yields the ``progress(done, total, rendered)`` callback of the dataset job. The bar
    appears with the first call, after every check has passed, so a refused run prints its
    one error line and nothing else."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    bar = Progress(
        TextColumn("[bold]samples"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=output.err,
        disable=not output.shows_progress,
    )
    task = bar.add_task("", total=None, rate="")
    clock: dict[str, float] = {}

    def progress(done: int, total: int, rendered: int) -> None:
        now = time.perf_counter()
        if "start" not in clock:
            clock["start"] = now
            bar.start()
        elapsed = now - clock["start"]
        rate = f"{rendered / elapsed:.2f} samples/s" if rendered and elapsed > 0 else ""
        bar.update(task, completed=done, total=total, rate=rate)

    try:
        yield progress
    finally:
        if clock:
            bar.stop()


def info(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Print what a store holds.

    Its mode, sizes, complete samples per split and disk use."""
    from virtus.data import DatasetStore

    data = DatasetStore.open(path).info()
    Output(json_out, quiet).emit(Summary({"path": str(path), **data}, _print_info))


def _print_info(console: Any, data: dict[str, Any]) -> None:
    from rich.table import Table

    path = data["path"]
    table = Table(title=f"virtus dataset {path}", show_header=False)
    for key in ("storage", "mode", "seed", "num_samples", "complete", "shard_samples"):
        table.add_row(key, str(data[key]))
    table.add_row("splits", ", ".join(f"{k}: {v}" for k, v in data["splits"].items()))
    f = data["frames"]
    table.add_row("frames", f"up to {f['max']} x {f['width']}x{f['height']} px {f['dtype']}")
    table.add_row("arrays", ", ".join(data["arrays"]))
    table.add_row("on disk", f"{data['bytes_on_disk'] / 2**20:.1f} MiB")
    console.print(table)


def verify(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Check every recorded sample against its checksum.

    Read every recorded sample back, compare its checksum and list missing samples;
    exit status 1 when a sample is bad or missing."""
    from virtus.data import DatasetStore

    store = DatasetStore.open(path)
    report = store.verify()
    summary = Summary(report.to_dict())
    state = "ok" if report.ok else "FAILED"
    summary.lines.append(
        f"{path}: {state}: {report.checked} samples checked, {len(report.bad)} bad, "
        f"{len(report.missing)} of {store.num_samples} missing"
    )
    summary.lines += [f"  sample {index}: {problem}" for index, problem in report.bad[:20]]
    if report.missing:
        summary.lines.append(
            f"  missing: {report.missing[:20]}{' ...' if len(report.missing) > 20 else ''}"
        )
    Output(json_out, quiet).emit(summary)
    if not report.ok:
        raise typer.Exit(1)


class ExportFormat(StrEnum):
    """What ``dataset export`` writes."""

    webdataset = "webdataset"
    fpp_ml_bench = "fpp-ml-bench"


def export(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    out: Annotated[
        Path | None, typer.Argument(help="Output folder (or --webdataset for tar shards).")
    ] = None,
    webdataset: Annotated[
        Path | None, typer.Option(help="Folder for WebDataset tar shards.")
    ] = None,
    export_format: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            help="webdataset (tar shards) or fpp-ml-bench (AnushLak/fpp-ml-bench's "
            "{train,val,test}/fringe/*.png + depth/*.mat, per-sample calibration JSON).",
        ),
    ] = ExportFormat.webdataset,
    frame: Annotated[
        str,
        typer.Option(
            help="fpp-ml-bench input frame: 'auto' (first vertical phase step) or an index."
        ),
    ] = "auto",
    split: Annotated[str | None, typer.Option(help="Only this split.")] = None,
    samples_per_tar: Annotated[int, typer.Option(help="Samples per tar.")] = 64,
    skip_damaged: Annotated[
        bool,
        typer.Option(
            "--skip-damaged",
            help="Leave out samples that fail their checksum (counted in the summary) "
            "instead of stopping at the first one.",
        ),
    ] = False,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """Export complete samples (WebDataset tars, FPP-ML-Bench).

    Export complete samples as WebDataset tars (<key>.<array>.npy + <key>.json). Every
    sample is checked against its checksum; a damaged one stops the export (nothing is
    written) unless --skip-damaged. --format fpp-ml-bench writes FPP-ML-Bench's layout
    into OUT (virtus.data.mlbench)."""
    from virtus.data import export_webdataset
    from virtus.errors import InputError

    if export_format == ExportFormat.fpp_ml_bench:
        from virtus.data import export_fpp_ml_bench

        if out is None or webdataset is not None or split is not None or skip_damaged:
            raise InputError(
                "--format fpp-ml-bench", "STORE OUT (no --webdataset/--split/--skip-damaged)",
                f"OUT {out}, --webdataset {webdataset}, --split {split}",
            )  # fmt: skip
        chosen: int | str = int(frame) if frame.isdigit() else frame
        summary = export_fpp_ml_bench(path, out, frame=chosen)
        counts = ", ".join(f"{k}: {v}" for k, v in summary["samples"].items()) or "no samples"
        done = Summary({"format": export_format.value, "out": str(out), **summary})
        done.lines.append(f"{out}: fpp-ml-bench layout, {counts}")
        Output(json_out, quiet).emit(done)
        return
    if (webdataset is None) == (out is None):
        raise InputError("webdataset", "one output folder: OUT or --webdataset", [out, webdataset])
    webdataset = webdataset if webdataset is not None else out
    damaged: list[int] = []
    tars = export_webdataset(
        path, webdataset, split=split, samples_per_tar=samples_per_tar,
        on_damaged=(lambda index, _problem: damaged.append(index)) if skip_damaged else None,
    )  # fmt: skip
    line = f"{webdataset}: {len(tars)} tar files"
    if skip_damaged:
        listed = ", ".join(str(i) for i in damaged[:20]) + (" ..." if len(damaged) > 20 else "")
        line += f", {len(damaged)} damaged samples skipped" + (f" ({listed})" if damaged else "")
    data = {"format": export_format.value, "out": str(webdataset), "tars": [str(t) for t in tars],
            "damaged_skipped": damaged if skip_damaged else None}  # fmt: skip
    Output(json_out, quiet).emit(Summary(data, lines=[line]))


def register(app: typer.Typer) -> None:
    dataset_app = typer.Typer(
        help="Generate, inspect, verify and export synthetic FPP datasets.", no_args_is_help=True
    )
    app.add_typer(dataset_app, name="dataset")
    for name, command in (("generate", generate), ("info", info), ("verify", verify),
                          ("export", export)):  # fmt: skip
        dataset_app.command(name)(command)
