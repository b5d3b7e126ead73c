"""Where a calibration observes its poses: threads of this process (the default), worker
processes, or one pose after the other here.

Observing a pose (:func:`~virtus.calib.observe.observe_arrays`: circle detection,
centroids, local homographies) is OpenCV and batched numpy work that releases the GIL
(the centroids and homographies batched on the GPU instead when the poses render there:
:func:`~virtus.calib.observe.observation_device`), so threads observe poses side by side while the
caller renders the next ones, sharing each pose's decode in place. Worker processes
(spawned: a renderer's threads and device context are not forked) each start an
interpreter and import virtus, every pose's decode (~30 MB at 960 x 960 px) is pickled to
them, and they observe on the host. Measured on 2 cores (``benchmarks/bench_calibrate.py``).
The observations do not depend on the choice (on the device: to rounding).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

from virtus.calib.observe import observe_arrays
from virtus.calib.solve import PoseObservation
from virtus.errors import InputError

__all__ = [
    "MAX_OBSERVE_PROCESSES",
    "MAX_OBSERVE_THREADS",
    "Observers",
    "observe_threads",
    "observe_timed",
    "observer_pool",
    "observers",
]

#: Most worker processes a caller may ask for.
MAX_OBSERVE_PROCESSES = 8
#: Most threads that observe poses by default (one per CPU up to this). On an H200 host (16
#: cores) 18 decoded poses were observed in 1.27-1.53 s by 4 threads, 1.35-1.78 s by 8 and
#: 1.73-2.19 s by 16 (``benchmarks/bench_calibrate.py``): beyond 4 they only contend for the
#: GIL -- with the thread that renders the next pose (33 ms a pose alone, 105 ms beside 8).
MAX_OBSERVE_THREADS = 4


@dataclass(frozen=True)
class Observers:
    """How poses are observed: ``kind`` ``"here"`` (in the calling thread, one after the
    other), ``"threads"`` or ``"processes"``, and ``count`` workers (0 for ``"here"``)."""

    kind: str
    count: int

    @property
    def in_flight(self) -> int:
        """Poses submitted but not yet taken back that the caller may hold (each holds its
        decode): one per worker, none when observing here."""
        return self.count


def observe_threads() -> int:
    """Threads that observe poses by default: one per CPU, at most
    :data:`MAX_OBSERVE_THREADS`."""
    return max(1, min(MAX_OBSERVE_THREADS, os.cpu_count() or 1))


def observers(processes: int | None) -> Observers:
    """The observers of a calibration's ``processes`` argument: None, threads
    (:func:`observe_threads`); 0, here; N in 1..:data:`MAX_OBSERVE_PROCESSES`, N worker
    processes. Anything else is an :class:`InputError`."""
    if processes is None:
        return Observers("threads", observe_threads())
    if (
        isinstance(processes, bool)
        or not isinstance(processes, int)
        or not 0 <= processes <= MAX_OBSERVE_PROCESSES
    ):
        raise InputError("processes", f"an integer in 0..{MAX_OBSERVE_PROCESSES}", processes)
    return Observers("here", 0) if processes == 0 else Observers("processes", processes)


def observe_timed(*arguments: Any, **options: Any) -> tuple[PoseObservation, float]:
    """:func:`~virtus.calib.observe.observe_arrays` and the seconds it took (in a worker
    thread, a worker process or here)."""
    start = time.perf_counter()
    return observe_arrays(*arguments, **options), time.perf_counter() - start


class _Here:
    """An executor that runs each submitted call at once, here (``submit`` returns a done
    :class:`~concurrent.futures.Future`)."""

    def submit(self, function: Callable, *arguments: Any, **options: Any) -> Future:
        future: Future = Future()
        future.set_result(function(*arguments, **options))
        return future


@contextlib.contextmanager
def observer_pool(chosen: Observers) -> Iterator[Any]:
    """An executor (``submit(function, *arguments, **options) -> Future``) of the ``chosen``
    observers; the workers end with the block."""
    if chosen.kind == "here":
        yield _Here()
        return
    if chosen.kind == "threads":
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(chosen.count, thread_name_prefix="virtus-observe") as threads:
            yield threads
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(chosen.count, mp_context=context) as pool:
        yield pool
