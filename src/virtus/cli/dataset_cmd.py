"""``virtus dataset generate|info|verify|export``: synthetic FPP datasets (virtus.data)."""

from __future__ import annotations

import json
import time
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer


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
        int,
        typer.Option(
            help="Local worker processes. On a CPU one uses every core; on a GPU the "
            "cores checksum and compress what it renders, so use about 3/4 of them "
            "(12 of 16 gave the most)."
        ),
    ] = 1,
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
) -> None:
    """Render the samples of CONFIG that OUT lacks. Rerun the same command after an
    interruption to complete the store; the result equals an uninterrupted run's."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from virtus.data import generate as generate_dataset
    from virtus.data import load_config

    the_config = load_config(config)
    # The bar appears with the first progress call, after every check has passed, so a
    # refused run prints its one error line and nothing else.
    bar = Progress(
        TextColumn("[bold]samples"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
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
        report = generate_dataset(
            the_config, out, num=num, workers=workers, ray=ray, storage=storage.value,
            progress=progress, ray_timeout=ray_timeout,
        )  # fmt: skip
    finally:
        if clock:
            bar.stop()
    typer.echo(
        f"{report.path}: {report.complete}/{report.num_samples} samples complete "
        f"({report.rendered} rendered in {report.seconds:.1f} s)"
    )


def info(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON only.")] = False,
) -> None:
    """Print what a store holds: mode, sizes, complete samples per split, disk use."""
    from virtus.data import DatasetStore

    data = DatasetStore.open(path).info()
    if json_out:
        typer.echo(json.dumps(data, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"virtus dataset {path}", show_header=False)
    for key in ("storage", "mode", "seed", "num_samples", "complete", "shard_samples"):
        table.add_row(key, str(data[key]))
    table.add_row("splits", ", ".join(f"{k}: {v}" for k, v in data["splits"].items()))
    f = data["frames"]
    table.add_row("frames", f"up to {f['max']} x {f['width']}x{f['height']} px {f['dtype']}")
    table.add_row("arrays", ", ".join(data["arrays"]))
    table.add_row("on disk", f"{data['bytes_on_disk'] / 2**20:.1f} MiB")
    Console().print(table)


def verify(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON only.")] = False,
) -> None:
    """Read every recorded sample back, compare its checksum and list missing samples;
    exit status 1 when a sample is bad or missing."""
    from virtus.data import DatasetStore

    store = DatasetStore.open(path)
    report = store.verify()
    if json_out:
        typer.echo(json.dumps(report.to_dict(), indent=2))
    else:
        state = "ok" if report.ok else "FAILED"
        typer.echo(
            f"{path}: {state}: {report.checked} samples checked, {len(report.bad)} bad, "
            f"{len(report.missing)} of {store.num_samples} missing"
        )
        for index, problem in report.bad[:20]:
            typer.echo(f"  sample {index}: {problem}")
        if report.missing:
            typer.echo(
                f"  missing: {report.missing[:20]}{' ...' if len(report.missing) > 20 else ''}"
            )
    if not report.ok:
        raise typer.Exit(1)


def export(
    path: Annotated[Path, typer.Argument(help="The store folder.")],
    webdataset: Annotated[Path, typer.Option(help="Folder for WebDataset tar shards.")],
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
) -> None:
    """Export complete samples as WebDataset tars (<key>.<array>.npy + <key>.json). Every
    sample is checked against its checksum; a damaged one stops the export (nothing is
    written) unless --skip-damaged."""
    from virtus.data import export_webdataset

    damaged: list[int] = []
    tars = export_webdataset(
        path, webdataset, split=split, samples_per_tar=samples_per_tar,
        on_damaged=(lambda index, _problem: damaged.append(index)) if skip_damaged else None,
    )  # fmt: skip
    summary = f"{webdataset}: {len(tars)} tar files"
    if skip_damaged:
        listed = ", ".join(str(i) for i in damaged[:20]) + (" ..." if len(damaged) > 20 else "")
        summary += f", {len(damaged)} damaged samples skipped" + (f" ({listed})" if damaged else "")
    typer.echo(summary)


def register(app: typer.Typer) -> None:
    dataset_app = typer.Typer(
        help="Generate, inspect, verify and export synthetic FPP datasets.", no_args_is_help=True
    )
    app.add_typer(dataset_app, name="dataset")
    for name, command in (("generate", generate), ("info", info), ("verify", verify),
                          ("export", export)):  # fmt: skip
        dataset_app.command(name)(command)
