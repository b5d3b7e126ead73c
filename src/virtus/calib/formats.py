"""Reading the values of calibration files, per format: text tables, FileStorage nodes,
``.npz`` arrays, and the mapping file that says which key of a file means what.

:mod:`virtus.calib.io` dispatches on the format and turns the values into a rig; this module
only reads and checks values (shapes, numbers, units, sizes), so every format's values are
checked by the same functions and name the file and key on error.

Mapping file
------------
A small YAML file (``.yaml``/``.yml``) for a file whose keys no table knows
(:func:`read_mapping`)::

    file: calib.npz          # .npz, OpenCV FileStorage .yaml/.yml/.xml, or a flat .json
    keys:                    # role: the key in that file
      camera_K: cam_mtx
      camera_dist: cam_dist  # null: the file has no camera distortion (recorded as such)
      projector_K: proj_mtx
      projector_dist: proj_dist
      R: R
      T: T
      camera_size: img_size  # optional: a key holding (width, height)
    units: mm                # the unit of T (or the file's units node, or units=)
    convention: X_proj = R X_cam + T    # or X_cam = R X_proj + T
    camera_size: [1280, 1024]           # optional, (width, height)
    projector_size: [912, 1140]

``file`` is relative to the mapping file's folder. Both distortions must be named (a key, or
null for none): the mapping exists to say what is what, so it never leaves a distortion out
by omission. ``convention`` is required (which way R, T map is the error a file cannot show).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from virtus.checks import as_float_array, positive_int
from virtus.errors import InputError
from virtus.io.safeio import MAX_CONFIG_BYTES, check_keys, load_npz, parse_yaml, read_text

__all__ = [
    "CONVENTIONS",
    "MAPPING_ROLES",
    "NPZ_MAX_BYTES",
    "UNIT_SPELLINGS",
    "Items",
    "MappingFile",
    "filestorage_items",
    "first_line",
    "given_size",
    "looks_like_mapping",
    "matrix33",
    "node_value",
    "npz_items",
    "read_calibration_text",
    "read_mapping",
    "read_table",
    "unit_name",
    "vector",
]

#: Metres per unit, and the spellings accepted for each unit (case-insensitive).
UNIT_SPELLINGS = {
    "m": ("m", "meter", "meters", "metre", "metres"),
    "cm": ("cm", "centimeter", "centimeters", "centimetre", "centimetres"),
    "mm": ("mm", "millimeter", "millimeters", "millimetre", "millimetres"),
}
#: Largest ``.npz`` calibration read (its arrays are read whole): stereo files may carry
#: rectification maps (4 x 1280 x 1024 float32 = 20 MiB) beside the parameters.
NPZ_MAX_BYTES = 256 * 2**20
#: Roles of a mapping file's ``keys`` -> the quantity each names (:mod:`virtus.calib.names`).
MAPPING_ROLES = {
    "camera_K": "camera_matrix",
    "camera_dist": "camera_distortion",
    "projector_K": "projector_matrix",
    "projector_dist": "projector_distortion",
    "R": "R",
    "T": "T",
    "camera_size": "camera_size",
    "projector_size": "projector_size",
}
#: Roles a mapping file must name (the distortions may be null: none).
REQUIRED_ROLES = ("camera_K", "camera_dist", "projector_K", "projector_dist", "R", "T")
#: A mapping file's ``convention`` (spaces ignored) -> the quantities its R and T are.
CONVENTIONS = {
    "X_proj = R X_cam + T": ("R", "T"),
    "X_cam = R X_proj + T": ("proj2cam_R", "proj2cam_t"),
}
_MAPPING_KEYS = ("file", "keys", "units", "convention", "camera_size", "projector_size")
_SEPARATORS = re.compile(r"[\s,;]+")

#: name in the file -> (key to match, loader of its value).
Items = dict[str, tuple[str, Callable[[], Any]]]


# -- values ---------------------------------------------------------------------------------


def matrix33(name: str, value: object) -> np.ndarray:
    """A (3, 3) float64 matrix, or :class:`InputError` naming ``name``."""
    array = as_float_array(name, value)
    if array.shape != (3, 3):
        raise InputError(name, "a 3 x 3 matrix (9 numbers in 3 rows of 3)", f"shape {array.shape}")
    return array


def vector(name: str, value: object, length: int | None = None) -> np.ndarray:
    """A vector written as one row, one column or a flat list; ``(length,)`` float64."""
    array = as_float_array(name, value)
    if array.ndim not in (1, 2) or (array.ndim == 2 and min(array.shape) != 1):
        want = "a vector" if length is None else f"a vector of {length} numbers"
        raise InputError(name, f"{want} (one row or one column)", f"shape {array.shape}")
    array = array.ravel()
    if length is not None and array.size != length:
        raise InputError(name, f"{length} numbers", f"{array.size} numbers")
    return array


def given_size(name: str, value: object) -> tuple[int, int] | None:
    """``(width, height)`` of positive integers, or None for None."""
    if value is None:
        return None
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise InputError(name, "(width, height) in pixels", value)
    return positive_int(f"{name} width", value[0]), positive_int(f"{name} height", value[1])


def unit_name(name: str, value: object) -> str:
    """``"m"``, ``"cm"`` or ``"mm"`` for a spelling of :data:`UNIT_SPELLINGS`."""
    text = value.strip().lower() if isinstance(value, str) else None
    for unit, spellings in UNIT_SPELLINGS.items():
        if text in spellings:
            return unit
    raise InputError(name, "units 'm', 'cm' or 'mm'", value)


# -- text -----------------------------------------------------------------------------------


def read_calibration_text(path: Path) -> str:
    """The file's text (:func:`virtus.io.safeio.read_text`: bounded, UTF-8, no NUL), non-empty."""
    text = read_text(path, "calibration", max_bytes=MAX_CONFIG_BYTES)
    if not text.strip():
        raise InputError(f"calibration {path}", "a calibration file", "an empty file")
    return text


