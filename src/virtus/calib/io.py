"""Calibration files: read every calibration virtus accepts, write virtus's own.

:func:`load_calibration` is the one entry point for reading; it returns a :class:`Rig`
(metres, ``proj2cam``: X_cam = R X_proj + t). :func:`load_calibration_report` reads the same
and also returns where each parameter came from (:class:`~virtus.calib.sources.
CalibrationSources`: file and key, or "none given" -- a distortion no file gave is zeros in
the rig, never silently). :func:`load_rig_file` is the reader for "a rig or calibration
file" given to a scan, a reconstruction or an import: the same reader, with image sizes a
file lacks taken from a known rig. Accepted inputs:

* **Rig JSON** (``.json``, DESIGN.md section 3): ``calibration.json`` of ``virtus
  calibrate`` (extra keys ignored), ``virtus rig info --json``, and ``capture.json`` (the rig
  under ``"rig"``; refused for a capture imported without a calibration, whose rig is a
  placeholder). Units from its ``"units"`` key (virtus writes ``"m"``).
* **OpenCV FileStorage** (``.yaml``, ``.yml``, ``.xml``) and **NumPy** ``.npz``: top-level
  nodes (keys) named as in :data:`CALIBRATION_NAMES` or as structured names
  (:mod:`virtus.calib.names`: ``[Cam|Proj] quantity [Left|Right|1|2]``), matched ignoring
  case and separators: virtus's own names (:func:`save_opencv_yaml`), OpenCV
  ``stereoCalibrate`` results with the camera first (``K1 D1 K2 D2 R T``,
  ``cameraMatrix1/2``, ``distCoeffs1/2``, ``M1 M2``, ``Kc Kp``, ``mtx1 dist1 ...``),
  Moreno-Taubin's scan3d-capture (``cam_K cam_kc proj_K proj_kc R T``), kamino410's
  procam-calibration (``cam_int cam_dist proj_int proj_dist rotation translation``, camera
  to projector, and ``img_shape`` = (height, width)), OpenCV's calibration sample
  (``camera_matrix distortion_coefficients image_width image_height``). A FileStorage node
  is an ``opencv-matrix``, a (nested) list of numbers or a number; an ``.npz`` member an
  array (:func:`virtus.io.safeio.load_npz`: nothing unpickled). Units from a ``units`` (or
  ``unit``) string node/key.
* **A mapping file** (``.yaml``/``.yml`` with ``file:`` and ``keys:``,
  :mod:`virtus.calib.formats`): names which key of an ``.npz``, FileStorage or flat JSON file
  is which quantity, the units and the convention of R, T.
* **Text folders** (the paper code's and labs' ``.txt`` files): a folder (or any ``.txt``
  file inside it, which stands for its folder) of files ``<name>.txt``, ``<name>`` as above:
  ``CamIntrinsicMatrix.txt``, ``ProjIntrinsicMatrix.txt``, ``ProjRotationMatrix.txt``,
  ``ProjTranslationVector.txt``, optionally ``CamDistortion[Coefficients].txt``,
  ``ProjDistortion[Coefficients].txt``; or the stereo spelling ``CamIntrinsicMatrixLeft.txt``
  (camera), ``CamIntrinsicMatrixRight.txt`` (projector), ``CamRotationMatrixRight.txt``,
  ``CamTranslationVectorRight.txt``, ``CamDistortionCoefficientsLeft/Right.txt``, or ``1``/``2``
  for ``Left``/``Right``; beside ``Proj...`` files a ``Cam...Right`` file is the camera's
  (a lab's one camera, :func:`virtus.calib.names.name_roles`; the record notes it).
  Numbers separated by tabs, spaces or commas; a matrix as 3 rows of 3; a vector as one row
  or one value per line (told apart by shape); lines starting with ``#`` or ``%`` are
  comments.

**Every file is used or named.** Two files (nodes, keys) for one quantity are refused,
naming both. A folder's file that matches no quantity is named in a
:class:`CalibrationFileWarning` ("ignored: CamDistortionCoefficientsRight.txt (...)"), each
``.txt`` file on its own line, other files together; so are unused FileStorage/``.npz``
keys that look like device parameters (all unused keys are in the record's ``ignored``).
Warnings are given only once the calibration has been read. A source without a distortion
for a device gives zeros, and the record says "none given".

Conventions of the extrinsics
-----------------------------
* ``R``, ``T`` (stereoCalibrate, the paper's ``ProjRotationMatrix``/``ProjTranslationVector``,
  a stereo folder's ``CamRotationMatrixRight``): X_proj = R X_cam + T.
* ``proj2cam_R``, ``proj2cam_t`` (virtus): X_cam = R X_proj + t. When a file holds both
  pairs (virtus YAML does) they must agree.
* ``CamRotationMatrix``/``CamTranslationVector`` (optional, some labs' folders; also
  ``...Left``): the camera's pose in the frame ``R``, ``T`` are given in, X_cam = R_c X_w +
  T_c; the rig is then X_proj = R R_c^T (X_cam - T_c) + T. Without them that frame is the
  camera's.

Units
-----
Translations are read in the unit the file states (``m``, ``cm`` or ``mm``) or, when it
states none, in ``units=`` (CLI ``--units``); a file stating none with no ``units=`` is
refused, and a stated unit contradicting ``units=`` is refused. **Decision**: the paper
code's text folder states nothing but is defined by that code to hold millimetres, so a
folder is read as mm unless ``units=`` says otherwise (the folder cannot contradict it).

Image sizes
-----------
From the file (``camera_size``/``imageSize`` etc., or ``image_width``+``image_height``
pairs, see :data:`SIZE_PAIR_NAMES`; always ``(width, height)``; ``img_shape``-like
:data:`~virtus.calib.names.SHAPE_NAMES` are ``(height, width)``), else from
``camera_size=``/``projector_size=``; neither is an error (no size is assumed). A size both
in the file and given must agree.

Bad files never escape as tracebacks: a path that does not exist, or a text folder lacking
a required file, raises ``FileNotFoundError`` naming it; anything else wrong raises
:class:`InputError` naming the file and key: an unknown file type, a file over
:data:`virtus.io.safeio.MAX_CONFIG_BYTES`, empty, binary or not UTF-8, syntax errors, missing or
ambiguous keys, wrong shapes, non-finite values, a K that is not ``[[fx, 0, cx], [0, fy,
cy], [0, 0, 1]]`` with fx, fy > 0, an R that is not a rotation.

Writing: :func:`save_json`, :func:`save_opencv_yaml` (metres, ``units: m``) and
:func:`save_paper_txt` (what the paper code's readers load: matrices as tab-separated
rows, vectors one value per line, T in mm).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from virtus.calib.formats import (
    MAPPING_ROLES,
    UNIT_SPELLINGS,
    Items,
    filestorage_items,
    given_size,
    looks_like_mapping,
    matrix33,
    npz_items,
    read_calibration_text,
    read_mapping,
    read_table,
    unit_name,
    vector,
)
from virtus.calib.names import (
    CALIBRATION_NAMES,
    SHAPE_NAMES,
    SIZE_PAIR_NAMES,
    UNITS_NAMES,
    name_role,
    name_roles,
    normalize,
)
from virtus.calib.sources import NONE_GIVEN, CalibrationSources, record_of
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose, check_rotation
from virtus.io.jsonio import write_json
from virtus.io.safeio import closest_key, parse_json

__all__ = [
    "CALIBRATION_NAMES",
    "METRES_PER_UNIT",
    "PAPER_TXT_FILES",
    "SIZE_PAIR_NAMES",
    "UNITS_NAMES",
    "UNIT_SPELLINGS",
    "CalibrationFileWarning",
    "load_calibration",
    "load_calibration_report",
    "load_opencv_yaml",
    "load_paper_txt",
    "load_rig_file",
    "save_json",
    "save_opencv_yaml",
    "save_paper_txt",
]

#: Metres per unit of the translations.
METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: The paper code's text folder holds translations in millimetres (its own definition).
PAPER_TXT_UNITS = "mm"
#: File names :func:`save_paper_txt` writes, by quantity (all in :data:`CALIBRATION_NAMES`).
PAPER_TXT_FILES = {
    "camera_matrix": "CamIntrinsicMatrix.txt",
    "camera_distortion": "CamDistortion.txt",
    "projector_matrix": "ProjIntrinsicMatrix.txt",
    "projector_distortion": "ProjDistortion.txt",
    "R": "ProjRotationMatrix.txt",
    "T": "ProjTranslationVector.txt",
}
#: Millimetres per metre (the paper's text files hold translations in mm).
MM_PER_M = 1000.0
#: ``proj2cam`` and ``R``/``T`` stored side by side (virtus YAML) hold the same pose written
#: with 17 digits: they agree to ~1e-16; 1e-9 (rotation entries, metres) flags a file edited
#: on one side only.
_EXTRINSICS_AGREEMENT = 1e-9
#: Suffixes read as FileStorage and JSON; what the error for an unknown type lists.
_FILESTORAGE_SUFFIXES = (".yaml", ".yml", ".xml")
_ACCEPTED = (
    "a rig .json (calibration.json, capture.json), an OpenCV FileStorage .yaml/.yml/.xml, "
    "a NumPy .npz, a mapping .yaml, or a folder (or a .txt file in it) of calibration text "
    "files"
)
#: Parts of an unused key's name that make it look like a device parameter (warned about).
_LOOKS_LIKE_A_PARAMETER = ("dist", "intrinsic", "kc", "cam", "proj", "rot", "trans", "mtx",
                           "matrix")  # fmt: skip
#: Prefixes of unused keys that are statistics of a solve (``rms_camera_px`` of virtus's own
#: YAML, ``reprojection_error``), never warned about.
_STATISTICS = ("rms", "error", "reprojection", "residual", "perview")
#: At most this many unused non-text files are named in a folder's warning.
_MAX_NAMED = 8


class CalibrationFileWarning(UserWarning):
    """A file of a calibration folder (or a key of a file) that was not used."""


def load_calibration(
    path: str | Path,
    *,
    units: str | None = None,
    camera_size: tuple[int, int] | None = None,
    projector_size: tuple[int, int] | None = None,
) -> Rig:
    """Read a camera-projector calibration from any file virtus accepts (see module doc).

    Parameters
    ----------
    path : a rig ``.json``, an OpenCV FileStorage ``.yaml``/``.yml``/``.xml``, a NumPy
        ``.npz``, a mapping ``.yaml``, or a folder of calibration text files (or a ``.txt``
        file inside that folder).
    units : ``"m"``, ``"cm"`` or ``"mm"``: the unit of the file's translations when it
        states none; must agree with a unit the file states. Text folders default to mm.
    camera_size, projector_size : ``(width, height)`` in pixels, for files that hold no image
        sizes (e.g. ``stereoCalibrate`` results, text folders); must agree with sizes a file
        holds.

    Returns
    -------
    The rig: intrinsics (pixels, OpenCV distortion order) and ``proj2cam`` in metres. Unused
    files and keys are named in :class:`CalibrationFileWarning` warnings; where each
    parameter came from is :func:`load_calibration_report`'s.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist, or a text folder lacks a required file.
    InputError
        Anything else wrong with the file or the arguments; the message names the file and
        key, what was expected and what came.
    """
    return load_calibration_report(
        path, units=units, camera_size=camera_size, projector_size=projector_size
    )[0]


def load_calibration_report(
    path: str | Path,
    *,
    units: str | None = None,
    camera_size: tuple[int, int] | None = None,
    projector_size: tuple[int, int] | None = None,
) -> tuple[Rig, CalibrationSources]:
    """:func:`load_calibration`, and where each parameter came from.

    Returns
    -------
    ``(rig, sources)``: the rig as :func:`load_calibration` returns it, and its
    :class:`~virtus.calib.sources.CalibrationSources` (per device the file/key of K, the
    distortion and the image size, or "none given (...)"; the extrinsics, the units, the
    files or keys not used). Warnings (:class:`CalibrationFileWarning`) are given once the
    calibration has been read, so a refused file gives its error only.
    """
    unit = None if units is None else unit_name("units", units)
    sizes = (given_size("camera_size", camera_size), given_size("projector_size", projector_size))
    source = Path(path)
    if not source.exists():
        raise FileNotFoundError(2, "no such calibration file or folder", str(source))
    if source.is_file() and source.suffix.lower() == ".txt":
        source = source.parent
    suffix = source.suffix.lower()
    notices: list[str] = []
    if source.is_dir():
        rig, sources = _load_txt_folder(source, unit, sizes, notices)
    elif suffix == ".json":
        rig, sources = _load_json(source, unit, *sizes)
    elif suffix == ".npz":
        found, unused = _collect(f"calibration {source}", npz_items(source))
        rig, sources = _from_found(source, "NumPy .npz", found, unused, unit, sizes, notices)
    elif suffix in _FILESTORAGE_SUFFIXES:
        mapping = looks_like_mapping(read_calibration_text(source)) if suffix != ".xml" else None
        if mapping is not None:
            rig, sources = _load_mapping(source, mapping, unit, sizes)
        else:
            with filestorage_items(source) as items:
                found, unused = _collect(f"calibration {source}", items)
            fmt = "OpenCV FileStorage"
            rig, sources = _from_found(source, fmt, found, unused, unit, sizes, notices)
    else:
        raise InputError(f"calibration {source}", _ACCEPTED, f"a {suffix or 'suffix-less'} file")
    for notice in notices:
        warnings.warn(notice, CalibrationFileWarning, stacklevel=3)
    return rig, sources


def load_rig_file(path: str | Path, like: Rig | None = None, *, units: str | None = None) -> Rig:
    """Read a rig from any calibration file :func:`load_calibration` reads; image sizes a
    file lacks (the paper code's text files) are taken from ``like`` (e.g. the capture's
    rig). ``units``: the length unit of a file that states none."""
    sizes = {}
    if like is not None:
        cam, proj = like.camera.intrinsics, like.projector.intrinsics
        sizes = {
            "camera_size": (cam.width, cam.height),
            "projector_size": (proj.width, proj.height),
        }
    return load_calibration(path, units=units, **sizes)


def load_opencv_yaml(
    path: str | Path,
    *,
    units: str | None = None,
    camera_size: tuple[int, int] | None = None,
    projector_size: tuple[int, int] | None = None,
) -> Rig:
    """Read an OpenCV FileStorage YAML/XML calibration; :func:`load_calibration` for one file."""
    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(2, "no such file", str(source))
    return load_calibration(
        source, units=units, camera_size=camera_size, projector_size=projector_size
    )


def load_paper_txt(
    directory: str | Path,
    camera_size: tuple[int, int] = (960, 960),
    projector_size: tuple[int, int] = (912, 1140),
    *,
    units: str | None = None,
) -> Rig:
    """Read the paper code's text folder (T in mm unless ``units``) as a rig.

    Unlike :func:`load_calibration`, the image sizes default to the paper's (camera
    960 x 960, projector 912 x 1140 px, as ``(width, height)``).
    """
    return load_calibration(
        Path(directory), units=units, camera_size=camera_size, projector_size=projector_size
    )


# -- writing --------------------------------------------------------------------------------


def save_json(data: dict[str, Any], path: str | Path) -> Path:
    """Write a calibration dict (rig schema + extras) as indented JSON; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_json(path, data)


