"""The CUDA driver (``libcuda.so.1``, present wherever a CUDA device works), reached through
ctypes for the two things the dataset workers ask of it directly: copies into page-locked
host memory (:mod:`virtus.data.hostcopy`) and how a process waits for its GPU
(:func:`block_while_waiting`).

**Waiting.** By default a CUDA context whose process has fewer contexts than the machine
has cores *spins* on a core while it waits for the GPU. Eight dataset workers sharing one
GPU each wait most of the time for the others' kernels, so they spun on cores the other
workers' labelling, checksums and compression needed. Measured on an NVIDIA H100 host (16
cores; ``benchmarks/bench_dataset.py --codec shuffle-zstd --compress-on gpu --gpus 1
--workers-per-gpu 8 --samples 480 --shard 4 --no-renderer``, spinning and blocking
alternated, two rounds, the flag set at interpreter start-up): 1,426-1,731 images/s in the
steady part blocking against 1,213-1,502 spinning, 825-929 against 767-909 over the whole
run, 0.44-0.49 against 0.49-0.57 CPU-s a sample.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any

__all__ = ["DRIVER_LIBRARY", "block_while_waiting", "driver"]

#: The driver library every CUDA installation provides (the runtime links it at run time).
DRIVER_LIBRARY = "libcuda.so.1"
#: ``CU_CTX_SCHED_BLOCKING_SYNC``: a thread waiting for the GPU sleeps instead of spinning.
_BLOCKING_SYNC = 0x4


@functools.cache
def driver() -> Any:
    """The driver's library with the signatures used here, or None where it does not load
    (no NVIDIA driver on this machine)."""
    try:
        lib = ctypes.CDLL(DRIVER_LIBRARY)
    except OSError:
        return None
    size, pointer, address, integer = (
        ctypes.c_size_t,
        ctypes.c_void_p,
        ctypes.c_uint64,
        ctypes.c_int,
    )
    signatures = {
        "cuInit": [ctypes.c_uint],
        "cuDeviceGet": [ctypes.POINTER(integer), integer],
        "cuDevicePrimaryCtxSetFlags_v2": [integer, ctypes.c_uint],
        "cuCtxGetCurrent": [ctypes.POINTER(pointer)],
        "cuMemHostRegister_v2": [pointer, size, ctypes.c_uint],
        "cuMemHostUnregister": [pointer],
        "cuMemcpyDtoH_v2": [pointer, address, size],
    }
    for name, arguments in signatures.items():
        function = getattr(lib, name)
        function.argtypes, function.restype = arguments, ctypes.c_int
    return lib


def block_while_waiting() -> bool:
    """Make this process's threads sleep, not spin, while they wait for the first visible
    GPU (its primary context's scheduling flag, which Dr.Jit, OptiX and nvCOMP all use).
    Call it before anything in the process starts CUDA: the driver refuses to change an
    active context's flags. Whether it was set (False without a driver or a device, or
    when refused)."""
    lib = driver()
    if lib is None or lib.cuInit(0) != 0:
        return False
    device = ctypes.c_int()
    if lib.cuDeviceGet(ctypes.byref(device), 0) != 0:
        return False
    return lib.cuDevicePrimaryCtxSetFlags_v2(device, _BLOCKING_SYNC) == 0