def read_table(name: str, path: Path) -> np.ndarray:
    """A text file of numbers as a 2-D float64 table (rows = lines); may hold NaN.

    Numbers separated by tabs, spaces, commas or semicolons; lines starting with ``#`` or
    ``%`` are comments."""
    rows = []
    for number, line in enumerate(read_calibration_text(path).splitlines(), 1):
        line = line.strip()
        if not line or line[0] in "#%":
            continue
        try:
            rows.append([float(x) for x in _SEPARATORS.split(line) if x])
        except ValueError:
            raise InputError(
                name, "numbers separated by tabs, spaces or commas", f"line {number}: {line}"
            ) from None
    if len({len(row) for row in rows}) > 1:
        raise InputError(name, "rows of equal length", [len(row) for row in rows])
    return np.array(rows, dtype=np.float64)


# -- FileStorage ----------------------------------------------------------------------------


def node_value(name: str, node: Any, depth: int = 0) -> Any:
    """A FileStorage node as an array, nested lists of numbers, a number or a string."""
    if node.isMap():
        # An opencv-matrix (rows, cols, data) or opencv-nd-matrix (sizes, data), read here
        # rather than by node.mat(), which crashes the process on inconsistent sizes
        # (OpenCV 5.0, e.g. "cols: -1").
        keys = set(node.keys())
        if "data" not in keys or not ({"rows", "cols"} <= keys or "sizes" in keys) or depth:
            raise InputError(name, "an opencv-matrix, a list of numbers or a number", "a map")
        if "sizes" in keys:
            sizes = node_value(name, node.getNode("sizes"), depth + 1)
        else:
            sizes = [node_value(name, node.getNode(key), depth + 1) for key in ("rows", "cols")]
        data = as_float_array(name, node_value(name, node.getNode("data"), depth + 1))
        shape = as_float_array(name, sizes).ravel()
        if data.ndim != 1 or np.any(shape < 1) or np.any(shape % 1) or shape.prod() != data.size:
            got = f"sizes {shape.tolist()} and {data.size} numbers"
            raise InputError(name, "an opencv-matrix whose data fills its rows x cols", got)
        return data.reshape(shape.astype(int))
    if node.isSeq():
        if depth >= 2:
            raise InputError(name, "a matrix (lists nested at most twice)", "deeper nesting")
        return [node_value(name, node.at(i), depth + 1) for i in range(node.size())]
    if node.isInt() or node.isReal():
        return node.real()
    if node.isString():
        return node.string()
    return None


@contextmanager
def filestorage_items(path: Path) -> Iterator[Items]:
    """The top-level nodes of a FileStorage file as items, readable inside the ``with``."""
    source = f"calibration {path}"
    text = read_calibration_text(path)
    what = "an OpenCV FileStorage YAML or XML file"
    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as error:
        got = f"a file OpenCV cannot parse ({first_line(error)})"
        raise InputError(source, what, got) from None
    try:
        root = storage.root() if storage.isOpened() else None
        if root is None or not root.isMap():
            raise InputError(source, what + " with named top-level nodes", "none")
        nodes = {key: storage.getNode(key) for key in root.keys()}
        yield {
            key: (key, lambda node=node, key=key: node_value(f"{source}: {key}", node))
            for key, node in nodes.items()
        }
    except cv2.error as error:
        raise InputError(source, what, f"unreadable nodes ({first_line(error)})") from None
    finally:
        storage.release()