def save_opencv_yaml(rig: Rig, path: str | Path, extras: dict[str, float] | None = None) -> Path:
    """Write ``rig`` as an OpenCV FileStorage YAML file (metres); ``extras``: scalar fields.

    Nodes: ``units: m``; ``camera_matrix``/``projector_matrix`` (3, 3), ``*_distortion``
    (1, 5 or 8), ``*_size`` (1, 2) ``[width, height]``; ``proj2cam_R``, ``proj2cam_t``
    (X_cam = R X_proj + t) and, for OpenCV tools, ``R``, ``T`` (X_proj = R X_cam + T).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    if not storage.isOpened():
        raise OSError(f"cannot write {path}")
    try:
        storage.write("units", "m")
        for prefix, intr in (
            ("camera", rig.camera.intrinsics),
            ("projector", rig.projector.intrinsics),
        ):
            storage.write(f"{prefix}_matrix", intr.K)
            storage.write(f"{prefix}_distortion", intr.dist_array.reshape(1, -1))
            storage.write(f"{prefix}_size", np.array([[intr.width, intr.height]], np.int32))
        storage.write("proj2cam_R", rig.proj2cam.R)
        storage.write("proj2cam_t", rig.proj2cam.t.reshape(3, 1))
        cam2proj = rig.cam2proj
        storage.write("R", cam2proj.R)
        storage.write("T", cam2proj.t.reshape(3, 1))
        for key, value in (extras or {}).items():
            storage.write(key, float(value))
    finally:
        storage.release()
    return path


def save_paper_txt(rig: Rig, directory: str | Path) -> Path:
    """Write the paper code's text files into ``directory`` (:data:`PAPER_TXT_FILES`).

    Matrices (K, R) as 3 tab-separated rows; vectors (distortion, T) one value per line, as
    the paper code reads them (``np.loadtxt(..., usecols=(0,))``); ``R``, ``T`` = cam2proj
    (X_proj = R X_cam + T), **T in millimetres**. Image sizes are not part of these files.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    cam2proj = rig.cam2proj
    tables = {
        "camera_matrix": rig.camera.intrinsics.K,
        "camera_distortion": rig.camera.intrinsics.dist_array[:, None],
        "projector_matrix": rig.projector.intrinsics.K,
        "projector_distortion": rig.projector.intrinsics.dist_array[:, None],
        "R": cam2proj.R,
        "T": cam2proj.t[:, None] * MM_PER_M,
    }
    for quantity, table in tables.items():
        text = "\n".join("\t".join(repr(float(v)) for v in row) for row in table) + "\n"
        (directory / PAPER_TXT_FILES[quantity]).write_text(text)
    return directory


