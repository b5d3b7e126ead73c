"""Run ownership of output directories (virtus.io.runs): lock, record, overwrite, resume,
atomic writes. No rendering: every test runs in milliseconds."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest

from virtus.errors import InputError, VirtusError
from virtus.io.runs import (
    LOCK_FILE,
    RUN_FILE,
    TMP_DIR,
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


def test_a_staging_directory_removed_by_another_writer_is_made_again(tmp_path):
    # Another process finishing its own write removes the shared staging directory when
    # it is empty: here, right before this writer's first file.
    calls = []

    def write(tmp):
        calls.append(tmp)
        if len(calls) == 1:
            tmp.parent.rmdir()  # the staging directory, still empty
        tmp.write_text("{}")

    atomic_write(tmp_path / "a.json", write)
    assert len(calls) == 2
    assert (tmp_path / "a.json").read_text() == "{}"
    assert not (tmp_path / TMP_DIR).exists()


def test_a_staging_directory_removed_while_mkdir_checks_it_is_made_again(tmp_path, monkeypatch):
    # mkdir found the directory (another writer's), which was removed before mkdir checked
    # that it is a directory: Path.mkdir raises FileExistsError for a path that is gone.
    real_mkdir = Path.mkdir
    raced = []

    def mkdir(self, *args, **kwargs):
        if self.name == TMP_DIR and not raced:
            raced.append(self)
            raise FileExistsError(17, "File exists", str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    atomic_write(tmp_path / "a.json", lambda tmp: tmp.write_text("{}"))
    assert raced and (tmp_path / "a.json").read_text() == "{}"
    # A file (not a directory) in the staging directory's place is an error, not a retry.
    monkeypatch.setattr(Path, "mkdir", real_mkdir)
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / TMP_DIR).write_text("not a directory")
    with pytest.raises(FileExistsError):
        atomic_write(tmp_path / "sub" / "b.json", lambda tmp: tmp.write_text("{}"))
