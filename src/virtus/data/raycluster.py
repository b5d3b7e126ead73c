"""Dataset tasks on a Ray cluster: connecting within a timeout, shard tasks on its CPUs,
and shard workers pinned to its GPUs.

* :func:`connect_ray` -- connect this process to a cluster (or start one), or refuse the
  address in one line within ``timeout`` seconds (Ray itself retries for minutes).
* :func:`gpu_slots` -- how many GPU workers a run starts and the GPU share each asks for:
  ``--gpus`` GPUs (default: all the cluster's) x ``--workers-per-gpu`` (fractional GPUs,
  ``1 / workers_per_gpu``), none when the cluster has no GPU resource.
* :func:`run_tasks` -- one Ray task per shard (``num_cpus=1``), for CPU clusters.
* :func:`run_actors` -- one long-lived actor per GPU slot: Ray gives each its GPU
  (``num_gpus``; Ray sets the actor's ``CUDA_VISIBLE_DEVICES`` before any of its code
  runs) and it renders shard after shard there, its renderer compiled once. A task would
  not do: Ray may run a later task in the same worker process on another GPU, but CUDA
  keeps the device a process started on.

The shard function is passed in (:func:`virtus.data.shardtask.render_shard`): it depends on
the store and the shard only, so a store made here is the one a local run makes.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import socket
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Any

from virtus.data.devices import gpu_count, variant_forces_cpu
from virtus.errors import InputError

__all__ = [
    "MAX_RAY_TIMEOUT_S",
    "RAY_TIMEOUT_S",
    "connect_ray",
    "gpu_slots",
    "run_actors",
    "run_tasks",
]

#: Seconds a Ray cluster address has to answer (``--ray-timeout``): Ray itself retries an
#: unreachable address for minutes (20 attempts of ~40 s in Ray 2.x).
RAY_TIMEOUT_S = 15.0
#: Longest ``ray_timeout`` accepted, seconds.
MAX_RAY_TIMEOUT_S = 3600.0
#: Times Ray restarts a GPU actor that died, and retries a shard that was on it.
_RETRIES = 3


def _ray_endpoint(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of a Ray cluster address (``host:port``, ``ray://host:port``);
    None for ``"auto"`` and ``"local"``."""
    if address in ("auto", "local"):
        return None
    host, colon, port = address.removeprefix("ray://").rpartition(":")
    host = host.removeprefix("[").removesuffix("]")  # [IPv6]:port
    if not colon or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError("--ray", "'auto', 'local' or a cluster address host:port", address)
    return host, int(port)


def _within(seconds: float, name: str, work: Callable[[], Any]) -> Any:
    """``work()`` on a daemon thread: its value or its exception, or :class:`TimeoutError`
    when it has not returned after ``seconds`` (it is then left to finish on its own: a
    connection attempt that Ray or the resolver cannot be told to abandon)."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = work()
        except BaseException as error:  # handed to the caller
            box["error"] = error

    thread = threading.Thread(target=run, name=name, daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        raise TimeoutError(f"no answer within {seconds:g} s")
    if "error" in box:
        raise box["error"]
    return box.get("value")


class _NotMainThread(logging.Filter):
    """Drops Ray's warning that ``ray.init`` runs off the main thread (on purpose here)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "not the main thread" not in record.getMessage()


def connect_ray(address: str, timeout: float = RAY_TIMEOUT_S) -> Any:
    """Connect this process to a Ray cluster, or give up after ``timeout`` seconds.

    Parameters
    ----------
    address : ``"auto"`` (the running cluster), ``"local"`` (start one here) or a cluster
        address ``host:port``; a Ray session already initialised in this process is used
        as it is.
    timeout : seconds the address has to accept a connection and Ray to connect to it.

    Returns
    -------
    The ``ray`` module, initialised.

    Raises
    ------
    InputError : Ray is not installed, the address is malformed, or no cluster answered
        there in time (the address named, with the reason: refused, unknown host, no
        answer).
    """
    try:
        import ray
    except ImportError:
        raise InputError(
            "--ray", "Ray installed (pip install 'virtus-fpp[data]' or ray)", "no ray module"
        ) from None
    if ray.is_initialized():
        return ray
    endpoint = _ray_endpoint(address)
    if address == "local":  # a cluster started here: nothing to wait for
        ray.init(log_to_driver=False)
        return ray
    expected = f"the address of a running Ray cluster that answers within {timeout:g} s"
    deadline = time.monotonic() + timeout
    if endpoint is not None:  # refused, unknown or unreachable: known before Ray is asked

        def probe() -> None:
            socket.create_connection(endpoint, timeout=timeout).close()

        try:
            _within(timeout, "virtus-ray-probe", probe)
        except OSError as error:  # TimeoutError included
            reason = error.strerror or str(error) or type(error).__name__
            raise InputError("--ray", expected, f"{address} ({reason})") from None
    log = logging.getLogger("ray._private.worker")
    quiet = _NotMainThread()
    log.addFilter(quiet)
    try:
        _within(
            max(deadline - time.monotonic(), 1.0), "virtus-ray-init",
            functools.partial(ray.init, address=address, log_to_driver=False),
        )  # fmt: skip
    except TimeoutError:
        raise InputError("--ray", expected, f"{address} (Ray did not connect in time)") from None
    except Exception as error:  # Ray raises many types for a failed connection
        reason = " ".join(str(error).split())[:160]
        raise InputError("--ray", expected, f"{address} ({reason})") from None
    finally:
        log.removeFilter(quiet)
    return ray


