"""Run ownership of output directories: one job at a time, its record, atomic files.

Every job that writes an output directory (``virtus calibrate``, ...) claims it with
:func:`claim_run`::

    with claim_run(out_dir, "calibrate", config, layout=("calibration.json", "poses/*.npz"),
                   resume=resume, overwrite=overwrite) as run:
        run.write_json("calibration.json", data)

What a claim guarantees:

* **One run at a time.** An exclusive, non-blocking ``fcntl.flock`` on ``OUT/.virtus.lock``
  (which holds the owner's pid) is held for the whole run; a second run into the same
  directory fails at once with ``OUT is in use by another virtus run (pid N)``. The lock
  goes with the process, so a killed run never leaves the directory locked. The lock file
  itself stays (removing it would let two runs lock two different files).
* **A record.** ``OUT/run.json`` (:data:`RUN_FORMAT`) holds the command, its configuration,
  the checksums of its input files, the virtus version, the ``status`` (``running``,
  ``complete`` or ``failed`` with the ``error``), the ``files`` the run owns (relative
  paths, registered *before* they are written, so the list is complete even after a
  ``kill -9``) and a ``log`` of events. It holds nothing that depends on time or the
  machine: two identical runs write the same ``run.json``.
* **No mixing.** A directory holding another run's files (another command or another
  configuration, or files of the command's ``layout`` without a ``run.json``) is refused,
  naming the difference. ``overwrite=True`` removes the old run's files first: only the
  files its ``run.json`` lists (or, without one, the files matching ``layout``), and the
  directories they leave empty; nothing else in the directory is touched.
* **Resume.** ``resume=True`` continues the run recorded in ``run.json``; its command,
  configuration, input checksums and virtus version must equal this run's, else the
  difference is named. Without a ``run.json``, a resumed run simply starts.
* **Atomic files.** :func:`atomic_write` writes through a temporary file in a directory of
  its own inside ``.virtus-tmp/`` beside the target and ``os.replace``: a reader (or a
  resumed run) sees the old file or the whole new one, never a partial file, and writers
  of the same file at once never touch each other's temporary files (the last rename
  wins). A killed writer's temporary directory stays until a later write into the same
  directory (or an ``overwrite``) finds it unlocked and removes it. Only a missing path or
  a regular file is replaced: a device, FIFO, socket, directory or symbolic link in the
  target's place is refused (:mod:`virtus.io.safewrite`), a link never followed. An
  ``OSError`` (disk full, permission denied) removes the temporary file and always carries
  the target's path, so the command line prints it as one line.
  Files are not fsync'ed: writes survive a killed process, not a power cut.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virtus import __version__
from virtus.errors import InputError, RunConflict
from virtus.io.jsonio import json_default
from virtus.io.safewrite import check_not_link, check_replaceable, name_os_error

#: The run record in an output directory.
RUN_FILE = "run.json"
#: The lock file in an output directory (holds the pid of the run that owns it).
LOCK_FILE = ".virtus.lock"
#: Format tag of ``run.json``.
RUN_FORMAT = "virtus.run/1"
#: Staging directory (beside the targets) of the files :func:`atomic_write_files` writes.
TMP_DIR = ".virtus-tmp"
#: Longest wait (s) for a lock holder to write its pid (it does right after locking).
_LOCK_OWNER_WAIT_S = 1.0
#: Times a staging directory is made again when another writer removed ``.virtus-tmp``.
_STAGING_ATTEMPTS = 20
#: Keys of ``run.json`` that must match for a run to be resumed.
_IDENTITY = ("command", "virtus_version", "config", "inputs")


# -- atomic files ---------------------------------------------------------------------------


def _named(error: OSError, staging: Path | None, directory: Path, fallback: Path) -> OSError:
    """``error`` naming the user's path: a staged file's target in ``directory`` (the
    staging copy is removed, naming it would mislead), ``fallback`` when it names none."""
    if error.filename is not None:
        where = Path(os.fsdecode(error.filename))
        if staging is None or where.parent != staging:
            return error
        code = error.errno if error.errno is not None else errno.EIO
        named = type(error)(code, error.strerror or os.strerror(code), str(directory / where.name))
        named.__cause__ = error
        return named
    return name_os_error(error, fallback)


def atomic_write_files(
    directory: str | os.PathLike[str], names: Sequence[str], write: Callable[[Path], object]
) -> list[Path]:
    """Write files atomically, one by one: ``write(staging)`` fills a staging directory with
    ``names``, then each replaces its target in ``directory``.

    Nothing but a missing path or a regular file is replaced: before anything is written
    (and again just before each rename) every target is looked at with ``os.lstat``
    (:func:`virtus.io.safewrite.check_replaceable`), and a device, FIFO, socket, directory
    or symbolic link is refused, naming it -- a link is never followed, so what it points to
    is never touched. Neither ``directory/.virtus-tmp`` nor the staging directory may be a
    symbolic link.

    Any number of writers (threads or processes) may write the same names into the same
    directory at once: each call stages in its own new directory, so the file that ends up
    in place is one writer's complete file (the last rename wins). Staging directories that
    a killed writer left are removed by a later write into the same directory
    (:func:`_remove_stale`); those of live writers are told apart by the lock they hold.

    Parameters
    ----------
    directory : where the files go (created if needed).
    names : the file names ``write`` creates (plain names, no sub-directories).
    write : called with this call's staging directory, a new directory inside
        ``directory/.virtus-tmp`` (same file system, so each rename is atomic; the files
        keep their names, so writers that choose a format by extension work); it must
        write every name there.

    Returns
    -------
    The target paths, in ``names`` order.

    Raises
    ------
    InputError : a target that is not a regular file, or a staging path that is a symbolic
        link (nothing is written).
    OSError : from the writes or the renames, naming the target (a staged file's error
        names the file it was to replace; one that names no file gets the target, or
        ``directory`` for several); the staging directory is removed and targets not yet
        replaced are unchanged (each file is replaced atomically, the set is not).
    """
    directory = Path(directory)
    shared = directory / TMP_DIR
    targets = [directory / name for name in names]
    for target in targets:
        check_replaceable(target)
    check_not_link(shared, "staging directory")
    staging: Path | None = None
    lock = -1
    try:
        staging, lock = _private_staging(shared)
        write(staging)
        for name, target in zip(names, targets, strict=True):
            check_replaceable(target)  # again: it may have appeared while writing
            os.replace(staging / name, target)
    except OSError as error:
        named = _named(error, staging, directory, targets[0] if len(targets) == 1 else directory)
        if named is error:
            raise
        raise named from error
    finally:
        if staging is not None:
            _remove_staging(staging, names)
        if lock >= 0:
            os.close(lock)  # releases the lock, after the directory is gone
        with contextlib.suppress(OSError):  # still holds another writer's staging
            shared.rmdir()
    return targets


def _private_staging(shared: Path) -> tuple[Path, int]:
    """A new staging directory inside ``shared`` (``.virtus-tmp``), locked by this writer:
    ``(path, fd)``; closing ``fd`` releases the lock.

    ``shared`` is common to all writers and one that finishes removes it when it is empty:
    between this writer's ``mkdir`` and its ``mkdtemp``, or inside ``mkdir`` itself,
    between finding the directory there and checking that it is one (seen with 12 and 16
    dataset workers; there may even be a new one there by then, seen with 4 x 4 writers);
    then it is made again. Once this writer's directory is inside,
    ``shared`` is not empty and stays. The lock (``flock`` on the directory, held until
    the directory is removed) tells :func:`_remove_stale` that the writer lives; one that
    took the new directory for stale in the instant before it was locked has removed it,
    which the inode check finds, and a new one is made."""
    for attempt in range(_STAGING_ATTEMPTS):
        last = attempt + 1 == _STAGING_ATTEMPTS
        try:
            shared.mkdir(parents=True, exist_ok=True)
        except FileExistsError:  # there, then removed before mkdir's is_dir check
            if last or (shared.exists() and not shared.is_dir()):
                raise  # (made again since by another writer: retried)
            continue
        check_not_link(shared, "staging directory")
        _remove_stale(shared)
        try:
            staging = Path(tempfile.mkdtemp(dir=shared))
            lock = os.open(staging, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
        except FileNotFoundError:  # ``shared`` or the new directory removed meanwhile
            if last:
                raise
            continue
        try:
            # A file system without locks: unlocked, and no sweeper can lock it either.
            with contextlib.suppress(OSError):
                fcntl.flock(lock, fcntl.LOCK_EX)
            check_not_link(shared, "staging directory")
            if os.path.samestat(os.lstat(staging), os.fstat(lock)):
                return staging, lock
        except FileNotFoundError:
            pass
        except BaseException:
            os.close(lock)
            with contextlib.suppress(OSError):
                staging.rmdir()
            raise
        os.close(lock)
    raise FileNotFoundError(errno.ENOENT, "staging directory kept disappearing", str(shared))


def _remove_staging(staging: Path, names: Sequence[str]) -> None:
    """Remove a writer's own staging directory (what ``write`` left there included)."""
    for name in names:
        with contextlib.suppress(OSError):
            (staging / name).unlink(missing_ok=True)
    try:
        staging.rmdir()
    except OSError:  # other files ``write`` made
        shutil.rmtree(staging, ignore_errors=True)


