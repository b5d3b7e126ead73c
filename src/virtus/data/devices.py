"""GPUs for dataset workers: which are visible, how many a run uses, which worker gets which.

A dataset run on a host with several GPUs starts one or more worker processes per GPU and
pins each to its GPU through ``CUDA_VISIBLE_DEVICES``, set in the worker before Mitsuba or
Dr.Jit is imported and before anything starts CUDA (the CUDA driver reads it once, when it
starts). Nothing here imports torch, Mitsuba or Dr.Jit.

* :func:`visible_gpus` -- the GPUs this process may use, as ``CUDA_VISIBLE_DEVICES``
  entries: ``$VIRTUS_FAKE_GPUS`` (a testing hook, below), else ``$CUDA_VISIBLE_DEVICES``
  when set, else ``nvidia-smi -L`` when it is installed, else none.
* :func:`plan` -- a run's :class:`Placement` from ``--workers``, ``--gpus`` and
  ``--workers-per-gpu``: worker ``k`` renders on GPU ``k mod G`` of the ``G`` used
  (:func:`assign`), and the CPU threads each worker uses to synthesise, checksum and
  compress are the process's cores shared out (``cores // workers``).
* :func:`pinned_pool` -- a process pool whose ``k``-th worker is given its device by the
  pool initializer, from a counter shared by the workers. Workers are forked from a server
  process that has imported what they need (:mod:`virtus.data.workerimports`; Linux's
  ``forkserver``), else spawned.

Testing hook: ``VIRTUS_FAKE_GPUS=N`` makes ``N`` GPUs named ``"0"`` .. ``"N-1"`` visible,
so the assignment, the pinned pools and the resulting stores can be tested on a machine
without a GPU (the workers then render with whatever variant works, the CPU's).
"""

from __future__ import annotations

import multiprocessing
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

from virtus.data.config import MAX_WORKERS
from virtus.data.cudadriver import block_while_waiting
from virtus.errors import InputError

__all__ = [
    "FAKE_GPUS_ENV",
    "MAX_GPUS",
    "Placement",
    "assign",
    "cpu_cores",
    "die_with_pool_maker",
    "gpu_count",
    "pinned",
    "pinned_pool",
    "plan",
    "start_worker_server",
    "variant_forces_cpu",
    "visible_gpus",
    "worker_context",
    "worker_server_pid",
]

#: Testing hook: an integer ``N`` makes ``N`` fake GPUs ``"0"`` .. ``"N-1"`` visible.
FAKE_GPUS_ENV = "VIRTUS_FAKE_GPUS"
#: The CUDA runtime's device list, read by the driver when it starts in a process.
CUDA_ENV = "CUDA_VISIBLE_DEVICES"
#: How CUDA numbers GPUs: by default fastest first, nvidia-smi by PCI bus (the same order
#: on a host of identical GPUs); a worker pinned to an nvidia-smi ordinal uses the latter.
ORDER_ENV = "CUDA_DEVICE_ORDER"
#: Most GPUs a run may name (more than any host has; bounds every list made from it).
MAX_GPUS = 256
#: Seconds ``nvidia-smi -L`` may take before it is taken to have found nothing.
_NVIDIA_SMI_TIMEOUT_S = 20.0
#: A ``CUDA_VISIBLE_DEVICES`` entry: an ordinal or a GPU/MIG UUID (prefix).
_ENTRY = re.compile(r"\d+|(GPU|MIG)-[0-9A-Za-z/-]+")
#: The module the server that forks a pool's workers imports first (:func:`pinned_pool`).
WORKER_IMPORTS = "virtus.data.workerimports"
#: In a pinned worker: what :func:`_pin` did (see :func:`pinned`).
_PINNED: dict[str, Any] | None = None


def _cuda_entries(value: str) -> tuple[str, ...]:
    """The devices a ``CUDA_VISIBLE_DEVICES`` value makes visible: its entries up to the
    first that is not an ordinal or a UUID (as CUDA reads it: ``"0,-1,1"`` is GPU 0 only;
    ``""`` and ``"-1"`` are none)."""
    entries = []
    for entry in value.split(","):
        entry = entry.strip()
        if not _ENTRY.fullmatch(entry):
            break
        entries.append(entry)
    return tuple(entries[:MAX_GPUS])


