"""GPU discovery and worker placement (virtus.data.devices), on CPU with fake device lists:
which GPUs are visible, which worker gets which, and what each spawned worker of a real
pool sees (its ``CUDA_VISIBLE_DEVICES``, set before any renderer module is imported)."""

from __future__ import annotations

import importlib
import os
import stat
import sys
import time
from pathlib import Path

import pytest

from virtus.data.devices import (
    CUDA_ENV,
    FAKE_GPUS_ENV,
    Placement,
    assign,
    pinned,
    pinned_pool,
    plan,
    visible_gpus,
)
from virtus.errors import InputError

#: ``nvidia-smi -L`` of a host with two GPUs, the second split into two MIG instances.
NVIDIA_SMI_L = """GPU 0: NVIDIA H100 80GB HBM3 (UUID: GPU-11111111-2222-3333-4444-555555555555)
GPU 1: NVIDIA H100 80GB HBM3 (UUID: GPU-66666666-7777-8888-9999-000000000000)
  MIG 3g.40gb     Device  0: (UUID: MIG-aaaaaaaa-bbbb-cccc-dddd-eeeeeeeeeeee)
  MIG 3g.40gb     Device  1: (UUID: MIG-ffffffff-0000-1111-2222-333333333333)
"""


def fake_nvidia_smi(folder: Path, output: str, status: int = 0) -> str:
    """A ``nvidia-smi`` program in ``folder`` that prints ``output`` for ``-L``; returns a
    PATH holding only that folder."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "listing.txt").write_text(output)
    program = folder / "nvidia-smi"
    program.write_text(f'#!/bin/sh\n/bin/cat "{folder}/listing.txt"\nexit {status}\n')
    program.chmod(program.stat().st_mode | stat.S_IXUSR)
    return str(folder)


def test_visible_gpus_from_the_fake_list_cuda_visible_devices_and_nvidia_smi(tmp_path) -> None:
    assert visible_gpus({FAKE_GPUS_ENV: "3", CUDA_ENV: "7"}) == ("0", "1", "2")
    assert visible_gpus({FAKE_GPUS_ENV: "0"}) == ()
    assert visible_gpus({CUDA_ENV: "2, 5"}) == ("2", "5")
    assert visible_gpus({CUDA_ENV: "GPU-12ab-34,MIG-9f"}) == ("GPU-12ab-34", "MIG-9f")
    # as CUDA reads it: the entries before the first invalid one; "" and -1 hide every GPU
    assert visible_gpus({CUDA_ENV: "0,-1,1"}) == ("0",)
    assert visible_gpus({CUDA_ENV: ""}) == ()
    assert visible_gpus({CUDA_ENV: "-1"}) == ()
    # no variable: nvidia-smi -L when it is on the PATH (MIG GPUs by their instances)
    path = fake_nvidia_smi(tmp_path / "smi", NVIDIA_SMI_L)
    assert visible_gpus({"PATH": path}) == (
        "0",
        "MIG-aaaaaaaa-bbbb-cccc-dddd-eeeeeeeeeeee",
        "MIG-ffffffff-0000-1111-2222-333333333333",
    )
    # set, CUDA_VISIBLE_DEVICES wins over nvidia-smi
    assert visible_gpus({"PATH": path, CUDA_ENV: "1"}) == ("1",)
    failing = fake_nvidia_smi(tmp_path / "failing", "NVIDIA-SMI has failed", status=9)
    assert visible_gpus({"PATH": failing}) == ()
    assert visible_gpus({"PATH": str(tmp_path / "nothing")}) == ()


def test_visible_gpus_reads_path_from_os_environ_when_not_given(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv(FAKE_GPUS_ENV, raising=False)
    monkeypatch.delenv(CUDA_ENV, raising=False)
    monkeypatch.setenv("PATH", fake_nvidia_smi(tmp_path, "GPU 0: A\nGPU 1: B\n"))
    assert visible_gpus() == ("0", "1")


@pytest.mark.parametrize("value", ["two", "-1", "1.5", "257", ""])
def test_a_bad_fake_gpu_count_is_refused_naming_the_variable(value) -> None:
    with pytest.raises(InputError, match=FAKE_GPUS_ENV):
        visible_gpus({FAKE_GPUS_ENV: value})


def test_assignment_puts_workers_round_robin_on_the_gpus() -> None:
    assert assign(["0", "1", "2"], 7) == ["0", "1", "2", "0", "1", "2", "0"]
    assert assign(["GPU-a"], 2) == ["GPU-a", "GPU-a"]
    with pytest.raises(InputError):
        assign([], 1)


def test_plan_uses_every_visible_gpu_and_shares_the_cores_out() -> None:
    four = {FAKE_GPUS_ENV: "4"}
    assert plan(environ=four, cores=16) == Placement(4, ("0", "1", "2", "3"), 4)
    eight = plan(workers_per_gpu=2, environ=four, cores=16)
    assert eight.workers == 8 and eight.threads == 2
    assert eight.worker_devices == ["0", "1", "2", "3"] * 2
    assert plan(gpus=2, environ=four, cores=16) == Placement(2, ("0", "1"), 8)
    assert plan(gpus="all", environ=four, cores=3) == Placement(4, ("0", "1", "2", "3"), 1)
    assert plan(gpus=" 3 ", workers_per_gpu=2, workers=6, environ=four, cores=12).threads == 2
    # --workers alone: spread over the GPUs; fewer workers than GPUs use the first ones
    assert plan(workers=6, environ=four, cores=12).worker_devices == ["0", "1", "2", "3", "0", "1"]
    assert plan(workers=2, environ=four, cores=12) == Placement(2, ("0", "1"), 6)
    # no GPU, or the CPU variant forced: one process (or --workers), no device
    assert plan(environ={FAKE_GPUS_ENV: "0"}, cores=8) == Placement(1, (), 8)
    assert plan(workers=4, environ={CUDA_ENV: ""}, cores=8) == Placement(4, (), 2)
    forced = {**four, "VIRTUS_MITSUBA_VARIANT": "llvm_ad_rgb"}
    assert plan(environ=forced, cores=8).devices == ()
    assert plan(gpus=2, environ=forced, cores=8).devices == ("0", "1")  # asked for: pinned


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gpus": 0}, "--gpus: expected a positive number of GPUs or 'all', got 0"),
        ({"gpus": "0"}, "--gpus: expected a positive number of GPUs or 'all', got '0'"),
        ({"gpus": "two"}, "--gpus: expected a positive number of GPUs or 'all', got 'two'"),
        ({"gpus": "1.5"}, "--gpus: expected a positive number of GPUs or 'all'"),
        ({"gpus": True}, "--gpus: expected a positive number"),
        ({"gpus": 3}, "--gpus: expected at most the 2 GPUs visible here (2: 0,1), got 3"),
        ({"gpus": "99999999999"}, "--gpus: expected a positive number"),
        ({"workers_per_gpu": 0}, "--workers-per-gpu: expected an integer in 1..256, got 0"),
        ({"workers": 0}, "workers: expected an integer in 1..256, got 0"),
        ({"workers_per_gpu": 200}, "workers (GPUs x workers a GPU): expected an integer in"),
        ({"workers": 3, "workers_per_gpu": 2}, "--workers: expected 2 GPUs x 2 workers a GPU"),
    ],
)
def test_plan_refuses_bad_counts_in_one_line(kwargs, message) -> None:
    with pytest.raises(InputError) as error:
        plan(**kwargs, environ={FAKE_GPUS_ENV: "2"}, cores=4)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_plan_refuses_gpus_where_none_is_visible() -> None:
    with pytest.raises(InputError, match=r"at most the 0 GPUs visible here \(none\), got 1"):
        plan(gpus=1, environ={CUDA_ENV: ""})
    with pytest.raises(InputError, match="--workers-per-gpu: expected GPUs to render on"):
        plan(workers_per_gpu=2, environ={CUDA_ENV: ""})


def _probe(barrier: str, workers: int) -> dict:
    """A pool task: what this worker sees. Waits until ``workers`` distinct workers have
    arrived (files in ``barrier``), so that every worker of the pool answers once."""
    generation = importlib.import_module("virtus.data.shardtask")
    store = importlib.import_module("virtus.data.store")
    folder = Path(barrier)
    (folder / str(os.getpid())).touch()
    deadline = time.monotonic() + 120  # a safety net, not a timing assumption
    while len(list(folder.iterdir())) < workers and time.monotonic() < deadline:
        time.sleep(0.02)
    return {
        "pid": os.getpid(),
        "env": os.environ.get(CUDA_ENV),
        "order": os.environ.get("CUDA_DEVICE_ORDER"),
        "pinned": pinned(),
        "threads": generation._WORKER_THREADS,
        "write_threads": store._WRITE_THREADS,
    }


def test_each_worker_of_a_real_pool_sees_its_own_gpu_before_the_renderer_loads(
    tmp_path, monkeypatch
) -> None:
    monkeypatch.delenv(CUDA_ENV, raising=False)
    monkeypatch.delenv("CUDA_DEVICE_ORDER", raising=False)
    generation = importlib.import_module("virtus.data.shardtask")
    assert pinned() is None  # not a worker
    with pinned_pool(2, ("GPU-a", "GPU-b"), generation.worker_init, (1, False)) as pool:
        answers = list(pool.map(_probe, [str(tmp_path)] * 2, [2] * 2))
    assert len({a["pid"] for a in answers}) == 2
    by_index = {a["pinned"]["index"]: a for a in answers}
    assert sorted(by_index) == [0, 1]
    for index, device in enumerate(["GPU-a", "GPU-b"]):
        answer = by_index[index]
        assert answer["env"] == device and answer["pinned"]["device"] == device
        assert answer["pinned"]["renderer_loaded"] == []  # CUDA_VISIBLE_DEVICES came first
        assert answer["pinned"]["cuda_started"] is False
        assert answer["pinned"]["blocking_waits"] is False  # no such GPU (or no driver) here
        assert answer["threads"] == 1 and answer["write_threads"] == 1
        assert answer["order"] == "PCI_BUS_ID"  # ordinals as nvidia-smi numbers them
    # without devices the workers are not pinned (and keep what they inherited)
    (tmp_path / "cpu").mkdir()
    with pinned_pool(1) as pool:
        answer = pool.submit(_probe, str(tmp_path / "cpu"), 1).result()
    assert answer["pinned"]["device"] is None and answer["env"] is None
    assert answer["pinned"]["blocking_waits"] is False  # a CPU worker never starts CUDA
    assert answer["order"] is None


def _surroundings(name: str) -> dict:
    """A pool task: the worker's value of ``name``, its working folder and its modules."""
    return {
        "value": os.environ.get(name),
        "cwd": os.getcwd(),
        "renderer_loaded": sorted(m for m in ("drjit", "mitsuba") if m in sys.modules),
    }


