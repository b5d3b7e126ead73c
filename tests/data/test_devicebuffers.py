"""Shard buffers of samples kept on the device (virtus.data.devicebuffers), on torch's CPU
device (CI has no GPU; the GPU's page-locked allocator is replaced by numpy's)."""

from __future__ import annotations

import types

import numpy as np
import pytest

from virtus.data.devicebuffers import (
    TORCH_DTYPES,
    copy_to_host,
    device_shard_buffer,
    page_locked_shard_buffer,
    staging_device,
    torch_view,
)
from virtus.data.labels import array_layout

torch = pytest.importorskip("torch")

LAYOUT_8 = array_layout(5, 6, 7, 8, "float32")
LAYOUT_12 = array_layout(3, 4, 5, 12, "float64")


def test_the_staging_device_is_the_renderers_when_the_compressor_reads_it() -> None:
    gpu = types.SimpleNamespace(torch_device="cuda")
    assert staging_device(gpu, True, "cuda") == "cuda"
    assert staging_device(gpu, False, "cuda") is None  # labelled on the host
    assert staging_device(gpu, True, "cpu") is None  # rendered elsewhere
    assert staging_device(types.SimpleNamespace(torch_device=None), True, "cuda") is None
    assert staging_device(None, True, "cuda") is None  # numcodecs, chunk by chunk


@pytest.mark.parametrize("layout", [LAYOUT_8, LAYOUT_12], ids=["8-bit", "12-bit"])
def test_page_locked_buffers_are_disjoint_aligned_views_of_one_block(layout) -> None:
    blocks = []

    def allocate(n: int) -> np.ndarray:
        blocks.append(np.zeros(n + 64, np.uint8)[1:][:n])  # misaligned on purpose
        return blocks[-1]

    buffer = page_locked_shard_buffer(layout, 3, allocate)
    assert len(blocks) == 1
    block = blocks[0]
    ends = []
    for spec in layout:
        array = buffer[spec.name]
        assert array.shape == (3, *spec.shape) and array.dtype == np.dtype(spec.dtype)
        assert array.base is not None and np.shares_memory(array, block)
        offset = array.ctypes.data - block.ctypes.data
        assert offset % 64 == 0
        ends.append((offset, offset + array.nbytes))
        array.reshape(-1).view(np.uint8)[...] = 1  # each writes only its own bytes
    assert all(a[1] <= b[0] for a, b in zip(ends, ends[1:], strict=False))
    assert ends[-1][1] <= block.size
    assert int(block.sum()) == sum(buffer[s.name].nbytes for s in layout)


@pytest.mark.parametrize("layout", [LAYOUT_8, LAYOUT_12], ids=["8-bit", "12-bit"])
def test_device_buffers_copy_to_host_byte_for_byte(layout) -> None:
    device = device_shard_buffer(layout, 2, "cpu")
    host = {s.name: np.empty((2, *s.shape), s.dtype) for s in layout}
    rng = np.random.default_rng(3)
    expected = {}
    for spec in layout:
        tensor = device[spec.name]
        assert tensor.shape == (2, *spec.shape)
        assert tensor.dtype == getattr(torch, TORCH_DTYPES[spec.dtype])
        assert tensor.element_size() == np.dtype(spec.dtype).itemsize
        values = rng.integers(0, 256, tensor.numel() * tensor.element_size(), dtype=np.uint8)
        if spec.dtype == "bool":
            values = values & 1
        if spec.dtype == "uint16":  # the full unsigned range, through int16
            values[1::2] = 0xFF
        tensor.view(torch.uint8).reshape(-1).copy_(torch.from_numpy(values))
        expected[spec.name] = values.view(spec.dtype).reshape(2, *spec.shape)
    copy_to_host(device, host)
    for spec in layout:
        np.testing.assert_array_equal(host[spec.name], expected[spec.name], err_msg=spec.name)
    for spec in layout:
        if spec.dtype == "uint16":
            assert host[spec.name].max() > 32767, spec.name  # no sign was lost
    view = torch_view(host["frames"])
    assert view.data_ptr() == host["frames"].ctypes.data  # no copy