def _nvidia_smi(path: str | None) -> tuple[str, ...]:
    """GPUs listed by ``nvidia-smi -L`` (found on ``path``, a PATH value): ordinals, or the
    UUIDs of a GPU's MIG instances (a MIG GPU is used through its instances); none when it
    is absent or fails."""
    program = shutil.which("nvidia-smi", path=path)
    if program is None:
        return ()
    try:
        listing = subprocess.run(
            [program, "-L"], capture_output=True, text=True, timeout=_NVIDIA_SMI_TIMEOUT_S,
            check=False,
        )  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return ()
    if listing.returncode != 0:
        return ()
    gpus: list[list[str]] = []  # [ordinal, MIG UUIDs...]
    for line in listing.stdout.splitlines():
        gpu = re.match(r"GPU (\d+):", line.strip())
        mig = re.search(r"\(UUID: (MIG-[^)\s]+)\)", line)
        if gpu:
            gpus.append([gpu.group(1)])
        elif mig and gpus and line.strip().startswith("MIG"):
            gpus[-1].append(mig.group(1))
    devices = [d for g in gpus for d in (g[1:] or g[:1])]
    return tuple(devices[:MAX_GPUS])


def visible_gpus(environ: Mapping[str, str] | None = None) -> tuple[str, ...]:
    """The GPUs this process may use, as ``CUDA_VISIBLE_DEVICES`` entries (ordinals such
    as ``"0"`` or UUIDs), in CUDA's order.

    ``$VIRTUS_FAKE_GPUS`` (testing hook: ``N`` fake GPUs ``"0"`` .. ``"N-1"``), else
    ``$CUDA_VISIBLE_DEVICES`` when set, else ``nvidia-smi -L`` when installed, else none.
    Torch is not imported and CUDA is not started.

    Raises
    ------
    InputError : ``$VIRTUS_FAKE_GPUS`` is not an integer in 0..:data:`MAX_GPUS`.
    """
    environ = os.environ if environ is None else environ
    fake = environ.get(FAKE_GPUS_ENV)
    if fake is not None:
        if not fake.strip().isdigit() or int(fake) > MAX_GPUS:
            raise InputError(FAKE_GPUS_ENV, f"an integer in 0..{MAX_GPUS}", fake)
        return tuple(str(k) for k in range(int(fake)))
    if CUDA_ENV in environ:
        return _cuda_entries(environ[CUDA_ENV])
    return _nvidia_smi(environ.get("PATH"))


