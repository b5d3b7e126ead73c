"""Run ownership of output directories (virtus.io.runs): lock, record, overwrite, resume,
atomic writes. No rendering: every test runs in milliseconds."""

from __future__ import annotations

import errno
import json
import os
import tempfile
import time
from pathlib import Path

import pytest

from virtus.errors import InputError, VirtusError
from virtus.io.runs import (
    LOCK_FILE,
    RUN_FILE,
    TMP_DIR,
    _remove_stale,
    atomic_write,
    atomic_write_files,
    claim_run,
    directory_lock,
    first_difference,
)

CONFIG = {"board": "4x7", "seed": 5, "scanner": {"spp": 4, "rig": {"K": [[1.0, 0.0], [0, 1]]}}}


def _record(path):
    return json.loads((path / RUN_FILE).read_text())


def test_a_contender_waits_for_the_lock_holder_to_write_its_pid(tmp_path):
    # The holder takes the lock, then writes its pid: a contender in between must not
    # report "pid unknown" (seen when two runs start together on a busy machine).
    import fcntl
    import threading

    fd = os.open(tmp_path / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        writer = threading.Timer(0.1, lambda: os.pwrite(fd, b"4242\n", 0))
        writer.start()
        with pytest.raises(VirtusError, match=r"in use by another virtus run \(pid 4242\)"):
            with directory_lock(tmp_path):
                pass
        writer.join()
    finally:
        os.close(fd)
    # A finished holder leaves no pid behind.
    with directory_lock(tmp_path):
        pass
    assert (tmp_path / LOCK_FILE).read_text() == ""


def test_a_second_run_into_a_locked_directory_is_refused_naming_the_owner(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG) as run:
        assert (tmp_path / LOCK_FILE).read_text().strip() == str(os.getpid())
        # flock locks belong to open file descriptions: a second claim fails even here.
        message = rf"^{tmp_path} is in use by another virtus run \(pid {os.getpid()}\)"
        with pytest.raises(VirtusError, match=message):
            with claim_run(tmp_path, "calibrate", CONFIG, resume=True):
                pass
        with pytest.raises(VirtusError, match="in use by another virtus run"):
            with directory_lock(tmp_path):
                pass
        assert _record(tmp_path)["status"] == "running"
        run.log("still mine")
    # Released on exit: the next run gets it (and finds the finished run).
    with claim_run(tmp_path, "calibrate", CONFIG, resume=True) as again:
        assert again.resumed
    assert _record(tmp_path)["log"] == ["start", "still mine", "resume"]


def test_record_status_and_identical_runs_write_identical_records(tmp_path):
    for name in ("one", "two"):
        with claim_run(tmp_path / name, "calibrate", CONFIG) as run:
            run.write_json("result.json", {"x": 1})
    first, second = ((tmp_path / n / RUN_FILE).read_bytes() for n in ("one", "two"))
    assert first == second  # nothing in run.json depends on time, pid or machine
    record = json.loads(first)
    assert record["status"] == "complete" and record["command"] == "calibrate"
    assert record["config"] == CONFIG and record["files"] == ["result.json"]
    assert record["virtus_version"]
    with pytest.raises(RuntimeError):
        with claim_run(tmp_path / "three", "calibrate", CONFIG):
            raise RuntimeError("boom")
    failed = _record(tmp_path / "three")
    assert failed["status"] == "failed" and failed["error"] == "RuntimeError: boom"


def test_another_runs_directory_is_refused_and_overwrite_removes_only_its_files(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG) as run:
        run.write_json("calibration.json", {"old": True})
        run.write("poses/a.npz", lambda tmp: tmp.write_bytes(b"pose"))
        run.own("poses/never_written.npz")  # registered, killed before writing: no error
    (tmp_path / "notes.txt").write_text("the user's")
    (tmp_path / "poses" / "mine.txt").write_text("the user's too")
    other = {**CONFIG, "seed": 6}
    with pytest.raises(
        VirtusError, match=r"other settings \(config\.seed: 6 here, 5 in the existing run"
    ):
        with claim_run(tmp_path, "calibrate", other):
            pass
    with pytest.raises(VirtusError, match="holds a `virtus calibrate` run"):
        with claim_run(tmp_path, "scan", CONFIG):
            pass
    assert (tmp_path / "calibration.json").is_file()  # refusals touch nothing
    with claim_run(tmp_path, "calibrate", other, overwrite=True) as run:
        assert not (tmp_path / "calibration.json").exists()
        assert not (tmp_path / "poses" / "a.npz").exists()
        assert (tmp_path / "notes.txt").read_text() == "the user's"
        assert (tmp_path / "poses" / "mine.txt").is_file()  # so poses/ stays
        assert run.record["files"] == [] and run.record["log"] == ["start"]
    assert _record(tmp_path)["config"]["seed"] == 6


def test_overwrite_removes_the_directory_it_emptied(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG) as run:
        run.write("poses/a.npz", lambda tmp: tmp.write_bytes(b"pose"))
    with claim_run(tmp_path, "calibrate", CONFIG, overwrite=True):
        assert not (tmp_path / "poses").exists()


def test_same_settings_need_resume_or_overwrite(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG):
        pass
    with pytest.raises(VirtusError, match="already holds a `virtus calibrate` run .complete."):
        with claim_run(tmp_path, "calibrate", CONFIG):
            pass
    with pytest.raises(InputError, match="at most one of them"):
        with claim_run(tmp_path, "calibrate", CONFIG, resume=True, overwrite=True):
            pass


def test_resume_with_a_different_configuration_is_refused_naming_the_difference(tmp_path):
    with pytest.raises(RuntimeError):
        with claim_run(tmp_path, "calibrate", CONFIG) as run:
            run.log("rendered pose 1")
            raise RuntimeError("killed")
    changed = {**CONFIG, "scanner": {**CONFIG["scanner"], "spp": 1}}
    with pytest.raises(
        VirtusError, match=r"cannot resume .*config\.scanner\.spp: 1 here, 4 in the exist"
    ):
        with claim_run(tmp_path, "calibrate", changed, resume=True):
            pass
    with pytest.raises(VirtusError, match=r"command: \"scan\" here, \"calibrate\" in the existing"):
        with claim_run(tmp_path, "scan", CONFIG, resume=True):
            pass
    with claim_run(tmp_path, "calibrate", CONFIG, resume=True) as run:
        assert run.resumed and run.record["status"] == "running"
    assert _record(tmp_path)["log"] == ["start", "rendered pose 1", "resume"]
    assert "error" not in _record(tmp_path)


def test_resume_compares_input_checksums(tmp_path):
    rig = tmp_path / "rig.json"
    rig.write_text('{"a": 1}')
    out = tmp_path / "out"
    with claim_run(out, "calibrate", CONFIG, inputs={"rig": rig}):
        pass
    assert _record(out)["inputs"]["rig"].startswith("sha256:")
    rig.write_text('{"a": 2}')
    with pytest.raises(VirtusError, match=r"inputs\.rig: \"sha256:"):
        with claim_run(out, "calibrate", CONFIG, inputs={"rig": rig}, resume=True):
            pass


def test_files_of_an_earlier_run_without_a_record_need_overwrite(tmp_path):
    layout = ("calibration.json", "poses/*.npz")
    (tmp_path / "poses").mkdir()
    (tmp_path / "poses" / "a.npz").write_bytes(b"old")
    (tmp_path / "calibration.json").write_text("{}")
    (tmp_path / "README.txt").write_text("keep")
    with pytest.raises(VirtusError, match=r"files of an earlier run without run\.json"):
        with claim_run(tmp_path, "calibrate", CONFIG, layout=layout):
            pass
    with claim_run(tmp_path, "calibrate", CONFIG, layout=layout, overwrite=True):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == [LOCK_FILE, "README.txt", RUN_FILE]


def test_unrelated_files_do_not_block_a_run(tmp_path):
    (tmp_path / "README.txt").write_text("keep")
    with claim_run(tmp_path, "calibrate", CONFIG, layout=("calibration.json",)) as run:
        run.write_json("calibration.json", {})
    assert (tmp_path / "README.txt").read_text() == "keep"


def test_file_names_must_stay_inside_the_directory(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG) as run:
        for bad in ("../escape.json", "/etc/passwd", RUN_FILE, ""):
            with pytest.raises(InputError, match="a relative path inside the output directory"):
                run.own(bad)


@pytest.mark.parametrize("named", [True, False])
def test_a_failed_write_leaves_the_old_file_and_no_partial_file(tmp_path, named):
    target = tmp_path / "calibration.json"
    target.write_text("old")

    def disk_full(tmp):
        with open(tmp, "wb") as handle:
            handle.write(b'{"half": ')
            # A write through an open handle raises without a file name.
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp) if named else None)

    with pytest.raises(OSError) as info:
        atomic_write(target, disk_full)
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename is not None  # the CLI prints "strerror: filename"
    if not named:
        assert info.value.filename == str(target)
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.json"]


