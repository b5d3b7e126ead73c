"""Binary PLY point clouds: xyz in metres, optional normals and 8-bit colours.

:func:`write_ply` writes ``binary_little_endian`` PLY 1.0 with one ``vertex`` element whose
properties are ``x y z`` (float32 or float64), optionally ``nx ny nz`` (float32) and
``red green blue`` (uchar). The header carries ``comment units m`` and, when given, the
frame (``comment frame camera``), so any PLY viewer opens the file and a reader knows its
units. :func:`read_ply` reads such files back, and vertex data of other PLY files
(ascii or binary, either endianness; faces and other elements are skipped).

:func:`read_ply` trusts nothing in the file: the size is bounded before reading
(:data:`MAX_CLOUD_BYTES`), the header must be UTF-8, every element count must be
non-negative and fit in the bytes that follow (checked before anything is allocated), a
truncated body is refused, and points must be finite.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from virtus.checks import as_float_array, as_points
from virtus.errors import InputError, VirtusError
from virtus.io.safeio import check_file

__all__ = ["PlyError", "PointCloud", "read_ply", "write_ply"]

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
#: Types a list's length may have (integers).
_PLY_COUNT_TYPES = tuple(name for name, code in _PLY_TYPES.items() if code[0] in "iu")
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}
#: Largest PLY file read (bytes): it is read whole. 2 GiB hold a merged scan of 70 million
#: points with normals and colours (27 bytes each).
MAX_CLOUD_BYTES = 2 * 2**30


class PlyError(VirtusError, ValueError):
    """A file is not a readable PLY point cloud (bad input: also a ``ValueError``)."""


@dataclass(frozen=True)
class PointCloud:
    """Points read from or written to a PLY file.

    Attributes
    ----------
    points : (N, 3) float64, metres (in the frame named by ``frame``).
    normals : (N, 3) float64 unit normals, or None.
    colors : (N, 3) uint8 RGB, or None.
    units : length unit stated in the file header (``"m"`` for files written here).
    frame : coordinate frame stated in the header (e.g. ``"camera"``), or None.
    comments : every header comment line, in order.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    units: str | None = "m"
    frame: str | None = None
    comments: tuple[str, ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return int(self.points.shape[0])


def write_ply(
    path: str | os.PathLike[str],
    points: object,
    *,
    normals: object | None = None,
    colors: object | None = None,
    dtype: type[np.floating] | str = np.float32,
    frame: str | None = None,
    comments: tuple[str, ...] = (),
) -> Path:
    """Write a binary little-endian PLY point cloud.

    Parameters
    ----------
    path : output file; parent directories are created.
    points : (N, 3) float, metres; must be finite (drop NaN rows first, e.g. with
        :func:`virtus.reconstruct.valid_points`).
    normals : (N, 3) float, optional unit normals (written as float32).
    colors : (N, 3) integer RGB in 0..255, optional (written as uchar); values outside the
        range are an error, not clipped.
    dtype : float32 (default, ~0.1 um resolution at 1 m) or float64 for the coordinates.
    frame : name of the points' frame, written as ``comment frame <name>``.
    comments : extra header comments (one ASCII line each).

    Returns
    -------
    The path written.
    """
    pts = as_points("points", points, 3)
    n = pts.shape[0]
    kind = np.dtype(dtype)
    if kind not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise InputError("dtype", "float32 or float64", dtype)
    fields: list[tuple[str, str]] = [(axis, "<" + kind.str[1:]) for axis in "xyz"]
    columns: list[np.ndarray] = [pts[:, 0], pts[:, 1], pts[:, 2]]
    if normals is not None:
        nrm = as_float_array("normals", normals, (n, 3))
        fields += [(name, "<f4") for name in ("nx", "ny", "nz")]
        columns += [nrm[:, 0], nrm[:, 1], nrm[:, 2]]
    if colors is not None:
        col = np.asarray(colors)
        if col.shape != (n, 3) or not np.issubdtype(col.dtype, np.integer):
            raise InputError(
                "colors", f"an integer array of shape ({n}, 3)", f"{col.dtype} {col.shape}"
            )
        if n and (col.min() < 0 or col.max() > 255):
            raise InputError("colors", "values in 0..255", f"range {col.min()}..{col.max()}")
        fields += [(name, "u1") for name in ("red", "green", "blue")]
        columns += [col[:, 0], col[:, 1], col[:, 2]]
    for line in (*comments, frame or ""):
        if "\n" in line or "\r" in line or not line.isascii():
            raise InputError("comments", "single-line ASCII strings (PLY headers are ASCII)", line)

    record = np.dtype(fields)
    data = np.empty(n, dtype=record)
    for (name, _), column in zip(fields, columns, strict=True):
        data[name] = column

    names = {"f4": "float", "f8": "double", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment units m"]
    if frame:
        header.append(f"comment frame {frame}")
    header += [f"comment {line}" for line in comments]
    header.append(f"element vertex {n}")
    header += [f"property {names[code.lstrip('<')]} {name}" for name, code in fields]
    header.append("end_header")

    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with open(target, "wb") as stream:
        stream.write(("\n".join(header) + "\n").encode("ascii"))
        stream.write(data.tobytes())
    return target


def read_ply(path: str | os.PathLike[str]) -> PointCloud:
    """Read the vertices of a PLY file.

    Parameters
    ----------
    path : PLY file (ascii, binary little- or big-endian).

    Returns
    -------
    :class:`PointCloud` with points as float64 (N, 3), normals if ``nx ny nz`` are present,
    colours if ``red green blue`` are present. Units are taken from a ``comment units``
    header line (None when the file does not say).

    Raises
    ------
    InputError
        The file does not exist, cannot be read, or is larger than :data:`MAX_CLOUD_BYTES`.
    PlyError
        The file is not a PLY file, its header is not UTF-8 or announces a negative or
        impossible element count, it is truncated, it has no ``vertex`` element with x, y, z,
        or a point is not finite.
    """
    source = check_file(path, "point cloud", max_bytes=MAX_CLOUD_BYTES, kind="PLY file")
    try:
        raw = source.read_bytes()
    except OSError as error:
        raise InputError(f"point cloud {source}", "a readable file", error.strerror) from None
    if not raw:
        raise PlyError(f"{source}: empty file (0 bytes), not a PLY file")
    if not raw.startswith(b"ply\n") and not raw.startswith(b"ply\r\n"):
        raise PlyError(f"{source}: not a PLY file (it does not start with 'ply')")
    end = raw.find(b"end_header")
    if end < 0:
        raise PlyError(f"{source}: PLY header has no 'end_header'")
    body_start = raw.index(b"\n", end) + 1 if b"\n" in raw[end:] else len(raw)
    try:
        header_lines = raw[:end].decode("utf-8").splitlines()
    except UnicodeDecodeError as error:
        raise PlyError(
            f"{source}: PLY header is not UTF-8 text (byte at offset {error.start})"
        ) from None

    fmt: str | None = None
    comments: list[str] = []
    elements: list[tuple[str, int, list[tuple[str, str | None, str]]]] = []
    for line in header_lines[1:]:
        words = line.split()
        if not words:
            continue
        key = words[0]
        if key == "format" and len(words) >= 2:
            fmt = words[1]
        elif key == "comment":
            comments.append(line.strip()[len("comment") :].strip())
        elif key == "element" and len(words) == 3:
            try:
                count = int(words[2])
            except ValueError:
                raise PlyError(f"{source}: bad element line {line!r}") from None
            if count < 0:
                raise PlyError(f"{source}: negative element count in {line.strip()!r}")
            elements.append((words[1], count, []))
        elif key == "property" and elements:
            if len(words) == 5 and words[1] == "list":
                elements[-1][2].append((words[4], words[2], words[3]))
            elif len(words) == 3:
                elements[-1][2].append((words[2], None, words[1]))
            else:
                raise PlyError(f"{source}: bad property line {line!r}")
            name, count_type, value_type = elements[-1][2][-1]
            if value_type not in _PLY_TYPES or count_type not in (None, *_PLY_COUNT_TYPES):
                raise PlyError(f"{source}: unknown PLY type in property line {line.strip()!r}")
            if [p[0] for p in elements[-1][2]].count(name) > 1:
                raise PlyError(f"{source}: property {name!r} twice in element {elements[-1][0]!r}")
    if fmt not in _FORMATS:
        raise PlyError(f"{source}: unknown PLY format {fmt!r}")
    vertex_index = next((i for i, e in enumerate(elements) if e[0] == "vertex"), None)
    if vertex_index is None:
        raise PlyError(f"{source}: PLY file has no vertex element")
    props = elements[vertex_index][2]
    names = [p[0] for p in props]
    if not {"x", "y", "z"} <= set(names):
        raise PlyError(f"{source}: vertex element has no x, y, z properties")
    for name, count_type, value_type in props:
        if value_type not in _PLY_TYPES or (
            count_type is not None and count_type not in _PLY_TYPES
        ):
            raise PlyError(f"{source}: unknown PLY type in property {name!r}")

    body = raw[body_start:]
    if _FORMATS[fmt] is None:
        vertices = _read_ascii_vertices(source, body, elements, vertex_index)
    else:
        vertices = _read_binary_vertices(source, body, elements, vertex_index, _FORMATS[fmt])

    units = None
    frame = None
    for text in comments:
        words = text.split()
        if len(words) >= 2 and words[0] == "units":
            units = words[1]
        elif len(words) >= 2 and words[0] == "frame":
            frame = " ".join(words[1:])
    points = np.stack([vertices[a].astype(np.float64) for a in "xyz"], axis=1)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise PlyError(
            f"{source}: {int(bad.sum())} of {len(points)} points have non-finite coordinates "
            f"(first: vertex {int(np.flatnonzero(bad)[0])})"
        )
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.stack([vertices[a].astype(np.float64) for a in ("nx", "ny", "nz")], axis=1)
    colors = None
    if {"red", "green", "blue"} <= set(names):
        colors = np.stack([vertices[a] for a in ("red", "green", "blue")], axis=1).astype(np.uint8)
    return PointCloud(points, normals, colors, units, frame, tuple(comments))


def _read_binary_vertices(source, body, elements, vertex_index, order):
    """The vertex records of a binary body (a view of ``body``, nothing copied)."""
    offset = 0
    for index, (name, count, props) in enumerate(elements[: vertex_index + 1]):
        # Each record takes at least this many bytes (a list at least its length field):
        # refuse a count the rest of the file cannot hold before walking or allocating it.
        least = sum(np.dtype(_PLY_TYPES[p[1] or p[2]]).itemsize for p in props)
        if least * count > len(body) - offset:
            raise PlyError(
                f"{source}: PLY file is truncated ({count} {name} records of at least "
                f"{least} bytes, {len(body) - offset} bytes left)"
            )
        if index == vertex_index:
            break
        if any(p[1] is not None for p in props):  # list properties: walk record by record
            offset = _skip_binary_lists(source, body, offset, count, props, order)
        else:
            offset += least * count
    name, count, props = elements[vertex_index]
    if any(p[1] is not None for p in props):
        raise PlyError(f"{source}: list properties in the vertex element are not supported")
    record = np.dtype([(p[0], order + _PLY_TYPES[p[2]]) for p in props])
    return np.frombuffer(body, dtype=record, count=count, offset=offset)


def _skip_binary_lists(source, body, offset, count, props, order):
    for _ in range(count):
        for _name, count_type, value_type in props:
            if count_type is None:
                offset += np.dtype(_PLY_TYPES[value_type]).itemsize
                continue
            ctype = np.dtype(order + _PLY_TYPES[count_type])
            if offset + ctype.itemsize > len(body):
                raise PlyError(f"{source}: PLY file is truncated")
            length = int(np.frombuffer(body, dtype=ctype, count=1, offset=offset)[0])
            if length < 0:
                raise PlyError(f"{source}: negative list length in property {_name!r}")
            offset += ctype.itemsize + length * np.dtype(_PLY_TYPES[value_type]).itemsize
        if offset > len(body):
            raise PlyError(f"{source}: PLY file is truncated")
    return offset


def _read_ascii_vertices(source, body, elements, vertex_index):
    lines = body.decode("ascii", errors="replace").splitlines()
    start = sum(e[1] for e in elements[:vertex_index])
    name, count, props = elements[vertex_index]
    if any(p[1] is not None for p in props):
        raise PlyError(f"{source}: list properties in the vertex element are not supported")
    rows = lines[start : start + count]
    if len(rows) < count:
        raise PlyError(f"{source}: PLY file is truncated ({name} data incomplete)")
    record = np.dtype([(p[0], _PLY_TYPES[p[2]]) for p in props])
    try:
        table = np.array([r.split()[: len(props)] for r in rows], dtype=np.float64)
    except ValueError:
        raise PlyError(f"{source}: bad ascii vertex data") from None
    if count == 0:  # np.array([]) has shape (0,), not (0, n_props)
        table = table.reshape(0, len(props))
    if table.shape != (count, len(props)):
        raise PlyError(f"{source}: bad ascii vertex data")
    data = np.empty(count, dtype=record)
    for column, prop in enumerate(props):
        data[prop[0]] = table[:, column]
    return data
