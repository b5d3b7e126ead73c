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
3. Each missing shard is one task, :func:`render_shard`: render its samples
   (:meth:`virtus.scanner.Scanner.capture`), make their labels
   (:func:`~virtus.data.labels.sample_arrays`) into a shard buffer, write the shard and
   then its record. On a GPU a sample is rendered and labelled where it is traced
   (:meth:`~virtus.scanner.Scanner.render_on_device`,
   :func:`~virtus.data.labels_jit.device_sample_arrays`) and copied once into the buffer,
   so the host's cores only checksum, compress and write; when the GPU compresses too, the
   compressor reads the device's copy (:mod:`virtus.data.devicebuffers`). A task depends
   only on the store path and the shard number, so it is idempotent: a retried or
   repeated task writes the same bytes. Tasks run in this process (``workers=1``:
   rendering, labelling and writing run side by side on three threads,
   :func:`_run_pipelined`), in ``workers`` spawned processes (each owns the shards it is
   given, a few a task, each written while the next renders, :func:`render_shards`; on a
   host with GPUs each is pinned to one, :mod:`virtus.data.devices`, and uses its share of
   the cores), or on Ray (:mod:`virtus.data.raycluster`: CPU tasks, or one actor per GPU
   share).

Rerunning the same command after an interruption (even ``kill -9``) renders only the
shards without a record; the store ends byte for byte as an uninterrupted run leaves it
(with the same encoder: ``storage.compress_on`` may move the compression to a GPU, whose
bytes differ while the arrays and their checksums do not, :mod:`virtus.data.chunkcodecs`).
Who compresses is decided before anything is written (:func:`plan_compression`: ``gpu``
without nvCOMP or a CUDA device is refused; ``auto`` falls back to the CPU with a warning);
each shard record and ``dataset.json``'s ``encoding`` name the encoders.
"""

from __future__ import annotations

import functools
import os
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus import __version__
from virtus.data import devices as _devices
from virtus.data import store as _store_module
from virtus.data.chunkcodecs import (
    GPU_CODECS,
    CompressionPlan,
    encoding_description,
    plan_compression,
)
from virtus.data.config import MAX_SHARD_BYTES, MAX_WORKERS, DatasetConfig
from virtus.data.devicebuffers import (
    device_shard_buffer,
    page_locked_shard_buffer,
    staging_device,
)
from virtus.data.devices import Placement
from virtus.data.labels import array_layout, sample_arrays
from virtus.data.raycluster import (
    MAX_RAY_TIMEOUT_S,
    RAY_TIMEOUT_S,
    connect_ray,
    gpu_slots,
    run_actors,
    run_tasks,
)
from virtus.data.sampling import Randomiser, SampleSpec
from virtus.data.store import ASSETS_DIR, DatasetStore, EncodedSample
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
]

#: Images up to this many pixels are synthesised on one thread (thread start-up would
#: cost more than the work).
_SMALL_IMAGE_PIXELS = 128 * 128
#: Progress callback: (complete samples, target samples, samples rendered by this run).
Progress = Callable[[int, int, int], None]
#: Stages timed by a run (seconds): ``render`` (scene, trace and frame synthesis),
#: ``labels`` (:func:`~virtus.data.labels.sample_arrays`), ``checksum`` and ``compression``
#: (work, summed over the threads doing it), ``io`` (shard files and records), ``write``
#: (the whole :meth:`~virtus.data.store.DatasetStore.write_shard`: checksum, compression
#: and io side by side), ``write_wait`` (rendering held up by the labelling and writing
#: behind it in a pipelined run).
TIMING_KEYS = ("render", "labels", "checksum", "compression", "io", "write", "write_wait")
#: Rendered samples that may wait for their labels in a pipelined run (each holds its
#: frames and float64 ground truth: ~110 MB at 960 x 960 with 52 frames).
_LABEL_QUEUE = 2
#: Threads that label, checksum and compress rendered samples in a pipelined run.
_SAMPLE_THREADS = 2
#: Most shards in one worker process's task (:func:`_next_task`): within a task each
#: shard's write overlaps the next one's rendering.
_TASK_SHARDS = 4
#: Whether this process is a dataset worker (:func:`_worker_init`).
_IN_WORKER = False
#: Where samples are labelled: None chooses the device that renders them on GPU variants
#: and the host otherwise (:func:`_labels_on_device`); True or False forces one (the test
#: suite checks the device path on the CPU's LLVM variant).
LABELS_ON_DEVICE: bool | None = None
#: A shard's buffers: the host's (name -> (count, *shape) array) and, where the compressor
#: reads the samples on the device, the device's (name -> torch tensor; else None).
_Buffers = tuple[dict[str, np.ndarray], "dict[str, Any] | None"]
#: In a worker process: the shard buffers kept between tasks (see :func:`_shard_buffers`).
_WORKER_BUFFER: tuple[tuple[str, str], dict[int, _Buffers]] | None = None
#: In a worker process: the CPU threads it may use to synthesise, checksum and compress
#: (its share of the host's cores, :attr:`virtus.data.devices.Placement.threads`).
_WORKER_THREADS: int | None = None


@dataclass
class GenerateReport:
    """What a :func:`generate` call did.

    Attributes
    ----------
    path : the store.
    num_samples : samples requested.
    complete : samples of ``[0, num_samples)`` complete at the end.
    rendered : samples rendered by this call (0 when the store was already complete).
    seconds : wall time of the rendering phase.
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


