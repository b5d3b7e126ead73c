"""What a dataset worker imports before its first task, imported once by the process that
forks the workers (multiprocessing's fork server, :func:`virtus.data.devices.pinned_pool`)
instead of once by each of them.

Eight workers spawned at once on a 16-core H100 host each spent 4.7-7.8 s importing
``virtus.data`` and torch (with torch's CUDA context), forked from a server that had
imported them 0.1-0.2 s (``benchmarks/bench_worker_startup.py --processes 8``).

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
import trimesh  # noqa: F401  (free-form and mesh-folder objects)
import zarr  # noqa: F401

import virtus.data.shardtask  # noqa: F401

#: Optional modules imported when they can be (GPU workers stage samples through torch).
OPTIONAL = ("torch",)

for _name in OPTIONAL:
    with contextlib.suppress(Exception):
        importlib.import_module(_name)