def cpu_cores() -> int:
    """The CPUs this process may run on (its affinity where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def assign(devices: Sequence[str], workers: int) -> list[str]:
    """The device of each of ``workers`` workers: worker ``k`` gets ``devices[k mod G]``,
    so ``G * m`` workers put ``m`` on every device."""
    if not devices:
        raise InputError("devices", "at least one device", "none")
    return [devices[k % len(devices)] for k in range(workers)]


@dataclass(frozen=True)
class Placement:
    """Where a run's workers render.

    Attributes
    ----------
    workers : worker processes (1: the calling process renders).
    devices : the GPUs used (``CUDA_VISIBLE_DEVICES`` entries), one per GPU; empty on CPU.
    threads : CPU threads each worker uses to synthesise, checksum and compress
        (``cores // workers``, at least 1).
    """

    workers: int
    devices: tuple[str, ...]
    threads: int

    @property
    def worker_devices(self) -> list[str] | None:
        """Each worker's device (:func:`assign`), or None on CPU."""
        return assign(self.devices, self.workers) if self.devices else None


def _count(name: str, value: object, maximum: int = MAX_WORKERS) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= maximum:
        raise InputError(name, f"an integer in 1..{maximum}", value)
    return value


def gpu_count(gpus: int | str | None, available: int, where: str = "visible here") -> int | None:
    """The GPUs a run uses of ``available``: None (``--gpus`` not given) or ``"all"`` ->
    ``available``; an integer (or its text) in ``1..available``.

    Raises
    ------
    InputError : not a positive integer or ``"all"``; zero; more than ``available``
        (the message says how many are ``where``).
    """
    if gpus is None or (isinstance(gpus, str) and gpus.strip().lower() == "all"):
        return None if gpus is None else available
    text = gpus.strip() if isinstance(gpus, str) else gpus
    if isinstance(text, str) and text.isdigit() and len(text) <= 6:
        text = int(text)
    if isinstance(text, bool) or not isinstance(text, int) or text < 1:
        raise InputError("--gpus", "a positive number of GPUs or 'all'", gpus)
    if text > available:
        raise InputError("--gpus", f"at most the {available} GPUs {where}", text)
    return text


def variant_forces_cpu(environ: Mapping[str, str]) -> bool:
    """Whether the Mitsuba variant is forced to the CPU (``$VIRTUS_MITSUBA_VARIANT``)."""
    from virtus.render.backend import VARIANT_ENV  # a constant: Mitsuba is not imported

    return environ.get(VARIANT_ENV, "").startswith("llvm")


def plan(
    workers: int | None = None,
    gpus: int | str | None = None,
    workers_per_gpu: int | None = None,
    *,
    environ: Mapping[str, str] | None = None,
    cores: int | None = None,
) -> Placement:
    """Where a local run's workers render.

    Parameters
    ----------
    workers : worker processes in all; default: one per GPU used times ``workers_per_gpu``,
        or 1 (this process) without GPUs. Given, workers are spread round robin over the
        GPUs (with fewer workers than GPUs, only the first ``workers`` GPUs are used).
    gpus : GPUs to use, ``"all"`` or an integer (text accepted, ``--gpus``); default: all
        visible (:func:`visible_gpus`) unless ``$VIRTUS_MITSUBA_VARIANT`` forces the CPU.
    workers_per_gpu : worker processes per GPU (default 1); with ``workers`` too, their
        product with the GPUs must be ``workers``.
    environ, cores : the environment and the CPU count (default: this process's).

    Raises
    ------
    InputError : a count that is not a positive integer, more GPUs than visible,
        ``workers_per_gpu`` without GPUs or disagreeing with ``workers``, more than
        :data:`~virtus.data.config.MAX_WORKERS` workers.
    """
    environ = os.environ if environ is None else environ
    if workers is not None:
        _count("workers", workers)
    if workers_per_gpu is not None:
        _count("--workers-per-gpu", workers_per_gpu)
    visible = visible_gpus(environ)
    count = gpu_count(gpus, len(visible), f"visible here ({_described(visible)})")
    if count is None:
        count = 0 if variant_forces_cpu(environ) else len(visible)
    devices = visible[:count]
    if not devices:
        if workers_per_gpu is not None:
            raise InputError("--workers-per-gpu", "GPUs to render on", "no GPU visible")
        total = workers or 1
    else:
        per_gpu = workers_per_gpu or 1
        if workers is not None and workers_per_gpu is not None and workers != count * per_gpu:
            raise InputError(
                "--workers", f"{count} GPUs x {per_gpu} workers a GPU = {count * per_gpu}", workers
            )
        total = workers if workers is not None else count * per_gpu
        devices = devices[:total]
    _count("workers (GPUs x workers a GPU)", total)
    share = max(1, (cores or cpu_cores()) // total)
    return Placement(total, tuple(devices), share)


def _described(visible: Sequence[str]) -> str:
    return (
        "none"
        if not visible
        else f"{len(visible)}: {','.join(visible[:8])}" + (",..." if len(visible) > 8 else "")
    )


def _pin(
    counter: Any, devices: tuple[str, ...], then: Callable[..., None] | None, args: tuple,
    environ: dict[str, str] | None = None, maker: int | None = None,
) -> None:  # fmt: skip
    """Pool initializer: take on the pool's maker's ``environ`` (a forked worker has its
    server's, taken when the server started); take the next worker index from
    ``counter``; pin the process to its device (``CUDA_VISIBLE_DEVICES``, before anything
    may start CUDA); remember the ``maker``'s process id (:func:`die_with_pool_maker`);
    run ``then``."""
    global _PINNED
    if environ is not None:
        os.environ.clear()
        os.environ.update(environ)
    with counter.get_lock():
        index = counter.value
        counter.value += 1
    device = assign(devices, index + 1)[index] if devices else None
    if device is not None:
        if CUDA_ENV not in os.environ:  # ordinals from nvidia-smi: number GPUs as it does
            os.environ.setdefault(ORDER_ENV, "PCI_BUS_ID")
        os.environ[CUDA_ENV] = device
    _PINNED = {
        "index": index,
        "device": device,
        "maker": maker,
        "renderer_loaded": sorted(m for m in ("drjit", "mitsuba") if m in sys.modules),
        "cuda_started": _cuda_started(),
        # Workers sharing a GPU wait for it most of the time: asleep, not spinning on cores.
        "blocking_waits": device is not None and block_while_waiting(),
    }
    if then is not None:
        then(*args)


def _cuda_started() -> bool:
    """Whether torch has started CUDA in this process (the fork server may have imported
    torch, which loads the CUDA driver library but does not start it)."""
    torch = sys.modules.get("torch")
    return torch is not None and bool(torch.cuda.is_initialized())


def die_with_pool_maker() -> None:
    """Be killed (SIGKILL) as soon as the process that made this worker's pool ends (the
    parent outside a :func:`pinned_pool`), so that a killed run leaves no worker writing
    into its store (Linux; elsewhere nothing is done).

    A pool's task queues are pipes every worker also holds the writing end of, so a worker
    is not told that its maker has gone. Where the maker is the parent, the kernel sends
    the signal (``PR_SET_PDEATHSIG``); a worker forked by the fork server (whose parent is
    the server, which lives as long as any of its children) is killed by a daemon thread
    waiting on the maker (a pidfd, which is readable once it has ended)."""
    import signal
    import threading

    maker = (_PINNED or {}).get("maker") or os.getppid()
    if maker == os.getppid():
        try:
            import ctypes

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            return
        if os.getppid() != maker:  # it ended before the request
            os.kill(os.getpid(), signal.SIGKILL)
        return
    try:
        handle = os.pidfd_open(maker)
    except ProcessLookupError:
        os.kill(os.getpid(), signal.SIGKILL)
    except (OSError, AttributeError):  # no pidfd here (kernel before 5.3, not Linux)
        return
    threading.Thread(
        target=_die_when_readable, args=(handle,), name="virtus-die-with-maker", daemon=True
    ).start()


def _die_when_readable(handle: int) -> None:
    """Kill this process once ``handle`` (a pidfd) is readable: its process has ended."""
    import select
    import signal

    select.select([handle], [], [])
    os.kill(os.getpid(), signal.SIGKILL)


def pinned() -> dict[str, Any] | None:
    """In a worker of :func:`pinned_pool`: its ``index``, its ``device`` (None on CPU),
    ``maker``, the process id of the process that made the pool,
    ``renderer_loaded``, the renderer modules already imported when it was pinned (none),
    ``cuda_started``, whether CUDA had started by then (never),
    and ``blocking_waits``, whether its threads sleep while they wait for the GPU
    (:func:`virtus.data.cudadriver.block_while_waiting`); None in any other process."""
    return None if _PINNED is None else dict(_PINNED)


def start_worker_server() -> None:
    """Start the fork server of :func:`pinned_pool` now, where there is one: it imports
    :data:`WORKER_IMPORTS` while the caller goes on (a run checks its inputs and probes the
    GPU meanwhile), and the pool made later finds it ready. Nothing is done where workers
    are spawned or the server already runs."""
    if worker_context().get_start_method() == "forkserver":
        import multiprocessing.forkserver

        multiprocessing.forkserver.ensure_running()


def worker_server_pid() -> int | None:
    """The process id of the fork server that forks :func:`pinned_pool`'s workers (their
    parent, which reaps them), or None where none has started in this process."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return None
    from multiprocessing import forkserver

    return getattr(forkserver._forkserver, "_forkserver_pid", None)


def worker_context() -> Any:
    """The multiprocessing context of :func:`pinned_pool`'s workers (also for benchmarks
    that start workers as a run does): the fork server's
    (importing :data:`WORKER_IMPORTS` first) where the platform has one, else spawn's."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([WORKER_IMPORTS])
    return context


def pinned_pool(
    workers: int,
    devices: Sequence[str] = (),
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes; the ``k``-th started is pinned to
    ``devices[k mod G]`` (:func:`assign`; none when ``devices`` is empty), then runs
    ``initializer(*initargs)``. Each worker has this process's environment, working
    folder and ``sys.path``.

    The workers are forked from multiprocessing's fork server, which imports
    :data:`WORKER_IMPORTS` once when it starts (the first pool of this process starts it),
    where the platform has one; else spawned. Never forked from this process: it may hold
    CUDA state and threads.

    ``initializer`` and the tasks must be importable functions (they are pickled by name).
    """
    _count("workers", workers)
    context = worker_context()
    counter = context.Value("i", 0)
    return ProcessPoolExecutor(
        workers, mp_context=context, initializer=_pin,
        initargs=(counter, tuple(devices), initializer, initargs, dict(os.environ), os.getpid()),
    )  # fmt: skip