def sample_meta(spec: SampleSpec, render: dict[str, Any]) -> dict[str, Any]:
    """The JSON-ready record of one sample: everything needed to triangulate it again
    (rig, cam2world, sequence) and to render it again (scanner, seed, objects);
    ``render`` is its rendering's ``metadata()``."""
    scanner = spec.scanner
    return {
        "index": spec.index,
        "group": spec.group,
        "split": spec.split,
        "seed": spec.capture_seed,
        "n_frames": len(scanner.sequence),
        "bit_depth": scanner.sensor.bit_depth,
        "rig": scanner.rig.to_dict(),
        "cam2world": spec.cam2world.to_dict(),
        "sequence": scanner.sequence.to_dict(),
        "sensor": scanner.sensor.to_dict(),
        "projector": scanner.projector.to_dict(),
        "scanner": {"spp": scanner.render.spp, "bounces": scanner.render.bounces},
        "render": render,
        "objects": [o.to_dict() for o in spec.objects],
        "info": spec.info,
    }


@functools.lru_cache(maxsize=4)
def _randomiser(path: str, digest: str) -> Randomiser:
    """The randomiser of a store (built once per process and dataset: sequences, sensors,
    instance tables)."""
    config = DatasetConfig.from_dict(DatasetStore.open(path).description["config"])
    return Randomiser(config, Path(path) / ASSETS_DIR)


def _render(randomiser: Randomiser, index: int, threads: int | None) -> tuple[Any, Any, float]:
    """Sample ``index``'s specification and capture (frames materialised), and the seconds."""
    begin = time.perf_counter()
    spec = randomiser.sample(index)
    capture = spec.scanner.capture(
        spec.scene, cam2world=spec.cam2world, rng=spec.capture_seed, command=[], threads=threads
    )
    capture.frames  # noqa: B018 - rendered frames are materialised here (timing)
    return spec, capture, time.perf_counter() - begin


def _label(
    store: DatasetStore, spec: Any, capture: Any, buffer: dict[str, np.ndarray], slot: int
) -> float:
    """Write a sample's arrays into slot ``slot`` of a shard buffer; returns the seconds."""
    begin = time.perf_counter()
    sample_arrays(capture, spec, store.layout, _slot(buffer, slot))
    return time.perf_counter() - begin


def _slot(buffer: dict[str, np.ndarray], slot: int) -> dict[str, np.ndarray]:
    """One sample's arrays (views) in a shard buffer."""
    return {name: b[slot] for name, b in buffer.items()}


