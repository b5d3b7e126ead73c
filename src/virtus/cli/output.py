"""What a command prints: its final summary as a table or as one JSON object, progress only
on a terminal.

Every command takes ``--json`` (:data:`JsonOption`) and ``--quiet`` (:data:`QuietOption`) and
makes one :class:`Output` of them. Its final summary is **one** :class:`Summary`: a JSON-ready
dict (``data``) and a function that prints that dict as tables (``render``), so the table and
the JSON show the same numbers by construction. Then:

* default: progress bars on stderr (only when stderr is a terminal: none in a pipe or a log),
  the summary's tables and lines on stdout;
* ``--json``: stdout holds the summary as one JSON object and nothing else (non-finite
  numbers as ``null``); no progress, warnings on stderr;
* ``--quiet``: no progress and no summary; warnings and errors on stderr as one line each,
  exit codes unchanged.

A line added after the table (``summary.add("report", path, f"report written: {path}")``)
is a key of the JSON object too, so a row another part of a command adds is never missing
from ``--json``.
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

#: ``--json``: the final summary as one JSON object on stdout.
JsonOption = Annotated[
    bool,
    typer.Option(
        "--json",
        help="Print the final summary as one JSON object on stdout and nothing else "
        "(progress off, warnings on stderr).",
    ),
]
#: ``--quiet``: no progress, no summary.
QuietOption = Annotated[
    bool,
    typer.Option(
        "--quiet",
        "-q",
        help="Print no progress and no summary; errors still print one line on stderr.",
    ),
]

#: How a summary prints as text: ``render(console, data)`` (tables and lines from ``data``).
Render = Callable[[Any, dict[str, Any]], None]


@dataclass
class Summary:
    """A command's final summary: ``data`` (JSON-ready: str, numbers, bools, None, lists,
    dicts; paths and numpy scalars are converted when printed) and ``render``, which prints
    ``data`` as the human-readable tables. ``lines`` are printed after them."""

    data: dict[str, Any] = field(default_factory=dict)
    render: Render | None = None
    lines: list[str] = field(default_factory=list)

    def add(self, key: str, value: Any, line: str | None = None) -> None:
        """Record ``value`` under ``key`` (in the JSON object) and, if given, a ``line`` to
        print after the tables (``summary.add("report", path, f"report written: {path}")``)."""
        self.data[key] = value
        if line is not None:
            self.lines.append(line)


def plain(value: Any) -> Any:
    """``value`` as strict JSON data: numpy scalars and arrays as numbers and lists, paths
    and enums as strings, tuples as lists, non-finite floats as None."""
    if isinstance(value, Mapping):
        return {str(key): plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [plain(item) for item in value]
    if isinstance(value, Enum):
        return plain(value.value)
    if isinstance(value, Path):
        return str(value)
    tolist = getattr(value, "tolist", None)  # numpy scalars and arrays
    if tolist is not None and not isinstance(value, str | bytes):
        return plain(tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class Output:
    """Where a command's text goes, after ``--json`` and ``--quiet``.

    Attributes
    ----------
    json : print the summary as one JSON object (stdout holds nothing else).
    quiet : print neither progress nor the summary.
    console : rich console on stdout (the summary's tables).
    err : rich console on stderr (progress bars, warnings).
    """

    def __init__(self, json: bool = False, quiet: bool = False) -> None:
        from rich.console import Console

        self.json = json
        self.quiet = quiet
        self.console = Console(highlight=False)
        self.err = Console(stderr=True, highlight=False)

    @property
    def shows_text(self) -> bool:
        """Whether the summary prints as text (neither ``--json`` nor ``--quiet``)."""
        return not (self.json or self.quiet)

    @property
    def shows_progress(self) -> bool:
        """Progress is drawn only on a terminal (stderr), never with ``--json``/``--quiet``."""
        return self.shows_text and self.err.is_terminal

    @contextlib.contextmanager
    def progress(self, *columns: Any) -> Iterator[Any]:
        """A started rich ``Progress`` on stderr with ``columns`` while the block runs, or
        None where progress is not shown (a pipe, ``--json``, ``--quiet``)."""
        if not self.shows_progress:
            yield None
            return
        from rich.progress import Progress

        with Progress(*columns, console=self.err, transient=False) as bar:
            yield bar

    def log(self, text: str) -> None:
        """A progress line (one per step of a long job) on stderr, unless ``--json`` or
        ``--quiet``: a line per step reads well in a log, unlike a bar."""
        if self.shows_text:
            self.err.print(text, highlight=False, markup=False, soft_wrap=True)

    def warn(self, text: str) -> None:
        """A warning as one line on stderr (also with ``--json`` and ``--quiet``)."""
        self.err.print(f"virtus: warning: {text}", highlight=False, markup=False, soft_wrap=True)

    def emit(self, summary: Summary) -> None:
        """Print the summary: one JSON object (``--json``), nothing (``--quiet``), or its
        tables then its lines."""
        if self.quiet:
            return
        if self.json:
            typer.echo(json.dumps(plain(summary.data), indent=2, allow_nan=False))
            return
        if summary.render is not None:
            summary.render(self.console, summary.data)
        for line in summary.lines:
            # Lines hold paths: never wrapped, never read as markup.
            self.console.print(line, markup=False, soft_wrap=True)
