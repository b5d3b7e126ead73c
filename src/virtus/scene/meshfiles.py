"""Mesh files (STL, OBJ, PLY) checked against their own structure before trimesh reads them.

trimesh reads a truncated binary STL as an empty mesh, a truncated ASCII PLY or OBJ as the
part before the cut; :func:`check_mesh_file` refuses such a file first, with one line
naming it and saying what is wrong, and :func:`load_mesh_file` is the one place scene
meshes are read (:meth:`virtus.scene.model.MeshObject.load`, the USD export).

* Binary STL: an 80-byte header, a uint32 triangle count ``n``, 50 bytes per triangle: the
  file has exactly ``84 + 50 n`` bytes.
* ASCII STL (starts with ``solid``, and is not a binary STL of the right size): text; as
  many ``facet normal`` as ``endfacet`` lines, three ``vertex`` lines each, at least one
  facet, and ``endsolid`` last.
* PLY: the header (``ply``, ``format``, ``element``/``property`` lines, ``end_header``,
  at most :data:`MAX_PLY_HEADER_BYTES`) is parsed; binary: the bytes after it hold at least
  what the elements need (fixed properties, list counts, and three indices per face);
  ASCII: at least one line per element entry.
* OBJ: text (no NUL byte), at most :data:`MAX_OBJ_LINES` lines of at most
  :data:`MAX_LINE_BYTES` bytes.

A file is read in blocks (the whole file only for the text formats' counts); the result is
kept per (path, size, modification time), so a mesh used by many samples is checked once.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from virtus.errors import InputError

__all__ = [
    "MAX_LINE_BYTES",
    "MAX_OBJ_LINES",
    "MAX_PLY_HEADER_BYTES",
    "check_mesh_file",
    "load_mesh_file",
]

#: Longest PLY header read (bytes): a few dozen short lines in practice.
MAX_PLY_HEADER_BYTES = 64 * 1024
#: Most lines of an OBJ file (10 million faces and their vertices, with room to spare).
MAX_OBJ_LINES = 50_000_000
#: Longest line of a text mesh file (bytes).
MAX_LINE_BYTES = 64 * 1024
#: Bytes read at a time (text files are read in blocks cut at line ends).
_BLOCK = 1 << 20
_STL_HEADER = 84
_STL_TRIANGLE = 50
#: Bytes of each PLY property type.
_PLY_SIZES = {
    "char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2,
    "uint16": 2, "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}  # fmt: skip
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_FACET = re.compile(rb"(?m)^[ \t]*facet[ \t]+normal\b")
_ENDFACET = re.compile(rb"(?m)^[ \t]*endfacet\b")
_VERTEX = re.compile(rb"(?m)^[ \t]*vertex\b")
_NON_BLANK = re.compile(rb"(?m)^[ \t\r]*\S")


def _refuse(path: Path, expected: str, got: str) -> InputError:
    return InputError(f"mesh {path}", expected, got)


def _lines(path: Path) -> Iterator[bytes]:
    """The file in blocks of whole lines (each about :data:`_BLOCK` bytes)."""
    with open(path, "rb") as handle:
        while block := handle.read(_BLOCK):
            yield block + handle.readline(MAX_LINE_BYTES + 1)


def _check_text(path: Path, kind: str, max_lines: int) -> tuple[int, bytes]:
    """Refuse a text mesh file with a NUL byte, a line over :data:`MAX_LINE_BYTES` or more
    than ``max_lines`` lines; returns its line count and its last non-blank line."""
    count, last = 0, b""
    for block in _lines(path):
        if b"\0" in block:
            raise _refuse(path, f"a text {kind} file", "binary data (a NUL byte)")
        lines = block.split(b"\n")
        if max(len(line) for line in lines) > MAX_LINE_BYTES:
            raise _refuse(path, f"lines of at most {MAX_LINE_BYTES} bytes", "a longer line")
        count += block.count(b"\n")
        if count > max_lines:
            raise _refuse(path, f"at most {max_lines} lines", "more")
        last = next((line for line in reversed(lines) if line.strip()), last)
    return count, last.strip()


def _check_ascii_stl(path: Path) -> str | None:
    """Why ``path`` is not a complete ASCII STL; None when it is one."""
    facets = ends = vertices = 0
    try:
        _, last = _check_text(path, "STL", MAX_OBJ_LINES)
    except InputError as error:
        return f"{error.got}"
    for block in _lines(path):
        block = block.lower()
        facets += len(_FACET.findall(block))
        ends += len(_ENDFACET.findall(block))
        vertices += len(_VERTEX.findall(block))
    if not facets or facets != ends or vertices != 3 * facets:
        return f"{facets} facet, {ends} endfacet and {vertices} vertex lines"
    if not last.lower().startswith(b"endsolid"):
        return "no endsolid line at the end (truncated?)"
    return None


def _check_stl(path: Path, size: int) -> None:
    with open(path, "rb") as handle:
        head = handle.read(_STL_HEADER)
    count = int.from_bytes(head[80:84], "little") if len(head) == _STL_HEADER else None
    if count is not None and size == _STL_HEADER + _STL_TRIANGLE * count:
        if count == 0:
            raise _refuse(path, "a binary STL with triangles", "a header of 0 triangles")
        return
    binary = (
        f"a binary STL of 84 + 50 x {count} = {_STL_HEADER + _STL_TRIANGLE * count} bytes "
        "(its header's triangle count)"
        if count is not None
        else "a binary STL (at least 84 bytes)"
    )
    if not head.lstrip().lower().startswith(b"solid"):
        raise _refuse(path, binary, f"{size} bytes (truncated?)")
    problem = _check_ascii_stl(path)
    if problem is not None:  # "solid" first: an ASCII STL cut short, most likely
        raise _refuse(
            path, "a complete ASCII STL (or a binary STL of the size its header says)",
            f"{size} bytes: {problem}",
        )  # fmt: skip


def _ply_header(path: Path) -> tuple[str, list[tuple[str, int, list[tuple]]], int]:
    """``(format, [(element, count, properties)], header bytes)`` of a PLY file; a property is
    ``(size,)`` or ``("list", count size, item size, name)``."""
    with open(path, "rb") as handle:
        head = handle.read(MAX_PLY_HEADER_BYTES)
    end = re.search(rb"(?m)^end_header[ \t]*\r?\n", head)
    if not head.startswith(b"ply") or end is None:
        raise _refuse(
            path, f"a PLY header (ply ... end_header, at most {MAX_PLY_HEADER_BYTES} bytes)",
            "none" if not head.startswith(b"ply") else "no end_header",
        )  # fmt: skip
    fmt, elements = None, []
    for number, raw in enumerate(head[: end.start()].decode("latin-1").splitlines()[1:], 2):
        words = raw.split()
        bad = _refuse(path, "a valid PLY header", f"line {number}: {raw.strip()[:60]!r}")
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) != 3 or words[1] not in _PLY_FORMATS:
                raise bad
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit() or int(words[2]) >= 2**32:
                raise bad
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if len(words) == 3 and words[1] in _PLY_SIZES:
                elements[-1][2].append((_PLY_SIZES[words[1]],))
            elif len(words) == 5 and words[1] == "list" and {*words[2:4]} <= _PLY_SIZES.keys():
                sizes = (_PLY_SIZES[words[2]], _PLY_SIZES[words[3]])
                elements[-1][2].append(("list", *sizes, words[4]))
            else:
                raise bad
        else:
            raise bad
    if fmt is None:
        raise _refuse(path, "a PLY header with a format line", "none")
    return fmt, elements, end.end()


def _whole_line(line: bytes, properties: list[tuple]) -> bool:
    """Whether an ASCII PLY line holds a value for every property (a list: its count, then
    that many items)."""
    tokens, at = line.split(), 0
    for prop in properties:
        if prop[0] == "list":
            if at >= len(tokens) or not tokens[at].isdigit():
                return False
            at += 1 + int(tokens[at])
        else:
            at += 1
    return len(tokens) >= at


def _check_ply(path: Path, size: int) -> None:
    fmt, elements, header = _ply_header(path)
    if fmt == "ascii":
        entries = sum(count for _, count, _ in elements)
        _, last = _check_text(path, "PLY", MAX_OBJ_LINES + entries)
        body = 0
        with open(path, "rb") as handle:
            handle.seek(header)
            while block := handle.read(_BLOCK):
                block += handle.readline(MAX_LINE_BYTES + 1)
                body += len(_NON_BLANK.findall(block))
        if body < entries:
            raise _refuse(
                path, f"{entries} element lines after the header (its element counts)",
                f"{body} lines (truncated?)",
            )  # fmt: skip
        final = next((e for e in reversed(elements) if e[1] > 0), None)
        if final is not None and not _whole_line(last, final[2]):
            raise _refuse(
                path, f"a last {final[0]} line with all its properties",
                f"{len(last.split())} values in the last line (truncated?)",
            )  # fmt: skip
        return
    need = 0
    for name, count, properties in elements:
        per = 0
        for prop in properties:
            if prop[0] == "list":  # the count, and 3 indices per face at least
                faces = name == "face" and prop[3] in ("vertex_indices", "vertex_index")
                per += prop[1] + (3 * prop[2] if faces else 0)
            else:
                per += prop[0]
        need += count * per
    if size - header < need:
        raise _refuse(
            path, f"at least {need} bytes after the header (its element counts)",
            f"{size - header} bytes (truncated?)",
        )  # fmt: skip


@functools.lru_cache(maxsize=256)
def _checked(path: str, size: int, mtime_ns: int) -> None:
    """:func:`check_mesh_file` of one version of a file (cached: raises again if bad)."""
    file = Path(path)
    suffix = file.suffix.lower()
    if suffix == ".stl":
        _check_stl(file, size)
    elif suffix == ".ply":
        _check_ply(file, size)
    elif suffix == ".obj":
        _check_text(file, "OBJ", MAX_OBJ_LINES)
    else:
        raise _refuse(file, "a mesh file (.stl, .obj, .ply)", suffix or "no suffix")


def check_mesh_file(path: str | Path) -> Path:
    """Check a mesh file against its own header or text structure (module docstring).

    Returns
    -------
    ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    InputError : ``mesh <path>: expected ..., got ...``: a truncated or malformed file, or
        one that cannot be read.
    """
    path = Path(path)
    try:
        stat = path.stat()
        _checked(str(path), stat.st_size, stat.st_mtime_ns)
    except OSError as error:
        raise _refuse(path, "a readable mesh file", error.strerror or str(error)) from None
    return path


def load_mesh_file(path: str | Path) -> Any:
    """The ``trimesh.Trimesh`` of a mesh file checked by :func:`check_mesh_file`, read
    without processing (vertices and faces as in the file).

    Raises
    ------
    InputError : the file fails the check, or trimesh cannot read it (named).
    """
    import trimesh

    path = check_mesh_file(path)
    try:
        return trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises many types for bad files
        raise InputError(f"mesh {path}", "a readable triangle mesh", f"{error}") from None
