"""``.npy`` and ``.npz`` files read by virtus' own header parser, every size bounded first.

numpy reads an ``.npy`` header with ``ast.literal_eval``, which on a hostile header raises
whatever the tokenizer or the compiler raises (``tokenize.TokenError``, ``SyntaxError``,
``MemoryError``, ``OverflowError`` for a shape entry of 2**64 ...) and, given a shape that
multiplies to terabytes over a 1 KB file, only finds out when it tries to allocate. Here the
header is parsed by a small strict parser that accepts exactly what ``np.save`` writes::

    \\x93NUMPY <major> <minor> <header length> {'descr': '<f8', 'fortran_order': False,
    'shape': (3, 4), }

(format versions 1.0, 2.0 and 3.0; the header dict at most :data:`MAX_NPY_HEADER_BYTES`
bytes; keys ``descr``, ``fortran_order`` and ``shape`` once each; ``descr`` a plain
non-object dtype string such as ``'<f8'`` or ``'|b1'``, structured, sub-array and object
dtypes refused; ``shape`` a tuple of at most :data:`MAX_NPY_DIMS` non-negative integers,
each below 2**63). The data size ``prod(shape) * itemsize`` is computed with Python
integers and compared with the bytes that follow the header and with the caller's bound
*before* any array is allocated; only then does numpy read the data.

``.npz`` archives (:func:`read_npz`): the zip's declared uncompressed sizes are bounded
(their sum, each member's ratio to its compressed size) before anything is decompressed,
every member must be an ``.npy`` file and is read as above.

Every failure is one :class:`~virtus.errors.InputError` naming the file. This module is
the engine of :func:`virtus.io.safeio.load_npy` and :func:`virtus.io.safeio.load_npz`.
"""

from __future__ import annotations

import math
import os
import re
import struct
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO

import numpy as np

from virtus.errors import InputError

__all__ = [
    "MAX_NPY_DIMS",
    "MAX_NPY_HEADER_BYTES",
    "MAX_NPZ_MEMBERS",
    "NpyHeader",
    "parse_header_dict",
    "read_npy_data",
    "read_npy_header",
    "read_npz",
]

#: The ``.npy`` magic string.
MAGIC = b"\x93NUMPY"
#: Longest header dict read (bytes); numpy's own reader stops at the same 10,000. A header
#: ``np.save`` writes is 118 bytes for a 2-D array, about 1,400 for 64 dimensions.
MAX_NPY_HEADER_BYTES = 10_000
#: Most dimensions of an array (numpy's ``NPY_MAXDIMS``).
MAX_NPY_DIMS = 64
#: Most members of an ``.npz`` archive (virtus' pose and view files hold fewer than 10).
MAX_NPZ_MEMBERS = 1024
#: Longest ``descr`` string: ``'<M8[ns]'`` is 7 characters.
_MAX_DESCR = 32
#: Shape entries must be below this (numpy's ``intp`` is 64-bit).
_MAX_DIM = 2**63
#: dtype kinds accepted: bool, integers, floats, complex, bytes, str, datetime, timedelta.
_KINDS = "biufcSUMm"
#: ``descr`` as numpy writes it for a plain dtype: byte order, kind, item size, an optional
#: datetime unit (``'<f8'``, ``'|b1'``, ``'<U12'``, ``'<M8[ns]'``).
_DESCR = re.compile(r"[<>|=][a-zA-Z?]\d{1,10}(?:\[\d{0,10}[a-zA-Z]{1,3}\])?")
#: ``descr`` of an object (pickled) array: ``'|O'``.
_OBJECT = re.compile(r"[<>|=]?O\d?")
#: The header's tokens: a quoted string (no escapes, no newline), a decimal integer, a
#: Python boolean, punctuation; whitespace between tokens.
_TOKEN = re.compile(
    r"""[ \t\r\n]*(?:(?P<str>'[^'\\\n]*'|"[^"\\\n]*")|(?P<int>[0-9]+)"""
    r"""|(?P<bool>True|False)|(?P<punct>[{}():,])|(?P<end>\Z))"""
)
#: Largest decompressed/compressed ratio of a deflated member (DEFLATE cannot do better
#: than about 1032:1); a member declaring more is not what it says.
_MAX_DEFLATE_RATIO = 1100
#: Bytes read per call while filling an array from a zip member.
_CHUNK = 1 << 24


