"""What a write may replace: checks shared by every writer that renames a file into place.

virtus writes a file through a temporary file that then replaces the target
(:func:`virtus.io.runs.atomic_write`, :func:`virtus.io.jsonio.write_json`). ``os.replace``
replaces whatever directory entry has the target's name: run as root with ``--out
/dev/full`` it would put a regular file where the device was; given a symbolic link it
would replace the link. So, before the temporary file is written (and again just before the
rename), :func:`check_replaceable` looks at the target with ``os.lstat`` (a link is never
followed) and refuses, naming the path, anything but a missing path or a regular file: a
character or block device, a FIFO, a socket, a directory, a symbolic link (wherever it
points).

:func:`name_os_error` gives an ``OSError`` the path it is about (a write into an open file
names none), so the command line prints it as one line; the command line's printer turns
``ENOSPC`` into "no space left on device" with that path.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from pathlib import Path

from virtus.errors import InputError

__all__ = [
    "check_directory",
    "check_not_link",
    "check_replaceable",
    "file_kind",
    "name_os_error",
]

#: ``stat`` tests and the names of the file kinds they find, for messages.
_KINDS = (
    (stat.S_ISLNK, "a symbolic link"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISREG, "a regular file"),
)


def file_kind(mode: int) -> str:
    """``"a character device"``, ``"a symbolic link"``, ... for an ``lstat`` mode."""
    return next((name for test, name in _KINDS if test(mode)), "a special file")


def _lstat(path: Path) -> os.stat_result | None:
    """``os.lstat(path)``, or None when nothing is there (or a parent is no directory: the
    write itself then fails and names it)."""
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None


def _refuse(what: str, path: Path, expected: str, mode: int) -> InputError:
    """``<what> <path>: expected <expected>, got 'a FIFO'`` (a link: ``'a symbolic link to
    <target>'``); the path leads, so a long one is never cut from the message."""
    got = file_kind(mode)
    if stat.S_ISLNK(mode):
        with contextlib.suppress(OSError):
            got = f"a symbolic link to {os.readlink(path)}"
    return InputError(f"{what} {path}", expected, got)


def check_replaceable(path: str | os.PathLike[str], what: str = "output file") -> Path:
    """Refuse to replace ``path`` unless it is missing or a regular file.

    Parameters
    ----------
    path : the file a write is about to replace.
    what : its role, for the message.

    Returns
    -------
    ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    InputError
        ``output file /dev/full: expected a regular file or a new path, got 'a character
        device'``; a symbolic link is refused wherever it points (``'a symbolic link to
        ...'``): it is never followed, and replacing it would silently break it.
    """
    path = Path(path)
    info = _lstat(path)
    if info is None or stat.S_ISREG(info.st_mode):
        return path
    raise _refuse(what, path, "a regular file or a new path", info.st_mode)


def check_directory(path: str | os.PathLike[str], what: str) -> Path:
    """Refuse ``path`` unless it is missing or a real directory (not a link to one): the
    staging directory a writer fills, or a directory a writer replaces."""
    path = Path(path)
    info = _lstat(path)
    if info is None or stat.S_ISDIR(info.st_mode):
        return path
    raise _refuse(what, path, "a directory or a new path", info.st_mode)


def check_not_link(path: str | os.PathLike[str], what: str) -> Path:
    """Refuse ``path`` if it is a symbolic link (a staging directory that is one would
    send the staged files wherever it points); anything else is left to the caller."""
    path = Path(path)
    info = _lstat(path)
    if info is None or not stat.S_ISLNK(info.st_mode):
        return path
    raise _refuse(what, path, "a directory or a new path", info.st_mode)


def name_os_error(error: OSError, path: str | os.PathLike[str]) -> OSError:
    """``error``, or a copy of it naming ``path`` when it names no file (a write into an
    open file); a missing errno becomes ``EIO``."""
    if error.filename is not None:
        return error
    code = error.errno if error.errno is not None else errno.EIO
    named = type(error)(code, error.strerror or os.strerror(code), str(path))
    named.__cause__ = error
    return named
