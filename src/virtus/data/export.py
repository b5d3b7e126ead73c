"""Export a store to WebDataset tar shards (streaming training without Zarr).

Each sample becomes the tar members ``<key>.<array>.npy`` (one per stored array, numpy
``.npy``, dtypes and metric units as stored) and ``<key>.json`` (its record: split, seed,
checksum, rig, cam2world, sequence, sensor, objects), with ``key`` the zero-padded sample
index -- the WebDataset convention (members sharing a key form one sample), readable by
``webdataset.WebDataset(urls).decode()`` or any tar reader. Tars are named
``<split>-000000.tar`` (``all-...`` without a split), hold ``samples_per_tar`` samples
each, are written atomically and byte-reproducibly (fixed member order, times and owners).
"""

from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import numpy as np

from virtus.data.store import DatasetStore
from virtus.errors import InputError
from virtus.io.runs import atomic_write

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


def export_webdataset(
    store_path: str | Path,
    out_dir: str | Path,
    *,
    split: str | None = None,
    samples_per_tar: int = 64,
    arrays: tuple[str, ...] | None = None,
) -> list[Path]:
    """Write the store's complete samples (of ``split``, or all) as WebDataset tars.

    Parameters
    ----------
    store_path : the store.
    out_dir : folder for the tars (created).
    split : only this split's samples.
    samples_per_tar : samples per tar, 1..:data:`MAX_SAMPLES_PER_TAR`.
    arrays : array names to export (default: all).

    Returns
    -------
    The tar paths, in order.
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
    names = tuple(a.name for a in store.layout) if arrays is None else tuple(arrays)
    samples = store.samples()
    if split is not None:
        configured = list(store.description["config"]["splits"])
        if split not in configured:
            raise InputError("split", f"one of {configured}", split)
        samples = {i: m for i, m in samples.items() if m["split"] == split}
    indices = list(samples)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for number, first in enumerate(range(0, len(indices), samples_per_tar)):
        chunk = indices[first : first + samples_per_tar]
        path = out / f"{split or 'all'}-{number:06d}.tar"

        def write(tmp: Path, chunk: list[int] = chunk) -> None:
            with tarfile.open(tmp, "w", format=tarfile.USTAR_FORMAT) as tar:
                for index in chunk:
                    key = f"{index:06d}"
                    data = store.read_sample(index, names)
                    for name in names:
                        _member(tar, f"{key}.{name}.npy", _npy(data[name]))
                    meta = json.dumps(samples[index], separators=(",", ":")).encode()
                    _member(tar, f"{key}.json", meta)

        written.append(atomic_write(path, write))
    return written
