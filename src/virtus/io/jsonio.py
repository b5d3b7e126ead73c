"""JSON files written one way: numpy values and paths serialised, the file replaced atomically.

Reading is the other half and lives in :mod:`virtus.io.safeio` (:func:`~virtus.io.safeio.read_json`:
size, UTF-8, depth and syntax checked). Non-finite floats are written as the ``NaN`` /
``Infinity`` literals Python's ``json`` uses; ``read_json`` refuses them unless called with
``allow_nan=True`` (reports may hold NaN statistics; configuration files never do).

Jobs that own an output directory write through :func:`virtus.io.runs.write_json_atomic`
(staging in the run's ``.virtus-tmp/``); :func:`write_json` is the same guarantee for the
lower layers, which may not import :mod:`virtus.io.runs`.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from virtus.io.safewrite import check_replaceable


def json_default(value: Any) -> Any:
    """``json.dumps`` hook: numpy scalars -> Python numbers, arrays -> lists, paths -> str."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_json(path: str | Path, data: Any, *, indent: int = 2) -> Path:
    """Write ``data`` as indented JSON (numpy values allowed, see :func:`json_default`).

    The text goes to a uniquely named hidden temporary file beside ``path`` first and then
    replaces ``path`` (``os.replace``), so a reader sees the old file or the whole new one.
    On an ``OSError`` (disk full, permission denied, a missing folder) the temporary file is
    removed, ``path`` is unchanged, and the error names ``path``. A ``path`` that exists and
    is not a regular file (a device, FIFO, directory, symbolic link) is refused with
    :class:`~virtus.errors.InputError` before anything is written
    (:func:`virtus.io.safewrite.check_replaceable`). Returns ``path``.
    """
    path = check_replaceable(path)
    text = json.dumps(data, indent=indent, default=json_default) + "\n"
    tmp: str | None = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        check_replaceable(path)  # again: it may have appeared while writing
        os.replace(tmp, path)
        tmp = None
    except OSError as error:
        code = error.errno if error.errno is not None else errno.EIO
        raise type(error)(code, error.strerror or os.strerror(code), str(path)) from error
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return path
