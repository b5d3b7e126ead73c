"""The one guarded layer through which virtus reads its input files.

Every reader of a user-supplied file (rig and calibration JSON, scene YAML, ``.npy`` arrays,
meshes, point clouds) goes through these functions, so each malformed input ends as one
:class:`~virtus.errors.InputError` line naming the file and the problem -- never a
traceback, a hang or a silently half-read value. What is checked:

* the file exists and is not larger than a stated bound, checked with ``stat`` before
  anything is read (:func:`check_file`);
* text is UTF-8 without NUL bytes (:func:`read_text`);
* JSON: nesting depth bounded *before* parsing (so a deeply nested file cannot exhaust the
  stack), no ``NaN``/``Infinity`` literals or overflowing numbers, no duplicate keys, syntax
  errors reported with line and column (:func:`parse_json`, :func:`read_json`);
* YAML: the safe loader only, with a bound on aliases, on the node count once aliases are
  expanded (an "alias bomb" fails in milliseconds) and on depth; recursive anchors,
  duplicate keys and non-finite floats refused; errors with line and column
  (:func:`parse_yaml`, :func:`read_yaml`);
* ``.npy``/``.npz``: never unpickled; the header is parsed by virtus' own strict parser and
  the data size it announces bounded and compared with the file before anything is
  allocated (:mod:`virtus.io.npyfile`); an ``.npz``'s declared sizes are bounded before
  anything is decompressed; optional dtype and shape checks (:func:`load_npy`,
  :func:`load_npz`);
* mappings: unknown keys refused with a "did you mean" suggestion (:func:`check_keys`).

Every ``what`` argument is a short noun naming the file's role (``"rig"``, ``"scene"``);
messages read ``<what> <path>: expected ..., got ...``.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import re
import zipfile
import zlib
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from virtus.checks import check_shape
from virtus.errors import InputError
from virtus.io.npyfile import read_npy_data, read_npy_header, read_npz

__all__ = [
    "MAX_ARRAY_BYTES",
    "MAX_CONFIG_BYTES",
    "MAX_DEPTH",
    "MAX_YAML_ALIASES",
    "MAX_YAML_NODES",
    "check_file",
    "check_keys",
    "closest_key",
    "is_file",
    "load_npy",
    "load_npz",
    "parse_json",
    "parse_yaml",
    "read_json",
    "read_text",
    "read_yaml",
]

#: Largest JSON/YAML configuration file read (bytes). The largest real ones -- a
#: calibration.json with per-pose residuals, a capture.json with its pattern sequence --
#: are tens of kilobytes; 16 MiB leaves a factor of 100 and keeps parsing under a second.
MAX_CONFIG_BYTES = 16 * 2**20
#: Deepest nesting of JSON arrays/objects and YAML collections. virtus files nest at most
#: 4 levels (capture.json -> rig -> camera -> K rows); 64 is far above any real file and far
#: below Python's recursion limit (1000), which the parsers would otherwise hit.
MAX_DEPTH = 64
#: Most YAML aliases (``*name``) in one document. Hand-written scenes use a few to share a
#: material; every alias beyond this is refused rather than expanded.
MAX_YAML_ALIASES = 1000
#: Most YAML nodes in one document with every alias expanded. An alias bomb (9 levels of 9
#: aliases each expand to 9**9 = 387 million nodes) is refused while it is composed, before
#: anything is built; 2 million nodes bound the Python objects built to about 200 MB.
MAX_YAML_NODES = 2_000_000
#: Largest ``.npy`` array read (bytes): 52 frames of 4096 x 4096 uint16 are 1.7 GB.
MAX_ARRAY_BYTES = 2 * 2**30

#: Integers beyond this cannot become floats (float() raises OverflowError): refused.
_FLOAT64_MAX = int(np.finfo(np.float64).max)
#: A JSON string literal (escapes included), unrolled so that matching is linear.
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
#: Names of JSON and YAML value kinds for "expected a JSON object, got a JSON array".
_JSON_KINDS = (
    (dict, "a JSON object"), (list, "a JSON array"), (str, "a JSON string"),
    (bool, "JSON true/false"), (int | float, "a JSON number"), (object, "JSON null"),
)  # fmt: skip
_YAML_KINDS = (
    (dict, "a YAML mapping"), (list, "a YAML sequence"), (type(None), "an empty YAML document"),
    (object, "a YAML scalar"),
)  # fmt: skip


# --------------------------------------------------------------------------------------------
# files and text
# --------------------------------------------------------------------------------------------


def _label(what: str, path: Path) -> str:
    """The name used in messages about one file: ``"<what> <path>"``."""
    return f"{what} {path}"


def check_file(
    path: str | os.PathLike[str], what: str, *, max_bytes: int, kind: str = "file"
) -> Path:
    """Check that ``path`` is an existing regular file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    path : the file.
    what : its role, for messages (e.g. ``"rig"``).
    max_bytes : the size bound, checked with ``stat`` (nothing is read).
    kind : the kind of file, for the "does not exist" message (e.g. ``"YAML file"``).

    Returns
    -------
    ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    InputError
        ``<what>: expected an existing <kind>, got '<path>'`` for a missing file or a
        folder; ``<what> <path>: expected at most N bytes, got ...`` for a larger one.
    """
    path = Path(path)
    if not is_file(path):
        got = f"{path} (a folder)" if is_file(path, folder=True) else str(path)
        raise InputError(what, f"an existing {kind}", got)
    try:
        size = path.stat().st_size
    except OSError as error:
        raise InputError(_label(what, path), "a readable file", error.strerror) from None
    if size > max_bytes:
        raise InputError(
            _label(what, path), f"a {kind} of at most {max_bytes:,} bytes", f"{size:,} bytes"
        )
    return path


def is_file(path: str | os.PathLike[str], *, folder: bool = False) -> bool:
    """``Path(path).is_file()`` (``is_dir()`` with ``folder``), False rather than an error
    for a name the system cannot look up -- too long, holding a NUL byte, a symlink loop --
    as a path read from a user's file may be."""
    try:
        return Path(path).is_dir() if folder else Path(path).is_file()
    except (OSError, ValueError, RuntimeError):
        return False


