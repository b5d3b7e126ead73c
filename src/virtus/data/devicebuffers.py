"""Shard buffers for samples that are labelled and compressed on the GPU that rendered them.

On a GPU with ``storage.compress_on: gpu`` a sample's arrays are made on the device
(:func:`virtus.data.labels_jit.device_sample_arrays`) into a **device shard buffer**
(:func:`device_shard_buffer`: torch tensors, one per array), which the GPU compressor reads
as it is (:meth:`virtus.data.chunkcodecs.NvcompZstdFrames.encode_chunks`); each array is
also copied once into the host shard buffer, where the checksums are taken
(:func:`copy_to_host`). With a **page-locked** host buffer (:func:`page_locked_shard_buffer`)
that copy is the GPU's DMA, with no work for the host's cores.

Before, the arrays came to the host in new (pageable) memory -- the driver copies through
its own staging buffer, the pages are faulted in, and the result is copied again into the
shard buffer -- and went back up to be compressed: about four passes of the host's cores
over the 133 MB of a 960 x 960 training sample. Measured on an NVIDIA H100 host (8
workers, 720 samples, ``shuffle-zstd`` on the GPU, alternated with the code before, two
rounds; ``benchmarks/bench_dataset.py --codec shuffle-zstd --compress-on gpu --gpus 1
--workers-per-gpu 8 --samples 720 --shard 4 --no-renderer``): 0.29-0.34 CPU-s a sample
against 0.33-0.36, 1,749-1,979 images/s in the steady part against 1,593-1,667.

Every function takes torch from the caller's environment (the ``gpu`` extra has it) and
works on torch's CPU device too, which is how the test suite runs this path without a GPU
(Mitsuba's ``llvm_ad_rgb`` variant hands its arrays to torch on the CPU).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from virtus.data.labels import ArraySpec

__all__ = [
    "TORCH_DTYPES",
    "copy_to_host",
    "device_shard_buffer",
    "page_locked_shard_buffer",
    "staging_device",
    "torch_view",
]

#: numpy dtype of a stored array -> torch dtype of its device twin: the same bytes (torch
#: has no general uint16, so 16-bit frames and object ids travel as int16).
TORCH_DTYPES = {
    "bool": "bool",
    "uint8": "uint8",
    "uint16": "int16",
    "int32": "int32",
    "float32": "float32",
    "float64": "float64",
}

#: Byte alignment of each array in a page-locked shard buffer (a cache line).
_ALIGN = 64


def _torch() -> Any:
    import torch

    return torch


def staging_device(compressor: Any, labels_on_device: bool, rendering_device: str) -> str | None:
    """Where a run keeps its samples for the compressor: ``rendering_device`` (``"cuda"``
    or ``"cpu"``, where the renderer's arrays live) when the samples are labelled there and
    the batch ``compressor`` reads torch tensors on that device (its ``torch_device``);
    None otherwise (the compressor reads the host shard buffer)."""
    device = getattr(compressor, "torch_device", None)
    if not labels_on_device or device is None or device != rendering_device:
        return None
    return device


def device_shard_buffer(layout: tuple[ArraySpec, ...], count: int, device: str) -> dict[str, Any]:
    """Uninitialised device arrays for ``count`` samples: name -> (count, *shape) torch
    tensor of the array's :data:`TORCH_DTYPES` twin on ``device``."""
    torch = _torch()
    return {
        a.name: torch.empty((count, *a.shape), dtype=getattr(torch, TORCH_DTYPES[a.dtype]),
                            device=device)
        for a in layout
    }  # fmt: skip


def page_locked_shard_buffer(
    layout: tuple[ArraySpec, ...], count: int, allocate: Callable[[int], np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """:meth:`virtus.data.store.DatasetStore.shard_buffer` in one page-locked block, so
    copies from the GPU into it are DMA: name -> (count, *shape) array of the layout's
    dtype, each 64-byte aligned in the block (which the arrays keep alive).

    ``allocate(n)`` makes the (n,) uint8 block: default torch's pinned allocator (needs a
    CUDA device)."""
    if allocate is None:
        torch = _torch()

        def allocate(n: int) -> np.ndarray:
            return torch.empty(n, dtype=torch.uint8, pin_memory=True).numpy()

    offsets, end = [], 0
    for a in layout:
        end = -(-end // _ALIGN) * _ALIGN
        offsets.append(end)
        end += count * a.nbytes
    block = allocate(max(end, 1))
    return {
        a.name: block[start : start + count * a.nbytes].view(a.dtype).reshape(count, *a.shape)
        for a, start in zip(layout, offsets, strict=True)
    }


def torch_view(array: np.ndarray) -> Any:
    """A host array as a torch tensor over the same memory, in its :data:`TORCH_DTYPES`
    twin dtype."""
    torch = _torch()
    twin = np.dtype(TORCH_DTYPES[array.dtype.name])
    return torch.from_numpy(array.view(twin) if twin != array.dtype else array)


def copy_to_host(on_device: dict[str, Any], out: dict[str, np.ndarray]) -> None:
    """Copy every device array into the host array of the same name (same shape; host
    dtypes as the layout's, device ones their :data:`TORCH_DTYPES` twins)."""
    for name, target in out.items():
        torch_view(target).copy_(on_device[name])