# -- the readers ----------------------------------------------------------------------------

_Found = dict[str, tuple[str, Any]]  # quantity -> (name in the file, raw value)
_Sizes = tuple[tuple[int, int] | None, tuple[int, int] | None]  # camera, projector (w, h)


def _load_json(
    path: Path, units: str | None, camera_size: tuple | None, projector_size: tuple | None
) -> tuple[Rig, CalibrationSources]:
    source = f"calibration {path}"
    data = parse_json(read_calibration_text(path), source, expect=dict)
    rig = data
    if "camera" not in data and isinstance(data.get("rig"), Mapping):  # capture.json
        rig = data["rig"]
        imported = data.get("calibration_source")
        if isinstance(imported, Mapping) and imported.get("calibrated") is False:
            raise InputError(
                source,
                "a calibration (this capture was imported without one: its rig is a "
                "placeholder; give the bench's calibration file)",
                "an uncalibrated capture.json",
            )
    stated = rig.get("units", data.get("units"))
    scale = _metres_per_unit(source, None if stated is None else ("units", stated), units)
    rig = dict(rig, units="m")
    parts: dict[str, dict[str, str]] = {}
    for device, given in (("camera", camera_size), ("projector", projector_size)):
        entry = rig.get(device)
        if isinstance(entry, Mapping):
            size = None
            if "width" in entry or "height" in entry:
                size = (f"{device}.width/height", [entry.get("width"), entry.get("height")])
            width, height = _image_size(source, device, size, given)
            rig[device] = dict(entry, width=width, height=height)
            dist = f"{NONE_GIVEN} (no {device}.dist in {path})"
            if "dist" in entry:
                empty = isinstance(entry["dist"], list) and not entry["dist"]
                dist = f"{path.name}: {device}.dist" + (" (empty: stated none)" if empty else "")
            parts[device] = {
                "K": f"{path.name}: {device}.K",
                "dist": dist,
                "size": f"{path.name}: {size[0]}" if size else f"given: {device}_size",
            }
    pose = rig.get("proj2cam")
    if isinstance(pose, Mapping) and "t" in pose:
        t = vector(f"{source}: proj2cam.t", pose["t"], 3)
        rig["proj2cam"] = dict(pose, t=t * scale)
    try:
        loaded = Rig.from_dict(rig)
    except InputError as error:
        raise InputError(f"{source}: {error.name}", error.expected, error.got) from None
    unit = unit_name("units", stated) if stated is not None else units
    sources = CalibrationSources(
        path=str(path),
        format="rig JSON",
        camera=parts["camera"],
        projector=parts["projector"],
        extrinsics=f"{path.name}: proj2cam (X_cam = R X_proj + t)",
        units=f"{unit} ({'stated: units' if stated is not None else 'given: units'})",
        files=(str(path),),
    )
    return loaded, sources