def first_line(error: BaseException) -> str:
    """The gist of an OpenCV error (the ``cv2.error`` behind a ``SystemError`` if any)."""
    error = error.__cause__ or error
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    # "OpenCV(5.0.0) /path/persistence.cpp:767: error: (-215:Assertion failed) ..." -> "(-215..."
    return lines[-1].split(" error: ", 1)[-1] if lines else type(error).__name__


# -- .npz -----------------------------------------------------------------------------------


def npz_items(path: Path) -> Items:
    """The arrays of an ``.npz`` calibration (:func:`virtus.io.safeio.load_npz`: headers
    bounded, nothing unpickled, at most :data:`NPZ_MAX_BYTES`) as items: a string array is
    its text (e.g. ``units``), any other array its values."""
    arrays = load_npz(path, "calibration", max_bytes=NPZ_MAX_BYTES)

    def value(array: np.ndarray) -> Any:
        if array.dtype.kind in "US":
            text = array.item() if array.size == 1 else array.tolist()
            return text.decode() if isinstance(text, bytes) else text
        return array

    return {key: (key, lambda a=array: value(a)) for key, array in arrays.items()}


# -- mapping files --------------------------------------------------------------------------


@dataclass(frozen=True)
class MappingFile:
    """A mapping file (module docstring), checked.

    Attributes
    ----------
    path : the mapping file.
    file : the data file it describes (resolved against the mapping file's folder).
    keys : role (:data:`MAPPING_ROLES`) -> the key in ``file``, or None (a distortion: none).
    units : the unit the mapping states for T, or None.
    pose : the quantities of ``keys["R"]`` and ``keys["T"]`` (:data:`CONVENTIONS`).
    convention : the convention as written.
    sizes : ``{"camera_size": (w, h), ...}`` stated in the mapping.
    """

    path: Path
    file: Path
    keys: dict[str, str | None]
    units: str | None
    pose: tuple[str, str]
    convention: str
    sizes: dict[str, tuple[int, int]]


def looks_like_mapping(text: str) -> dict[str, Any] | None:
    """The parsed mapping of a YAML text that is a mapping file (a mapping with ``file`` and
    ``keys``), else None (OpenCV FileStorage YAML starts with ``%YAML:``, which is not YAML
    1.1 and is never a mapping file)."""
    if text.lstrip().startswith("%YAML:"):
        return None
    try:
        data = parse_yaml(text, "calibration")
    except InputError:
        return None
    return data if isinstance(data, dict) and "file" in data and "keys" in data else None


def read_mapping(path: Path, data: dict[str, Any]) -> MappingFile:
    """Check the parsed mapping file ``data`` read from ``path`` (module docstring)."""
    where = f"mapping file {path}"
    check_keys(data, _MAPPING_KEYS, where)
    target = data["file"]
    if not isinstance(target, str) or not target.strip():
        raise InputError(f"{where}: file", "the name of the calibration file it describes", target)
    file = path.parent / target
    try:
        exists = file.is_file()
    except OSError as error:  # e.g. a name too long
        raise InputError(f"{where}: file", "a readable file name", target) from error
    if not exists:
        raise FileNotFoundError(2, f"no such file (named by {where})", str(file))
    keys = data["keys"]
    check_keys(keys, tuple(MAPPING_ROLES), f"{where}: keys")
    missing = [role for role in REQUIRED_ROLES if role not in keys]
    if missing:
        raise InputError(
            f"{where}: keys",
            f"the roles {', '.join(REQUIRED_ROLES)} (a distortion may be null: none)",
            f"no {', '.join(missing)}",
        )
    for role, key in keys.items():
        nullable = role.endswith("_dist")
        if not (isinstance(key, str) and key) and not (nullable and key is None):
            want = "a key of the file" + (" or null (none)" if nullable else "")
            raise InputError(f"{where}: keys.{role}", want, key)
    units = data.get("units")
    units = None if units is None else unit_name(f"{where}: units", units)
    written = data.get("convention")
    spelled = {c.replace(" ", ""): c for c in CONVENTIONS}
    convention = spelled.get(written.replace(" ", "")) if isinstance(written, str) else None
    if convention is None:
        raise InputError(f"{where}: convention", " or ".join(repr(c) for c in CONVENTIONS), written)
    sizes = {}
    for name in ("camera_size", "projector_size"):
        if data.get(name) is not None:
            if name in keys:
                raise InputError(where, f"{name} given once (as a key or a value)", "both")
            sizes[name] = given_size(f"{where}: {name}", data[name])
    return MappingFile(path, file, dict(keys), units, CONVENTIONS[convention], convention, sizes)
