"""Copies from CUDA device memory into a kept, page-locked host buffer, through the CUDA
driver (:mod:`virtus.data.cudadriver`): how the GPU compressor
(:class:`virtus.data.chunkcodecs.NvcompZstdFrames`) brings its frames back.

Why not nvCOMP's own copy: ``.cpu()`` copies every frame into newly allocated host memory,
whose pages the kernel must first map. Measured on an NVIDIA H100 host, one 133 MB training
sample cut into 2,025 pieces: the Zstd kernel took 18-22 ms, ``.cpu()`` of its frames
47-58 ms, one ``.cpu()`` of the whole output buffer 57-145 ms (over nvCOMP's algorithms),
and one driver copy of that buffer into a kept page-locked buffer 2.4-2.5 ms (54 GB/s;
``benchmarks/bench_dataset.py --samples 1 --codecs`` prints both).

A :class:`HostCopier` belongs to one thread: the copies run on the thread's current CUDA
context (the one nvCOMP made current), and its buffer is overwritten by the next copy.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from virtus.data.cudadriver import driver

__all__ = ["HostCopier", "host_copier"]


def _device_address(array: Any) -> int:
    """Where a device array (``__cuda_array_interface__``) starts."""
    return array.__cuda_array_interface__["data"][0]


class HostCopier:
    """Device-to-host copies into one host buffer, kept (grown as needed) and page-locked
    where the driver allows it (copies into an unlocked one are correct, only slower).

    Parameters
    ----------
    driver : the CUDA driver library (:func:`virtus.data.cudadriver.driver`).
    """

    def __init__(self, driver: Any) -> None:
        self._driver = driver
        self._buffer = np.empty(0, np.uint8)
        self._locked = 0  # the locked buffer's address (0: none is locked)

    def copy(self, source: Any, nbytes: int) -> np.ndarray:
        """The first ``nbytes`` of ``source`` (device memory with
        ``__cuda_array_interface__``), as a (nbytes,) uint8 view of the kept buffer, valid
        until the next copy.

        Raises
        ------
        RuntimeError : the driver refused the copy (its error code said).
        """
        if self._buffer.size < nbytes:
            self._release()
            self._buffer = np.empty(nbytes, np.uint8)
            address = self._buffer.ctypes.data
            if self._driver.cuMemHostRegister_v2(address, nbytes, 0) == 0:
                self._locked = address
        host = self._buffer
        status = self._driver.cuMemcpyDtoH_v2(host.ctypes.data, _device_address(source), nbytes)
        if status != 0:
            raise RuntimeError(f"CUDA driver error {status} copying {nbytes} bytes to the host")
        return host[:nbytes]

    def _release(self) -> None:
        """Unlock the pages before the buffer goes (at exit the driver may already have let
        them go: its answer is not checked)."""
        if self._locked:
            self._driver.cuMemHostUnregister(self._locked)
            self._locked = 0

    def __del__(self) -> None:
        self._release()


def host_copier() -> HostCopier | None:
    """A copier for this thread, or None where the driver does not load or the thread has
    no current CUDA context (call it after nvCOMP has worked on the thread)."""
    lib = driver()
    if lib is None:
        return None
    context = ctypes.c_void_p()
    if lib.cuCtxGetCurrent(ctypes.byref(context)) != 0 or not context.value:
        return None
    return HostCopier(lib)
