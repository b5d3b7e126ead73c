"""Datasets on Ray (virtus.data.raycluster): the GPU workers a cluster gets, and a local
cluster started here with fake GPU resources, whose GPU actors -- one per fake GPU, each
pinned by Ray -- make the store a one-process run makes."""

from __future__ import annotations

import pytest

from tests.data.test_dataset import store_files, tiny_config
from virtus.data import generate, load_config
from virtus.data.raycluster import gpu_slots
from virtus.errors import InputError


class FakeCluster:
    """What :func:`gpu_slots` asks of the ``ray`` module."""

    def __init__(self, **resources: float) -> None:
        self.resources = resources

    def cluster_resources(self) -> dict[str, float]:
        return dict(self.resources)


def test_gpu_slots_share_the_cluster_gpus_out() -> None:
    four = FakeCluster(CPU=64.0, GPU=4.0)
    assert gpu_slots(four, None, None, environ={}) == (4, 1.0)
    assert gpu_slots(four, "all", 3, environ={}) == (12, 0.3333)  # 3 x 0.3333 fit one GPU
    assert gpu_slots(four, 2, 12, environ={}) == (24, 0.0833)
    assert gpu_slots(FakeCluster(CPU=8.0, GPU=2.5), None, None, environ={}) == (2, 1.0)
    # CPU tasks: no GPU in the cluster, or the CPU variant forced without --gpus
    assert gpu_slots(FakeCluster(CPU=8.0), None, None, environ={}) == (0, 0.0)
    forced = {"VIRTUS_MITSUBA_VARIANT": "llvm_ad_rgb"}
    assert gpu_slots(four, None, None, environ=forced) == (0, 0.0)
    with pytest.raises(InputError, match="at most the 4 GPUs of the Ray cluster, got 5"):
        gpu_slots(four, 5, None, environ={})
    with pytest.raises(InputError, match="--gpus: expected a positive number"):
        gpu_slots(four, "none", None, environ={})
    with pytest.raises(InputError, match="--workers-per-gpu: expected GPUs to render on"):
        gpu_slots(FakeCluster(CPU=8.0), None, 2, environ={})


def test_ray_gpu_actors_make_the_same_store(tmp_path, monkeypatch) -> None:
    ray = pytest.importorskip(
        "ray", reason="Ray is not installed (optional: pip install 'virtus-fpp[ray]')"
    )
    monkeypatch.delenv("VIRTUS_MITSUBA_VARIANT", raising=False)
    config = load_config(tiny_config(tmp_path, num_samples=12))
    generate(config, tmp_path / "local")
    ray.init(num_cpus=2, num_gpus=2, include_dashboard=False, log_to_driver=False)
    try:
        with pytest.raises(InputError, match="at most the 2 GPUs of the Ray cluster, got 3"):
            generate(config, tmp_path / "refused", ray="auto", gpus=3)
        report = generate(config, tmp_path / "ray", ray="auto")
    finally:
        ray.shutdown()
    assert not (tmp_path / "refused").exists()
    assert store_files(tmp_path / "ray") == store_files(tmp_path / "local")
    # two actors, one fake GPU each (Ray set their CUDA_VISIBLE_DEVICES); shards 0 and 2
    # were queued on the first actor, shard 1 on the second
    devices = report.shard_devices
    assert sorted(devices) == [0, 1, 2] and set(devices.values()) == {"0", "1"}, devices
    assert devices[0] == devices[2] != devices[1]
