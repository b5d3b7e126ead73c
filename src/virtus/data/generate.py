"""Dataset generation: render the missing shards of a store, here, in worker processes or on Ray.

:func:`generate` is the library function behind ``virtus dataset generate``:

1. Everything that can be refused is checked before any rendering: the configuration
   (:mod:`virtus.data.config`), the candidate sequences, sensors, projectors and object
   instances (:class:`~virtus.data.sampling.Randomiser`), the mesh files against their
   headers (:mod:`virtus.scene.meshfiles`), the output folder (writable; empty, new, or a
   store of the same configuration whose description and records are its own) and the
   sizes (samples, workers, shard memory). A Ray cluster is connected to before the
   store is touched, within ``ray_timeout`` seconds (:func:`connect_ray`).
2. Under the output folder's lock (:func:`virtus.io.runs.directory_lock`: one generating
   process at a time), the store is created or extended (:meth:`DatasetStore.prepare`) and
   its manifest says which shards are missing.
3. Each missing shard is rendered, labelled and written by a shard task
   (:mod:`virtus.data.shardtask`: :func:`render_shard`, the shard's record written last),
   idempotent, so a retried or repeated task writes the same bytes. Tasks run in this
   process (``workers=1``: rendering, labelling and writing side by side on three
   threads, :func:`~virtus.data.shardtask.run_pipelined`), in ``workers`` worker
   processes (forked from a server started as the run begins, which has imported what
   they need; a few consecutive shards a task, :func:`_next_task`, each written while the
   next renders, :func:`~virtus.data.shardtask.render_shards`; on a host with GPUs each
   worker is pinned to one, :mod:`virtus.data.devices`, and uses its share of the cores),
   or on Ray (:mod:`virtus.data.raycluster`: CPU tasks, or one actor per GPU share).

Rerunning the same command after an interruption (even ``kill -9``) renders only the
shards without a record; the store ends byte for byte as an uninterrupted run leaves it
(with the same encoder: ``storage.compress_on`` may move the compression to a GPU, whose
bytes differ while the arrays and their checksums do not, :mod:`virtus.data.chunkcodecs`).
Who compresses is decided before anything is written (:func:`plan_compression`: ``gpu``
without nvCOMP or a CUDA device is refused; ``auto`` falls back to the CPU with a warning);
each shard record and ``dataset.json``'s ``encoding`` name the encoders.
"""

from __future__ import annotations

import os
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virtus import __version__
from virtus.data import devices as _devices
from virtus.data.chunkcodecs import (
    GPU_CODECS,
    CompressionPlan,
    encoding_description,
    plan_compression,
)
from virtus.data.config import MAX_SHARD_BYTES, MAX_WORKERS, DatasetConfig
from virtus.data.devices import Placement
from virtus.data.labels import array_layout
from virtus.data.raycluster import (
    MAX_RAY_TIMEOUT_S,
    RAY_TIMEOUT_S,
    connect_ray,
    gpu_slots,
    run_actors,
    run_tasks,
)
from virtus.data.sampling import Randomiser
from virtus.data.shardtask import (
    TIMING_KEYS,
    render_shard,
    render_shards,
    run_pipelined,
    sample_meta,
    worker_init,
)
from virtus.data.store import ASSETS_DIR, DatasetStore
from virtus.errors import InputError
from virtus.io.runs import directory_lock, file_digest

__all__ = [
    "RAY_TIMEOUT_S",
    "TIMING_KEYS",
    "GenerateReport",
    "connect_ray",
    "generate",
    "input_digests",
    "render_shard",
    "sample_meta",
    "wait_for_workers",
]

#: Progress callback: (complete samples, target samples, samples rendered by this run).
Progress = Callable[[int, int, int], None]
#: Most shards in one worker process's task (:func:`_next_task`): within a task each
#: shard's write overlaps the next one's rendering.
_TASK_SHARDS = 4
#: Threads reaping the worker pools of finished runs (:func:`wait_for_workers`).
_REAPERS: list[threading.Thread] = []


