"""A worker's shard task (virtus.data.shardtask): its buffers and what it writes."""

from __future__ import annotations

import threading

from tests.data.test_dataset import store_files, tiny_config
from virtus.data import DatasetStore, generate, load_config, shardtask


def test_a_workers_second_set_of_buffers_is_made_on_the_writer(tmp_path, monkeypatch) -> None:
    """A worker that writes one shard while it renders the next makes the second shard's
    buffers on its writer thread, idle while the first shard renders, and keeps both from
    task to task; the shards it writes are the store's own bytes."""
    config = load_config(tiny_config(tmp_path, num_samples=12, storage={"shard_samples": 2}))
    out = tmp_path / "store"
    generate(config, out)
    before = store_files(out)
    made = []
    new_buffers = shardtask._new_shard_buffers

    def recorded(store):
        made.append(threading.current_thread().name)
        return new_buffers(store)

    monkeypatch.setattr(shardtask, "_new_shard_buffers", recorded)
    monkeypatch.setattr(shardtask, "_IN_WORKER", True)
    monkeypatch.setattr(shardtask, "_WORKER_BUFFER", None)
    digest = DatasetStore.open(out).digest
    first = shardtask.render_shards(str(out), [0, 1, 2], 12, digest, overlap=True)
    assert made == ["MainThread", "virtus-shard-writer_0"]
    again = shardtask.render_shards(str(out), [3, 4], 12, digest, overlap=True)
    assert made == ["MainThread", "virtus-shard-writer_0"]  # kept from the first task
    assert [r["shard"] for r in first + again] == [0, 1, 2, 3, 4]
    assert store_files(out) == before