def _from_found(
    path: Path,
    fmt: str,
    found: _Found,
    unused: list[tuple[str, str]],
    units: str | None,
    sizes: _Sizes,
    notices: list[str],
) -> tuple[Rig, CalibrationSources]:
    """The rig and record of a keyed file (FileStorage, ``.npz``): units, assembly, and a
    warning naming unused keys that look like device parameters."""
    source = f"calibration {path}"
    stated = found.pop("units", None)
    if stated is not None and not isinstance(stated[1], str):
        raise InputError(f"{source}: {stated[0]}", "one units string (m, cm or mm)", stated[0])
    scale = _metres_per_unit(source, stated, units)
    rig, used = _assemble(source, found, scale, *sizes)
    suspicious = [
        name
        for name, why in unused
        if not normalize(name).startswith(_STATISTICS)
        and (
            not why.startswith("not a name")
            or any(part in normalize(name) for part in _LOOKS_LIKE_A_PARAMETER)
        )
    ]
    if suspicious:
        notices.append(f"{source}: not used: {', '.join(suspicious)} (no calibration quantity)")
    unit = unit_name("units", stated[1]) if stated else units
    return rig, record_of(
        path,
        fmt,
        used,
        label=lambda key: f"{path.name}: {key}",
        none=f"no distortion node in {path}",
        units=f"{unit} ({'stated: ' + stated[0] if stated else 'given: units'})",
        ignored=[name for name, _ in unused],
    )


