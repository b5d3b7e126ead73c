"""JSON files written one way: numpy values and paths serialised, the file replaced atomically.

Reading is the other half and lives in :mod:`virtus.safeio` (:func:`~virtus.safeio.read_json`:
size, UTF-8, depth and syntax checked). Non-finite floats are written as the ``NaN`` /
``Infinity`` literals Python's ``json`` uses; ``read_json`` refuses them unless called with
``allow_nan=True`` (reports may hold NaN statistics; configuration files never do).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np


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

    The text goes to ``<name>.tmp`` beside ``path`` first and then replaces ``path``, so a
    reader never sees a half-written file. Returns ``path``.
    """
    path = Path(path)
    text = json.dumps(data, indent=indent, default=json_default) + "\n"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path
