"""What a dataset worker imports before its first task, imported once by the process that
forks the workers (multiprocessing's fork server, :func:`virtus.data.devices.pinned_pool`)
instead of once by each of them.

Eight workers started at once on a 16-core GPU host each spent 1.3-1.8 s importing
``virtus.data`` and 3.6-4.9 s importing torch (``benchmarks/bench_worker_startup.py``);
forked from a server that has imported them, a worker starts with them in memory.

Nothing here may start CUDA or a thread that a fork would lose: Dr.Jit starts a thread
when it is imported and Mitsuba imports Dr.Jit, so each worker imports those itself,
after it has been pinned to its GPU. numpy's and SciPy's OpenBLAS thread pools are made
again in a forked child (``pthread_atfork``); torch starts no thread and no CUDA when
imported (it is optional: a missing or broken torch is left to the workers that need it).
"""

from __future__ import annotations

import contextlib
import importlib

import numcodecs  # noqa: F401
import zarr  # noqa: F401

import virtus.data.shardtask  # noqa: F401

#: Optional modules imported when they can be (GPU workers stage samples through torch).
OPTIONAL = ("torch",)

for _name in OPTIONAL:
    with contextlib.suppress(Exception):
        importlib.import_module(_name)