def _load_txt_folder(
    folder: Path, units: str | None, sizes: _Sizes, notices: list[str]
) -> tuple[Rig, CalibrationSources]:
    source = f"calibration {folder}"
    entries = sorted(p for p in folder.iterdir() if p.is_file())
    files = [p for p in entries if p.suffix.lower() == ".txt"]
    others = [p.name for p in entries if p.suffix.lower() != ".txt"]
    items = {
        file.name: (file.stem, lambda file=file: read_table(f"{source}/{file.name}", file))
        for file in files
    }
    found, unused = _collect(source, items, units_node=False)
    for quantity in ("camera_matrix", "projector_matrix", "R", "T"):
        if quantity not in found:
            raise FileNotFoundError(
                2,
                f"no {PAPER_TXT_FILES[quantity]} (or <name>.txt for another name of the "
                f"{quantity}: {', '.join(CALIBRATION_NAMES[quantity])}, or Cam/Proj names "
                "with Left/Right or 1/2) in the calibration folder",
                str(folder),
            )
    scale = METRES_PER_UNIT[units or PAPER_TXT_UNITS]
    rig, used = _assemble(source, found, scale, *sizes)
    notices += [f"{source}: ignored: {name} ({why})" for name, why in unused]
    if others:
        more = f" and {len(others) - _MAX_NAMED} more" if len(others) > _MAX_NAMED else ""
        named = ", ".join(others[:_MAX_NAMED])
        notices.append(f"{source}: ignored (not .txt): {named}{more}")
    why = "given: units" if units else "the paper code's text folders hold mm"
    return rig, record_of(
        folder,
        "text folder",
        used,
        label=str,
        none=f"no distortion file in {folder}",
        units=f"{units or PAPER_TXT_UNITS} ({why})",
        ignored=[name for name, _ in unused] + others,
        files=tuple(folder / name for name in items if name not in dict(unused)),
    )