def gpu_slots(
    ray: Any,
    gpus: int | str | None,
    workers_per_gpu: int | None,
    environ: Mapping[str, str] | None = None,
) -> tuple[int, float]:
    """GPU workers to start on the cluster and the GPU share each asks for: ``(0, 0.0)``
    (CPU tasks) when the cluster has no GPU resource, or ``gpus`` is not given and
    ``$VIRTUS_MITSUBA_VARIANT`` forces the CPU; else ``(G * m, 1 / m)`` for ``G`` GPUs
    (``gpus``, default all of the cluster's whole GPUs) and ``m = workers_per_gpu``
    (default 1; the share is rounded down to Ray's 1e-4 resolution).

    Raises
    ------
    InputError : ``gpus`` not a positive integer or 'all', more than the cluster has;
        ``workers_per_gpu`` without GPUs.
    """
    environ = os.environ if environ is None else environ
    available = int(ray.cluster_resources().get("GPU", 0))
    count = gpu_count(gpus, available, "of the Ray cluster")
    if count is None:
        count = 0 if variant_forces_cpu(environ) else available
    if count == 0:
        if workers_per_gpu is not None:
            raise InputError("--workers-per-gpu", "GPUs to render on", "no GPU in the cluster")
        return 0, 0.0
    per_gpu = workers_per_gpu or 1
    return count * per_gpu, math.floor(10_000 / per_gpu) / 10_000


def run_tasks(
    ray: Any, task: Callable[..., dict[str, Any]], args: Callable[[int], tuple],
    shards: list[int], in_flight: int,
) -> Iterator[dict[str, Any]]:  # fmt: skip
    """``task(*args(shard))`` for every shard as Ray tasks of one CPU each (retried up to
    three times), at most ``in_flight`` at a time; yields the results as they finish."""
    remote = ray.remote(num_cpus=1, max_retries=_RETRIES)(task)
    queue: Iterable[int] = iter(shards)
    first = [s for _, s in zip(range(in_flight), queue, strict=False)]
    pending = [remote.remote(*args(s)) for s in first]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        yield ray.get(done[0])
        nxt = next(queue, None)  # type: ignore[call-overload]
        if nxt is not None:
            pending.append(remote.remote(*args(nxt)))


class _ShardWorker:
    """A Ray actor that runs shard tasks on the GPU Ray gave it."""

    def __init__(self, initializer: Callable[..., None], initargs: tuple) -> None:
        initializer(*initargs)

    def run(self, task: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
        return task(*args)


def run_actors(
    ray: Any, task: Callable[..., dict[str, Any]], args: Callable[[int], tuple],
    shards: list[int], slots: int, gpu_share: float,
    initializer: Callable[..., None], initargs: tuple,
) -> Iterator[dict[str, Any]]:  # fmt: skip
    """``task(*args(shard))`` for every shard on ``slots`` actors of ``gpu_share`` GPU
    each (:func:`gpu_slots`), two shards queued per actor; yields the results as they
    finish. Each actor runs ``initializer(*initargs)`` first; an actor that dies is
    restarted and its shards retried (three times). The actors are ended afterwards.

    The CPU share an actor asks for is the cluster's CPUs shared out (at most one), so
    every actor can be placed wherever the GPUs are.
    """
    cpus = float(ray.cluster_resources().get("CPU", 1))
    cpu_share = min(1.0, math.floor(10_000 * cpus / slots) / 10_000) or 0.0001
    actor = ray.remote(
        num_cpus=cpu_share, num_gpus=gpu_share, max_restarts=_RETRIES, max_task_retries=_RETRIES
    )(_ShardWorker)
    actors = [actor.remote(initializer, initargs) for _ in range(slots)]
    try:
        queue: Iterator[int] = iter(shards)
        pending: dict[Any, Any] = {}
        for _ in range(2):
            for worker in actors:
                shard = next(queue, None)
                if shard is not None:
                    pending[worker.run.remote(task, *args(shard))] = worker
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            worker = pending.pop(done[0])
            yield ray.get(done[0])
            shard = next(queue, None)
            if shard is not None:
                pending[worker.run.remote(task, *args(shard))] = worker
    finally:
        for worker in actors:
            ray.kill(worker)