def _remove_stale(shared: str | os.PathLike[str]) -> list[str]:
    """Remove the staging directories in ``shared`` (``.virtus-tmp``) that killed writers
    left: those nobody holds the lock of (a live writer holds it from just after making its
    directory until it has removed it; a killed one's lock went with its process). Files
    directly in ``shared`` (left by earlier versions, which staged every writer's files
    there) are left alone: nothing tells whether their writer lives. Returns the names
    removed."""
    removed: list[str] = []
    flags = os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW
    try:  # a link in .virtus-tmp's place is never followed: nothing elsewhere is removed
        top = os.open(shared, flags)
    except OSError:  # missing, a link, no directory
        return removed
    try:
        for entry in list(os.scandir(top)):
            if not entry.is_dir(follow_symlinks=False):
                continue
            try:
                fd = os.open(entry.name, flags, dir_fd=top)
            except OSError:  # removed meanwhile, or not ours to read
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # a live writer's (or no locks on this file system: can't tell)
                os.close(fd)
                continue
            try:
                shutil.rmtree(entry.name, ignore_errors=True, dir_fd=top)
                removed.append(entry.name)
            finally:
                os.close(fd)
    finally:
        os.close(top)
    return removed


def atomic_write(path: str | os.PathLike[str], write: Callable[[Path], object]) -> Path:
    """Write one file atomically: ``write(tmp)`` fills a temporary file that replaces ``path``.

    The temporary file is ``<parent>/.virtus-tmp/<private>/<name>``, ``<private>`` this
    call's own directory (see :func:`atomic_write_files`): a reader sees the old file or
    the whole new one; on an ``OSError`` (raised with ``path`` attached) the temporary file
    is removed and ``path`` is unchanged. A ``path`` that exists and is not a regular file
    (a device such as ``/dev/full``, a FIFO, a directory, a symbolic link) is refused with
    :class:`InputError` before anything is written.
    """
    path = Path(path)
    return atomic_write_files(path.parent, [path.name], lambda staging: write(staging / path.name))[
        0
    ]