def _load_mapping(
    path: Path, data: dict[str, Any], units: str | None, sizes: _Sizes
) -> tuple[Rig, CalibrationSources]:
    """A mapping file (:mod:`virtus.calib.formats`): its keys of its file, by role."""
    spec = read_mapping(path, data)
    target, where = spec.file, f"mapping file {path}"
    quantities = dict(MAPPING_ROLES, R=spec.pose[0], T=spec.pose[1])

    def resolve(items: Items) -> tuple[_Found, list[str]]:
        found: _Found = {}
        for role, key in spec.keys.items():
            if key is None:
                continue
            if key not in items:
                near = closest_key(key, list(items))
                hint = f" (did you mean {near!r}?)" if near else ""
                raise InputError(f"{where}: keys.{role}", f"a key of {target}{hint}", key)
            found[quantities[role]] = (key, items[key][1]())
        named = [k for k in items if name_role(items[k][0])[0] == "units"]
        if len(named) == 1 and spec.units is None:
            found["units"] = (named[0], items[named[0]][1]())
        return found, [k for k in items if k not in spec.keys.values() and k not in named]

    suffix = target.suffix.lower()
    if suffix == ".npz":
        found, unused = resolve(npz_items(target))
    elif suffix in _FILESTORAGE_SUFFIXES:
        with filestorage_items(target) as items:
            found, unused = resolve(items)
    elif suffix == ".json":
        flat = parse_json(read_calibration_text(target), f"calibration {target}", expect=dict)
        found, unused = resolve({k: (k, lambda v=v: v) for k, v in flat.items()})
    else:
        raise InputError(f"{where}: file", "an .npz, .yaml/.yml/.xml or .json file", target.name)
    literal = {name: f"{path.name}: {name}" for name in spec.sizes}
    for name, size in spec.sizes.items():
        found[name] = (literal[name], list(size))
    literal = set(literal.values())
    stated = ("units", spec.units) if spec.units else found.pop("units", None)
    source = f"calibration {target}"
    if stated is not None and not isinstance(stated[1], str):
        raise InputError(f"{source}: {stated[0]}", "one units string (m, cm or mm)", stated[0])
    scale = _metres_per_unit(f"{where} ({target.name})", stated, units)
    rig, used = _assemble(source, found, scale, *sizes)
    unit = unit_name("units", stated[1]) if stated else units
    said = "given: units" if stated is None else f"stated: {stated[0]}"
    nulls = [role for role, key in spec.keys.items() if key is None]
    return rig, record_of(
        path,
        f"mapping file -> {target.name}",
        used,
        label=lambda key: key if key in literal else f"{target.name}: {key}",
        none=f"keys.{'/'.join(nulls)}: null in {path.name}",
        units=f"{unit} ({'stated by the mapping' if spec.units else said})",
        ignored=unused,
        files=(path, target),
    )