@dataclass(frozen=True)
class NpyHeader:
    """What a checked ``.npy`` header announces.

    Attributes
    ----------
    shape : the array's shape.
    fortran_order : data stored in Fortran (column-major) order.
    dtype : the (plain, non-object) dtype.
    offset : bytes from the start of the file to the data.
    count : number of elements (``prod(shape)``).
    nbytes : data bytes (``count * dtype.itemsize``).
    """

    shape: tuple[int, ...]
    fortran_order: bool
    dtype: np.dtype
    offset: int
    count: int
    nbytes: int


# --------------------------------------------------------------------------------------------
# the header dict
# --------------------------------------------------------------------------------------------


def _tokens(text: str, label: str) -> Iterator[tuple[str, str, int]]:
    """``(kind, text, column)`` for each token of ``text``, ending with ``("end", "", n)``;
    made one at a time, so a parser that stops early reads no further."""
    pos = 0
    while True:
        match = _TOKEN.match(text, pos)
        if match is None:
            rest = text[pos:].lstrip(" \t\r\n")
            column = len(text) - len(rest) + 1
            raise InputError(label, "a valid .npy header", f"{rest[:12]!r} at column {column}")
        kind = match.lastgroup or "end"
        yield kind, match.group(kind), match.start(kind) + 1
        if kind == "end":
            return
        pos = match.end()


#: Token kinds in messages.
_NAMES = {"str": "a quoted string", "int": "a number", "bool": "True or False", "end": "the end"}


def parse_header_dict(text: str, label: str) -> dict[str, object]:
    """The dict of an ``.npy`` header, parsed strictly (no ``eval``, no recursion).

    Accepted: ``{`` then ``'key': value`` pairs separated by commas (a trailing comma
    allowed) then ``}``; keys are quoted strings; values are quoted strings, ``True`` /
    ``False``, or tuples of at most :data:`MAX_NPY_DIMS` decimal integers (``()``,
    ``(5,)``, ``(3, 4)``) below 2**63. Keys must be ``descr``, ``fortran_order`` and
    ``shape``, each once. Tokens are read one at a time and parsing stops at the first
    problem, so any header costs at most a few hundred tokens.

    Raises
    ------
    InputError : ``<label>: expected a valid .npy header, got ...`` naming the first
        problem and its column.
    """

    def refuse(got: str) -> InputError:
        return InputError(label, "a valid .npy header", got)

    tokens = _tokens(text, label)

    def take(*wanted: str) -> tuple[str, str, int]:
        kind, value, column = next(tokens)
        if kind == "punct":
            kind = value  # punctuation is its own kind
        if kind not in wanted:
            shown = "the end" if kind == "end" else repr(value[:16])
            names = " or ".join(_NAMES.get(w, repr(w)) for w in wanted)
            raise refuse(f"{shown} at column {column} (expected {names})")
        return kind, value, column

    def integer(value: str, column: int) -> int:
        if len(value) > 19 or int(value) >= _MAX_DIM:
            shown = value if len(value) <= 30 else value[:27] + "..."
            raise refuse(f"shape entry {shown} at column {column} (2**63 or more)")
        if len(value) > 1 and value[0] == "0":
            raise refuse(f"{value!r} at column {column} (a number with a leading zero)")
        return int(value)

    def tuple_value() -> tuple[int, ...]:
        items: list[int] = []
        trailing = False
        while True:
            kind, value, column = take("int", ")")
            if kind == ")":
                break
            if len(items) == MAX_NPY_DIMS:
                raise refuse(f"more than {MAX_NPY_DIMS} shape entries")
            items.append(integer(value, column))
            kind, value, column = take(",", ")")
            trailing = kind == ","
            if kind == ")":
                break
        if len(items) == 1 and not trailing:
            raise refuse(f"({items[0]}) without a comma (a number, not a tuple)")
        return tuple(items)

    result: dict[str, object] = {}
    take("{")
    while True:
        kind, key, column = take("str", "}")
        if kind == "}":
            break
        name = key[1:-1]
        if name not in ("descr", "fortran_order", "shape"):
            raise refuse(f"unknown key {name[:20]!r} at column {column}")
        if name in result:
            raise refuse(f"key {name!r} twice")
        take(":")
        kind, value, column = take("str", "bool", "(")
        if kind == "str":
            result[name] = value[1:-1]
        elif kind == "bool":
            result[name] = value == "True"
        else:
            result[name] = tuple_value()
        kind, _, _ = take(",", "}")
        if kind == "}":
            break
    take("end")
    missing = [key for key in ("descr", "fortran_order", "shape") if key not in result]
    if missing:
        raise refuse(f"no {' or '.join(repr(k) for k in missing)} key")
    return result


