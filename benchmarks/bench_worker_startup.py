"""Start-up of dataset worker processes: how long each takes to reach its steady rate.

A dataset run's workers are spawned processes (:func:`virtus.data.devices.pinned_pool`);
before a worker's first shard is written it imports virtus's data modules, starts CUDA
where a GPU renders, loads Mitsuba's variant, opens the store, makes its compressor and
shard buffers, and renders a first shard whose kernels come from the disk cache. Over a
short run that start-up is much of the wall time (``benchmarks/bench_dataset.py`` reports
a run's rate over the whole run and in its steady part).

This benchmark makes a small store of the training configuration of
``bench_dataset.py`` (960 x 960, 52 frames, ``shuffle-zstd``; ``--compress-on gpu`` where
nvCOMP and a GPU are here) in this process, then starts ``--processes`` worker processes
at once (and then one alone), spawned and then forked from a fork server that has
imported :mod:`virtus.data.workerimports` (as :func:`virtus.data.devices.pinned_pool`
starts a run's workers; the server starts in the first forked run and its start counts
in that run's wall time), each timing its steps: imports of ``virtus.data``, Mitsuba's
variant, torch and its CUDA context (where Mitsuba renders on a GPU), the store and its
randomiser, the compressor, the shard buffers (device and page-locked ones on the GPU
path), the first shard and a second one (each re-rendered and rewritten: the same bytes).
Reported per step: the range over the processes.

    PYTHONPATH=src python benchmarks/bench_worker_startup.py [--processes 8] [--json out.json]
    PYTHONPATH=src python benchmarks/bench_worker_startup.py --tiny --processes 2   # CPU smoke

Not a test: numbers depend on the machine, its disk cache and its load.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import multiprocessing
import os
import sys
import tempfile
import time
from pathlib import Path

#: The steps each worker times, in order.
STEPS = (
    "import virtus.data",
    "Mitsuba variant",
    "torch's CUDA context (GPU)",
    "store + randomiser",
    "compressor",
    "shard buffers",
    "first shard",
    "second shard",
)


def worker(path: str, digest: str, shards: tuple[int, int], num: int, out: object) -> None:
    """One worker's start-up, timed step by step (run in a spawned process)."""
    marks = [time.perf_counter()]
    from virtus.data.cudadriver import block_while_waiting
    from virtus.data.devices import visible_gpus

    if visible_gpus():
        block_while_waiting()  # as a pinned worker does, before anything starts CUDA
    importlib.import_module("virtus.data.generate")  # what a worker imports first
    task = importlib.import_module("virtus.data.shardtask")
    marks.append(time.perf_counter())
    from virtus.render.backend import mitsuba, on_gpu

    mitsuba()
    marks.append(time.perf_counter())
    if on_gpu():  # the GPU path's device buffers and staging are torch's
        try:
            import torch

            torch.zeros(1, device="cuda")
        except (ImportError, RuntimeError):
            pass
    marks.append(time.perf_counter())
    task.worker_init(max(1, (os.cpu_count() or 1) // 8), False)
    store, _ = task._open(path, digest)
    marks.append(time.perf_counter())
    store.batch_compressor()
    marks.append(time.perf_counter())
    task._shard_buffers(store)
    marks.append(time.perf_counter())
    for shard in shards:
        task.render_shard(path, shard, num, digest)
        marks.append(time.perf_counter())
    out.put([b - a for a, b in zip(marks, marks[1:], strict=False)])  # type: ignore[attr-defined]


def start(count: int, path: Path, digest: str, num: int, shards: int, method: str) -> dict:
    """``count`` workers started at once by ``method``: ``"spawn"``, or ``"pool"`` as
    :func:`virtus.data.devices.pinned_pool` starts them (its context; the fork server where
    there is one). The range of each step and the wall time."""
    from virtus.data.devices import worker_context

    context = multiprocessing.get_context("spawn") if method == "spawn" else worker_context()
    queue = context.Queue()
    begin = time.perf_counter()
    processes = [
        context.Process(
            target=worker, args=(str(path), digest, (k % shards, (k + 1) % shards), num, queue)
        )
        for k in range(count)
    ]
    for process in processes:
        process.start()
    rows = [queue.get() for _ in processes]
    for process in processes:
        process.join()
    wall = time.perf_counter() - begin
    return {
        "start": context.get_start_method(),
        "processes": count,
        "wall_s": round(wall, 2),
        "steps_s": {
            step: [round(min(r[i] for r in rows), 3), round(max(r[i] for r in rows), 3)]
            for i, step in enumerate(STEPS)
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=8)
    parser.add_argument("--tiny", action="store_true", help="64 x 48 camera, 22 frames")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if not 1 <= args.processes <= 64:
        parser.error(f"--processes must be 1..64, got {args.processes}")
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_dataset import config_file

    from virtus.data import DatasetStore, generate, load_config
    from virtus.data.chunkcodecs import plan_compression

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        samples, shard = 16, 4
        config = load_config(
            config_file(folder, samples, shard, "shuffle-zstd", 1, "float32", args.tiny)
        )
        on = plan_compression("shuffle-zstd", "auto").on  # the GPU where it can
        config = dataclasses.replace(config, compress_on=on)
        begin = time.perf_counter()
        generate(config, folder / "store", workers=1)
        made = time.perf_counter() - begin
        digest = DatasetStore.open(folder / "store").digest
        shards = samples // shard
        runs = [
            start(count, folder / "store", digest, samples, shards, method)
            for method in ("spawn", "pool")
            for count in dict.fromkeys((args.processes, 1))
        ]
    result = {"compress_on": on, "store_s": round(made, 2), "runs": runs}
    for run in runs:
        print(
            f"{run['processes']} processes at once, {run['start']}: {run['wall_s']} s",
            file=sys.stderr,
        )
        for step, (low, high) in run["steps_s"].items():
            print(f"  {step:28s} {low:7.3f} - {high:7.3f} s", file=sys.stderr)
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
