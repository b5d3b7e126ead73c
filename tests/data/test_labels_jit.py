"""Dataset labels made on the device (virtus.data.labels_jit) against the host's labels.

CI has no GPU: the same code runs on ``llvm_ad_rgb``, the CPU twin of ``cuda_ad_rgb``. Each
case renders samples once on the device and labels that one rendering both ways, so the
frames are the same and every difference is the labels' own.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.data.test_dataset import store_files, tiny_config
from virtus.capture.capture import Capture
from virtus.data import DatasetStore, generate, load_config
from virtus.data import chunkcodecs as codecs
from virtus.data.devicebuffers import device_shard_buffer
from virtus.data.labels import array_layout, sample_arrays
from virtus.data.labels_jit import device_sample_arrays
from virtus.data.sampling import Randomiser

#: The modules (``virtus.data.generate`` the name is its function).
generate_module = importlib.import_module("virtus.data.generate")
task_module = importlib.import_module("virtus.data.shardtask")
VARIANT = "llvm_ad_rgb"
#: Float32 labels computed in float32 on both sides (modulation, numerator, denominator)
#: differ by the rounding of sums taken in another order, fused multiply-adds and the
#: device's sin/cos: a few float32 ulps of the largest value (measured below 3e-6).
REAL_RTOL = 2e-5
#: Labels computed in float64 and rounded once to the stored dtype (phase, wrap,
#: coordinates) may differ by that one rounding.
STORED_ULPS = 1

CONFIGS = {
    "mixed objects, noisy 8-bit camera, gray code, float32 labels": {
        "objects": {
            "count": [1, 3],
            "sources": [
                {"type": "sphere", "instances": 6},
                {"type": "box", "instances": 6},
                {"type": "freeform", "instances": 3, "subdivisions": 2},
            ],
        },
        "planes": {"count": [1, 2]},
        "sensor": ["webcam"],
    },
    "heterodyne, noisy 12-bit camera, interreflections, float64 labels": {
        "fringes": {"codings": ["heterodyne"], "steps": [4], "periods": [16]},
        "render": {"spp": 1, "bounces": 2},
        "sensor": ["imx174"],
        "planes": {"count": [1, 1]},
        "storage": {"shard_samples": 4, "label_dtype": "float64"},
    },
}


@pytest.fixture
def llvm(monkeypatch) -> None:
    monkeypatch.setenv("VIRTUS_MITSUBA_VARIANT", VARIANT)


def host_capture(spec, rendering) -> Capture:
    """The host capture of a device rendering (as ``Scanner.capture`` builds it)."""
    host = rendering.to_rendering()
    scanner = spec.scanner
    return Capture(
        sequence=scanner.sequence, rig=scanner.rig, frame_data=host.frames,
        cam2world=spec.cam2world, bit_depth=scanner.sensor.bit_depth, sensor=scanner.sensor,
        seed=spec.capture_seed, scene=spec.scene, gt_data=host.gt, render=host.metadata(),
    )  # fmt: skip


def assert_close_labels(host: dict, device: dict, layout, *, frames_exact: bool = True) -> None:
    for spec in layout:
        h, d = host[spec.name], device[spec.name]
        assert d.dtype == h.dtype and d.shape == h.shape, spec.name
        if spec.name == "frames" and not frames_exact:
            assert np.abs(h.astype(np.int64) - d.astype(np.int64)).max() <= 1
        elif spec.name in ("frames", "masks", "order", "object_id"):
            np.testing.assert_array_equal(d, h, err_msg=spec.name)
        elif spec.name in ("modulation", "numerator", "denominator"):
            scale = np.nanmax(np.abs(h)) if np.any(np.isfinite(h)) else 1.0
            np.testing.assert_allclose(d, h, rtol=0, atol=REAL_RTOL * scale, err_msg=spec.name)
        else:
            np.testing.assert_array_max_ulp(d, h, maxulp=STORED_ULPS)


@pytest.mark.parametrize("changes", CONFIGS.values(), ids=CONFIGS.keys())
def test_device_labels_match_host_labels(tmp_path, llvm, changes) -> None:
    config = load_config(tiny_config(tmp_path, **changes))
    randomiser = Randomiser(config, tmp_path / "assets")
    cam = randomiser.rig.camera.intrinsics
    layout = array_layout(
        randomiser.max_frames, cam.height, cam.width, randomiser.bit_depth, config.label_dtype
    )
    checked_objects = 0
    kept = device_shard_buffer(layout, 2, "cpu")  # torch's CPU stands in for the GPU
    for tensor in kept.values():
        tensor.view(torch.uint8).fill_(0x5A)  # every byte must be written
    for index in range(4):
        spec = randomiser.sample(index)
        rendering = spec.scanner.render_on_device(
            spec.scene, cam2world=spec.cam2world, rng=spec.capture_seed
        )
        device = device_sample_arrays(rendering, spec, layout)
        # made in the device buffer and copied from it: the same arrays, on both sides
        slot = {name: tensor[index % 2] for name, tensor in kept.items()}
        through = device_sample_arrays(rendering, spec, layout, on_device=slot)
        for array in layout:
            name = array.name
            np.testing.assert_array_equal(through[name], device[name], err_msg=name)
            on_device = slot[name].reshape(-1).view(torch.uint8).numpy()
            assert on_device.tobytes() == device[name].tobytes(), name
        host = sample_arrays(host_capture(spec, rendering), spec, layout)
        assert_close_labels(host, device, layout)
        valid = host["masks"][0]
        assert valid.any()  # the comparison covers decodable pixels
        checked_objects += len(np.unique(host["object_id"][host["object_id"] > 0]))
    assert checked_objects >= 4  # several objects were told apart


def test_device_labels_refuse_a_trace_without_ground_truth(tmp_path, llvm) -> None:
    import dataclasses

    from virtus.errors import VirtusError

    config = load_config(tiny_config(tmp_path))
    randomiser = Randomiser(config, tmp_path / "assets")
    spec = randomiser.sample(0)
    rendering = spec.scanner.render_on_device(spec.scene, cam2world=spec.cam2world)
    bare = dataclasses.replace(
        rendering, trace=dataclasses.replace(rendering.trace, device_truth=None)
    )
    cam = randomiser.rig.camera.intrinsics
    layout = array_layout(randomiser.max_frames, cam.height, cam.width, 8, "float32")
    with pytest.raises(VirtusError, match="ground truth"):
        device_sample_arrays(bare, spec, layout)


def store_arrays(path: Path) -> dict[int, dict[str, np.ndarray]]:
    store = DatasetStore.open(path)
    return {index: store.read_sample(index) for index in sorted(store.samples())}


def test_generate_labels_on_the_device_as_on_the_host(tmp_path, llvm, monkeypatch) -> None:
    """A store labelled on the device: verified, same metadata, labels within the twin's
    tolerances of a host-labelled store (frames within 1 DN: the host synthesises its own);
    and the same bytes when generated again (kill/resume relies on it)."""
    config = load_config(tiny_config(tmp_path, num_samples=6))
    monkeypatch.setattr(task_module, "LABELS_ON_DEVICE", False)
    generate(config, tmp_path / "host")
    monkeypatch.setattr(task_module, "LABELS_ON_DEVICE", True)
    report = generate(config, tmp_path / "device")
    assert report.complete == 6
    store = DatasetStore.open(tmp_path / "device")
    assert store.verify().ok
    host, device = store_arrays(tmp_path / "host"), store_arrays(tmp_path / "device")
    assert host.keys() == device.keys() == set(range(6))
    for index in host:
        h, d = dict(host[index]), dict(device[index])
        # Labels that depend on the frames (modulation and what scales with it, saturation)
        # may move with a 1 DN frame difference; the rest must agree as in the twin test.
        for name in ("modulation", "numerator", "denominator"):
            np.testing.assert_allclose(d[name], h[name], rtol=0.05, atol=0.5, equal_nan=True)
            h.pop(name), d.pop(name)
        h["masks"], d["masks"] = h["masks"][:5], d["masks"][:5]
        layout = [a for a in store.layout if a.name in h]
        assert_close_labels(h, d, layout, frames_exact=False)
    generate(config, tmp_path / "again")
    again = store_arrays(tmp_path / "again")
    for index in device:
        for name, value in device[index].items():
            np.testing.assert_array_equal(again[index][name], value, err_msg=name)


@pytest.mark.parametrize("pipelined", [True, False], ids=["pipelined", "shard by shard"])
def test_the_gpu_compressor_reads_the_device_buffers(tmp_path, llvm, monkeypatch, pipelined):
    """Labelled on the device and compressed on the GPU path (its CPU twin reading torch's
    CPU tensors as nvCOMP reads CUDA ones): every batch comes from the device buffers, and
    the store's chunk files are byte for byte those of the same run compressing the host's
    copies."""
    monkeypatch.setattr(task_module, "LABELS_ON_DEVICE", True)
    monkeypatch.setenv(codecs.FAKE_NVCOMP_ENV, "1")
    monkeypatch.setattr(codecs, "_PROCESS_COMPRESSOR", {})
    storage = {"shard_samples": 4, "codec": "shuffle-zstd", "compress_on": "gpu"}
    config = load_config(tiny_config(tmp_path, num_samples=6, storage=storage))
    if not pipelined:  # room for one shard in memory, not two: no pipeline
        layout = generate_module._layout(config, tmp_path / "layout")[1]
        monkeypatch.setattr(generate_module, "MAX_SHARD_BYTES", layout * 3 // 2)
    from_device = []
    encode = codecs.CpuZstdFrames.encode_chunks

    def spy(self, chunks, sizes, on_device=None):
        from_device.append(on_device is not None)
        return encode(self, chunks, sizes, on_device)

    monkeypatch.setattr(codecs.CpuZstdFrames, "encode_chunks", spy)
    generate(config, tmp_path / "device")
    assert from_device and all(from_device)
    from_device.clear()
    monkeypatch.setattr(task_module, "staging_device", lambda *args: None)
    generate(config, tmp_path / "host")
    assert from_device and not any(from_device)
    device, host = store_files(tmp_path / "device"), store_files(tmp_path / "host")
    chunks = [name for name in device if "/c/" in name]
    assert len(chunks) >= 13 * 2
    assert {n: device[n] for n in chunks} == {n: host[n] for n in chunks}
    assert DatasetStore.open(tmp_path / "device").verify().ok


def test_a_gpu_run_without_room_keeps_its_samples_on_the_host(tmp_path, monkeypatch) -> None:
    config = load_config(tiny_config(tmp_path, num_samples=2))
    generate(config, tmp_path / "store")
    store = DatasetStore.open(tmp_path / "store")
    monkeypatch.setattr(task_module, "_staging_device", lambda store: "cuda")
    monkeypatch.setattr(task_module, "device_shard_buffer", lambda *args: "on the GPU")
    locked = {"frames": "page-locked"}
    monkeypatch.setattr(task_module, "page_locked_shard_buffer", lambda *args: locked)
    assert task_module._new_shard_buffers(store) == (locked, "on the GPU")

    def refused(*args):
        raise RuntimeError("CUDA error: out of memory")

    monkeypatch.setattr(task_module, "page_locked_shard_buffer", refused)
    host, device = task_module._new_shard_buffers(store)
    assert device == "on the GPU"
    assert host.keys() == {a.name for a in store.layout}
    assert all(host[a.name].shape == (store.shard_samples, *a.shape) for a in store.layout)
    monkeypatch.setattr(task_module, "device_shard_buffer", refused)  # no room on the GPU
    host, device = task_module._new_shard_buffers(store)
    assert device is None and host.keys() == {a.name for a in store.layout}