def test_a_failed_multi_file_write_replaces_nothing(tmp_path):
    (tmp_path / "a.txt").write_text("old a")

    def second_fails(staging):
        (staging / "a.txt").write_text("new a")
        raise OSError(errno.EACCES, "Permission denied")

    with pytest.raises(OSError, match="Permission denied") as info:
        atomic_write_files(tmp_path, ["a.txt", "b.txt"], second_fails)
    assert info.value.filename == str(tmp_path)
    assert (tmp_path / "a.txt").read_text() == "old a"
    assert not (tmp_path / "b.txt").exists() and not (tmp_path / TMP_DIR).exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_permission_denied_names_the_path(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(PermissionError) as info:
            atomic_write(locked / "x.json", lambda tmp: tmp.write_text("{}"))
        assert str(locked) in str(info.value.filename)
    finally:
        locked.chmod(0o700)


def test_first_difference_names_the_path():
    assert first_difference({"a": {"b": [1, 2]}}, {"a": {"b": [1, 2]}}) is None
    assert first_difference({"a": {"b": [1, 3]}}, {"a": {"b": [1, 2]}}) == (
        "a.b[1]: 3 here, 2 in the existing run"
    )
    assert first_difference({"a": 1}, {"a": 1, "z": 0}) == (
        "z: absent here, set in the existing run"
    )


def test_a_staging_directory_removed_by_another_writer_is_made_again(tmp_path, monkeypatch):
    # Another writer finishing its own write removes the shared .virtus-tmp when it is
    # empty: here, between this writer's mkdir of it and the making of its own directory.
    real_mkdtemp = tempfile.mkdtemp
    calls = []

    def mkdtemp(*args, dir=None, **kwargs):
        calls.append(dir)
        if len(calls) == 1:
            Path(dir).rmdir()  # .virtus-tmp, still empty
        return real_mkdtemp(*args, dir=dir, **kwargs)

    monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp)
    atomic_write(tmp_path / "a.json", lambda tmp: tmp.write_text("{}"))
    assert len(calls) == 2
    assert (tmp_path / "a.json").read_text() == "{}"
    assert not (tmp_path / TMP_DIR).exists()