def test_a_worker_has_the_environment_and_folder_of_its_pools_maker_not_its_servers(
    tmp_path, monkeypatch
) -> None:
    name = "VIRTUS_TEST_POOL_VALUE"
    monkeypatch.setenv(name, "first")
    with pinned_pool(1) as pool:  # starts the fork server (once a process) if not started
        assert pool.submit(_surroundings, name).result()["value"] == "first"
    monkeypatch.setenv(name, "second")
    monkeypatch.chdir(tmp_path)
    with pinned_pool(1, ("GPU-a",)) as pool:
        seen = pool.submit(_surroundings, name).result()
    assert seen["value"] == "second" and seen["cwd"] == str(tmp_path)
    assert seen["renderer_loaded"] == []  # the server never imports the renderer
    monkeypatch.delenv(name)
    with pinned_pool(1) as pool:
        assert pool.submit(_surroundings, name).result()["value"] is None


#: ``python -c`` program: a pool of one worker set up as a run's (dying with its maker),
#: whose maker prints the worker's process id and is then killed by SIGKILL.
_KILLED_MAKER = """
import os, signal
from virtus.data.devices import pinned_pool
from virtus.data.shardtask import worker_init
pool = pinned_pool(1, ("GPU-a",), worker_init, (1,))
print(pool.submit(os.getpid).result(), flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_worker_dies_with_the_process_that_made_its_pool() -> None:
    import signal
    import subprocess

    # run() returns once every holder of the output pipes -- the worker and the fork server
    # among them -- has ended; the timeout is a safety net, not a timing assumption.
    killed = subprocess.run(
        [sys.executable, "-c", _KILLED_MAKER], capture_output=True, text=True, timeout=120
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    worker = int(killed.stdout.split()[0])
    deadline = time.monotonic() + 60
    while Path(f"/proc/{worker}").exists() and time.monotonic() < deadline:
        time.sleep(0.05)  # ended, but perhaps not yet reaped by its parent
    assert not Path(f"/proc/{worker}").exists() or _state(worker) == "Z"


def _state(pid: int) -> str:
    """A process's state letter (``/proc/<pid>/stat``; "" once it is gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return ""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's fork server")
def test_the_worker_server_starts_before_a_pool_and_forks_its_workers() -> None:
    from virtus.data.devices import start_worker_server, worker_server_pid

    start_worker_server()
    server = worker_server_pid()
    assert server is not None and Path(f"/proc/{server}").exists()
    with pinned_pool(2) as pool:
        parents = {pool.submit(os.getppid).result() for _ in range(2)}
    assert parents == {server}  # forked by the server, not by this process
    start_worker_server()  # already running: the same server
    assert worker_server_pid() == server
