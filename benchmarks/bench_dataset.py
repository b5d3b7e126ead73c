"""Dataset generation speed: images written per second into a Zarr store, split by stage.

Generates ``--samples`` samples of a training configuration on the paper's rig (960 x 960
camera, the paper's 52-frame sequence, 1 spp, ideal sensor and projector, one sphere or box
before a plane) with :func:`virtus.data.generate`, once per ``--workers`` value (e.g.
``--workers 1 2``), and reports in one run:

* images/s written (frames of all samples / wall time of the generation), samples/s, the
  bytes on disk, the CPU seconds a sample (this process and its workers: on a GPU host the
  cores, not the GPU, bound the rate), and the load average before and after each
  generation;
* the per-stage split (:data:`virtus.data.shardtask.TIMING_KEYS`), seconds summed over the
  samples: render (trace + synthesis of every frame), labels (ground truth -> phase, order,
  numerator/denominator, modulation, masks, object ids), checksum (SHA-256 of every stored
  byte), compression (chunk encoding), io (shard files and records), write_wait (rendering
  held up by the work behind it). With one worker, each rendered sample is labelled,
  checksummed and compressed on one of two threads while the next one renders, and a third
  thread writes the shard files: the stages overlap, so they sum to more than the wall
  time, and each runs slower than alone (two cores shared);
* for context, the renderer alone on the same scenes (``Scanner.capture``, frames/s): the
  ceiling a dataset run can reach on this machine;
* with ``--codecs``, every codec and level on one stored sample: compression seconds on one
  thread and compressed bytes (speed against size); then ``zstd`` and ``shuffle-zstd`` in
  the GPU layout (:mod:`virtus.data.chunkcodecs`: pieces of 64 KiB, 256 KiB, 1 MiB, one
  zstd frame each) by the numcodecs twin on one thread and, where nvCOMP and a GPU are
  here, by nvCOMP (every piece of the sample in one batch, copies to and from the device
  included), and every algorithm of nvCOMP on the same sample (:func:`nvcomp_rows`: speed,
  size, and whether plain Zarr could read it);
* with ``--compress-on cpu gpu`` (codec ``zstd`` or ``shuffle-zstd``): the same store made
  once per setting, side by side -- images/s (over the run and in its steady part), the
  call's wall time and how long it took to return after the last shard's result, CPU
  seconds a sample and its split (render, labels, checksum, compression, io), compressed MB
  a sample, who encoded, and whether the arrays are the same (every sample's checksum equal
  to the first run's);
  with ``--gpus 1`` on a GPU host, else with the first ``--workers``; with
  ``--disk-ceiling``, then the last store's files alone, written by as many processes as
  it had workers, each file handed to the disk as written (as the store does) and then
  left to the page cache (:func:`disk_ceiling`: until the writes return, and until they
  are on the disk) -- what the disk allows any generator;
* with ``--gpus 1,2,4``: the same store made on 1, 2, 4 GPUs (``--workers-per-gpu`` pinned
  workers each, default 3/4 of the cores shared out over the most GPUs asked for), side by
  side: images/s over the whole run and in its steady state (between 10 % and 90 % of the
  samples: worker start-up and the last stragglers left out), CPU seconds a sample, the
  scaling against linear (steady images/s per GPU over the first count's), and whether the
  store is byte for byte the first count's. Without GPUs, ``--fake-gpus N`` makes ``N``
  fake ones visible (``VIRTUS_FAKE_GPUS``: the workers render on the CPU) -- a smoke check
  of the code path, not a measurement; ``--tiny`` uses a 64 x 48 camera and 22 frames.

    PYTHONPATH=src python benchmarks/bench_dataset.py [--samples 8] [--workers 1 2] [--codecs]
        [--json out.json]
    PYTHONPATH=src python benchmarks/bench_dataset.py --gpus 1,2,4 --samples 480
    PYTHONPATH=src python benchmarks/bench_dataset.py --gpus 1,2 --fake-gpus 2 --tiny --samples 16
    PYTHONPATH=src python benchmarks/bench_dataset.py --codec shuffle-zstd --compress-on cpu gpu \
        --gpus 1 --workers-per-gpu 8 --samples 480 --shard 8 --codecs
    PYTHONPATH=src python benchmarks/bench_dataset.py --codec shuffle-zstd --compress-on gpu \
        --gpus 1 --workers-per-gpu 8 --samples 720 --shard 4 --no-renderer --disk-ceiling

Stores are made in a temporary folder under ``$TMPDIR`` (``TMPDIR=/dev/shm`` makes them
in memory, taking the disk out of the measurement).

The process and its workers run with glibc's malloc as the ``virtus`` command sets it
(:mod:`virtus.allocator`); ``--malloc default`` keeps glibc's defaults.

Not a test: numbers depend on the machine and its load (quote them with the load average;
on a shared machine compare old and new code back to back).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from virtus.data import DatasetStore, generate, load_config
from virtus.data.chunkcodecs import COMPRESS_ON, GPU_CODECS, quiet_numcodecs
from virtus.data.config import CODECS
from virtus.data.sampling import Randomiser
from virtus.data.shards import ShardEncoder
from virtus.data.shardtask import TIMING_KEYS
from virtus.data.store import zarr_compressor


def config_file(
    folder: Path, samples: int, shard: int, codec: str, level: int, dtype: str, tiny: bool = False
) -> Path:
    data = {
        "mode": "training",
        "seed": 0,
        "num_samples": samples,
        "fringes": {"codings": ["gray"], "steps": [18], "periods": [18]},
        "objects": {
            "sources": [
                {"type": "sphere", "radius_m": [0.05, 0.1], "instances": 32},
                {"type": "box", "size_m": [0.05, 0.12], "instances": 32},
            ]
        },
        "planes": {"count": [1, 1]},
        "storage": {
            "shard_samples": shard,
            "codec": codec,
            "level": level,
            "label_dtype": dtype,
        },
    }
    if tiny:  # a 64 x 48 camera, the projector at a quarter of its size, 22 frames
        from virtus.geometry.devices import Camera, Projector, Rig, default_rig
        from virtus.geometry.optics import Intrinsics

        rig = default_rig()
        camera = Intrinsics(152.4, 152.4, 31.5, 23.5, 64, 48)
        small = Rig(Camera(camera), Projector(rig.projector.intrinsics.scaled(0.25)), rig.proj2cam)
        small.save_json(folder / "rig.json")
        data["rig"] = {"file": "rig.json"}
        data["fringes"] = {"codings": ["gray"], "steps": [4], "periods": [16]}
    path = folder / "bench.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def cpu_seconds() -> float:
    """CPU seconds (user + system) used so far by this process and its finished workers
    (once they have exited: :func:`virtus.data.generate.wait_for_workers`, which also keeps
    one run's exiting workers out of the next run's time): spawned workers are its
    children; forked ones are the fork server's (:func:`virtus.data.devices.pinned_pool`),
    counted with the server's own start-up through its ``/proc`` record (it reaps them)."""
    import resource

    from virtus.data.devices import worker_server_pid
    from virtus.data.generate import wait_for_workers

    wait_for_workers()
    total = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        usage = resource.getrusage(who)
        total += usage.ru_utime + usage.ru_stime
    server = worker_server_pid()
    if server is not None:
        try:
            stat = Path(f"/proc/{server}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return total
        # fields 14-17 of proc(5): utime, stime, cutime, cstime, counted from "state" (3)
        total += sum(int(v) for v in stat[11:15]) / os.sysconf("SC_CLK_TCK")
    return total


def load() -> float:
    """The 1-minute load average."""
    return round(os.getloadavg()[0], 2)


def renderer_only(config, folder: Path, samples: int) -> float:
    """Frames/s of ``Scanner.capture`` alone on the benchmark's samples (after a warm-up
    capture: the first kernel compilation)."""
    randomiser = Randomiser(config, folder / "assets")
    spec = randomiser.sample(0)
    spec.scanner.capture(spec.scene, rng=spec.capture_seed).frames  # noqa: B018
    start = time.perf_counter()
    frames = 0
    for index in range(samples):
        spec = randomiser.sample(index)
        capture = spec.scanner.capture(spec.scene, cam2world=spec.cam2world, rng=spec.capture_seed)
        frames += len(capture.frames)
    return frames / (time.perf_counter() - start)


def codec_table(store: DatasetStore) -> list[dict]:
    """Every codec and level on sample 0's arrays (one thread, as the store encodes one
    chunk per thread): seconds and bytes."""
    import zarr

    sample = store.read_sample(0)
    raw = sum(a.nbytes for a in sample.values())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        group = zarr.open_group(tmp, mode="w")
        for codec in CODECS:
            for level in (1, 3, 5) if codec != "none" else (0,):
                seconds, size = 0.0, 0
                for spec in store.layout:
                    with quiet_numcodecs():  # shuffle-zstd's numcodecs.shuffle
                        array = group.create_array(
                            f"{codec}_{level}_{spec.name}", shape=(1, *spec.shape),
                            chunks=(1, *spec.shape), shards=(1, *spec.shape), dtype=spec.dtype,
                            fill_value=spec.fill,
                            compressors=zarr_compressor(
                                codec, level, spec.name, np.dtype(spec.dtype).itemsize
                            ),
                        )  # fmt: skip
                    encoder = ShardEncoder.for_array(array, Path(tmp) / array.name)
                    start = time.perf_counter()
                    data = encoder.encode(sample[spec.name])
                    seconds += time.perf_counter() - start
                    size += 0 if data is None else len(data)
                rows.append(
                    {
                        "codec": codec,
                        "level": level,
                        "seconds_per_sample": round(seconds, 3),
                        "mb_per_s": round(raw / seconds / 1e6, 1) if seconds else None,
                        "bytes_per_sample": size,
                        "ratio": round(raw / size, 2),
                    }
                )
    return rows


def frames_rows(sample: dict, repeats: int = 3) -> list[dict]:
    """``zstd`` and ``shuffle-zstd`` of one sample's arrays in the GPU layout (each chunk cut
    into pieces of 64 KiB -- the default, :data:`virtus.data.chunkcodecs.PIECE_BYTES` --,
    256 KiB or 1 MiB, one zstd frame each): by the numcodecs twin on one CPU thread, and
    where nvCOMP and a GPU are here by nvCOMP (one batch of every piece, host copies
    included). The best of ``repeats`` after a warm-up."""
    from virtus.data.chunkcodecs import CpuZstdFrames, NvcompZstdFrames
    from virtus.errors import VirtusError

    raw = sum(a.nbytes for a in sample.values())
    chunks = [a.reshape(-1).view("u1") for a in sample.values()]
    makers = [("CPU", CpuZstdFrames), ("GPU", NvcompZstdFrames)]
    rows = []
    for where, make in makers:
        for piece_kib in (64, 256, 1024):
            try:
                compressor = make(piece_bytes=piece_kib << 10)
            except VirtusError as error:
                print(f"no GPU codec rows: {error}", file=sys.stderr)
                return rows
            for codec in GPU_CODECS:
                sizes = [
                    a.dtype.itemsize if codec == "shuffle-zstd" else 1 for a in sample.values()
                ]
                compressor.encode_chunks(chunks, sizes)  # warm-up: allocations, kernels
                best, size = float("inf"), 0
                for _ in range(repeats):
                    start = time.perf_counter()
                    size = sum(len(c) for c in compressor.encode_chunks(chunks, sizes))
                    best = min(best, time.perf_counter() - start)
                rows.append(
                    {
                        "codec": f"{codec} {where} {piece_kib}K",
                        "level": 1 if where == "CPU" else 0, "encoder": compressor.name,
                        "device_shuffle": getattr(compressor, "_torch", None) is not None,
                        "seconds_per_sample": round(best, 4),
                        "mb_per_s": round(raw / best / 1e6, 1),
                        "bytes_per_sample": size, "ratio": round(raw / size, 2),
                    }
                )  # fmt: skip
    return rows


#: nvCOMP's algorithms surveyed by :func:`nvcomp_rows`, and what a CPU reader needs for
#: their RAW output: Zstd frames are read by plain Zarr (the ``zstd`` codec); LZ4 blocks
#: could be wrapped into Blosc frames; Deflate would need a gzip/zlib wrapper with a CRC;
#: the others are nvCOMP's own formats.
NVCOMP_ALGORITHMS = {
    "Zstd": "plain zarr (zstd)", "LZ4": "as blosc-lz4 blocks", "Snappy": "no",
    "Deflate": "with a wrapper", "GDeflate": "no", "Bitcomp": "no", "ANS": "no",
    "Cascaded": "no",
}  # fmt: skip


def nvcomp_rows(sample: dict, repeats: int = 3) -> list[dict]:
    """Every nvCOMP algorithm of :data:`NVCOMP_ALGORITHMS` on one sample's arrays (each
    byte-shuffled by its element size, as ``shuffle-zstd`` stages them, and cut into pieces
    of 32 KiB to 256 KiB, all pieces in one batch on the device); then Zstd and LZ4 on 4
    copies of the sample in one batch. Per row, seconds a sample: the encode (frames written
    into slots of one device buffer, waited for: the kernel), bringing the frames back as
    :class:`~virtus.data.chunkcodecs.NvcompZstdFrames` does (one copy of the slots' buffer
    into a kept page-locked host buffer, :mod:`virtus.data.hostcopy`) and as nvCOMP's
    ``.cpu()`` does (each frame into new host memory); bytes, ratio, and whether plain Zarr
    could read the result. The best of ``repeats`` after a warm-up (the upload is not
    timed). Empty without nvCOMP or a GPU."""
    from virtus.data.chunkcodecs import STAGING_ALIGN, import_nvcomp, shuffle_bytes
    from virtus.data.hostcopy import host_copier
    from virtus.errors import VirtusError

    try:
        nvcomp = import_nvcomp()
    except VirtusError as error:
        print(f"no nvCOMP survey: {error}", file=sys.stderr)
        return []
    raw = sum(a.nbytes for a in sample.values())
    staged = [shuffle_bytes(a.reshape(-1).view("u1"), a.dtype.itemsize) for a in sample.values()]
    one = np.concatenate(staged)
    starts = np.cumsum([0] + [a.size for a in staged])[:-1]
    configs = [(1, piece, tuple(NVCOMP_ALGORITHMS)) for piece in (1 << 15, 1 << 16, 1 << 18)]
    configs += [(4, piece, ("Zstd", "LZ4")) for piece in (1 << 16, 1 << 17)]
    rows = []
    for copies, piece, algorithms in configs:
        bounds = [
            (int(k * one.size + start + a), min(piece, chunk.size - a))
            for k in range(copies)
            for start, chunk in zip(starts, staged, strict=True)
            for a in range(0, chunk.size, piece)
        ]
        lengths = [n for _, n in bounds]
        try:
            device = nvcomp.as_array(np.tile(one, copies)).cuda()
        except Exception as error:  # no usable CUDA device
            print(f"no nvCOMP survey: {error}", file=sys.stderr)
            return rows
        batch = nvcomp.as_arrays(device, [o for o, _ in bounds], lengths)
        for algorithm in algorithms:
            codec = nvcomp.Codec(
                algorithm=algorithm, bitstream_kind=nvcomp.BitstreamKind.RAW,
                uncomp_chunk_size=piece,
            )  # fmt: skip
            slot = -(-codec.get_max_comp_buffer_size(batch[0]) // STAGING_ALIGN) * STAGING_ALIGN
            target = nvcomp.as_array(np.empty(slot * len(bounds), np.uint8)).cuda()
            slots = nvcomp.as_arrays(target, [k * slot for k in range(len(bounds))],
                                     [slot] * len(bounds))  # fmt: skip
            config = codec.compression_config(lengths)
            copier = None
            times: dict[str, float] = {"kernel": np.inf, "copy": np.inf, "nvcomp_copy": np.inf}
            for attempt in range(repeats + 1):  # the first is the warm-up
                start = time.perf_counter()
                encoded = codec.encode(batch, out=slots, compression_config=config)
                sizes = encoded.buffer_sizes  # waits for the kernel
                middle = time.perf_counter()
                copier = copier or host_copier()
                if copier is not None:
                    copier.copy(target, slot * (len(sizes) - 1) + sizes[-1])
                end = time.perf_counter()
                encoded.cpu()
                last = time.perf_counter()
                if attempt:
                    times["kernel"] = min(times["kernel"], (middle - start) / copies)
                    times["copy"] = min(times["copy"], (end - middle) / copies)
                    times["nvcomp_copy"] = min(times["nvcomp_copy"], (last - end) / copies)
            size = sum(sizes) // copies
            label = f"nvCOMP {algorithm} {piece >> 10}K" + (f" x{copies}" if copies > 1 else "")
            rows.append(
                {
                    "codec": label, "level": 0, "encoder": f"nvcomp {nvcomp.__version__}",
                    "plain_zarr": NVCOMP_ALGORITHMS[algorithm],
                    "kernel_s": round(times["kernel"], 4),
                    "kernel_gb_per_s": round(raw / times["kernel"] / 1e9, 2),
                    "copy_back_s": round(times["copy"], 4) if copier else None,
                    "nvcomp_copy_back_s": round(times["nvcomp_copy"], 4),
                    "seconds_per_sample": round(times["kernel"] + (times["copy"] if copier
                                                                   else times["nvcomp_copy"]), 4),
                    "bytes_per_sample": size, "ratio": round(raw / size, 2),
                }
            )  # fmt: skip
            rows[-1]["mb_per_s"] = round(raw / rows[-1]["seconds_per_sample"] / 1e6, 1)
            del slots, target
        del batch, device
    return rows


def compression_runs(config, folder: Path, args, per_gpu: int | None, frames: int) -> list[dict]:
    """The store made once per ``--compress-on`` value (module docstring), after a one-shard
    warm-up on the GPU path; the arrays compared through the records' checksums."""
    import dataclasses
    import shutil

    where = {"gpus": args.gpus[0], "workers_per_gpu": per_gpu} if args.gpus else {
        "workers": args.workers[0]}  # fmt: skip
    warm = dataclasses.replace(config, num_samples=config.shard_samples, compress_on="auto")
    generate(warm, folder / "warm-up", **where)
    shutil.rmtree(folder / "warm-up")
    runs, first = [], None
    for value in args.compress_on:
        path = folder / f"store_{value}"
        ticks: list[tuple[float, int]] = []

        def progress(done: int, total: int, rendered: int, ticks=ticks) -> None:
            ticks.append((time.perf_counter(), rendered))

        before = cpu_seconds()
        called = time.perf_counter()
        report = generate(
            dataclasses.replace(config, compress_on=value), path, progress=progress, **where
        )
        returned = time.perf_counter()
        cpu = cpu_seconds() - before
        steady = steady_rate(ticks, args.samples)
        store = DatasetStore.open(path)
        checksums = {i: m["checksum"] for i, m in store.samples().items()}
        first = checksums if first is None else first
        stages = {k: round(report.timing_s.get(k, 0.0) / args.samples, 4) for k in TIMING_KEYS}
        size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
        arrays = {a.name: stored_bytes(path / a.name) / args.samples for a in store.layout}
        runs.append(
            {
                "compress_on": value, **where, "encoders": report.encoders,
                "note": report.compression_note, "seconds": round(report.seconds, 3),
                "call_s": round(returned - called, 3),
                "end_s": round(returned - ticks[-1][0], 3),
                "images_per_s": round(args.samples * frames / report.seconds, 1),
                "steady_images_per_s": steady and round(steady * frames, 1),
                "cpu_s_per_sample": round(cpu / args.samples, 4),
                "stage_s_per_sample": stages, "mb_per_sample": round(size / args.samples / 1e6, 2),
                "array_bytes_per_sample": {k: round(v) for k, v in arrays.items()},
                "same_arrays_as_first": checksums == first,
            }
        )  # fmt: skip
        print(compression_line(runs[-1]), file=sys.stderr, flush=True)
        shutil.rmtree(path)
    return runs


def stored_bytes(folder: Path) -> int:
    """Bytes of every file under ``folder``."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def _write_shards(root: str, shards: list[int], sizes: list[int], seed: int,
                  writeback: bool) -> None:  # fmt: skip
    """One writer of :func:`disk_ceiling`: each shard's file of each array (``sizes``
    bytes), written under a temporary name and renamed, as the store's shard writer does;
    with ``writeback``, each file handed to the disk once written, as the store does
    (:func:`virtus.data.shards.start_writeback`), else left to the page cache."""
    from virtus.data.shards import start_writeback

    data = np.random.default_rng(seed).integers(0, 256, max(sizes), np.uint8).tobytes()
    for shard in shards:
        for array, size in enumerate(sizes):
            folder = Path(root) / f"a{array}"
            folder.mkdir(parents=True, exist_ok=True)
            temporary = folder / f".{shard}.tmp"
            with open(temporary, "wb") as handle:
                handle.write(memoryview(data)[:size])
                if writeback:
                    start_writeback(handle)
            os.replace(temporary, folder / str(shard))


def disk_ceiling(folder: Path, array_bytes: dict, samples: int, shard: int, writers: int,
                 frames: int, writeback: bool = True) -> dict:  # fmt: skip
    """What the disk alone allows a run: ``writers`` processes write the files that
    ``samples`` samples make (each array's shard files, ``array_bytes`` a sample, random
    bytes; each handed to the disk once written, as the store does, with ``writeback``),
    and nothing else; then ``os.sync()``. Seconds until the writes return and until they
    are on the disk, as GB/s and the images/s they allow."""
    import shutil
    from concurrent.futures import ProcessPoolExecutor

    shards = list(range(-(-samples // shard)))
    sizes = [max(1, round(b * shard)) for b in array_bytes.values()]
    root = folder / "disk-ceiling"
    begin = time.perf_counter()
    with ProcessPoolExecutor(writers) as pool:
        jobs = [pool.submit(_write_shards, str(root), shards[k::writers], sizes, k, writeback)
                for k in range(writers)]  # fmt: skip
        for job in jobs:
            job.result()
    written = time.perf_counter() - begin
    os.sync()
    synced = time.perf_counter() - begin
    total = len(shards) * sum(sizes)
    shutil.rmtree(root)
    return {
        "writers": writers, "writeback": writeback, "gb": round(total / 1e9, 2),
        "written_s": round(written, 2), "written_gb_per_s": round(total / written / 1e9, 2),
        "written_images_per_s": round(len(shards) * shard * frames / written, 1),
        "synced_s": round(synced, 2), "synced_gb_per_s": round(total / synced / 1e9, 2),
        "synced_images_per_s": round(len(shards) * shard * frames / synced, 1),
    }  # fmt: skip


def disk_line(entry: dict) -> str:
    return (
        f"disk alone ({entry['writers']} writers, {entry['gb']} GB of the run's files, "
        f"{'handed to the disk as written' if entry['writeback'] else 'left to the page cache'}): "
        f"written in {entry['written_s']} s ({entry['written_gb_per_s']} GB/s, "
        f"{entry['written_images_per_s']} images/s), on the disk after {entry['synced_s']} s "
        f"({entry['synced_gb_per_s']} GB/s, {entry['synced_images_per_s']} images/s)"
    )


def compression_line(entry: dict) -> str:
    stages = entry["stage_s_per_sample"]
    split = ", ".join(f"{k} {stages[k]:.3f}" for k in TIMING_KEYS if k != "write")
    return (
        f"compress_on {entry['compress_on']} ({', '.join(entry['encoders'])}): "
        f"{entry['images_per_s']:.1f} images/s ({entry.get('steady_images_per_s')} in the "
        f"steady part; the call {entry['call_s']} s, returning {entry['end_s']} s after the "
        f"last shard's result), {entry['cpu_s_per_sample']:.3f} CPU-s a sample "
        f"(stage s a sample: {split}), {entry['mb_per_sample']:.1f} MB a sample, same arrays "
        f"as the first: {entry['same_arrays_as_first']}"
    )


def run(config, folder: Path, samples: int, workers: int, frames_per_sample: int) -> dict:
    """One generation into a new store: rate, stage seconds, bytes."""
    store_path = folder / f"store_w{workers}"
    load_before = load()
    cpu_before = cpu_seconds()
    report = generate(config, store_path, workers=workers)
    cpu = cpu_seconds() - cpu_before
    load_after = load()
    store = DatasetStore.open(store_path)
    stages = {key: round(report.timing_s.get(key, 0.0), 3) for key in TIMING_KEYS}
    return {
        "workers": workers,
        "load_average_before": load_before,
        "load_average_after": load_after,
        "images_per_s": round(samples * frames_per_sample / report.seconds, 2),
        "samples_per_s": round(samples / report.seconds, 3),
        "seconds": round(report.seconds, 3),
        "cpu_s_per_sample": round(cpu / samples, 3),
        "stage_s": stages,
        "stage_s_per_sample": {k: round(v / samples, 3) for k, v in stages.items()},
        "bytes_raw": samples * sum(a.nbytes for a in store.layout),
        "bytes_on_disk": sum(p.stat().st_size for p in store_path.rglob("*") if p.is_file()),
    }


def store_digests(path: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file of a store (the lock file aside), hashed on a
    few threads (hashlib releases the GIL)."""
    import hashlib
    from concurrent.futures import ThreadPoolExecutor

    files = [p for p in sorted(path.rglob("*")) if p.is_file() and p.name != ".virtus.lock"]

    def digest(file: Path) -> str:
        with file.open("rb") as handle:
            return hashlib.file_digest(handle, "sha256").hexdigest()

    with ThreadPoolExecutor(8) as pool:
        names = [p.relative_to(path).as_posix() for p in files]
        return dict(zip(names, pool.map(digest, files), strict=True))


def steady_rate(ticks: list[tuple[float, int]], samples: int) -> float | None:
    """Samples/s between the progress ticks at 10 % and 90 % of ``samples`` (None when the
    run had too few ticks between them)."""
    low = next((t for t in ticks if t[1] >= 0.1 * samples), None)
    high = next((t for t in ticks if t[1] >= 0.9 * samples), None)
    if low is None or high is None or high[0] <= low[0] or high[1] <= low[1]:
        return None
    return (high[1] - low[1]) / (high[0] - low[0])


def gpu_run(config, folder: Path, samples: int, gpus: int, per_gpu: int, frames: int) -> dict:
    """One generation of the store on ``gpus`` GPUs, ``per_gpu`` pinned workers each."""
    store_path = folder / f"store_g{gpus}"
    ticks: list[tuple[float, int]] = []

    def progress(done: int, total: int, rendered: int) -> None:
        ticks.append((time.perf_counter(), rendered))

    load_before, cpu_before = load(), cpu_seconds()
    report = generate(config, store_path, gpus=gpus, workers_per_gpu=per_gpu, progress=progress)
    cpu = cpu_seconds() - cpu_before
    steady = steady_rate(ticks, samples)
    per_device: dict[str, int] = {}
    for device in report.shard_devices.values():
        per_device[str(device)] = per_device.get(str(device), 0) + 1
    return {
        "gpus": gpus,
        "workers": gpus * per_gpu,
        "load_average_before": load_before,
        "load_average_after": load(),
        "seconds": round(report.seconds, 3),
        "images_per_s": round(samples * frames / report.seconds, 2),
        "steady_images_per_s": None if steady is None else round(steady * frames, 2),
        "cpu_s_per_sample": round(cpu / samples, 3),
        "shards_per_device": per_device,
        "bytes_on_disk": sum(p.stat().st_size for p in store_path.rglob("*") if p.is_file()),
    }


def gpu_scaling(config, folder: Path, samples: int, counts: list[int], per_gpu: int,
                frames: int, keep_first: bool) -> list[dict]:  # fmt: skip
    """:func:`gpu_run` per GPU count, after a one-shard warm-up (kernel caches); each store
    is compared with the first count's (SHA-256 of every file), then deleted (at 960 x 960 a
    sample takes ~35 MB on disk): only the first is kept, with ``keep_first``."""
    import shutil

    warm = config.with_num_samples(config.shard_samples)
    generate(warm, folder / "warm-up", gpus=1, workers_per_gpu=1)
    shutil.rmtree(folder / "warm-up")
    runs, first = [], None
    for count in counts:
        entry = gpu_run(config, folder, samples, count, per_gpu, frames)
        digests = store_digests(folder / f"store_g{count}")
        if first is None:
            first = digests
        if not (keep_first and len(runs) == 0):
            shutil.rmtree(folder / f"store_g{count}")
        entry["store_identical_to_first"] = digests == first
        rate, base = entry["steady_images_per_s"], runs[0] if runs else entry
        if rate is not None and base["steady_images_per_s"]:
            linear = base["steady_images_per_s"] * count / base["gpus"]
            entry["scaling_vs_linear"] = round(rate / linear, 3)
        else:
            entry["scaling_vs_linear"] = None
        runs.append(entry)
        print(gpu_line(entry), file=sys.stderr, flush=True)
    return runs


def gpu_line(entry: dict) -> str:
    steady = entry["steady_images_per_s"]
    return (
        f"gpus {entry['gpus']} ({entry['workers']} workers): {entry['images_per_s']:.1f} "
        f"images/s, steady {steady if steady is not None else '-'}; "
        f"{entry['cpu_s_per_sample']:.2f} CPU-s a sample; scaling "
        f"{entry['scaling_vs_linear'] if entry['scaling_vs_linear'] is not None else '-'} x "
        f"linear; store identical: {entry['store_identical_to_first']}; "
        f"{entry['seconds']:.1f} s, load {entry['load_average_before']} -> "
        f"{entry['load_average_after']}; shards per device {entry['shards_per_device']}"
    )


def summary(result: dict) -> str:
    lines = [
        f"{result['machine']}; {result['image_px']} px, {result['frames_per_sample']} frames a "
        f"sample, {result['samples']} samples, codec {result['codec']} level {result['level']}"
    ]
    if result["renderer_only_images_per_s"] is not None:
        lines.append(
            f"renderer alone: {result['renderer_only_images_per_s']:.1f} images/s "
            f"(load {result['renderer_load_average']})"
        )
    for entry in result.get("gpu_runs", []):
        lines.append(gpu_line(entry))
    for entry in result["runs"]:
        stages = entry["stage_s"]
        split = ", ".join(f"{k} {stages[k]:.2f}" for k in TIMING_KEYS if k != "write")
        lines.append(
            f"workers {entry['workers']}: {entry['images_per_s']:.1f} images/s "
            f"({entry['seconds']:.2f} s; load {entry['load_average_before']} -> "
            f"{entry['load_average_after']}; {entry['cpu_s_per_sample']:.2f} CPU-s a sample); "
            f"stage seconds: {split}; "
            f"{entry['bytes_on_disk'] / 1e6:.0f} MB on disk of {entry['bytes_raw'] / 1e6:.0f} MB"
        )
    for entry in result.get("compression_runs", []):
        lines.append(compression_line(entry))
    for row in result.get("codecs", []):
        lines.append(
            f"  codec {row['codec']:<10} level {row['level']}: {row['seconds_per_sample']:.3f} "
            f"s/sample ({row['mb_per_s']} MB/s), ratio {row['ratio']}"
            + (
                f" (kernel {row['kernel_s'] * 1e3:.1f} ms, {row['kernel_gb_per_s']} GB/s; copy "
                f"back {row['copy_back_s']} s, nvCOMP's .cpu() {row['nvcomp_copy_back_s']} s)"
                if "kernel_s" in row
                else ""
            )
        )
    return "\n".join(lines)


def gpu_counts(text: str) -> list[int]:
    """``--gpus``: a comma-separated list of positive GPU counts, e.g. ``1,2,4``."""
    try:
        counts = [int(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected GPU counts such as 1,2,4, got {text!r}"
        ) from None
    if not counts or min(counts) < 1 or len(counts) > 16:
        raise argparse.ArgumentTypeError(f"expected 1 to 16 positive GPU counts, got {text!r}")
    return counts


def gpu_setup(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """Check ``--gpus`` against the visible GPUs (after ``--fake-gpus``); the workers a GPU."""
    from virtus.data.devices import FAKE_GPUS_ENV, cpu_cores, visible_gpus

    if args.fake_gpus is not None:
        os.environ[FAKE_GPUS_ENV] = str(args.fake_gpus)
    visible = visible_gpus()
    if max(args.gpus) > len(visible):
        parser.error(
            f"--gpus {max(args.gpus)}: only {len(visible)} GPUs are visible here "
            "(--fake-gpus N for a CPU smoke check)"
        )
    return args.workers_per_gpu or max(1, cpu_cores() * 3 // 4 // max(args.gpus))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--shard", type=int, default=4, help="samples per shard")
    parser.add_argument("--codec", default="blosc-zstd", choices=list(CODECS))
    parser.add_argument("--level", type=int, default=1)
    parser.add_argument("--label-dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--workers", type=int, nargs="+", default=[1])
    parser.add_argument(
        "--gpus", type=gpu_counts, help="GPU counts to compare, e.g. 1,2,4 (replaces --workers)"
    )
    parser.add_argument(
        "--workers-per-gpu", type=int, help="pinned workers a GPU (default: 3/4 of the cores "
        "shared out over the largest GPU count)",
    )  # fmt: skip
    parser.add_argument("--fake-gpus", type=int, help="make N fake GPUs visible (CPU smoke)")
    parser.add_argument("--tiny", action="store_true", help="64 x 48 camera, 22 frames")
    parser.add_argument("--codecs", action="store_true", help="also compare codecs and levels")
    parser.add_argument("--no-renderer", action="store_true", help="skip the renderer alone")
    parser.add_argument(
        "--compress-on", nargs="+", choices=list(COMPRESS_ON),
        help="compare who compresses (codec zstd or shuffle-zstd), e.g. cpu gpu",
    )  # fmt: skip
    parser.add_argument(
        "--disk-ceiling", action="store_true",
        help="with --compress-on: also write the files of the last run's store, and nothing "
        "else, from as many processes as it had workers (what the disk alone allows)",
    )  # fmt: skip
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    parser.add_argument(
        "--malloc", choices=["virtus", "default"], default="virtus",
        help="glibc's malloc as the virtus command sets it (virtus.allocator), or its "
        "defaults, here and in the workers (default: virtus)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.malloc == "virtus":
        from virtus.allocator import keep_freed_memory

        keep_freed_memory()
    if args.compress_on and args.codec not in GPU_CODECS:
        parser.error(f"--compress-on compares codecs {' or '.join(GPU_CODECS)}, not {args.codec}")
    if args.disk_ceiling and not args.compress_on:
        parser.error("--disk-ceiling needs --compress-on (the store whose files it writes)")
    per_gpu = gpu_setup(parser, args) if args.gpus else None

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        config = load_config(
            config_file(
                folder, args.samples, args.shard, args.codec, args.level, args.label_dtype,
                args.tiny,
            )
        )  # fmt: skip
        sample = Randomiser(config, folder / "assets").sample(0)
        frames_per_sample = len(sample.scanner.sequence)
        cam = sample.scanner.rig.camera.intrinsics
        renderer_load = load()
        renderer, runs, gpu_runs, compression, disk = None, [], [], [], None
        if args.compress_on:
            compression = compression_runs(config, folder, args, per_gpu, frames_per_sample)
            if args.disk_ceiling:
                writers = per_gpu * args.gpus[0] if args.gpus else args.workers[0]
                disk = [
                    disk_ceiling(
                        folder, compression[-1]["array_bytes_per_sample"], args.samples,
                        args.shard, writers, frames_per_sample, writeback,
                    )
                    for writeback in (True, False)
                ]  # fmt: skip
                for entry in disk:
                    print(disk_line(entry), file=sys.stderr, flush=True)
            if args.codecs:  # one store to take the sample from
                generate(config.with_num_samples(1), folder / "store_w1", workers=1)
            first = folder / "store_w1"
        elif args.gpus:  # the renderer alone would hold a CUDA context in this process
            gpu_runs = gpu_scaling(
                config, folder, args.samples, args.gpus, per_gpu, frames_per_sample, args.codecs
            )
            first = folder / f"store_g{args.gpus[0]}"
        else:
            renderer = None if args.no_renderer else renderer_only(config, folder, args.samples)
            runs = [run(config, folder, args.samples, w, frames_per_sample) for w in args.workers]
            first = folder / f"store_w{args.workers[0]}"
        codecs = codec_table(DatasetStore.open(first)) if args.codecs else []
        if args.codecs:
            sample = DatasetStore.open(first).read_sample(0)
            codecs += frames_rows(sample) + nvcomp_rows(sample)
    result = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"{platform.system()}",
        "image_px": f"{cam.width}x{cam.height}",
        "frames_per_sample": frames_per_sample,
        "samples": args.samples,
        "shard_samples": args.shard,
        "codec": args.codec,
        "level": args.level,
        "label_dtype": args.label_dtype,
        "renderer_only_images_per_s": renderer and round(renderer, 1),
        "renderer_load_average": renderer_load,
        "runs": runs,
        "workers_per_gpu": per_gpu,
        "fake_gpus": args.fake_gpus,
        "gpu_runs": gpu_runs,
        "compression_runs": compression,
        "disk_ceiling": disk,
        "codecs": codecs,
        "paper_images_per_s": 3.1,
        "target_images_per_s": 150.0,
    }
    print(summary(result), file=sys.stderr)
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