def _dtype(descr: object, label: str) -> np.dtype:
    """The plain dtype ``descr`` names, or :class:`InputError` (checked before numpy sees it)."""
    if not isinstance(descr, str):
        raise InputError(label, "a .npy header with a dtype string", type(descr).__name__)
    if _OBJECT.fullmatch(descr):
        raise InputError(label, "a numeric array", "an object array (pickled arrays are refused)")
    if len(descr) > _MAX_DESCR or not _DESCR.fullmatch(descr):
        raise InputError(
            label, "a plain numeric or string dtype (e.g. '<f8')", f"descr {descr[:_MAX_DESCR]!r}"
        )
    try:
        dtype = np.dtype(descr)
    except (TypeError, ValueError, OverflowError, SyntaxError):
        raise InputError(label, "a dtype numpy knows", f"descr {descr!r}") from None
    if dtype.hasobject:
        raise InputError(label, "a numeric array", "an object array (pickled arrays are refused)")
    if dtype.kind not in _KINDS or dtype.fields is not None or dtype.subdtype is not None:
        raise InputError(label, "a plain numeric or string dtype", f"descr {descr!r}")
    return dtype


def _shape(shape: object, label: str) -> tuple[int, ...]:
    if not isinstance(shape, tuple):
        raise InputError(label, "a .npy header with a shape tuple", type(shape).__name__)
    if len(shape) > MAX_NPY_DIMS:
        raise InputError(label, f"at most {MAX_NPY_DIMS} dimensions", f"{len(shape)}")
    for entry in shape:
        if not 0 <= entry < _MAX_DIM:
            raise InputError(label, "shape entries below 2**63", f"shape entry {entry}")
    return shape


# --------------------------------------------------------------------------------------------
# the header
# --------------------------------------------------------------------------------------------


def _read_exactly(stream: IO[bytes], size: int, label: str, what: str) -> bytes:
    data = stream.read(size)
    if len(data) != size:
        raise InputError(
            label, "a readable .npy file", f"truncated {what} ({len(data)} of {size} bytes)"
        )
    return data


def read_npy_header(stream: IO[bytes], label: str, *, size: int, max_bytes: int) -> NpyHeader:
    """Read and check the header at the start of ``stream`` (an ``.npy`` file of ``size``
    bytes, or a zip member of that uncompressed size); leaves the stream at the data.

    Checks, in order, before anything is allocated: the magic, the format version (1.0,
    2.0 or 3.0), the header length (at most :data:`MAX_NPY_HEADER_BYTES`), the header dict
    (:func:`parse_header_dict`), the dtype, the shape, then ``prod(shape) * itemsize``
    against the bytes that follow the header and against ``max_bytes``.

    Raises
    ------
    InputError : one line starting with ``label`` for each problem.
    """
    prefix = stream.read(8)
    if prefix[:1] == b"\x80":
        raise InputError(label, "a .npy array", "pickled data (pickles are refused)")
    if prefix[:6] != MAGIC:
        if len(prefix) < 6 and MAGIC.startswith(prefix) and prefix:
            raise InputError(label, "a readable .npy file", "truncated header")
        raise InputError(label, "a .npy file", "no .npy header (bad magic)")
    if len(prefix) < 8:
        raise InputError(label, "a readable .npy file", "truncated header")
    version = (prefix[6], prefix[7])
    if version not in ((1, 0), (2, 0), (3, 0)):
        raise InputError(label, ".npy format version 1.0, 2.0 or 3.0", f"{version[0]}.{version[1]}")
    width = 2 if version == (1, 0) else 4
    raw = _read_exactly(stream, width, label, "header")
    length = struct.unpack("<H" if width == 2 else "<I", raw)[0]
    if length > MAX_NPY_HEADER_BYTES:
        raise InputError(
            label, f"a .npy header of at most {MAX_NPY_HEADER_BYTES:,} bytes", f"{length:,} bytes"
        )
    offset = 8 + width + length
    if size < offset:
        got = f"truncated header ({max(size - 8 - width, 0)} of {length} bytes)"
        raise InputError(label, "a readable .npy file", got)
    data = _read_exactly(stream, length, label, "header")
    try:
        text = data.decode("utf-8" if version == (3, 0) else "latin1")
    except UnicodeDecodeError:
        raise InputError(label, "a .npy header in UTF-8", "other bytes") from None
    fields = parse_header_dict(text, label)
    dtype = _dtype(fields["descr"], label)
    if not isinstance(fields["fortran_order"], bool):
        raise InputError(label, "fortran_order True or False", fields["fortran_order"])
    shape = _shape(fields["shape"], label)
    count = math.prod(shape)
    announced = count * dtype.itemsize
    available = size - offset
    if announced != available:
        problem = "truncated" if available < announced else "extra data"
        raise InputError(
            label,
            f"{announced:,} data bytes for shape {shape} {dtype}",
            f"{available:,} bytes ({problem})",
        )
    if announced > max_bytes:
        raise InputError(label, f"an array of at most {max_bytes:,} bytes", f"{announced:,} bytes")
    return NpyHeader(shape, fields["fortran_order"], dtype, offset, count, announced)