@dataclass
class GenerateReport:
    """What a :func:`generate` call did.

    Attributes
    ----------
    path : the store.
    num_samples : samples requested.
    complete : samples of ``[0, num_samples)`` complete at the end.
    rendered : samples rendered by this call (0 when the store was already complete).
    seconds : wall time of the rendering phase, until every shard is recorded (worker
        processes are not waited for as they exit: :func:`wait_for_workers`).
    timing_s : seconds per stage (:data:`TIMING_KEYS`) summed over the shards rendered
        here, across all workers and threads; stages that run side by side (samples are
        labelled and written while later ones render) sum to more than ``seconds``.
    shard_devices : shard -> the GPU (``CUDA_VISIBLE_DEVICES`` entry) that rendered it in
        this call; None on CPU (not recorded in the store: it does not change a byte).
    encoders : who compressed the shards of this call -> how many shards
        (``{"nvcomp 6.0.0.12": 12}``; also in each shard record).
    compression_note : why ``storage.compress_on: auto`` compressed on the CPU (None when
        it did not fall back).
    """

    path: Path
    num_samples: int
    complete: int
    rendered: int
    seconds: float
    timing_s: dict[str, float] = field(default_factory=dict)
    shard_devices: dict[int, str | None] = field(default_factory=dict)
    encoders: dict[str, int] = field(default_factory=dict)
    compression_note: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": str(self.path),
            "num_samples": self.num_samples,
            "complete": self.complete,
            "rendered": self.rendered,
            "seconds": self.seconds,
            "samples_per_s": self.rendered / self.seconds if self.seconds > 0 else None,
            "timing_s": self.timing_s,
            "shard_devices": {str(k): v for k, v in self.shard_devices.items()},
            "encoders": self.encoders,
            "compression_note": self.compression_note,
        }


def input_digests(config: DatasetConfig) -> dict[str, str]:
    """``path -> "sha256:..."`` of every input file the configuration reads (rig, sensor,
    projector and sequence files, mesh files): part of a store's identity, so a changed
    file is never mixed into an existing dataset."""
    files: list[str] = []
    if config.rig_file:
        files.append(config.rig_file)
    files += [s for s in (*config.sensors, *config.projectors) if os.path.sep in s]
    files += list(config.fringes.sequences)
    for source in config.sources:
        if source.type == "mesh_folder":
            files += [str(source.path / name) for name in source.files]  # type: ignore[operator]
    return {path: file_digest(path) for path in files}


def _identity(config: DatasetConfig) -> dict[str, Any]:
    return {
        "config": config.identity(),
        "inputs": input_digests(config),
        "virtus_version": __version__,
    }


def _run_local(
    path: Path, shards: list[int], num: int, digest: str, placement: Placement,
    tick: Callable, pipelined: bool,
) -> Iterator[dict[str, Any]]:  # fmt: skip
    """The shards in this process (one worker) or in ``placement.workers`` worker
    processes, each pinned to its GPU (:func:`virtus.data.devices.pinned_pool`). A worker's
    task is a few consecutive shards (:func:`_next_task`); workers pinned to GPUs write
    each while the next renders when two shards fit in memory (``pipelined``,
    :func:`render_shards`): there the writes wait for the disk and the GPU, while on the
    cores both are the cores' work (2-core VM, 2 CPU workers, 48 samples at 960 x 960,
    two rounds: 94-106 images/s overlapped against 117-123 not). At most two tasks a worker
    are queued."""
    workers = placement.workers
    if workers == 1 and pipelined:
        yield from run_pipelined(path, shards, num, digest, tick)
        return
    if workers == 1:
        for shard in shards:
            yield render_shard(path, shard, num, digest, on_sample=lambda: tick(1))
        return
    from collections import deque
    from concurrent.futures import FIRST_COMPLETED, wait

    queue = deque(shards)
    overlap = pipelined and bool(placement.devices)

    def submit() -> Any:
        task = _next_task(queue, workers)
        return pool.submit(render_shards, str(path), task, num, digest, overlap=overlap)

    pool = _devices.pinned_pool(workers, placement.devices, worker_init, (placement.threads,))
    try:
        pending = set()
        while queue and len(pending) < 2 * workers:
            pending.add(submit())
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                for result in future.result():
                    tick(result["samples"])
                    yield result
                if queue:
                    pending.add(submit())
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    # Every shard is written and recorded: the workers are told to exit and reaped by a
    # thread, and the run does not wait for them to go (8 GPU workers take 1.3-1.5 s to
    # release their page-locked buffers and CUDA contexts on an H100 host). The thread
    # holds the last reference to the pool: dropped here, the executor's collection
    # would wait for the workers all the same (CPython >= 3.12 joins them holding a lock
    # that the collection takes; one run in three on the H100 host waited 1.4 s so).
    reaper = threading.Thread(target=pool.shutdown, name="virtus-pool-shutdown", daemon=True)
    reaper.start()
    _REAPERS.append(reaper)


def wait_for_workers() -> None:
    """Return once the worker processes of every finished :func:`generate` call of this
    process have exited (:func:`generate` does not wait for them: they release their GPU
    memory, page-locked buffers and CPU time to the system as they go)."""
    while _REAPERS:
        _REAPERS.pop().join()


