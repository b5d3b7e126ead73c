"""Shard files are handed to the disk as they are written (virtus.data.shards).

(That their bytes are Zarr's is tested with the store, tests/data/test_dataset.py.)"""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from virtus.data import shards


def _shard_encoder(tmp_path):
    import zarr

    from virtus.data.store import zarr_compressor

    group = zarr.open_group(tmp_path / "group", mode="w")
    array = group.create_array(
        "a", shape=(4, 5, 6), chunks=(1, 5, 6), shards=(2, 5, 6), dtype="uint16",
        fill_value=0, compressors=zarr_compressor("zstd", 3, "frames"),
    )  # fmt: skip
    encoder = shards.ShardEncoder.for_array(array, tmp_path / "group" / "a")
    assert encoder is not None
    return array, encoder


def test_each_shard_file_is_handed_to_the_disk_once_whole(tmp_path, monkeypatch) -> None:
    array, encoder = _shard_encoder(tmp_path)
    seen = []

    def record(fd: int, offset: int, length: int, flags: int) -> int:
        seen.append((os.fstat(fd).st_size, offset, length, flags))
        return 0

    monkeypatch.setattr(shards, "_sync_file_range", lambda: record)
    data = np.arange(4 * 5 * 6, dtype="uint16").reshape(4, 5, 6) + 1
    sizes = [encoder.write(shard, [encoder.encode(c) for c in data[2 * shard : 2 * shard + 2]])
             for shard in range(2)]  # fmt: skip
    # whole files (flushed before the request), from their start to their end, not waited for
    assert seen == [(size, 0, 0, 2) for size in sizes]
    assert np.array_equal(array[:], data)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="sync_file_range is Linux's")
def test_the_kernel_takes_the_request_on_linux(tmp_path) -> None:
    call = shards._sync_file_range()
    assert call is not None
    with open(tmp_path / "f", "wb") as handle:
        handle.write(b"x" * 100_000)
        shards.start_writeback(handle)
        assert call(handle.fileno(), 0, 0, 2) == 0
    assert (tmp_path / "f").stat().st_size == 100_000
