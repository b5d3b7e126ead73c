"""Export a store to WebDataset tar shards (streaming training without Zarr).

Each sample becomes the tar members ``<key>.<array>.npy`` (one per stored array, numpy
``.npy``, dtypes and metric units as stored) and ``<key>.json`` (its record: split, seed,
checksum, rig, cam2world, sequence, sensor, objects), with ``key`` the zero-padded sample
index -- the WebDataset convention (members sharing a key form one sample), readable by
``webdataset.WebDataset(urls).decode()`` or any tar reader. Tars are named
``<split>-000000.tar`` (``all-...`` without a split), hold ``samples_per_tar`` samples
each and are byte-reproducible (fixed member order, times and owners).

Every sample is checked against its recorded checksum as it is read
(:meth:`~virtus.data.store.DatasetStore.read_sample`). A damaged sample stops the export
with :class:`~virtus.data.store.DamagedSample` naming it, and nothing is written: the tars
are made in a staging folder inside ``out_dir`` and moved into place only when all are
complete. With ``on_damaged`` a damaged sample is reported and left out instead.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import tarfile
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data.store import DamagedSample, DatasetStore
from virtus.errors import InputError

__all__ = ["MAX_SAMPLES_PER_TAR", "export_webdataset"]

#: Most samples per tar (a 960 x 960 sample of 52 frames is ~100 MB uncompressed).
MAX_SAMPLES_PER_TAR = 100_000


def _member(tar: tarfile.TarFile, name: str, payload: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(payload)
    info.mtime = 0
    info.mode = 0o644
    tar.addfile(info, io.BytesIO(payload))


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def _readable(
    store: DatasetStore,
    samples: dict[int, dict[str, Any]],
    names: tuple[str, ...],
    on_damaged: Callable[[int, str], None] | None,
) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
    """``(index, arrays)`` of every sample that reads back intact, in index order."""
    for index, meta in samples.items():
        try:
            data = store.read_sample(index, names, checksum=meta["checksum"])
        except DamagedSample as error:
            if on_damaged is None:
                raise
            on_damaged(index, error.problem)
            continue
        yield index, data


def _new_folders(folder: Path) -> list[Path]:
    """The folders that creating ``folder`` makes, deepest first."""
    made = []
    while not folder.exists() and folder != folder.parent:
        made.append(folder)
        folder = folder.parent
    return made


def export_webdataset(
    store_path: str | Path,
    out_dir: str | Path,
    *,
    split: str | None = None,
    samples_per_tar: int = 64,
    arrays: tuple[str, ...] | None = None,
    on_damaged: Callable[[int, str], None] | None = None,
) -> list[Path]:
    """Write the store's complete samples (of ``split``, or all) as WebDataset tars.

    Parameters
    ----------
    store_path : the store.
    out_dir : folder for the tars (created).
    split : only this split's samples.
    samples_per_tar : samples per tar, 1..:data:`MAX_SAMPLES_PER_TAR`.
    arrays : array names to export (default: all).
    on_damaged : called with ``(index, problem)`` for each damaged sample, which is then
        left out (the tars hold ``samples_per_tar`` intact samples each); None: a damaged
        sample raises.

    Returns
    -------
    The tar paths, in order.

    Raises
    ------
    DamagedSample : a sample cannot be read or does not match its checksum (without
        ``on_damaged``); no tar is written.
    InputError, RunConflict : a bad argument, a store whose description or manifest is not
        its own (:meth:`~virtus.data.store.DatasetStore.records`).
    """
    if (
        isinstance(samples_per_tar, bool)
        or not isinstance(samples_per_tar, int)
        or not 1 <= samples_per_tar <= MAX_SAMPLES_PER_TAR
    ):
        raise InputError(
            "samples_per_tar", f"an integer in 1..{MAX_SAMPLES_PER_TAR}", samples_per_tar
        )
    store = DatasetStore.open(store_path)
    known = [a.name for a in store.layout]
    names = tuple(known) if arrays is None else tuple(arrays)
    if not names or any(name not in known for name in names):
        raise InputError("arrays", f"names among {known}", list(names))
    samples = store.samples()
    if split is not None:
        configured = list(store.description["config"]["splits"])
        if split not in configured:
            raise InputError("split", f"one of {configured}", split)
        samples = {i: m for i, m in samples.items() if m["split"] == split}
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("webdataset", "a folder for the tars", f"a file {out}")
    made = _new_folders(out)
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".virtus-export-", dir=out))
    written: list[str] = []
    try:
        stream = _readable(store, samples, names, on_damaged)
        pending = next(stream, None)
        while pending is not None:
            name = f"{split or 'all'}-{len(written):06d}.tar"
            with tarfile.open(staging / name, "w", format=tarfile.USTAR_FORMAT) as tar:
                for _ in range(samples_per_tar):
                    if pending is None:
                        break
                    index, data = pending
                    key = f"{index:06d}"
                    for array in names:
                        _member(tar, f"{key}.{array}.npy", _npy(data[array]))
                    meta = json.dumps(samples[index], separators=(",", ":")).encode()
                    _member(tar, f"{key}.json", meta)
                    pending = next(stream, None)
            written.append(name)
        for name in written:
            os.replace(staging / name, out / name)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        for folder in made:  # what this call created, if nothing else is there
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    shutil.rmtree(staging, ignore_errors=True)
    return [out / name for name in written]
