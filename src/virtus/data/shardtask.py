"""Rendering a dataset's shards: the work of one shard task, wherever it runs.

:func:`render_shard` (and :func:`render_shards`, a few in a row) renders a shard's samples
(:meth:`virtus.scanner.Scanner.capture`), makes their labels
(:func:`~virtus.data.labels.sample_arrays`) into a shard buffer, writes the shard and then
its record. On a GPU a sample is rendered and labelled where it is traced
(:meth:`~virtus.scanner.Scanner.render_on_device`,
:func:`~virtus.data.labels_jit.device_sample_arrays`) and copied once into the buffer, so
the host's cores only checksum, compress and write; when the GPU compresses too, the
compressor reads the device's copy (:mod:`virtus.data.devicebuffers`). A task depends only
on the store path and the shard numbers, so it is idempotent: a retried or repeated task
writes the same bytes. It runs in the calling process, in a worker process
(:func:`worker_init` sets it up: its share of the cores, buffers kept from task to task) or
in a Ray actor; :func:`run_pipelined` runs shards in one process as a pipeline (rendering,
labelling and writing side by side on three threads). :func:`virtus.data.generate.generate`
decides which and where.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data import devices as _devices
from virtus.data import store as _store_module
from virtus.data.config import DatasetConfig
from virtus.data.devicebuffers import (
    device_shard_buffer,
    page_locked_shard_buffer,
    staging_device,
)
from virtus.data.labels import sample_arrays
from virtus.data.sampling import Randomiser, SampleSpec
from virtus.data.store import ASSETS_DIR, DatasetStore, EncodedSample, slot_views
from virtus.errors import InputError

__all__ = [
    "LABELS_ON_DEVICE",
    "TIMING_KEYS",
    "render_shard",
    "render_shards",
    "run_pipelined",
    "sample_meta",
    "worker_init",
]

#: Images up to this many pixels are synthesised on one thread (thread start-up would
#: cost more than the work).
_SMALL_IMAGE_PIXELS = 128 * 128
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
#: Whether this process is a dataset worker (:func:`worker_init`).
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
    sample_arrays(capture, spec, store.layout, slot_views(buffer, slot))
    return time.perf_counter() - begin


def _label_and_encode(
    store: DatasetStore, spec: Any, capture: Any, buffer: dict[str, np.ndarray], slot: int
) -> tuple[float, EncodedSample]:
    """:func:`_label`, then the sample's checksum and chunks
    (:meth:`~virtus.data.store.DatasetStore.encode_sample`)."""
    seconds = _label(store, spec, capture, buffer, slot)
    return seconds, store.encode_sample(slot_views(buffer, slot))


def _encode(store: DatasetStore, buffers: _Buffers, slot: int) -> tuple[float, EncodedSample]:
    """:func:`_label_and_encode` of a sample labelled already (on the device; the
    compressor reads the device's copy where the buffers have one)."""
    host, device = buffers
    on_device = None if device is None else slot_views(device, slot)
    return 0.0, store.encode_sample(slot_views(host, slot), on_device)


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
    on = None if device is None else slot_views(device, slot)
    device_sample_arrays(rendering, spec, store.layout, slot_views(buffer, slot), on_device=on)
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
    from virtus.render.backend import on_gpu

    rendering_device = "cuda" if on_gpu() else "cpu"
    return staging_device(store.batch_compressor(), _labels_on_device(), rendering_device)


def _new_shard_buffers(store: DatasetStore) -> _Buffers:
    """A shard's host buffer and, where the compressor reads the device's copy
    (:func:`_staging_device`), its device buffer; the host buffer page-locked when that
    device is a GPU (:mod:`virtus.data.devicebuffers`). Where the GPU has no room for the
    device buffer, or the system will not lock that much host memory, the run goes on
    without (the compressor reads the host's copy; ordinary memory): the same bytes, made
    more slowly."""
    count, device = store.shard_samples, _staging_device(store)
    on_device = None
    if device is not None:
        try:
            on_device = device_shard_buffer(store.layout, count, device)
        except RuntimeError:  # torch's out-of-memory errors are RuntimeErrors
            on_device = None
    if on_device is None or device != "cuda":
        return store.shard_buffer(count), on_device
    try:
        return page_locked_shard_buffer(store.layout, count), on_device
    except RuntimeError:  # torch's pinned allocator: no lockable memory left
        return store.shard_buffer(count), on_device


def _shard_buffers(store: DatasetStore, which: int = 0) -> _Buffers:
    """Set ``which`` (0 or 1: a worker that writes one shard while it renders the next
    alternates two) of a shard's buffers (:func:`_new_shard_buffers`), kept from one task
    to the next in a worker process (fresh memory costs page faults, and on a virtual
    machine often more: the host may have taken freed pages back; page-locking costs more
    still), new in any other process (nothing is held after a run)."""
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
        pending = spare = None
        for number, shard in enumerate(shards):
            which = number % 2 if overlap else 0
            if which and spare is not None:
                spare.result()
            buffers = _shard_buffers(store, which)
            if overlap and number == 0 and len(shards) > 1 and _IN_WORKER:
                # The second set is made on the writer, idle while the first shard renders
                # (page-locking a set took 0.2-0.6 s of a GPU worker's start on an H100 host).
                spare = writer.submit(_shard_buffers, store, 1)
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


def run_pipelined(
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


def worker_init(threads: int, die_with_parent: bool = True) -> None:
    """In a worker process (after :func:`virtus.data.devices.pinned_pool` pinned it to its
    GPU, or in a Ray actor): use ``threads`` CPU threads to synthesise, checksum and
    compress; keep one shard buffer from task to task; with ``die_with_parent`` die with
    the process that made the pool (:func:`virtus.data.devices.die_with_pool_maker`), so
    a killed ``generate`` leaves no orphan writing into the store."""
    global _IN_WORKER, _WORKER_THREADS
    _IN_WORKER = True
    _WORKER_THREADS = threads
    # More compression threads than the worker's share of the cores only add memory in flight.
    _store_module.limit_write_threads(threads)
    if die_with_parent:
        _devices.die_with_pool_maker()