def _label_and_encode(
    store: DatasetStore, spec: Any, capture: Any, buffer: dict[str, np.ndarray], slot: int
) -> tuple[float, EncodedSample]:
    """:func:`_label`, then the sample's checksum and chunks
    (:meth:`~virtus.data.store.DatasetStore.encode_sample`)."""
    seconds = _label(store, spec, capture, buffer, slot)
    return seconds, store.encode_sample(_slot(buffer, slot))


def _encode(store: DatasetStore, buffers: _Buffers, slot: int) -> tuple[float, EncodedSample]:
    """:func:`_label_and_encode` of a sample labelled already (on the device; the
    compressor reads the device's copy where the buffers have one)."""
    host, device = buffers
    on_device = None if device is None else _slot(device, slot)
    return 0.0, store.encode_sample(_slot(host, slot), on_device)


def _labels_on_device() -> bool:
    """Whether samples are labelled on the device that renders them: with a GPU variant
    (:func:`virtus.render.backend.on_gpu`; a dataset's scanners render with the default
    variant), unless :data:`LABELS_ON_DEVICE` says otherwise."""
    if LABELS_ON_DEVICE is not None:
        return LABELS_ON_DEVICE
    from virtus.render.backend import on_gpu

    return on_gpu()


def _render_and_label(
    store: DatasetStore,
    randomiser: Randomiser,
    index: int,
    threads: int | None,
    buffers: _Buffers,
    slot: int,
    on_device: bool,
) -> tuple[dict[str, Any], float, float]:
    """Render sample ``index`` and write its arrays into slot ``slot`` of the host buffer:
    on the device that renders it (:func:`~virtus.data.labels_jit.device_sample_arrays`;
    into the device buffer too, where there is one) with ``on_device``
    (:func:`_labels_on_device`), else on the host. Returns its metadata and the ``render``
    and ``labels`` seconds (device work is asynchronous: the labels' seconds include the
    rendering the host waited for when copying)."""
    buffer, device = buffers
    if not on_device:
        spec, capture, seconds = _render(randomiser, index, threads)
        labels = _label(store, spec, capture, buffer, slot)
        return sample_meta(spec, capture.render), seconds, labels
    from virtus.data.labels_jit import device_sample_arrays

    begin = time.perf_counter()
    spec = randomiser.sample(index)
    rendering = spec.scanner.render_on_device(
        spec.scene, cam2world=spec.cam2world, rng=spec.capture_seed
    )
    middle = time.perf_counter()
    on = None if device is None else _slot(device, slot)
    device_sample_arrays(rendering, spec, store.layout, _slot(buffer, slot), on_device=on)
    return sample_meta(spec, rendering.metadata()), middle - begin, time.perf_counter() - middle


def _synthesis_threads(randomiser: Randomiser) -> int | None:
    """Host synthesis threads: 1 for small images, else the worker's share of the cores
    (:data:`_WORKER_THREADS`; None, all cores, outside a worker)."""
    cam = randomiser.rig.camera.intrinsics
    return 1 if cam.width * cam.height <= _SMALL_IMAGE_PIXELS else _WORKER_THREADS


def _fill_shard(
    store: DatasetStore,
    randomiser: Randomiser,
    shard: int,
    num_samples: int,
    buffers: _Buffers,
    on_sample: Callable[[], None] | None,
) -> tuple[list[dict[str, Any]], dict[str, float]]:
    """Render and label a shard's samples into ``buffers`` (:func:`_shard_buffers`, slot
    ``k`` = the shard's ``k``-th sample). Returns their metadata and the seconds spent
    (``render``, ``labels``)."""
    start, stop = store.shard_bounds(shard, num_samples)
    threads = _synthesis_threads(randomiser)
    on_device = _labels_on_device()
    timing = {"render": 0.0, "labels": 0.0}
    metas = []
    for slot, index in enumerate(range(start, stop)):
        meta, render, labels = _render_and_label(
            store, randomiser, index, threads, buffers, slot, on_device
        )
        timing["render"] += render
        timing["labels"] += labels
        metas.append(meta)
        if on_sample is not None:
            on_sample()
    return metas, timing


