"""The C allocator of virtus's processes: freed memory kept for reuse (glibc).

numpy takes its arrays from ``malloc``. By default glibc gives a block above its mmap
threshold a mapping of its own and hands freed memory at the top of its heap back to the
system above its trim threshold (both start at 128 KiB and adapt to what is freed), so a job
that makes and frees many temporaries of a few MB -- observing a calibration pose makes tens
of MB of them -- faults the same pages in again and again, and threads doing it side by side
wait on the kernel's memory map. :func:`keep_freed_memory` raises the mmap threshold to glibc's
largest (:data:`MMAP_THRESHOLD`, 32 MiB on 64-bit systems) and the trim threshold to
:data:`TRIM_THRESHOLD`: blocks below 32 MiB come from the heap, and freed memory is used again.

Measured on 2 CPU cores (8 observations of a paper calibration pose, ``virtus.calib.observe``):
1.39 s in one thread and 0.87 s in two with glibc's defaults, 1.02-1.07 s and 0.64-0.67 s with
these settings (trim thresholds of 64 MiB to 1 GiB alike); the process's peak memory 167 MB
against 186 MB. On an NVIDIA H100 host (16 cores), glibc's defaults and these settings
alternated, two rounds (``benchmarks/bench_calibrate.py --repeat 2 --skip-cli --malloc
default|virtus``; ``benchmarks/bench_dataset.py --codec shuffle-zstd --gpus 1
--workers-per-gpu 8 --samples 480 --shard 4 --no-renderer --malloc default|virtus``): the
warm calibration 1.76-2.23 s against 1.83-2.11 s (6 calls each: within the machine's noise),
dataset generation 1,245-1,421 images/s against 1,138-1,282 (steady part 1,829-2,058
against 1,632-1,740; 0.46-0.47 against 0.50 CPU-s a sample).

The ``virtus`` command calls it when it starts; a program using the library may call it too.
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Any

__all__ = ["ENVIRONMENT", "MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

#: glibc's largest mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``).
MMAP_THRESHOLD = 32 << 20
#: Freed memory kept at the top of the heap before glibc returns it (64 MiB did as well as
#: 1 GiB in the measurement of the module docstring).
TRIM_THRESHOLD = 64 << 20
#: The variables glibc reads when a process starts, and the values given to them.
ENVIRONMENT = {"MALLOC_MMAP_THRESHOLD_": MMAP_THRESHOLD, "MALLOC_TRIM_THRESHOLD_": TRIM_THRESHOLD}
#: ``mallopt`` parameter numbers (glibc's malloc.h) of each variable.
_MALLOPT = {"MALLOC_TRIM_THRESHOLD_": -1, "MALLOC_MMAP_THRESHOLD_": -3}


def keep_freed_memory() -> dict[str, int]:
    """Raise glibc's mmap and trim thresholds in this process (``mallopt``) and, through the
    variables glibc reads when a process starts (:data:`ENVIRONMENT`), in the processes it
    starts (e.g. dataset workers). A variable already set is left as it is, and its
    parameter untouched in this process: the user's choice wins.

    Returns
    -------
    The variables whose parameter this call set in this process (empty where the C library
    is not glibc, or every variable was already set).
    """
    libc = _glibc()
    changed = {}
    for name, value in ENVIRONMENT.items():
        if name in os.environ:
            continue
        os.environ[name] = str(value)
        if libc is not None and libc.mallopt(_MALLOPT[name], value) == 1:
            changed[name] = value
    return changed


def _glibc() -> Any:
    """This process's C library through ctypes if it is glibc (it has ``mallopt`` and
    ``gnu_get_libc_version``), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return None
    if not (hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt")):
        return None
    libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    libc.mallopt.restype = ctypes.c_int
    return libc