@pytest.mark.parametrize("made_again", [False, True], ids=["gone", "made-again"])
def test_a_staging_directory_removed_while_mkdir_checks_it_is_made_again(
    tmp_path, monkeypatch, made_again
):
    # mkdir found the directory (another writer's), which was removed before mkdir checked
    # that it is a directory: Path.mkdir raises FileExistsError for a path that is gone --
    # or that a third writer has made again since (seen with 4 x 4 writers).
    real_mkdir = Path.mkdir
    raced = []

    def mkdir(self, *args, **kwargs):
        if self.name == TMP_DIR and not raced:
            raced.append(self)
            if made_again:
                real_mkdir(self)
            raise FileExistsError(17, "File exists", str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    atomic_write(tmp_path / "a.json", lambda tmp: tmp.write_text("{}"))
    assert raced and (tmp_path / "a.json").read_text() == "{}"
    assert not (tmp_path / TMP_DIR).exists()
    # A file (not a directory) in the staging directory's place is an error, not a retry.
    monkeypatch.setattr(Path, "mkdir", real_mkdir)
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / TMP_DIR).write_text("not a directory")
    with pytest.raises(FileExistsError):
        atomic_write(tmp_path / "sub" / "b.json", lambda tmp: tmp.write_text("{}"))


# -- writers of the same file at once ---------------------------------------------------------