# -- from named values to a rig -------------------------------------------------------------


def _aliases(role: str) -> tuple[str, ...]:
    """The table's names of a role of :func:`virtus.calib.names.name_role` (for messages)."""
    if role.startswith("pair:"):
        _, quantity, index, side = role.split(":")
        return tuple(pair[int(side)] for pair in SIZE_PAIR_NAMES[quantity][int(index) :][:1])
    if role.endswith("_shape"):
        return SHAPE_NAMES[role.replace("_shape", "_size")]
    return CALIBRATION_NAMES.get(role, UNITS_NAMES if role == "units" else (role,))


def _collect(
    source: str, items: Mapping[str, tuple[str, Callable[[], Any]]], *, units_node: bool = True
) -> tuple[_Found, list[tuple[str, str]]]:
    """Match ``items`` (name in the file -> (key to match, loader)) to the quantities
    (:func:`virtus.calib.names.name_role`); returns the found values and the unused names
    with the reason. Only matched items are loaded. Two names of one quantity is an error
    (which to trust?). ``units_node``: a ``units`` key is the units (else it is unused)."""
    by_role: dict[str, list[str]] = {}
    unused: list[tuple[str, str]] = []
    roles = name_roles(key for key, _ in items.values())
    for name, (key, _) in items.items():
        role, why = roles[key]
        if role == "units" and not units_node:
            role, why = None, "units are not read from a text folder (mm, or --units)"
        if role is None:
            unused.append((name, why))
        else:
            by_role.setdefault(role, []).append(name)
    for role, names in by_role.items():
        if len(names) > 1:
            raise InputError(source, f"one of {', '.join(_aliases(role))} ({role})", names)
    found: _Found = {
        role: (names[0], items[names[0]][1]())
        for role, names in by_role.items()
        if not role.startswith("pair:")
    }
    for device in ("camera", "projector"):
        shape = found.pop(f"{device}_shape", None)
        if shape is not None:
            if f"{device}_size" in found:
                names = [found[f"{device}_size"][0], shape[0]]
                raise InputError(source, f"one {device}_size", names)
            height, width = vector(f"{source}: {shape[0]}", shape[1], 2).tolist()
            found[f"{device}_size"] = (f"{shape[0]} (height, width)", [width, height])
    for quantity, pairs in SIZE_PAIR_NAMES.items():
        for index, pair in enumerate(pairs):
            width, height = (by_role.get(f"pair:{quantity}:{index}:{side}") for side in (0, 1))
            if width is None and height is None:
                continue
            if width is None or height is None:
                raise InputError(
                    source, f"both {pair[0]} and {pair[1]}", f"{(width or height)[0]} only"
                )
            if quantity in found:
                names = [found[quantity][0], width[0], height[0]]
                raise InputError(source, f"one {quantity}", names)
            found[quantity] = (
                f"{width[0]}/{height[0]}",
                [items[width[0]][1](), items[height[0]][1]()],
            )
    return found, unused