def json_text(data: Any, *, allow_nan: bool = False) -> str:
    """The JSON text virtus writes: 2-space indent, numpy values allowed, final newline.

    ``allow_nan``: write NaN/Infinity literals (reports with undefined statistics, read back
    with ``safeio.read_json(..., allow_nan=True)``); otherwise they raise ``ValueError``.
    """
    return json.dumps(data, indent=2, default=json_default, allow_nan=allow_nan) + "\n"


def write_json_atomic(path: str | os.PathLike[str], data: Any, *, allow_nan: bool = False) -> Path:
    """Write ``data`` as JSON (:func:`json_text`) through :func:`atomic_write`."""
    text = json_text(data, allow_nan=allow_nan)
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def file_digest(path: str | os.PathLike[str]) -> str:
    """``"sha256:<hex>"`` of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return f"sha256:{digest.hexdigest()}"


def canonical(data: Any) -> Any:
    """``data`` as it reads back from JSON (tuples -> lists, numpy -> Python numbers)."""
    return json.loads(json.dumps(data, default=json_default, allow_nan=False))


def config_digest(config: Mapping[str, Any]) -> str:
    """``"sha256:<hex>"`` of a configuration's canonical JSON (key order as given)."""
    text = json.dumps(canonical(config), separators=(",", ":"))
    return f"sha256:{hashlib.sha256(text.encode()).hexdigest()}"


def first_difference(new: Any, old: Any, where: str = "") -> str | None:
    """The first place where two JSON values differ, as ``"key.sub: A here, B in the run"``;
    ``None`` when they are equal."""
    if isinstance(new, dict) and isinstance(old, dict):
        for key in [*new, *(k for k in old if k not in new)]:
            place = f"{where}.{key}" if where else str(key)
            if key not in old:
                return f"{place}: set here, absent in the existing run"
            if key not in new:
                return f"{place}: absent here, set in the existing run"
            found = first_difference(new[key], old[key], place)
            if found:
                return found
        return None
    if isinstance(new, list) and isinstance(old, list) and len(new) == len(old):
        for index, (a, b) in enumerate(zip(new, old, strict=True)):
            found = first_difference(a, b, f"{where}[{index}]")
            if found:
                return found
        return None
    if new == old:
        return None
    return f"{where or 'value'}: {_short(new)} here, {_short(old)} in the existing run"