def _open(path: str | Path, digest: str) -> tuple[DatasetStore, Randomiser]:
    store = DatasetStore.open(path)
    if store.digest != digest:
        raise InputError("store", f"the dataset {digest}", store.digest)
    return store, _randomiser(str(path), digest)


def _staging_device(store: DatasetStore) -> str | None:
    """Where this process keeps its samples for the compressor
    (:func:`virtus.data.devicebuffers.staging_device`): the rendering device when samples
    are labelled there and the store's batch compressor reads its tensors, else None."""
    on_device = _labels_on_device()
    if not on_device:
        return None
    from virtus.render.backend import on_gpu

    rendering_device = "cuda" if on_gpu() else "cpu"
    return staging_device(store.batch_compressor(), on_device, rendering_device)


def _new_shard_buffers(store: DatasetStore) -> _Buffers:
    """A shard's host buffer and, where the compressor reads the device's copy
    (:func:`_staging_device`), its device buffer; the host buffer page-locked when that
    device is a GPU (:mod:`virtus.data.devicebuffers`) and the system lets it lock that
    much memory (else ordinary memory: the same bytes, copied more slowly)."""
    count, device = store.shard_samples, _staging_device(store)
    if device is None:
        return store.shard_buffer(count), None
    host = None
    if device == "cuda":
        try:
            host = page_locked_shard_buffer(store.layout, count)
        except RuntimeError:  # torch's pinned allocator: no lockable memory left
            host = None
    if host is None:
        host = store.shard_buffer(count)
    return host, device_shard_buffer(store.layout, count, device)


def _shard_buffers(store: DatasetStore, which: int = 0) -> _Buffers:
    """Set ``which`` (0 or 1: a worker that writes one shard while it renders the next
    alternates two) of a shard's buffers (:func:`_new_shard_buffers`), kept from one task
    to the next in a worker process (fresh memory costs page faults, and on a virtual
    machine often more: the host may have taken freed pages back; page-locking costs more
    still), new in any other process (nothing is held after :func:`generate`)."""
    global _WORKER_BUFFER
    if not _IN_WORKER:
        return _new_shard_buffers(store)
    key = (str(store.path), store.digest)
    if _WORKER_BUFFER is None or _WORKER_BUFFER[0] != key:
        _WORKER_BUFFER = None  # the old ones are freed before the new ones are made
        _WORKER_BUFFER = (key, {})
    kept = _WORKER_BUFFER[1]
    if which not in kept:
        kept[which] = _new_shard_buffers(store)
    return kept[which]