def read_npy_data(stream: IO[bytes], header: NpyHeader, label: str) -> np.ndarray:
    """The array whose checked ``header`` was just read from ``stream``: read straight into
    its buffer (``np.fromfile`` for a real file, chunked reads for a zip member)."""
    if header.count == 0 or header.dtype.itemsize == 0:
        flat = np.ndarray(header.count, dtype=header.dtype)  # np.empty mishandles 'U0'
    elif _is_real_file(stream):
        flat = np.fromfile(stream, dtype=header.dtype, count=header.count)
    else:
        flat = np.empty(header.count, dtype=header.dtype)
        view = memoryview(flat.view(np.uint8))
        filled = 0
        while filled < header.nbytes:
            chunk = stream.read(min(_CHUNK, header.nbytes - filled))
            if not chunk:
                break
            view[filled : filled + len(chunk)] = chunk
            filled += len(chunk)
        if filled != header.nbytes:
            flat = flat[: filled // header.dtype.itemsize]
    if flat.size != header.count:
        raise InputError(
            label, f"{header.nbytes:,} data bytes", f"{flat.size * header.dtype.itemsize:,} bytes "
            "(truncated while reading)"
        )  # fmt: skip
    if header.fortran_order:
        return flat.reshape(header.shape[::-1]).transpose()
    return flat.reshape(header.shape)


def _is_real_file(stream: IO[bytes]) -> bool:
    try:
        stream.fileno()
    except (OSError, AttributeError, ValueError):
        return False
    return True


# --------------------------------------------------------------------------------------------
# .npz archives
# --------------------------------------------------------------------------------------------


def read_npz(path: str | os.PathLike[str], label: str, *, max_bytes: int) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` archive (``np.savez`` / ``np.savez_compressed``).

    Before anything is decompressed: at most :data:`MAX_NPZ_MEMBERS` members, each an
    ``.npy`` file stored or deflated (not encrypted), named once, declaring at most
    ``max_bytes`` uncompressed bytes in all and no more than DEFLATE can produce from its
    compressed size (a zip bomb is refused). Then each member's header is checked as
    :func:`read_npy_header` does, against the member's declared size, and its data read
    (the zip's CRC is checked as the last byte is read).

    Raises
    ------
    InputError : ``<label>: expected ..., got ...``; a member's problem starts with
        ``member <name>``.
    zipfile.BadZipFile, OSError, EOFError : an unreadable archive (the caller names it).
    """
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        if len(members) > MAX_NPZ_MEMBERS:
            raise InputError(
                label, f"an .npz archive of at most {MAX_NPZ_MEMBERS} arrays", len(members)
            )
        total = 0
        keys: dict[str, zipfile.ZipInfo] = {}
        for info in members:
            name = info.filename
            if not name.endswith(".npy") or info.is_dir():
                raise InputError(label, "an archive of .npy files", f"member {name[:40]!r}")
            if info.flag_bits & 0x1:
                raise InputError(label, "an unencrypted archive", f"member {name[:40]!r}")
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise InputError(
                    label, "members stored or deflated (as numpy writes them)",
                    f"member {name[:40]!r} with compression method {info.compress_type}",
                )  # fmt: skip
            ratio_bound = 1 if info.compress_type == zipfile.ZIP_STORED else _MAX_DEFLATE_RATIO
            if info.file_size > max(info.compress_size, 1) * ratio_bound + 64:
                raise InputError(
                    label, "member sizes DEFLATE can produce",
                    f"member {name[:40]!r} declaring {info.file_size:,} bytes from "
                    f"{info.compress_size:,} (a zip bomb?)",
                )  # fmt: skip
            total += info.file_size
            if total > max_bytes:
                raise InputError(
                    label, f"at most {max_bytes:,} uncompressed bytes", "more (a zip bomb?)"
                )
            key = name[: -len(".npy")]
            if key in keys:
                raise InputError(label, "each array once", f"member {name[:40]!r} twice")
            keys[key] = info
        arrays = {}
        for key, info in keys.items():
            member = f"{label} member {info.filename}"
            with archive.open(info) as stream:
                header = read_npy_header(stream, member, size=info.file_size, max_bytes=max_bytes)
                arrays[key] = read_npy_data(stream, header, member)
        return arrays