def _content(writer: int, round_: int) -> bytes:
    """A writer's file: 64 KiB naming it, so a mix of two writers' files is seen."""
    return f"writer {writer:03d} round {round_}\n".encode() * 3000


def _write_in_step(target: Path, content: bytes, barrier) -> None:
    """Write ``content`` to ``target``; every writer has staged its whole file before any
    renames (the barrier), so the writers certainly overlap."""

    def write(tmp: Path) -> None:
        tmp.write_bytes(content)
        barrier.wait(timeout=60)

    atomic_write(target, write)


def _assert_one_writers_file(target: Path, contents: set[bytes]) -> None:
    assert target.read_bytes() in contents  # one writer's complete file, no mix
    staging = target.parent / TMP_DIR
    assert not staging.exists() or not any(staging.iterdir()), list(staging.rglob("*"))


def test_threads_writing_the_same_name_at_once_never_collide(tmp_path):
    # (With one staging directory shared by all writers, a writer's rename took another's
    # file and the other's rename failed: FileNotFoundError on every round.)
    import threading

    target, threads, rounds = tmp_path / "same.bin", 12, 4
    for round_ in range(rounds):
        barrier = threading.Barrier(threads)
        errors: list[BaseException] = []

        def run(writer: int, barrier=barrier, round_=round_, errors=errors) -> None:
            try:
                _write_in_step(target, _content(writer, round_), barrier)
            except BaseException as error:  # reported below, with the others
                errors.append(error)
                barrier.abort()

        workers = [threading.Thread(target=run, args=(w,)) for w in range(threads)]
        for worker in workers:
            worker.start()
        for worker in workers:
            worker.join()
        assert not errors, errors
        _assert_one_writers_file(target, {_content(w, round_) for w in range(threads)})


def _process_writer(target: Path, writer: int, rounds: int, barrier, failures) -> None:
    for round_ in range(rounds):
        try:
            _write_in_step(target, _content(writer, round_), barrier)
        except BaseException as error:
            failures.put(f"writer {writer} round {round_}: {type(error).__name__}: {error}")
            barrier.abort()
            return


def test_processes_writing_the_same_name_at_once_never_collide(tmp_path):
    import multiprocessing

    context = multiprocessing.get_context("fork")
    target, processes, rounds = tmp_path / "same.bin", 4, 3
    barrier, failures = context.Barrier(processes), context.SimpleQueue()
    workers = [
        context.Process(target=_process_writer, args=(target, w, rounds, barrier, failures))
        for w in range(processes)
    ]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(timeout=120)
    found = []
    while not failures.empty():
        found.append(failures.get())
    assert not found, found
    assert [worker.exitcode for worker in workers] == [0] * processes
    _assert_one_writers_file(target, {_content(w, rounds - 1) for w in range(processes)})


def _killed_writer(target: Path, staged) -> None:
    def write(tmp: Path) -> None:
        tmp.write_text("half of it")
        staged.set()
        time.sleep(120)  # killed here

    atomic_write(target, write)


def test_a_killed_writers_staging_is_removed_by_a_later_write_a_live_ones_is_not(tmp_path):
    import multiprocessing
    import threading

    context = multiprocessing.get_context("fork")
    staged = context.Event()
    killed = context.Process(target=_killed_writer, args=(tmp_path / "a.txt", staged))
    killed.start()
    assert staged.wait(timeout=60)
    killed.kill()
    killed.join(timeout=60)
    left = list((tmp_path / TMP_DIR).iterdir())
    assert [p.name for p in left[0].iterdir()] == ["a.txt"] and len(left) == 1
    # A live writer (this process, waiting inside its write) keeps its staging directory
    # while another write into the directory removes the killed one's.
    in_write, release = threading.Event(), threading.Event()

    def slow(tmp: Path) -> None:
        tmp.write_text("live")
        in_write.set()
        release.wait(timeout=60)

    live = threading.Thread(target=atomic_write, args=(tmp_path / "b.txt", slow))
    live.start()
    assert in_write.wait(timeout=60)
    atomic_write(tmp_path / "c.txt", lambda tmp: tmp.write_text("c"))
    remaining = list((tmp_path / TMP_DIR).iterdir())
    assert left[0] not in remaining and len(remaining) == 1
    assert [p.name for p in remaining[0].iterdir()] == ["b.txt"]
    release.set()
    live.join()
    assert (tmp_path / "b.txt").read_text() == "live" and not (tmp_path / "a.txt").exists()
    assert not (tmp_path / TMP_DIR).exists()