def _next_task(queue: Any, workers: int) -> list[int]:
    """The next worker task's shards, taken from the front of ``queue`` (a deque): up to
    :data:`_TASK_SHARDS` (more shards a task overlap more writes with rendering), fewer as
    the queue empties so that the workers finish together (at most half a worker's share
    of the queue)."""
    size = max(1, min(_TASK_SHARDS, len(queue) // (2 * workers)))
    return [queue.popleft() for _ in range(min(size, len(queue)))]


def _run_ray(
    path: Path, shards: list[int], num: int, digest: str, ray: Any, workers: int,
    slots: tuple[int, float], tick: Callable,
) -> Iterator[dict[str, Any]]:  # fmt: skip
    """The shards on a connected Ray cluster: as CPU tasks (``2 * max(workers, CPUs)`` in
    flight), or on ``slots = (actors, GPU share)`` GPU actors (:func:`gpu_slots`)."""
    resources = ray.cluster_resources()

    def args(shard: int) -> tuple:
        return (str(path), shard, num, digest)

    if slots[0]:
        threads = max(1, int(resources.get("CPU", 1)) // slots[0])
        results = run_actors(
            ray, render_shard, args, shards, slots[0], slots[1], worker_init, (threads, False)
        )
    else:
        in_flight = max(2 * workers, 2 * int(resources.get("CPU", 1)))
        results = run_tasks(ray, render_shard, args, shards, in_flight)
    for result in results:
        tick(result["samples"])
        yield result


def _check_mesh_files(config: DatasetConfig) -> None:
    """Refuse a truncated or malformed mesh file of a ``mesh_folder`` source, naming it,
    before anything is written (:func:`virtus.scene.meshfiles.check_mesh_file`)."""
    from virtus.scene.meshfiles import check_mesh_file

    for source in config.sources:
        if source.type == "mesh_folder":
            for name in source.files:
                check_mesh_file(source.path / name)  # type: ignore[operator]


def _layout(config: DatasetConfig, out: Path) -> tuple[Any, int]:
    """The store's array layout and the bytes of one shard in memory (bounded)."""
    randomiser = Randomiser(config, out / ASSETS_DIR)
    cam = randomiser.rig.camera.intrinsics
    layout = array_layout(
        randomiser.max_frames, cam.height, cam.width, randomiser.bit_depth, config.label_dtype
    )
    shard_bytes = config.shard_samples * sum(a.nbytes for a in layout)
    if shard_bytes > MAX_SHARD_BYTES:
        raise InputError(
            "storage.shard_samples",
            f"shards of at most {MAX_SHARD_BYTES >> 20} MiB in memory",
            f"{config.shard_samples} samples x {sum(a.nbytes for a in layout) >> 20} MiB",
        )
    return layout, shard_bytes


def _plan(config: DatasetConfig, storage: str) -> CompressionPlan | None:
    """Who compresses this run's chunks (None: PNG storage), checked before anything is
    written; ``auto`` falling back to the CPU for a codec the GPU writes says so (a warning,
    and :attr:`GenerateReport.compression_note`)."""
    if storage != "zarr":
        return None
    plan = plan_compression(config.codec, config.compress_on)
    if plan.note and config.compress_on == "auto" and config.codec in GPU_CODECS:
        warnings.warn(f"storage.compress_on auto: {plan.note}", stacklevel=3)
    return plan


def _connect(
    ray: str, timeout: float, workers: int | None, gpus: int | str | None,
    workers_per_gpu: int | None,
) -> tuple[Any, tuple[int, float]]:  # fmt: skip
    """The connected ``ray`` module and the GPU actors to start (:func:`gpu_slots`)."""
    if (
        isinstance(timeout, bool)
        or not isinstance(timeout, int | float)
        or not (0 < timeout <= MAX_RAY_TIMEOUT_S)
    ):
        raise InputError("ray_timeout", f"seconds in (0, {MAX_RAY_TIMEOUT_S:g}]", timeout)
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= MAX_WORKERS
    ):
        raise InputError("workers", f"an integer in 1..{MAX_WORKERS}", workers)
    module = connect_ray(ray, float(timeout))
    return module, gpu_slots(module, gpus, workers_per_gpu)


def generate(
    config: DatasetConfig,
    out: str | Path,
    *,
    num: int | None = None,
    workers: int | None = None,
    gpus: int | str | None = None,
    workers_per_gpu: int | None = None,
    ray: str | None = None,
    storage: str = "zarr",
    progress: Progress | None = None,
    ray_timeout: float = RAY_TIMEOUT_S,
) -> GenerateReport:
    """Generate (or complete) a dataset store.

    Parameters
    ----------
    config : the configuration.
    out : the store folder (created; or an existing store of the same configuration,
        which is completed or extended to ``num`` samples).
    num : samples (default ``config.num_samples``), at most
        :data:`~virtus.data.config.MAX_SAMPLES`.
    workers : local worker processes in all (1: this process), at most
        :data:`~virtus.data.config.MAX_WORKERS`; default one per GPU used times
        ``workers_per_gpu``, or 1 without GPUs. With Ray, the CPU tasks kept in flight per
        CPU.
    gpus : GPUs to render on, an integer or ``"all"`` (default: every visible GPU,
        :func:`virtus.data.devices.visible_gpus`, or with Ray the cluster's); worker ``k``
        is pinned to GPU ``k mod G`` (:func:`virtus.data.devices.plan`).
    workers_per_gpu : worker processes (Ray: actors of ``1 / workers_per_gpu`` GPU) per GPU.
    ray : None (local), ``"auto"`` (the running Ray cluster), ``"local"`` (start one here)
        or a cluster address; a Ray session already initialised in this process is used.
    storage : ``"zarr"`` (sharded Zarr v3) or ``"png"`` (per-sample folders).
    progress : called with (complete, target, rendered by this call) as samples finish.
    ray_timeout : seconds a Ray cluster address has to answer (:func:`connect_ray`),
        at most :data:`MAX_RAY_TIMEOUT_S`.

    The store does not depend on the workers, GPUs or Ray: its bytes are those of a
    one-process run of the same configuration (which GPU rendered which shard is in the
    report, :attr:`GenerateReport.shard_devices`, not in the store).

    Raises
    ------
    InputError, VirtusError, OSError : bad configuration or sizes, an output folder that
        is not writable, not empty or a store of another configuration (or with records of
        another dataset, or an edited ``dataset.json``), a truncated mesh file, a Ray
        address where no cluster answers in time, more GPUs than visible (or than the
        cluster has) -- all before any sample is rendered and before the store is written
        to (its lock file aside).
    """
    config = config.with_num_samples(num)
    placement = None if ray is not None else _devices.plan(workers, gpus, workers_per_gpu)
    if placement is not None and placement.workers > 1:
        _devices.start_worker_server()  # its imports overlap the checks below
    out = Path(out)
    layout, shard_bytes = _layout(config, out)
    if out.exists() and not out.is_dir():
        raise InputError("--out", "a folder (new, empty, or a dataset store)", f"a file {out}")
    _check_mesh_files(config)
    plan = _plan(config, storage)
    if ray is not None:  # before the store is touched
        cluster, slots = _connect(ray, ray_timeout, workers, gpus, workers_per_gpu)
    with directory_lock(out):
        store = DatasetStore.prepare(
            out,
            config=config.stored_dict(),
            identity=_identity(config),
            layout=layout,
            storage=storage,
            num_samples=config.num_samples,
            encoding=encoding_description(config.codec, config.level, config.compress_on, [])
            if storage == "zarr"
            else None,
        )
        target = config.num_samples
        before = store.records()  # a killed run's too: read once, the run adds its own
        todo = store.missing_shards(target, before)
        todo_samples = sum(b - a for a, b in (store.shard_bounds(s, target) for s in todo))
        complete = target - todo_samples
        counter = {"complete": complete, "rendered": 0}

        def tick(count: int) -> None:
            counter["complete"] += count
            counter["rendered"] += count
            if progress is not None:
                progress(counter["complete"], target, counter["rendered"])

        if progress is not None:
            progress(complete, target, 0)
        timing = dict.fromkeys(TIMING_KEYS, 0.0)
        shard_devices: dict[int, str | None] = {}
        start = time.perf_counter()
        if placement is not None:
            # two shards in memory when one is written while the next is rendered
            pipelined = 2 * shard_bytes <= MAX_SHARD_BYTES
            results = _run_local(out, todo, target, store.digest, placement, tick, pipelined)
        else:
            results = _run_ray(out, todo, target, store.digest, cluster, workers or 1, slots, tick)
        here = placement.devices[0] if placement is not None and placement.devices else None
        encoders: dict[str, int] = {}
        for result in results:
            for stage, seconds in result["timing_s"].items():
                timing[stage] += seconds
            shard_devices[result["shard"]] = result["device"] or here
            encoders[result["encoder"]] = encoders.get(result["encoder"], 0) + 1
        seconds = time.perf_counter() - start
        # Each result is a shard of ``todo`` written and recorded: with the records from
        # before, every shard of the target is complete (not read back: 0.4-0.8 s for 180
        # records on an H100 host's disk).
        complete = counter["complete"]
        if storage == "zarr":  # every encoder a record names (a killed run's too)
            named = {r.get("encoder") for r in before.values()} | set(encoders)
            store.add_encoders(sorted(e for e in named if isinstance(e, str)))
    return GenerateReport(
        out,
        target,
        complete,
        counter["rendered"],
        seconds,
        timing,
        dict(sorted(shard_devices.items())),
        encoders,
        plan.note if plan is not None else None,
    )
