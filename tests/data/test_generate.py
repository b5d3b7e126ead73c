"""Dataset generation across GPUs (virtus.data.generate with virtus.data.devices), on CPU
with fake device lists (``VIRTUS_FAKE_GPUS``): a store made by workers pinned to two GPUs
is byte for byte the one-GPU store, a killed multi-GPU run resumes to the same bytes, and
bad ``--gpus`` / ``--workers-per-gpu`` values are refused in one line before any work."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.data.test_dataset import run_cli, store_files, tiny_config
from virtus.data import DatasetStore, generate, load_config
from virtus.data.devices import CUDA_ENV, FAKE_GPUS_ENV, worker_server_pid
from virtus.data.generate import _TASK_SHARDS, wait_for_workers


def test_two_pinned_gpus_make_the_one_gpu_store(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(FAKE_GPUS_ENV, "2")
    config = load_config(tiny_config(tmp_path, num_samples=12))
    one = generate(config, tmp_path / "one", gpus=1)
    two = generate(config, tmp_path / "two")  # default: every visible GPU, one worker each
    assert store_files(tmp_path / "one") == store_files(tmp_path / "two")
    assert one.shard_devices == {0: "0", 1: "0", 2: "0"}  # rendered here, on the first GPU
    # each shard was rendered by a worker pinned to one of the two (which one: the order in
    # which the workers came up); only the report says so, the store does not
    assert sorted(two.shard_devices) == [0, 1, 2]
    assert set(two.shard_devices.values()) <= {"0", "1"}
    assert two.to_dict()["shard_devices"] == {str(k): v for k, v in two.shard_devices.items()}
    assert DatasetStore.open(tmp_path / "two").verify().ok


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's fork server, /proc")
def test_wait_for_workers_returns_once_a_runs_workers_have_exited(tmp_path) -> None:
    """generate reports a run once every shard is recorded, without waiting for its worker
    processes to exit; wait_for_workers waits for them (the worker server, which forked
    them, then has no child left)."""
    config = load_config(tiny_config(tmp_path, num_samples=8, storage={"shard_samples": 2}))
    report = generate(config, tmp_path / "store", workers=2)
    assert (report.complete, report.rendered) == (8, 8)
    assert report.encoders == {name: 4 for name in report.encoders} and len(report.encoders) == 1
    wait_for_workers()
    server = worker_server_pid()
    assert Path(f"/proc/{server}/task/{server}/children").read_text().split() == []
    again = generate(config, tmp_path / "store", workers=2)  # complete: nothing to render
    assert (again.complete, again.rendered) == (8, 0)


#: ``python -c`` program: the CLI (arguments after the kill count) killed by SIGKILL when its
#: k-th shard result reaches the calling process -- a point set by the work done, not by the
#: clock. Its pinned workers die with it (PR_SET_PDEATHSIG), wherever they are in a shard.
_KILLED_AFTER_RESULTS = """
import os, signal, sys
import importlib
generation = importlib.import_module("virtus.data.generate")
kill_at, run_local = int(sys.argv[1]), generation._run_local
def killed_run_local(*args, **kwargs):
    for count, result in enumerate(run_local(*args, **kwargs), 1):
        if count >= kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        yield result
generation._run_local = killed_run_local
from virtus.cli import main
main(sys.argv[2:])
"""


@pytest.mark.slow
def test_a_killed_multi_gpu_run_resumes_to_the_one_gpu_store(tmp_path) -> None:
    config = tiny_config(tmp_path, num_samples=64, storage={"shard_samples": 2})
    reference = tmp_path / "reference"
    generate(load_config(config), reference)  # one process, no GPU
    out = tmp_path / "killed"
    arguments = ["dataset", "generate", "--config", str(config), "--out", str(out)]
    environment = {**_environ(), FAKE_GPUS_ENV: "2"}
    complete = []
    # 32 shards; 2 workers are given 4 tasks of at most _TASK_SHARDS (4) shards at first,
    # and one more task each time a task's results have all reached the caller, so a run
    # killed at its k-th result (k <= 3) has finished at most (4 + k - 1) * 4 = 24 < 32
    # shards whatever the machine's speed.
    assert _TASK_SHARDS == 4
    for kill_at in (1, 3):
        killed = subprocess.run(
            [sys.executable, "-c", _KILLED_AFTER_RESULTS, str(kill_at), *arguments],
            capture_output=True, text=True, timeout=300, env=environment,
        )  # fmt: skip
        assert killed.returncode == -signal.SIGKILL, (kill_at, killed.stderr)
        complete.append(len(DatasetStore.open(out).samples()))
    assert 0 < complete[0] and complete == sorted(complete) and complete[-1] < 64, complete
    final = subprocess.run(
        [sys.executable, "-m", "virtus", *arguments, "--gpus", "2"],
        capture_output=True, text=True, timeout=300, env=environment,
    )  # fmt: skip
    assert final.returncode == 0, final.stderr
    mine, theirs = store_files(out), store_files(reference)
    differing = sorted(k for k in mine.keys() | theirs.keys() if mine.get(k) != theirs.get(k))
    assert not differing, (differing[:10], complete)
    assert DatasetStore.open(out).verify().ok


def _environ() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if k not in (FAKE_GPUS_ENV, CUDA_ENV)}


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--gpus", "0"], "--gpus: expected a positive number of GPUs or 'all', got '0'"),
        (["--gpus", "3"], "--gpus: expected at most the 2 GPUs visible here (2: 0,1), got 3"),
        (["--gpus", "two"], "--gpus: expected a positive number of GPUs or 'all', got 'two'"),
        (["--gpus", "1.5"], "--gpus: expected a positive number of GPUs or 'all', got '1.5'"),
        (["--workers-per-gpu", "0"], "--workers-per-gpu: expected an integer in 1..256, got 0"),
        (["--workers-per-gpu", "x"], "workers-per-gpu"),
        (["--workers", "3", "--workers-per-gpu", "2"], "--workers: expected 2 GPUs x 2"),
    ],
)
def test_bad_gpu_options_are_refused_in_one_line(tmp_path, capsys, monkeypatch, options, message):
    monkeypatch.setenv(FAKE_GPUS_ENV, "2")
    config = tiny_config(tmp_path)
    out = tmp_path / "out"
    code, _, err = run_cli(
        ["dataset", "generate", "--config", str(config), "--out", str(out), *options], capsys
    )
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("virtus: error:") and message in err, err
    assert not out.exists()


def test_no_visible_gpu_refuses_gpus_but_all_renders_here(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setenv(FAKE_GPUS_ENV, "0")
    config = tiny_config(tmp_path, num_samples=4)
    base = ["dataset", "generate", "--config", str(config), "--out"]
    code, _, err = run_cli([*base, str(tmp_path / "a"), "--gpus", "1"], capsys)
    assert code == 2 and "at most the 0 GPUs visible here (none), got 1" in err, err
    code, _, err = run_cli([*base, str(tmp_path / "b"), "--gpus", "all"], capsys)
    assert code == 0, err
    generate(load_config(config), tmp_path / "reference")
    assert store_files(tmp_path / "b") == store_files(tmp_path / "reference")