def _assemble(
    source: str,
    found: _Found,
    metres_per_unit: float,
    camera_size: tuple[int, int] | None,
    projector_size: tuple[int, int] | None,
) -> tuple[Rig, dict[str, Any]]:
    """Validate the values of ``found`` (named by their key in ``source``) and build the rig;
    also returns the keys used: ``{"camera": {"K", "dist", "size"}, "projector": ...,
    "extrinsics": [keys], "convention": str}`` ("" for a distortion or size not in the file).
    """

    def require(quantity: str) -> tuple[str, Any]:
        if quantity not in found:
            names = ", ".join(CALIBRATION_NAMES[quantity])
            raise InputError(source, f"a {quantity} node (one of {names})", "none")
        return found[quantity]

    devices = []
    used: dict[str, Any] = {}
    for device, given in (("camera", camera_size), ("projector", projector_size)):
        k_key, k_value = require(f"{device}_matrix")
        K = matrix33(f"{source}: {k_key}", k_value)  # noqa: N806
        d_key, d_value = found.get(f"{device}_distortion", ("", None))
        dist = np.zeros(0) if d_value is None else vector(f"{source}: {d_key}", d_value)
        stated = found.get(f"{device}_size")
        width, height = _image_size(source, device, stated, given)
        try:
            devices.append(Intrinsics.from_opencv(K, dist, width, height))
        except InputError as error:
            key = d_key if error.name == "dist" else k_key
            raise InputError(f"{source}: {key} ({error.name})", error.expected, error.got) from None
        used[device] = {"K": k_key, "dist": d_key, "size": stated[0] if stated else ""}

    poses, keys = {}, []
    for pose, r_name, t_name in (
        ("proj2cam", "proj2cam_R", "proj2cam_t"),
        ("cam2proj", "R", "T"),
        ("world2cam", "cam_R", "cam_T"),
    ):
        if r_name in found or t_name in found:
            (r_key, r_value), (t_key, t_value) = require(r_name), require(t_name)
            r_label = f"{source}: {r_key}"
            rotation = check_rotation(r_label, matrix33(r_label, r_value))
            translation = vector(f"{source}: {t_key}", t_value, 3) * metres_per_unit
            poses[pose] = Pose(rotation, translation)
            keys += [r_key, t_key]
    conventions = {
        "proj2cam": "X_cam = R X_proj + t",
        "cam2proj": "X_proj = R X_cam + T",
        "world2cam": "with the camera's pose X_cam = R_c X_w + T_c",
    }
    convention = "; ".join(conventions[pose] for pose in poses)
    if "world2cam" in poses:
        if "cam2proj" not in poses:
            raise InputError(source, "R and T with the camera's pose", "the camera's pose only")
        poses["cam2proj"] = poses["cam2proj"] @ poses.pop("world2cam").inverse()
    if "proj2cam" in poses and "cam2proj" in poses:
        other = poses["cam2proj"].inverse()
        gap = np.max(np.abs(poses["proj2cam"].matrix - other.matrix))
        if gap > _EXTRINSICS_AGREEMENT:
            raise InputError(source, "proj2cam_R/t and R/T describing one pose", f"{gap:.3g} apart")
    if "proj2cam" in poses:
        proj2cam = poses["proj2cam"]
    elif "cam2proj" in poses:
        proj2cam = poses["cam2proj"].inverse()
    else:
        raise InputError(
            source,
            "the extrinsics: R and T (X_proj = R X_cam + T) or proj2cam_R and proj2cam_t",
            "none",
        )
    used |= {"extrinsics": keys, "convention": convention}
    return Rig(Camera(devices[0]), Projector(devices[1]), proj2cam), used


def _image_size(
    source: str, device: str, stated: tuple[str, Any] | None, given: tuple[int, int] | None
) -> tuple[int, int]:
    """(width, height) from the file (``stated``: (key, value)), else ``given``; never assumed."""
    if stated is None:
        if given is None:
            raise InputError(
                source,
                f"the {device} image size (width, height) in the file or as {device}_size",
                "neither",
            )
        return given
    key, value = stated
    size = given_size(f"{source}: {key}", vector(f"{source}: {key}", value, 2).tolist())
    if given is not None and size != given:
        raise InputError(f"{source}: {key}", f"the {device}_size given, {given}", size)
    return size


def _metres_per_unit(source: str, stated: tuple[str, object] | None, given: str | None) -> float:
    """Metres per unit of the file's translations: ``stated`` (key, value) by the file, else
    ``given`` (a unit name); a file stating none with none given is refused."""
    unit = given
    if stated is not None:
        key, value = stated
        unit = unit_name(f"{source}: {key}", value)
        if given is not None and unit != given:
            raise InputError(f"{source}: {key}", f"the units given ({given}) or none", unit)
    if unit is None:
        raise InputError(
            source,
            "units stated in the file or given (pass --units mm or --units m)",
            "a file that states no units",
        )
    return METRES_PER_UNIT[unit]
