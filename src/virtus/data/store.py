"""The dataset store: sharded arrays plus a manifest that is the only record of completeness.

Layout of a store directory ``STORE`` (format :data:`STORE_FORMAT`)::

    STORE/dataset.json              what the store holds: format, storage (zarr | png),
                                    the configuration (canonical), the identity (config
                                    without num_samples + input file digests + virtus
                                    version) and its digest, the array layout (names,
                                    per-sample shapes, dtypes, units, fills), units,
                                    num_samples (the latest requested), encoding (stored
                                    bytes' format, encoders: virtus.data.chunkcodecs)
    STORE/manifest/shard_000012.json  one record per finished shard, written atomically
                                    after the shard's data: format, dataset digest, shard,
                                    and per sample: index, split, group, seed, checksum,
                                    n_frames, rig, cam2world, scanner (sequence, sensor,
                                    projector, spp, bounces), render settings, objects,
                                    mode details; the encoder ("nvcomp 6.0.0.12")
    STORE/assets/                   generated meshes (free-form objects), STL, metres
    STORE/.virtus.lock              held by the generating process

    storage "zarr": STORE is a Zarr v3 group; one array per layout entry (see
    virtus.data.labels), shape (N, *per-sample shape), chunks of one sample,
    shards of ``shard_samples`` samples (the write unit):
    STORE/zarr.json, STORE/<name>/zarr.json, STORE/<name>/c/<shard>/0/...

    storage "png": STORE/samples/000123/frames/000.png ... (the sample's own n_frames
    frames, 8- or 16-bit PNG) and STORE/samples/000123/<name>.npy for every label.

**Completeness.** A sample exists when, and only when, the record of its shard lists it
and the record carries this store's dataset digest; a record that does not (copied from
another store, or beside an edited ``dataset.json``) is refused, named, by every reader
(:mod:`virtus.data.integrity`). A writer owns whole shards: it
renders all the shard's samples, writes each array's shard file at once (written beside
its place and renamed over it, :mod:`virtus.data.shards`; a PNG sample folder is renamed
into place), then writes the record. A process killed at any moment leaves either a
complete, recorded shard or one without a record, which the next run writes again with the
same bytes (samples are deterministic), so nothing is duplicated or half-written.

**Checksums.** Each sample's checksum (:func:`virtus.data.labels.sample_checksum`: a CRC-32C
per array) covers its arrays as stored; :meth:`DatasetStore.read_sample` checks it on every
read (:class:`~virtus.data.integrity.DamagedSample`), :meth:`DatasetStore.verify` reads
every sample back, compares, and names the arrays that differ.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus import __version__
from virtus.capture.capture import UNITS as CAPTURE_UNITS
from virtus.data import chunkcodecs as _codecs
from virtus.data.chunkcodecs import quiet_numcodecs, zarr_compressor
from virtus.data.integrity import (
    DamagedSample,
    VerifyReport,
    check_arrays,
    check_description,
    describe,
    record_problem,
)
from virtus.data.labels import CRC32C_PREFIX, ArraySpec, checksum_mismatches, sample_checksum
from virtus.data.shards import ShardEncoder
from virtus.errors import InputError, RunConflict
from virtus.io.runs import canonical, config_digest, first_difference, write_json_atomic
from virtus.io.safeio import read_json

__all__ = [
    "DESCRIPTION_FILE",
    "MANIFEST_DIR",
    "SHARD_FORMAT",
    "STORAGES",
    "STORE_FORMAT",
    "DamagedSample",
    "DatasetStore",
    "EncodedSample",
    "VerifyReport",
    "slot_views",
    "zarr_compressor",
]

#: Format tags of ``dataset.json`` and of a shard record.
STORE_FORMAT = "virtus.dataset/1"
SHARD_FORMAT = "virtus.dataset_shard/1"
#: Storage back-ends.
STORAGES = ("zarr", "png")
DESCRIPTION_FILE = "dataset.json"
MANIFEST_DIR = "manifest"
ASSETS_DIR = "assets"
SAMPLES_DIR = "samples"
#: Units recorded in ``dataset.json``: those of a capture.
UNITS = CAPTURE_UNITS
#: Largest shard record read (bytes): ~10 kB of metadata per sample, 1024 samples.
_MAX_RECORD_BYTES = 64 << 20
#: Threads that checksum and compress a shard while it is written (the work releases the
#: GIL; more threads than cores only add memory in flight).
_WRITE_THREADS = max(1, min(4, os.cpu_count() or 1))
#: Held while a store opens its Zarr arrays and shard encoders (once per process, possibly
#: from several pipeline threads); module-wide so that a store stays picklable.
_OPEN_LOCK = threading.Lock()
#: Files a store may hold besides its own (checked before a directory becomes a store).
_IGNORED = (".virtus.lock", ".virtus-tmp")


def limit_write_threads(threads: int) -> None:
    """Use at most ``threads`` checksum/compression threads in this process (a dataset
    worker's share of the cores; never more than the default)."""
    global _WRITE_THREADS
    _WRITE_THREADS = max(1, min(_WRITE_THREADS, threads))


def slot_views(buffer: dict[str, Any], slot: int) -> dict[str, Any]:
    """Sample ``slot``'s arrays in a shard buffer (:meth:`DatasetStore.shard_buffer`, or
    its device twin of torch tensors): name -> view, no copy."""
    return {name: block[slot] for name, block in buffer.items()}


def _timed(work: Callable[..., Any], *args: Any) -> tuple[Any, float]:
    """``(work(*args), seconds it took)``."""
    begin = time.perf_counter()
    value = work(*args)
    return value, time.perf_counter() - begin


@dataclass(frozen=True)
class _Done:
    """A value already computed, read like a :func:`_timed` future (no seconds: counted
    where it was made)."""

    value: Any

    def result(self) -> tuple[Any, float]:
        return self.value, 0.0


@dataclass(frozen=True)
class EncodedSample:
    """One sample ready to be written (:meth:`DatasetStore.encode_sample`).

    Attributes
    ----------
    checksum : :func:`virtus.data.labels.sample_checksum` of its arrays.
    chunks : array name -> its stored chunk (None: only the fill value), for the arrays
        written by :class:`~virtus.data.shards.ShardEncoder` (zarr storage).
    seconds : ``checksum`` and ``compression`` seconds it took.
    """

    checksum: str
    chunks: dict[str, Any]
    seconds: dict[str, float]


class DatasetStore:
    """A dataset store on disk (module docstring for the layout).

    Use :meth:`open` to read one and :meth:`prepare` (the generator) to create or extend
    one. Reading arrays opens them lazily, once per process.
    """

    def __init__(self, path: str | Path, description: dict[str, Any]) -> None:
        self.path = Path(path)
        self.description = description
        self.layout = tuple(ArraySpec.from_dict(a) for a in description["layout"])
        self.storage: str = description["storage"]
        self.shard_samples: int = int(description["config"]["storage"]["shard_samples"])
        self.digest: str = description["identity_digest"]
        self._arrays: dict[str, Any] = {}
        self._encoders: dict[str, ShardEncoder | None] = {}
        self._pid = self._encoders_pid = os.getpid()
        self._checksums: dict[int, Any] = {}  # sample -> recorded checksum (read_sample)

    # -- opening --------------------------------------------------------------------------

    @classmethod
    def open(cls, path: str | Path) -> DatasetStore:
        """Open an existing store.

        Raises
        ------
        InputError : ``path`` holds no ``dataset.json``, one of another format or a
            malformed one.
        RunConflict : a ``dataset.json`` edited since it was written (its identity digest
            or configuration disagree with its identity).
        """
        path = Path(path)
        file = path / DESCRIPTION_FILE
        if not file.is_file():
            raise InputError(
                "store", f"a dataset store (a folder with {DESCRIPTION_FILE})", str(path)
            )
        data = read_json(file, "dataset description", expect=dict)
        if data.get("format") != STORE_FORMAT:
            raise InputError(f"{file} format", STORE_FORMAT, data.get("format"))
        check_description(file, data, STORAGES)
        return cls(path, data)

    @classmethod
    def prepare(
        cls,
        path: str | Path,
        *,
        config: dict[str, Any],
        identity: dict[str, Any],
        layout: tuple[ArraySpec, ...],
        storage: str,
        num_samples: int,
        encoding: dict[str, Any] | None = None,
    ) -> DatasetStore:
        """Create the store, or reopen one made with the same identity and extend it.

        Call it holding the directory's lock. Nothing is rendered here; the arrays are
        created (or resized) so that ``num_samples`` fit. ``encoding``: this run's
        :func:`~virtus.data.chunkcodecs.encoding_description`.

        Raises
        ------
        VirtusError : the folder holds something else, or a store made with another
            configuration (the first difference is named).
        OSError : the folder cannot be created or written.
        """
        path = Path(path)
        if storage not in STORAGES:
            raise InputError("format", f"one of {', '.join(STORAGES)}", storage)
        file = path / DESCRIPTION_FILE
        digest = config_digest(identity)
        if file.is_file():
            store = cls.open(path)
            old = store.description.get("identity", {})
            if store.digest != digest or store.storage != storage:
                where = first_difference(
                    {"storage": storage, **identity}, {"storage": store.storage, **old}
                )
                raise RunConflict(
                    f"{path} holds a dataset made with another configuration ({where}); "
                    "choose another --out or remove it"
                )
            where = first_difference(
                canonical([a.to_dict() for a in layout]), store.description["layout"]
            )
            if where is not None:
                raise RunConflict(
                    f"{file}: its layout differs from this configuration's "
                    f"(layout{where.split(': ', 1)[0]}); the file was edited: restore it, or "
                    "generate into a new store"
                )
            store.records()  # every record is this dataset's (else the file is named)
        elif path.exists() and any(p.name not in _IGNORED for p in path.iterdir()):
            raise RunConflict(
                f"{path} exists and is not a virtus dataset (no {DESCRIPTION_FILE}); choose a "
                "new or empty folder"
            )
        previous = cls.open(path).description if file.is_file() else None
        description = {
            "format": STORE_FORMAT,
            "virtus_version": __version__,
            "storage": storage,
            "units": UNITS,
            "num_samples": num_samples,
            "config": config,
            "identity": identity,
            "identity_digest": digest,
            "layout": [a.to_dict() for a in layout],
        }
        if encoding is not None:
            description["encoding"] = encoding
            _codecs.merge_encoding(description, _codecs.recorded_encoders(previous))
        if previous is not None:
            description["num_samples"] = max(num_samples, int(previous["num_samples"]))
        store = cls(path, description)
        # dataset.json first: it claims the folder, so a run killed while the arrays are
        # being created is resumed (creation is idempotent) rather than refused.
        if previous != description:
            write_json_atomic(file, description)
        (path / MANIFEST_DIR).mkdir(exist_ok=True)
        (path / ASSETS_DIR).mkdir(exist_ok=True)
        store._remove_strays()
        if storage == "zarr":
            store._zarr_create(description["num_samples"], config["storage"])
        return store

    # -- shards and the manifest ----------------------------------------------------------

    @property
    def num_samples(self) -> int:
        """Samples the store is meant to hold (the largest ``num_samples`` requested)."""
        return int(self.description["num_samples"])

    def shard_count(self, num_samples: int | None = None) -> int:
        """Shards that hold ``num_samples`` (default: the store's)."""
        num = self.num_samples if num_samples is None else num_samples
        return -(-num // self.shard_samples)

    def shard_bounds(self, shard: int, num_samples: int | None = None) -> tuple[int, int]:
        """``(start, stop)`` sample indices of a shard."""
        num = self.num_samples if num_samples is None else num_samples
        start = shard * self.shard_samples
        return start, min(start + self.shard_samples, num)

    def _record_path(self, shard: int) -> Path:
        return self.path / MANIFEST_DIR / f"shard_{shard:06d}.json"

    def records(self) -> dict[int, dict[str, Any]]:
        """Shard -> record, for every record of the manifest.

        Raises
        ------
        RunConflict : a file of the manifest that is not a record of this dataset (another
            dataset's digest -- copied from another store, or this ``dataset.json`` was
            edited --, another shard's number, samples outside its shard, unreadable): the
            first one is named. Records are written atomically, so none of these comes
            from an interrupted run; removing the file makes ``dataset generate`` render
            its shard again.
        """
        out: dict[int, dict[str, Any]] = {}
        folder = self.path / MANIFEST_DIR
        if not folder.is_dir():
            return out
        rejected = []
        for file in sorted(folder.glob("shard_*.json")):
            try:
                record = read_json(file, "shard record", expect=dict, max_bytes=_MAX_RECORD_BYTES)
            except InputError as error:
                rejected.append((file, f"unreadable ({error})"))
                continue
            problem = record_problem(
                file, record, shard_format=SHARD_FORMAT, digest=self.digest,
                shard_samples=self.shard_samples,
            )  # fmt: skip
            if problem is None:
                out[record["shard"]] = record
            else:
                rejected.append((file, problem))
        if rejected:
            file, problem = rejected[0]
            more = f" ({len(rejected) - 1} more such files)" if len(rejected) > 1 else ""
            raise RunConflict(
                f"{file}: not a shard record of this dataset: {problem}{more}; remove it "
                "(dataset generate renders its shard again)"
            )
        return out

    def samples(self) -> dict[int, dict[str, Any]]:
        """Sample index -> its metadata (with ``shard``), for every complete sample."""
        out = {}
        for shard, record in self.records().items():
            for meta in record["samples"]:
                out[int(meta["index"])] = {**meta, "shard": shard}
        return dict(sorted(out.items()))

    def missing_shards(
        self, num_samples: int, records: dict[int, dict[str, Any]] | None = None
    ) -> list[int]:
        """Shards of ``[0, num_samples)`` without a record listing all their samples
        (``records``: :meth:`records`, read here when not given)."""
        records = self.records() if records is None else records
        todo = []
        for shard in range(self.shard_count(num_samples)):
            start, stop = self.shard_bounds(shard, num_samples)
            have = {int(m["index"]) for m in records.get(shard, {}).get("samples", [])}
            if not set(range(start, stop)) <= have:
                todo.append(shard)
        return todo

    def shard_buffer(self, count: int) -> dict[str, np.ndarray]:
        """Uninitialised arrays for ``count`` samples of a shard: name -> (count, *shape) of
        the layout's dtype (fill them with :func:`virtus.data.labels.sample_arrays`, one
        sample slot at a time, then :meth:`write_shard`; reusable for the next shard)."""
        return {a.name: np.empty((count, *a.shape), dtype=a.dtype) for a in self.layout}

    def encode_sample(
        self, arrays: dict[str, np.ndarray], on_device: dict[str, Any] | None = None
    ) -> EncodedSample:
        """A sample's checksum and stored chunks, ahead of :meth:`write_shard` (so a pipeline
        can encode each sample as soon as it is labelled).

        Parameters
        ----------
        arrays : name -> the sample's array (layout shape and dtype).
        on_device : the same arrays on the batch compressor's device, which it then reads
            (:func:`virtus.data.devicebuffers.staging_device`); None: it reads ``arrays``.
        """
        begin = time.perf_counter()
        checksum = sample_checksum(arrays, self.layout)
        middle = time.perf_counter()
        chunks = {}
        if self.storage == "zarr":
            encoders, batch = self._shard_encoders(), self.batch_compressor()
            device = None if on_device is None else [on_device]
            chunks = _codecs.encode_samples(encoders, [arrays], batch, device)[0]
        seconds = {"checksum": middle - begin, "compression": time.perf_counter() - middle}
        return EncodedSample(checksum, chunks, seconds)

    def write_shard(
        self,
        shard: int,
        arrays: dict[str, np.ndarray],
        metas: list[dict[str, Any]],
        encoded: list[EncodedSample] | None = None,
        on_device: dict[str, Any] | None = None,
    ) -> dict[str, float]:
        """Write one shard's samples (consecutive, from the shard's first index), then its
        record. Each sample's ``checksum`` is added to its metadata.

        Parameters
        ----------
        shard : the shard number.
        arrays : name -> (n, *shape) block of the layout's dtype, sample ``k`` of the shard
            at ``[k]`` (:meth:`shard_buffer`); rows past ``n = len(metas)`` are ignored.
        metas : the ``n`` samples' metadata (:func:`virtus.data.shardtask.sample_meta`).
        encoded : the samples' :meth:`encode_sample` of ``arrays``, if already made (else
            checksums and chunks are computed here, on a few threads).
        on_device : ``arrays`` on the batch compressor's device, which it then reads
            (as :meth:`encode_sample`).

        Returns
        -------
        Seconds spent: ``checksum`` and ``compression`` (work summed over the threads that
        do it side by side; ``encoded``'s included), ``io`` (writing the files and the
        record), ``wall`` (the call).
        """
        start_time = time.perf_counter()
        start = shard * self.shard_samples
        count = len(metas)
        if (
            not 1 <= count <= self.shard_samples
            or any(arrays[a.name].shape[0] < count for a in self.layout)
            or (encoded is not None and len(encoded) != count)
        ):
            raise InputError("samples", f"1..{self.shard_samples} samples with metadata", count)
        samples = [{a.name: arrays[a.name][k] for a in self.layout} for k in range(count)]
        timing = {"checksum": 0.0, "compression": 0.0, "io": 0.0}
        for sample in encoded or []:
            for stage, seconds in sample.seconds.items():
                timing[stage] += seconds

        def result(future: Any, stage: str) -> Any:
            value, seconds = future.result()
            timing[stage] += seconds
            return value

        # The compressors release the GIL (CRC-32C takes ~10 ms a sample): checksums and
        # chunks are computed on a few threads while this one writes each array's shard as
        # soon as it is encoded.
        with ThreadPoolExecutor(_WRITE_THREADS) as pool:
            if encoded is None:
                checksums = [
                    pool.submit(_timed, sample_checksum, arrays_k, self.layout)
                    for arrays_k in samples
                ]
            else:
                checksums = [_Done(sample.checksum) for sample in encoded]
            io_start = time.perf_counter()
            if self.storage == "zarr":
                encoders = self._shard_encoders()
                batch = self.batch_compressor() if encoded is None else None
                if batch is not None:  # the shard's chunks in one batch, here (nvCOMP)
                    device = None
                    if on_device is not None:
                        device = [slot_views(on_device, k) for k in range(count)]
                    done, seconds = _timed(_codecs.encode_samples, encoders, samples, batch, device)
                    timing["compression"] += seconds
                    encoded = [EncodedSample("", chunks, {}) for chunks in done]
                chunks = {
                    name: [
                        pool.submit(_timed, encoder.encode, s[name])
                        if encoded is None
                        else _Done(encoded[k].chunks[name])
                        for k, s in enumerate(samples)
                    ]
                    for name, encoder in encoders.items()
                    if encoder is not None
                }
                zarr_arrays = self._zarr_arrays()
                for spec in self.layout:
                    encoder = encoders[spec.name]
                    if encoder is not None:
                        data = [result(f, "compression") for f in chunks[spec.name]]
                        io_start = time.perf_counter()
                        encoder.write(shard, data)
                        timing["io"] += time.perf_counter() - io_start
                    else:  # a layout the direct writer does not handle: through Zarr
                        io_start = time.perf_counter()
                        zarr_arrays[spec.name][start : start + count] = arrays[spec.name][:count]
                        timing["io"] += time.perf_counter() - io_start
            else:
                for offset, (arrays_k, meta) in enumerate(zip(samples, metas, strict=True)):
                    self._png_write(start + offset, arrays_k, int(meta["n_frames"]))
                timing["io"] += time.perf_counter() - io_start
            for meta, future in zip(metas, checksums, strict=True):
                meta["checksum"] = result(future, "checksum")
        record = {
            "format": SHARD_FORMAT,
            "dataset": self.digest,
            "shard": shard,
            "samples": metas,
            "encoder": self.encoder_name(),
        }
        io_start = time.perf_counter()
        write_json_atomic(self._record_path(shard), record)
        timing["io"] += time.perf_counter() - io_start
        timing["wall"] = time.perf_counter() - start_time
        return timing

    # -- reading --------------------------------------------------------------------------

    def read_sample(
        self,
        index: int,
        names: tuple[str, ...] | None = None,
        *,
        verify: bool = True,
        checksum: str | None = None,
    ) -> dict[str, np.ndarray]:
        """The arrays of sample ``index`` (all, or ``names``), as stored, checked against the
        checksum of its record.

        Parameters
        ----------
        index : a complete sample (one its shard's record lists).
        names : the arrays to read (default: all). With a CRC-32C checksum (one per array)
            only these are read and checked; an old SHA-256 checksum covers the whole sample,
            which is then read.
        verify : compare the checksum (False: read as stored, unchecked).
        checksum : the sample's recorded checksum, if the caller holds its record (else it
            is looked up in the manifest).

        Raises
        ------
        InputError : ``index`` is not a complete sample, ``names`` holds an unknown name.
        DamagedSample : the data cannot be read (a decompression error, a truncated or
            missing file) or does not match the checksum; the sample and the arrays named.
        """
        wanted = [a for a in self.layout if names is None or a.name in names]
        if names is not None and len(wanted) != len(set(names)):
            known = [a.name for a in self.layout]
            raise InputError("names", f"array names among {known}", list(names))
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise InputError("index", "a sample index (an integer)", index)
        index = int(index)
        if verify:
            recorded = self._recorded_checksum(index) if checksum is None else checksum
            if not str(recorded).startswith(CRC32C_PREFIX):
                wanted = list(self.layout)  # a whole-sample checksum: read every array
        elif not 0 <= index < self.num_samples:
            raise InputError("index", f"a sample index in 0..{self.num_samples - 1}", index)
        arrays = self._zarr_arrays() if self.storage == "zarr" else {}
        data = {}
        for spec in wanted:
            try:
                if self.storage == "zarr":
                    data[spec.name] = np.asarray(arrays[spec.name][index])
                else:
                    data[spec.name] = self._png_read(index, spec)
            except Exception as error:  # zarr, numcodecs, Blosc and images raise many types
                raise DamagedSample(
                    self.path, index, f"{spec.name} unreadable ({describe(error)})"
                ) from None
        if verify:
            wrong = checksum_mismatches(data, self.layout, recorded)
            if wrong:
                raise DamagedSample(self.path, index, f"checksum mismatch ({', '.join(wrong)})")
        if names is not None:
            data = {a.name: data[a.name] for a in self.layout if a.name in names}
        return data

    def _recorded_checksum(self, index: int) -> Any:
        """The checksum sample ``index``'s record holds (the manifest is read once, and again
        for a sample recorded since)."""
        if index not in self._checksums:
            self._checksums = {i: m["checksum"] for i, m in self.samples().items()}
        if index not in self._checksums:
            raise InputError(
                "index",
                f"a complete sample of {self.path} ({len(self._checksums)} recorded)",
                index,
            )
        return self._checksums[index]

    def _read_block(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """Every array of samples ``[start, stop)``, stacked (as stored)."""
        if self.storage == "zarr":
            arrays = self._zarr_arrays()
            return {a.name: np.asarray(arrays[a.name][start:stop]) for a in self.layout}
        samples = [self.read_sample(index, verify=False) for index in range(start, stop)]
        return {a.name: np.stack([s[a.name] for s in samples]) for a in self.layout}

    def verify(self, progress: Callable[[int, int], None] | None = None) -> VerifyReport:
        """Read every recorded sample back and compare its checksum; list missing samples
        of ``[0, num_samples)`` and leftover temporary files (a manifest file that is not
        this dataset's record raises :class:`RunConflict`, :meth:`records`)."""
        report = VerifyReport()
        records = self.records()
        samples = self.samples()
        done = 0
        for record in records.values():
            metas = record["samples"]
            indices = [int(m["index"]) for m in metas]
            try:  # one read per array and shard (per-sample reads cost Zarr's overhead each)
                blocks = self._read_block(min(indices), max(indices) + 1)
                short = [n for n, b in blocks.items() if len(b) < max(indices) - min(indices) + 1]
                if short:  # an array's zarr.json declares fewer samples than are recorded
                    raise IndexError(f"{', '.join(short)} shorter than the records")
            except Exception as error:  # a damaged shard: zarr/numcodecs raise many types
                problem = f"unreadable: {type(error).__name__}: {error}"
                report.bad += [(index, problem) for index in indices]
                continue
            for meta, index in zip(metas, indices, strict=True):
                arrays = {name: block[index - min(indices)] for name, block in blocks.items()}
                wrong = checksum_mismatches(arrays, self.layout, meta.get("checksum"))
                if wrong:
                    report.bad.append((index, f"checksum mismatch ({', '.join(wrong)})"))
                report.checked += 1
                done += 1
                if progress is not None:
                    progress(done, len(samples))
        report.bad.sort()
        report.missing = [i for i in range(self.num_samples) if i not in samples]
        report.stray = [str(p.relative_to(self.path)) for p in self._strays()]
        return report

    def info(self) -> dict[str, Any]:
        """A JSON-ready summary: format, storage, mode, sizes, samples per split, disk use."""
        samples = self.samples()
        splits: dict[str, int] = {}
        for meta in samples.values():
            splits[meta["split"]] = splits.get(meta["split"], 0) + 1
        frames = next(a for a in self.layout if a.name == "frames")
        size = sum(p.stat().st_size for p in self.path.rglob("*") if p.is_file())
        return {
            "path": str(self.path),
            "format": self.description["format"],
            "storage": self.storage,
            "mode": self.description["config"]["mode"],
            "seed": self.description["config"]["seed"],
            "num_samples": self.num_samples,
            "complete": len(samples),
            "splits": splits,
            "shard_samples": self.shard_samples,
            "frames": {
                "max": frames.shape[0],
                "height": frames.shape[1],
                "width": frames.shape[2],
                "dtype": frames.dtype,
            },  # fmt: skip
            "arrays": [a.name for a in self.layout],
            "bytes_on_disk": size,
            "identity_digest": self.digest,
        }

    # -- zarr -----------------------------------------------------------------------------

    @quiet_numcodecs()
    def _zarr_create(self, num: int, storage: dict[str, Any]) -> None:
        import zarr

        group = zarr.open_group(self.path, mode="a")
        group.attrs.update({"virtus": {"format": STORE_FORMAT, "units": UNITS}})
        codec = (storage["codec"], int(storage["level"]))
        for spec in self.layout:
            if spec.name in group:
                array = group[spec.name]
                if array.shape[0] < num:
                    array.resize((num, *spec.shape))
                continue
            group.create_array(
                spec.name,
                shape=(num, *spec.shape),
                chunks=(1, *spec.shape),
                shards=(self.shard_samples, *spec.shape),
                dtype=spec.dtype,
                fill_value=spec.fill,
                compressors=zarr_compressor(*codec, spec.name, np.dtype(spec.dtype).itemsize),
                attributes={"unit": spec.unit, "channels": list(spec.channels)},
            )
        self._arrays = {}
        self._encoders = {}

    def _shard_encoders(self) -> dict[str, ShardEncoder | None]:
        """Name -> the direct shard writer of each array (None: written through Zarr)."""
        with _OPEN_LOCK:
            if not self._encoders or self._encoders_pid != os.getpid():
                arrays = self._zarr_arrays_locked()
                self._encoders = {
                    name: ShardEncoder.for_array(array, self.path / name)
                    for name, array in arrays.items()
                }
                self._encoders_pid = os.getpid()
            return self._encoders

    def batch_compressor(self) -> Any:
        """This process's GPU batch compressor (None: numcodecs, chunk by chunk)."""
        return _codecs.process_compressor(self.description) if self.storage == "zarr" else None

    def encoder_name(self) -> str:
        """Who encodes this process's shards (``"nvcomp 6.0.0.12"``, ``"numcodecs ..."``)."""
        return _codecs.encoder_name(self.batch_compressor(), self.storage)

    def add_encoders(self, encoders: list[str]) -> None:
        """Add the encoders that wrote a run's shards to ``dataset.json`` (under its lock)."""
        if _codecs.merge_encoding(self.description, encoders):
            write_json_atomic(self.path / DESCRIPTION_FILE, self.description)

    def _zarr_arrays(self) -> dict[str, Any]:
        with _OPEN_LOCK:
            return self._zarr_arrays_locked()

    def _zarr_arrays_locked(self) -> dict[str, Any]:
        """The Zarr arrays, opened once per process (the caller holds :data:`_OPEN_LOCK`:
        pipeline threads encode samples side by side)."""
        import zarr

        if not self._arrays or self._pid != os.getpid():
            try:
                with quiet_numcodecs():
                    group = zarr.open_group(self.path, mode="r+")
                    opened = {spec.name: group[spec.name] for spec in self.layout}
            except Exception as error:  # zarr raises many types for missing or bad metadata
                raise InputError(
                    f"store {self.path}", "Zarr arrays for the layout of its dataset.json",
                    describe(error),
                ) from None  # fmt: skip
            check_arrays(self.path, self.layout, opened)
            self._arrays = opened
            self._pid = os.getpid()
        return self._arrays

    # -- png ------------------------------------------------------------------------------

    def _sample_dir(self, index: int) -> Path:
        return self.path / SAMPLES_DIR / f"{index:06d}"

    def _png_write(self, index: int, arrays: dict[str, np.ndarray], n_frames: int) -> None:
        """Write a sample folder beside its place, then rename it into place."""
        from virtus.io.images import write_frames
        from virtus.io.safewrite import check_directory

        target = check_directory(self._sample_dir(index), "sample folder")
        staging = check_directory(target.parent / f".tmp-{target.name}", "staging folder")
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir(parents=True)
        write_frames(staging / "frames", arrays["frames"][:n_frames], workers=1)
        for spec in self.layout:
            if spec.name != "frames":
                np.save(staging / f"{spec.name}.npy", arrays[spec.name])
        shutil.rmtree(target, ignore_errors=True)
        os.replace(staging, target)

    def _png_read(self, index: int, spec: ArraySpec) -> np.ndarray:
        from virtus.io.images import list_images, read_images
        from virtus.io.safeio import load_npy

        folder = self._sample_dir(index)
        if spec.name == "frames":
            out = np.zeros(spec.shape, dtype=spec.dtype)
            frames = read_images(list_images(folder / "frames"), workers=1)
            out[: len(frames)] = frames
            return out
        return load_npy(folder / f"{spec.name}.npy", spec.name, dtype=spec.dtype, shape=spec.shape)

    # -- housekeeping ---------------------------------------------------------------------

    def _strays(self) -> list[Path]:
        """Temporary files a killed writer may leave (Zarr's ``*.partial``, staging)."""
        found = [p for p in self.path.rglob("*.partial")]
        found += [p for p in self.path.rglob(".virtus-tmp")]
        samples = self.path / SAMPLES_DIR
        if samples.is_dir():
            found += [p for p in samples.iterdir() if p.name.startswith(".tmp-")]
        return sorted(found)

    def _remove_strays(self) -> None:
        for path in self._strays():
            with contextlib.suppress(OSError):
                if path.is_dir():
                    shutil.rmtree(path)
                else:
                    path.unlink()