def test_overwrite_removes_a_killed_writers_staging_and_never_follows_a_link(tmp_path):
    with claim_run(tmp_path, "calibrate", CONFIG) as run:
        run.write_json("poses/p1.json", {"a": 1})
    stale = tmp_path / "poses" / TMP_DIR / "tmpkilled"  # no lock holder: a killed writer's
    stale.mkdir(parents=True)
    (stale / "p2.json").write_text("half")
    with claim_run(tmp_path, "calibrate", {**CONFIG, "seed": 6}, overwrite=True):
        pass
    assert not (tmp_path / "poses").exists()
    # A link in .virtus-tmp's place: nothing it points to is removed.
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "tmpnotmine").mkdir(parents=True)
    (tmp_path / "linked").mkdir()
    (tmp_path / "linked" / TMP_DIR).symlink_to(elsewhere)
    assert _remove_stale(tmp_path / "linked" / TMP_DIR) == []
    assert (elsewhere / "tmpnotmine").is_dir()


def test_without_file_locks_writes_work_and_nothing_is_taken_for_stale(tmp_path, monkeypatch):
    # A file system without flock (some network mounts): nothing tells a killed writer's
    # staging from a live one's, so none is removed; the writes themselves still work.
    import fcntl

    real_flock = fcntl.flock
    stale = tmp_path / TMP_DIR / "tmpkilled"
    stale.mkdir(parents=True)

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", no_locks)
    atomic_write(tmp_path / "a.txt", lambda tmp: tmp.write_text("a"))
    assert (tmp_path / "a.txt").read_text() == "a" and stale.is_dir()
    monkeypatch.setattr(fcntl, "flock", real_flock)
    atomic_write(tmp_path / "a.txt", lambda tmp: tmp.write_text("b"))
    assert (tmp_path / "a.txt").read_text() == "b" and not (tmp_path / TMP_DIR).exists()


def test_a_staging_directory_taken_for_stale_before_it_was_locked_is_made_again(
    tmp_path, monkeypatch
):
    # Another writer's sweep may find this writer's new directory in the instant between
    # its making and its locking, and remove it: the writer makes another.
    real_mkdtemp = tempfile.mkdtemp
    made = []

    def mkdtemp(*args, dir=None, **kwargs):
        made.append(real_mkdtemp(*args, dir=dir, **kwargs))
        if len(made) == 1:
            assert _remove_stale(dir) == [Path(made[0]).name]  # not locked yet
        return made[-1]

    monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp)
    atomic_write(tmp_path / "a.txt", lambda tmp: tmp.write_text("a"))
    assert len(made) == 2 and (tmp_path / "a.txt").read_text() == "a"
    assert not (tmp_path / TMP_DIR).exists()


def test_a_link_in_a_killed_writers_staging_is_removed_not_followed(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "a.txt").write_text("precious")
    stale = tmp_path / "out" / TMP_DIR / "tmpkilled"
    stale.mkdir(parents=True)
    (stale / "a.txt").symlink_to(elsewhere / "a.txt")
    (stale / "linked-dir").symlink_to(elsewhere)
    atomic_write(tmp_path / "out" / "a.txt", lambda tmp: tmp.write_text("new"))
    assert (tmp_path / "out" / "a.txt").read_text() == "new"
    assert (elsewhere / "a.txt").read_text() == "precious"
    assert not (tmp_path / "out" / TMP_DIR).exists()