def _short(value: Any, limit: int = 60) -> str:
    text = json.dumps(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


# -- the lock -------------------------------------------------------------------------------


@contextlib.contextmanager
def directory_lock(directory: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold the exclusive lock of an output directory (created if needed).

    Raises
    ------
    VirtusError : ``<dir> is in use by another virtus run (pid N)`` if another process holds
        it (the call does not wait).
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    lock_path = directory / LOCK_FILE
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunConflict(
                f"{directory} is in use by another virtus run (pid {_lock_owner(fd)}); wait "
                "for it to finish or choose another output directory"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        try:
            yield lock_path
        finally:
            os.ftruncate(fd, 0)  # no stale pid for the next contender to report
    finally:
        os.close(fd)  # releases the lock


def _lock_owner(fd: int) -> str:
    """The pid in a held lock file. Its holder writes it just after taking the lock, so a
    contender arriving in between finds the file empty and waits for it (at most
    :data:`_LOCK_OWNER_WAIT_S`; ``"unknown"`` after that)."""
    deadline = time.monotonic() + _LOCK_OWNER_WAIT_S
    while True:
        owner = os.pread(fd, 32, 0).decode(errors="replace").strip()
        if owner or time.monotonic() > deadline:
            return owner or "unknown"
        time.sleep(0.005)


# -- the run --------------------------------------------------------------------------------


@dataclass
class RunDirectory:
    """An output directory owned by a running job (made by :func:`claim_run`).

    Attributes
    ----------
    path : the directory.
    command : the job's name (``"calibrate"``).
    config : the job's configuration (canonical JSON values).
    resumed : True when this run continues an earlier run of the same configuration.
    record : the ``run.json`` content, kept up to date on disk.
    """

    path: Path
    command: str
    config: dict[str, Any]
    resumed: bool = False
    record: dict[str, Any] = field(default_factory=dict)

    def file(self, name: str) -> Path:
        """The path of ``name`` (relative, inside the directory)."""
        return self.path / _relative(name)

    def own(self, *names: str) -> None:
        """Register files the run is about to write (so an overwrite can remove them)."""
        files = self.record["files"]
        new = [_relative(n) for n in names if _relative(n) not in files]
        if new:
            files.extend(new)
            self._save()

    def log(self, line: str) -> None:
        """Append an event to ``run.json``'s ``log`` (no time stamps: runs stay comparable)."""
        self.record["log"].append(str(line))
        self._save()

    def write(self, name: str, write: Callable[[Path], object]) -> Path:
        """Register ``name`` and write it with :func:`atomic_write`."""
        self.own(name)
        return atomic_write(self.file(name), write)

    def write_json(self, name: str, data: Any, *, allow_nan: bool = False) -> Path:
        """Register ``name`` and write ``data`` as JSON with :func:`write_json_atomic`."""
        self.own(name)
        return write_json_atomic(self.file(name), data, allow_nan=allow_nan)

    def _save(self) -> None:
        write_json_atomic(self.path / RUN_FILE, self.record)


def _relative(name: str) -> str:
    """A clean relative POSIX path inside the directory, or :class:`InputError`."""
    path = Path(name)
    if not name or path.is_absolute() or ".." in path.parts or path.name in (RUN_FILE, LOCK_FILE):
        raise InputError("file name", "a relative path inside the output directory", name)
    return path.as_posix()


def _read_record(path: Path) -> dict[str, Any] | None:
    from virtus.io.safeio import read_json

    file = path / RUN_FILE
    if not file.exists():
        return None
    record = read_json(file, "run record", expect=dict)
    if record.get("format") != RUN_FORMAT or not isinstance(record.get("files"), list):
        raise InputError(f"{file}", f"a {RUN_FORMAT} record", record.get("format"))
    return record


def _layout_files(path: Path, layout: Sequence[str]) -> list[str]:
    """Existing files under ``path`` matching the ``layout`` patterns (relative, sorted)."""
    found = set()
    for pattern in layout:
        for match in path.glob(pattern):
            if match.is_file():
                found.add(match.relative_to(path).as_posix())
    return sorted(found)


def _remove_files(path: Path, names: Sequence[str]) -> None:
    """Remove the listed files (and their leftover temporary files), then the directories
    they leave empty; anything else stays."""
    parents = set()
    for name in names:
        target = path / _relative(name)
        # (a file of the target's name directly in .virtus-tmp: earlier versions' staging)
        for candidate in (target, target.parent / TMP_DIR / target.name):
            if candidate.is_file() or candidate.is_symlink():
                candidate.unlink()
        relative = target.relative_to(path)
        parents.add(relative.parent / TMP_DIR)
        parents.update(p for p in relative.parents if str(p) != ".")
    for parent in sorted(parents, key=lambda p: len(p.parts), reverse=True):
        if parent.name == TMP_DIR:
            _remove_stale(path / parent)  # killed writers' staging directories
        with contextlib.suppress(OSError):  # not empty: it holds other files
            (path / parent).rmdir()


def _describe(record: dict[str, Any]) -> str:
    return f"a `virtus {record.get('command')}` run ({record.get('status')})"


@contextlib.contextmanager
def claim_run(
    out_dir: str | os.PathLike[str],
    command: str,
    config: Mapping[str, Any],
    *,
    inputs: Mapping[str, str | os.PathLike[str]] | None = None,
    layout: Sequence[str] = (),
    overwrite: bool = False,
    resume: bool = False,
) -> Iterator[RunDirectory]:
    """Own ``out_dir`` for one run of ``command`` (see the module docstring).

    Parameters
    ----------
    out_dir : the output directory (created if needed).
    command : the job's name, e.g. ``"calibrate"``.
    config : JSON-ready settings that determine the run's output; resuming requires equal
        settings.
    inputs : name -> input file whose SHA-256 is recorded (and compared on resume).
    layout : glob patterns (relative) of the files the command writes, e.g.
        ``("calibration.json", "poses/*.npz")``: such files without a ``run.json`` are an
        earlier run's and are refused (or removed by ``overwrite``).
    overwrite : remove an earlier run's files first.
    resume : continue the earlier run recorded in ``out_dir/run.json``.

    Yields
    ------
    :class:`RunDirectory`; ``run.json`` says ``complete`` when the block ends normally and
    ``failed`` (with the error) when it raises.

    Raises
    ------
    VirtusError : the directory is locked by another run, or holds another run's files.
    InputError : ``overwrite`` and ``resume`` together.
    """
    if overwrite and resume:
        raise InputError("overwrite, resume", "at most one of them", "both")
    path = Path(out_dir)
    config = canonical(dict(config))
    checksums = {str(k): file_digest(v) for k, v in (inputs or {}).items()}
    with directory_lock(path):
        old = _read_record(path)
        identity = {
            "command": command,
            "virtus_version": __version__,
            "config": config,
            "inputs": checksums,
        }
        resumed = False
        if old is not None:
            difference = first_difference(identity, {k: old.get(k) for k in _IDENTITY})
            if overwrite:
                _remove_files(path, old["files"])
            elif resume and difference is None:
                resumed = True
            elif resume:
                raise RunConflict(
                    f"cannot resume in {path}: it holds {_describe(old)} with other settings "
                    f"({difference}); pass --overwrite to start again"
                )
            elif difference is None:
                raise RunConflict(
                    f"{path} already holds {_describe(old)} with these settings; pass --resume "
                    "to continue it or --overwrite to start again"
                )
            else:
                raise RunConflict(
                    f"{path} holds {_describe(old)} with other settings ({difference}); "
                    "pass --overwrite to replace it, or choose another output directory"
                )
        else:
            stale = _layout_files(path, layout)
            if stale and overwrite:
                _remove_files(path, stale)
            elif stale:
                raise RunConflict(
                    f"{path} holds files of an earlier run without {RUN_FILE} "
                    f"({', '.join(stale[:3])}{', ...' if len(stale) > 3 else ''}); pass "
                    "--overwrite to replace them, or choose another output directory"
                )
        record = {
            "format": RUN_FORMAT,
            **identity,
            "status": "running",
            "files": list(old["files"]) if resumed else [],
            "log": list(old.get("log", [])) if resumed else [],
        }
        run = RunDirectory(path, command, config, resumed, record)
        run.log("resume" if resumed else "start")
        try:
            yield run
        except BaseException as error:
            record["status"] = "failed"
            record["error"] = f"{type(error).__name__}: {error}"
            with contextlib.suppress(OSError):  # keep the original error
                run._save()
            raise
        record["status"] = "complete"
        record.pop("error", None)
        run._save()