def _read_bytes(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as error:
        raise InputError(_label(what, path), "a readable file", error.strerror) from None


def read_text(
    path: str | os.PathLike[str],
    what: str,
    *,
    max_bytes: int = MAX_CONFIG_BYTES,
    kind: str = "file",
) -> str:
    """Read a UTF-8 text file (a leading byte-order mark is dropped).

    Parameters
    ----------
    path, what, max_bytes, kind : as for :func:`check_file`.

    Returns
    -------
    The text.

    Raises
    ------
    InputError
        Missing or too large (see :func:`check_file`), a NUL byte ("a binary file"), or bytes
        that are not UTF-8 (the offset of the first is given).
    """
    path = check_file(path, what, max_bytes=max_bytes, kind=kind)
    data = _read_bytes(path, what)
    nul = data.find(b"\x00")
    if nul >= 0:
        raise InputError(_label(what, path), "UTF-8 text", f"a binary file (NUL byte at {nul})")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise InputError(
            _label(what, path),
            "UTF-8 text",
            f"not UTF-8 text (byte 0x{data[error.start]:02x} at {error.start})",
        ) from None


def _check_kind(label: str, value: Any, expect: type | None, kinds: tuple) -> Any:
    """Refuse a parsed document whose top-level value is not an instance of ``expect``;
    ``kinds`` names the language's value kinds, e.g. ``(dict, "a JSON object")``."""
    if expect is None or isinstance(value, expect):
        return value
    wanted = next((text for kind, text in kinds if issubclass(expect, kind)), expect.__name__)
    got = next(text for kind, text in kinds if isinstance(value, kind))
    raise InputError(label, wanted, got)


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------


def _json_depth(text: str | bytes) -> int:
    """Deepest nesting of arrays/objects in JSON ``text``, found without recursion.

    String literals are removed first (brackets inside them do not count); the depth is the
    running maximum of ``[``/``{`` minus ``]``/``}``. Linear in the text's length.
    """
    data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
    codes = np.frombuffer(_JSON_STRING.sub(b"", data), dtype=np.uint8)
    brackets = codes[np.isin(codes, np.frombuffer(b"[]{}", dtype=np.uint8))]
    steps = np.where((brackets == ord("[")) | (brackets == ord("{")), 1, -1).astype(np.int32)
    return int(np.cumsum(steps).max(initial=0))


def parse_json(
    text: str,
    what: str,
    *,
    expect: type | None = None,
    max_depth: int = MAX_DEPTH,
    allow_nan: bool = False,
) -> Any:
    """Parse JSON text strictly.

    Parameters
    ----------
    text : the JSON text.
    what : the document's name in messages (:func:`read_json` passes ``"<what> <path>"``).
    expect : the type the top-level value must have (e.g. ``dict`` for a JSON object).
    max_depth : the deepest nesting accepted, checked before parsing.
    allow_nan : accept ``NaN``/``Infinity`` (for virtus' own reports, which may hold NaN
        statistics); configuration files never need them.

    Returns
    -------
    The value (dicts, lists, str, int, float, bool, None).

    Raises
    ------
    InputError
        Too deep, invalid JSON (with line and column), a ``NaN``/``Infinity`` literal or a
        number that overflows float64, a duplicate key, or the wrong top-level type.
    """

    refused: list[_Refused] = []  # found while parsing, reported with their key path after

    def no_constant(name: str) -> Any:
        if allow_nan:
            return float(name)
        refused.append(_Refused(name, "finite numbers (JSON has no NaN or Infinity)"))
        return refused[-1]

    def finite_float(literal: str) -> Any:
        number = float(literal)
        if not (allow_nan or math.isfinite(number)):
            refused.append(_Refused(literal, "numbers within float64 range"))
            return refused[-1]
        return number

    def bounded_int(literal: str) -> Any:
        number = int(literal)
        if abs(number) > _FLOAT64_MAX:
            refused.append(_Refused(literal, "numbers within float64 range"))
            return refused[-1]
        return number

    def unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        result: dict[str, Any] = {}
        for key, value in pairs:
            if key in result:
                raise InputError(what, "each key once per object", f"key {key!r} twice")
            result[key] = value
        return result

    depth = _json_depth(text)
    if depth > max_depth:
        raise InputError(what, f"JSON nested at most {max_depth} deep", f"depth {depth}")
    try:
        value = json.loads(
            text,
            parse_constant=no_constant,
            parse_float=finite_float,
            parse_int=bounded_int,
            object_pairs_hook=unique_keys,
        )
    except json.JSONDecodeError as error:
        where = f"line {error.lineno}, column {error.colno}"
        raise InputError(what, "valid JSON", f"{error.msg} at {where}") from None
    except RecursionError:  # only when max_depth is set above the interpreter's limit
        raise InputError(what, "JSON nested less deeply", "too deep to parse") from None
    except ValueError as error:  # e.g. an integer of more than 4300 digits
        if isinstance(error, InputError):
            raise
        raise InputError(what, "valid JSON", str(error).splitlines()[0]) from None
    if refused:
        key, number = _first_refused(value)
        raise _in_key(InputError(what, number.expected, number.literal), key)
    return _check_kind(what, value, expect, _JSON_KINDS)


class _Refused:
    """A number :func:`parse_json` refuses (NaN, an overflow), left in the parsed value
    until the key path that holds it is known."""

    def __init__(self, literal: str, expected: str) -> None:
        self.literal = literal
        self.expected = expected


def _first_refused(value: Any, key: str = "") -> tuple[str, Any]:
    """``(key path, marker)`` of the first :class:`_Refused` in ``value`` (document order:
    JSON objects keep it), e.g. ``("camera.dist[2]", marker)``; ``("", None)`` if none."""
    if isinstance(value, _Refused):
        return key, value
    if not isinstance(value, dict | list):
        return "", None
    for name, item in value.items() if isinstance(value, dict) else enumerate(value):
        step = f"[{name}]" if isinstance(name, int) else f".{name}" if key else str(name)
        found = _first_refused(item, key + step)
        if found[1] is not None:
            return found
    return "", None


def _in_key(error: InputError, key: str) -> InputError:
    """``error`` with the key path of the value at fault appended to its line (``... got
    'NaN' in camera.dist[2]``); the file's name stays first."""
    if key:
        error.args = (f"{error.args[0]} in {key}",)
    return error


def read_json(
    path: str | os.PathLike[str],
    what: str,
    *,
    expect: type | None = None,
    max_bytes: int = MAX_CONFIG_BYTES,
    max_depth: int = MAX_DEPTH,
    allow_nan: bool = False,
) -> Any:
    """Read a JSON file: :func:`read_text` then :func:`parse_json` (see both)."""
    text = read_text(path, what, max_bytes=max_bytes, kind="JSON file")
    return parse_json(
        text, _label(what, Path(path)), expect=expect, max_depth=max_depth, allow_nan=allow_nan
    )


# --------------------------------------------------------------------------------------------
# YAML
# --------------------------------------------------------------------------------------------


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader with bounds checked while the document is composed.

    The composer keeps, for every node, its size with aliases expanded (one per node plus
    its children's sizes; an alias counts as the size of its anchor). A node over
    :data:`MAX_YAML_NODES`, more than :data:`MAX_YAML_ALIASES` aliases, an alias to an
    anchor still being composed (a recursive structure), a collection nested deeper than
    the depth bound or a key given twice raises :class:`InputError` at once, before anything
    is constructed or expanded.
    """

    def __init__(self, text: str, what: str, max_depth: int) -> None:
        super().__init__(text)
        self.what = what
        self.max_depth = max_depth
        self.depth = 0
        self.aliases = 0
        self.sizes: dict[int, int] = {}  # id(node) -> node count with aliases expanded
        self.keys: list[str] = []  # the key path of the node being composed

    def _refuse(self, expected: str, got: str) -> InputError:
        mark = self.peek_event().start_mark
        return InputError(self.what, expected, f"{got} at line {mark.line + 1}")

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_YAML_ALIASES:
                raise self._refuse(f"at most {MAX_YAML_ALIASES:,} YAML aliases", "more")
            event = self.peek_event()
            node = super().compose_node(parent, index)
            if id(node) not in self.sizes:
                raise InputError(
                    self.what,
                    "no recursive YAML anchors",
                    f"alias *{event.anchor} inside its own anchor at line "
                    f"{event.start_mark.line + 1}",
                )
            return node
        self.depth += 1
        if self.depth > self.max_depth:
            raise self._refuse(f"YAML nested at most {self.max_depth} deep", "deeper nesting")
        self.keys.append(
            f"[{index}]" if isinstance(index, int)
            else "" if not isinstance(index, yaml.ScalarNode)  # the root, or a key itself
            else f".{index.value}" if any(self.keys) else str(index.value)
        )  # fmt: skip
        node = super().compose_node(parent, index)
        if isinstance(node, yaml.ScalarNode):
            self._check_number(node)
        self.keys.pop()
        self.depth -= 1
        if isinstance(node, yaml.MappingNode):
            _check_unique_yaml_keys(self.what, node)
            children = [child for pair in node.value for child in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = node.value
        else:
            children = []
        size = 1 + sum(self.sizes[id(child)] for child in children)
        if size > MAX_YAML_NODES:
            raise InputError(
                self.what,
                f"at most {MAX_YAML_NODES:,} YAML nodes with aliases expanded",
                f"more (an alias bomb?) at line {node.start_mark.line + 1}",
            )
        self.sizes[id(node)] = size
        return node

    def _check_number(self, node: yaml.ScalarNode) -> None:
        """Refuse a non-finite float or an integer beyond float64, naming its key path."""
        if node.tag == "tag:yaml.org,2002:float":
            if not math.isfinite(yaml.SafeLoader.construct_yaml_float(self, node)):
                error = InputError(self.what, "finite numbers", _at(node))
                raise _in_key(error, "".join(self.keys))
        elif node.tag == "tag:yaml.org,2002:int":
            if abs(yaml.SafeLoader.construct_yaml_int(self, node)) > _FLOAT64_MAX:
                error = InputError(self.what, "numbers within float64 range", _at(node))
                raise _in_key(error, "".join(self.keys))

    def construct_yaml_float(self, node: Any) -> float:
        number = super().construct_yaml_float(node)
        if not math.isfinite(number):
            raise InputError(self.what, "finite numbers", _at(node))
        return number

    def construct_yaml_int(self, node: Any) -> int:
        number = super().construct_yaml_int(node)
        if abs(number) > _FLOAT64_MAX:
            raise InputError(self.what, "numbers within float64 range", _at(node))
        return number


_BoundedLoader.add_constructor("tag:yaml.org,2002:float", _BoundedLoader.construct_yaml_float)
_BoundedLoader.add_constructor("tag:yaml.org,2002:int", _BoundedLoader.construct_yaml_int)


def _at(node: yaml.Node) -> str:
    """``"<value> at line N"`` for messages about a scalar node."""
    return f"{node.value} at line {node.start_mark.line + 1}"


def _check_unique_yaml_keys(what: str, node: yaml.MappingNode) -> None:
    """Refuse a mapping that gives a plain key twice (PyYAML would keep the last silently);
    merge keys (``<<``) are exempt."""
    seen: set[tuple[str, str]] = set()
    for key, _ in node.value:
        if not isinstance(key, yaml.ScalarNode) or key.tag == "tag:yaml.org,2002:merge":
            continue
        if (key.tag, key.value) in seen:
            raise InputError(
                what, "each key once per mapping", f"key {key.value!r} twice at line "
                f"{key.start_mark.line + 1}"
            )  # fmt: skip
        seen.add((key.tag, key.value))


def parse_yaml(
    text: str, what: str, *, expect: type | None = None, max_depth: int = MAX_DEPTH
) -> Any:
    """Parse YAML text with the safe loader and the bounds of this module.

    Parameters
    ----------
    text : the YAML text (one document).
    what : the document's name in messages (:func:`read_yaml` passes ``"<what> <path>"``).
    expect : the type the top-level value must have (e.g. ``dict`` for a mapping).
    max_depth : the deepest nesting accepted.

    Returns
    -------
    The value (only plain Python types: the safe loader builds no objects).

    Raises
    ------
    InputError
        Invalid YAML (problem, line and column), more than :data:`MAX_YAML_ALIASES` aliases,
        more than :data:`MAX_YAML_NODES` nodes with aliases expanded, a recursive anchor,
        nesting deeper than ``max_depth``, a duplicate key, a non-finite float, or the wrong
        top-level type.
    """
    try:
        loader = _BoundedLoader(text, what, max_depth)
    except yaml.YAMLError as error:  # the reader checks the characters at once (e.g. \x00)
        raise InputError(what, "valid YAML", str(error).splitlines()[0]) from None
    try:
        value = loader.get_single_data()
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        problem = error.problem or error.context or "invalid YAML"
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise InputError(what, "valid YAML", f"{problem}{where}") from None
    except yaml.YAMLError as error:
        raise InputError(what, "valid YAML", str(error).splitlines()[0]) from None
    except RecursionError:  # only when max_depth is set above the interpreter's limit
        raise InputError(what, "YAML nested less deeply", "too deep to parse") from None
    except (ValueError, TypeError, OverflowError) as error:  # e.g. a 5000-digit integer
        if isinstance(error, InputError):
            raise
        raise InputError(what, "valid YAML values", str(error).splitlines()[0]) from None
    finally:
        loader.dispose()
    return _check_kind(what, value, expect, _YAML_KINDS)


def read_yaml(
    path: str | os.PathLike[str],
    what: str,
    *,
    expect: type | None = None,
    max_bytes: int = MAX_CONFIG_BYTES,
    max_depth: int = MAX_DEPTH,
) -> Any:
    """Read a YAML file: :func:`read_text` then :func:`parse_yaml` (see both)."""
    text = read_text(path, what, max_bytes=max_bytes, kind="YAML file")
    return parse_yaml(text, _label(what, Path(path)), expect=expect, max_depth=max_depth)


# --------------------------------------------------------------------------------------------
# .npy arrays
# --------------------------------------------------------------------------------------------


def load_npz(
    path: str | os.PathLike[str], what: str, *, max_bytes: int = MAX_ARRAY_BYTES
) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file a run wrote (pose and view files), without
    unpickling anything.

    The archive's declared sizes are bounded before anything is decompressed (at most
    ``max_bytes`` in all, nothing a zip bomb declares) and each member's ``.npy`` header is
    parsed and bounded by :func:`virtus.io.npyfile.read_npz` before its data is allocated.

    Raises
    ------
    InputError : ``"<path>: not a readable <what> (<reason>)"`` for a missing, truncated,
        oversized or foreign file, a pickled member, a lying header.
    """
    label = _label(what, Path(path))
    try:
        checked = check_file(path, what, max_bytes=max_bytes, kind=".npz file")
        return read_npz(checked, label, max_bytes=max_bytes)
    except InputError as error:
        where = error.name.removeprefix(label).strip() if error.name.startswith(label) else ""
        detail = str(error).removeprefix(f"{error.name}: ")
        raise _unreadable(path, what, f"{where}: {detail}" if where else detail) from None
    except (OSError, ValueError, KeyError, EOFError, NotImplementedError, RuntimeError,
            MemoryError, zipfile.BadZipFile, zlib.error) as error:  # fmt: skip
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise _unreadable(path, what, reason) from None


def _unreadable(path: str | os.PathLike[str], what: str, reason: str) -> InputError:
    """``<path>: not a readable <what> (<reason>)`` as an :class:`InputError` (the line
    :func:`load_npz` has always given, which callers and users match)."""
    error = InputError(f"{what} {path}", f"a readable {what}", reason)
    error.args = (f"{path}: not a readable {what} ({reason})",)
    return error


def load_npy(
    path: str | os.PathLike[str],
    what: str,
    *,
    max_bytes: int = MAX_ARRAY_BYTES,
    dtype: Any = None,
    shape: Sequence[int | None] | None = None,
) -> np.ndarray:
    """Read a ``.npy`` array without unpickling anything.

    The header is parsed by virtus' own strict parser (:mod:`virtus.io.npyfile`, not
    numpy's ``literal_eval``): magic, version, header length and dict, a plain dtype
    (object, structured and sub-array dtypes refused) and a shape of non-negative integers
    below 2**63; then ``prod(shape) * itemsize`` must equal the bytes after the header and
    be at most ``max_bytes`` -- all before the data is allocated, so a 1 KB file declaring
    terabytes is refused in microseconds.

    Parameters
    ----------
    path, what : the file and its role in messages.
    max_bytes : the file-size bound, checked before reading.
    dtype : required dtype (anything ``np.dtype`` accepts), or a tuple of allowed dtypes.
    shape : required shape; ``None`` entries match any length (e.g. ``(None, None)`` for
        any 2-D array).

    Returns
    -------
    The array (C or Fortran order, as stored).

    Raises
    ------
    InputError
        Missing or too large, not a ``.npy`` file, a pickled or object array ("pickled
        arrays are refused"), a malformed header, a truncated/corrupt file, or the wrong
        dtype or shape.
    """
    path = check_file(path, what, max_bytes=max_bytes, kind=".npy file")
    label = _label(what, path)
    try:
        with open(path, "rb") as stream:
            size = os.fstat(stream.fileno()).st_size
            header = read_npy_header(stream, label, size=size, max_bytes=max_bytes)
            array = read_npy_data(stream, header, label)
    except InputError:
        raise
    except (ValueError, OSError, EOFError, MemoryError) as error:
        got = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise InputError(label, "a readable .npy file", got) from None
    if dtype is not None:
        allowed = tuple(np.dtype(d) for d in (dtype if isinstance(dtype, tuple) else (dtype,)))
        if array.dtype not in allowed:
            names = " or ".join(str(d) for d in allowed)
            raise InputError(label, f"an array of dtype {names}", f"dtype {array.dtype}")
    if shape is not None:
        check_shape(label, array.shape, shape)
    return array


# --------------------------------------------------------------------------------------------
# keys
# --------------------------------------------------------------------------------------------


def check_keys(mapping: Any, allowed: Collection[str], where: str) -> Mapping[str, Any]:
    """Refuse keys of ``mapping`` that are not in ``allowed`` (a misspelt key would be
    silently ignored otherwise).

    Parameters
    ----------
    mapping : the parsed object to check.
    allowed : the accepted keys (required keys are checked by the caller).
    where : the object's name in messages (e.g. ``"camera"``).

    Returns
    -------
    ``mapping``, unchanged.

    Raises
    ------
    InputError
        ``mapping`` is not a mapping, or has unknown keys:
        ``camera: expected only the keys width, height, K, dist, got "unknown key
        'distortion' (did you mean 'dist'?)"``.
    """
    known = ", ".join(allowed)
    if not isinstance(mapping, Mapping):
        raise InputError(where, f"an object with the keys {known}", type(mapping).__name__)
    unknown = [key for key in mapping if key not in allowed]
    if not unknown:
        return mapping
    parts = []
    for key in unknown:
        guess = closest_key(key, allowed)
        parts.append(f"{key!r}" + (f" (did you mean {guess!r}?)" if guess else ""))
    noun = "unknown key" if len(unknown) == 1 else "unknown keys"
    raise InputError(where, f"only the keys {known}", f"{noun} {', '.join(parts)}")


def closest_key(key: object, allowed: Collection[str]) -> str | None:
    """The key of ``allowed`` that ``key`` most likely means: the same letters ignoring case,
    a prefix of at least 3 letters (``distortion`` -> ``dist``), or a close spelling
    (:func:`difflib.get_close_matches`); None when nothing is close."""
    if not isinstance(key, str):
        return None
    lower = {name.lower(): name for name in allowed}
    if key.lower() in lower:
        return lower[key.lower()]
    prefixes = [
        name for name in allowed
        if min(len(name), len(key)) >= 3
        and (key.lower().startswith(name.lower()) or name.lower().startswith(key.lower()))
    ]  # fmt: skip
    if prefixes:
        return max(prefixes, key=len)
    close = difflib.get_close_matches(key.lower(), list(lower), n=1, cutoff=0.6)
    return lower[close[0]] if close else None