def render_shard(
    path: str | Path,
    shard: int,
    num_samples: int,
    digest: str,
    on_sample: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """Render, label and write one shard (a task: idempotent, any process may run it).

    Parameters
    ----------
    path : the store (already prepared).
    shard : the shard number.
    num_samples : the dataset size this run targets (the last shard may be partial).
    digest : the store's identity digest (a task for another dataset is refused).
    on_sample : called after each sample is rendered (progress in this process).

    Returns
    -------
    ``{"shard", "samples", "timing_s", "device"}``, ``timing_s`` with the keys of
    :data:`TIMING_KEYS`, ``device`` the GPU a worker process was pinned to (its
    ``CUDA_VISIBLE_DEVICES``; None in the calling process and on CPU).
    """
    return render_shards(path, [shard], num_samples, digest, on_sample=on_sample)[0]


def render_shards(
    path: str | Path,
    shards: list[int],
    num_samples: int,
    digest: str,
    *,
    overlap: bool = False,
    on_sample: Callable[[], None] | None = None,
) -> list[dict[str, Any]]:
    """:func:`render_shard` of each of ``shards``, in order (a task; each shard is written,
    record last, before the call returns).

    With ``overlap``, a shard is written (checksums, compression, files) on a second thread
    while the next one renders, in a second set of buffers: the writes wait mostly for the
    disk and the GPU, which the renderer then does not wait for (a worker holds two shards
    in memory instead of one). The first failure is raised once the shards before it are
    written.
    """
    from concurrent.futures import ThreadPoolExecutor

    store, randomiser = _open(path, digest)
    results: list[dict[str, Any]] = []

    def write(shard: int, buffers: _Buffers, metas: list, timing: dict) -> dict[str, Any]:
        buffer, device = buffers
        done = store.write_shard(shard, buffer, metas, on_device=device)
        result = _result(shard, metas, timing, done, 0.0)
        result["encoder"] = store.encoder_name()
        if _IN_WORKER:
            result["device"] = os.environ.get(_devices.CUDA_ENV) or None
        return result

    with ThreadPoolExecutor(1, thread_name_prefix="virtus-shard-writer") as writer:
        pending = None
        for number, shard in enumerate(shards):
            buffers = _shard_buffers(store, number % 2 if overlap else 0)
            filled = _fill_shard(store, randomiser, shard, num_samples, buffers, on_sample)
            if pending is not None:  # before another write: shards are written in order
                results.append(pending.result())
            if not overlap:
                results.append(write(shard, buffers, *filled))
                continue
            pending = writer.submit(write, shard, buffers, *filled)
        if pending is not None:
            results.append(pending.result())
    return results


def _result(
    shard: int,
    metas: list[dict[str, Any]],
    timing: dict[str, float],
    write: dict[str, float],
    wait: float,
) -> dict[str, Any]:
    """A shard task's result: its stage seconds (:data:`TIMING_KEYS`)."""
    stages = {
        **timing,
        "checksum": write["checksum"],
        "compression": write["compression"],
        "io": write["io"],
        "write": write["wall"],
        "write_wait": wait,
    }
    return {"shard": shard, "samples": len(metas), "timing_s": stages, "device": None}


def _write_labelled(
    store: DatasetStore,
    shard: int,
    buffer: dict[str, np.ndarray],
    metas: list[dict[str, Any]],
    labelled: list[Any],
) -> tuple[dict[str, float], float]:
    """Write a shard once all its samples are labelled and encoded (a failed sample fails
    the write: nothing is written). Returns the write's timing and the labelling seconds."""
    done = [future.result() for future in labelled]
    write = store.write_shard(shard, buffer, metas, [encoded for _, encoded in done])
    return write, sum(seconds for seconds, _ in done)


def _run_pipelined(
    path: Path, shards: list[int], num: int, digest: str, tick: Callable
) -> Iterator[dict[str, Any]]:
    """Shards in this process as a pipeline: this thread renders; each rendered sample is
    labelled into a shard buffer, checksummed and compressed on one of
    :data:`_SAMPLE_THREADS` threads; one more thread writes each shard once its samples are
    done. So the work behind the renderer is spread over the samples, not the end of each
    shard; it is numpy, the compressors and file I/O, mostly outside the GIL.

    Two shard buffers alternate: a shard's buffer is reused only after the write of the
    shard two before it has finished. At most :data:`_LABEL_QUEUE` rendered samples wait
    for their labels (bounded memory). Shards are written in order by one thread, each
    record after its data, so an interrupted run leaves what the sequential order would.
    """
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    store, randomiser = _open(path, digest)
    threads = _synthesis_threads(randomiser)
    on_device = _labels_on_device()
    buffers: list[_Buffers] = []
    writes: deque[tuple[Any, int, list[dict[str, Any]], dict[str, float]]] = deque()
    queue: deque[Any] = deque()  # sample futures not yet known to be done
    waited = 0.0

    def finish() -> dict[str, Any]:
        nonlocal waited
        future, shard, metas, timing = writes.popleft()
        begin = time.perf_counter()
        write, labels = future.result()
        wait, waited = waited + time.perf_counter() - begin, 0.0
        labels += timing.pop("labels", 0.0)  # labelled on the device, while rendering
        out = _result(shard, metas, {**timing, "labels": labels}, write, wait)
        return {**out, "encoder": store.encoder_name()}

    with (
        ThreadPoolExecutor(_SAMPLE_THREADS, thread_name_prefix="virtus-labels") as labeller,
        ThreadPoolExecutor(1, thread_name_prefix="virtus-shard-writer") as writer,
    ):
        for number, shard in enumerate(shards):
            if len(buffers) < 2:
                buffers.append(_new_shard_buffers(store))
            pair = buffers[number % 2]
            buffer = pair[0]
            while len(writes) >= 2:  # the shard that last used this buffer is written first
                yield finish()
            start, stop = store.shard_bounds(shard, num)
            timing = {"render": 0.0, "labels": 0.0}
            metas, labelled = [], []
            for slot, index in enumerate(range(start, stop)):
                if on_device:
                    meta, seconds, labels = _render_and_label(
                        store, randomiser, index, threads, pair, slot, True
                    )
                    timing["labels"] += labels
                    job = labeller.submit(_encode, store, pair, slot)
                else:
                    spec, capture, seconds = _render(randomiser, index, threads)
                    meta = sample_meta(spec, capture.render)
                    job = labeller.submit(_label_and_encode, store, spec, capture, buffer, slot)
                    del spec, capture  # held by the job only
                timing["render"] += seconds
                metas.append(meta)
                labelled.append(job)
                queue.append(job)
                tick(1)
                begin = time.perf_counter()
                while len(queue) > _LABEL_QUEUE:
                    queue.popleft().result()
                waited += time.perf_counter() - begin
                while writes and writes[0][0].done():
                    yield finish()
            job = writer.submit(_write_labelled, store, shard, buffer, metas, labelled)
            writes.append((job, shard, metas, timing))
        while writes:
            yield finish()


def _worker_init(threads: int, die_with_parent: bool = True) -> None:
    """In a worker process (after :func:`virtus.data.devices.pinned_pool` pinned it to its
    GPU, or in a Ray actor): use ``threads`` CPU threads to synthesise, checksum and
    compress; keep one shard buffer from task to task; with ``die_with_parent`` die with
    the parent (Linux), so a killed ``generate`` leaves no orphan writing into the store."""
    global _IN_WORKER, _WORKER_THREADS
    _IN_WORKER = True
    _WORKER_THREADS = threads
    # More compression threads than the worker's share of the cores only add memory in flight.
    _store_module.limit_write_threads(threads)
    if not die_with_parent:
        return
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _run_local(
    path: Path, shards: list[int], num: int, digest: str, placement: Placement,
    tick: Callable, pipelined: bool,
) -> Iterator[dict[str, Any]]:  # fmt: skip
    """The shards in this process (one worker) or in ``placement.workers`` spawned
    processes, each pinned to its GPU (:func:`virtus.data.devices.pinned_pool`). A worker's
    task is a few consecutive shards (:func:`_next_task`), written while the next renders
    when two shards fit in memory (``pipelined``, :func:`render_shards`); at most two tasks
    a worker are queued."""
    workers = placement.workers
    if workers == 1 and pipelined:
        yield from _run_pipelined(path, shards, num, digest, tick)
        return
    if workers == 1:
        for shard in shards:
            yield render_shard(path, shard, num, digest, on_sample=lambda: tick(1))
        return
    from collections import deque
    from concurrent.futures import FIRST_COMPLETED, wait

    queue = deque(shards)

    def submit() -> Any:
        task = _next_task(queue, workers)
        return pool.submit(render_shards, str(path), task, num, digest, overlap=pipelined)

    pool = _devices.pinned_pool(workers, placement.devices, _worker_init, (placement.threads,))
    with pool:
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
            ray, render_shard, args, shards, slots[0], slots[1], _worker_init, (threads, False)
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
        todo = store.missing_shards(target)
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
        records = store.records()
        complete = sum(int(m["index"]) < target for r in records.values() for m in r["samples"])
        if storage == "zarr":  # every encoder a record names (a killed run's too)
            named = {r.get("encoder") for r in records.values()}
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
