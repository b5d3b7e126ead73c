"""Calibration files: read every calibration virtus accepts, write virtus's own.

:func:`load_calibration` is the one entry point for reading; it returns a :class:`Rig`
(metres, ``proj2cam``: X_cam = R X_proj + t). :func:`load_rig_file` is the reader for "a rig
or calibration file" given to a scan, a reconstruction or an import: the same reader, with
image sizes a file lacks taken from a known rig. Accepted inputs:

* **Rig JSON** (``.json``, DESIGN.md section 3): ``calibration.json`` of ``virtus
  calibrate`` (extra keys ignored), ``virtus rig info --json``, and ``capture.json`` (the rig
  under ``"rig"``). Units from its ``"units"`` key (virtus writes ``"m"``).
* **OpenCV FileStorage** (``.yaml``, ``.yml``, ``.xml``): top-level nodes named as in
  :data:`CALIBRATION_NAMES`, matched ignoring case, ``_`` and ``-``: virtus's own names
  (:func:`save_opencv_yaml`), OpenCV ``stereoCalibrate`` results with the camera first
  (``K1 D1 K2 D2 R T``, ``cameraMatrix1/2``, ``distCoeffs1/2``, ``M1 M2``, ``Kc Kp``),
  Moreno-Taubin's scan3d-capture (``cam_K cam_kc proj_K proj_kc R T``) and OpenCV's
  calibration sample (``camera_matrix distortion_coefficients image_width image_height``).
  A node is an ``opencv-matrix``, a (nested) list of numbers or a number. Units from a
  ``units`` (or ``unit``) string node.
* **The paper code's text files**: a folder (or any ``.txt`` file inside it, which stands
  for its folder) holding files named ``<name>.txt`` for a name of the same table, e.g.
  ``CamIntrinsicMatrix.txt``, ``ProjIntrinsicMatrix.txt``, ``ProjRotationMatrix.txt``,
  ``ProjTranslationVector.txt`` and optionally ``CamDistortion[Coefficients].txt``,
  ``ProjDistortion[Coefficients].txt``. Numbers separated by tabs, spaces or commas; a
  matrix as 3 rows of 3; a vector as one row or one value per line (told apart by shape);
  lines starting with ``#`` or ``%`` are comments. A missing distortion file means no
  distortion.

Conventions of the extrinsics
-----------------------------
* ``R``, ``T`` (stereoCalibrate, the paper's ``ProjRotationMatrix``/``ProjTranslationVector``):
  X_proj = R X_cam + T.
* ``proj2cam_R``, ``proj2cam_t`` (virtus): X_cam = R X_proj + t. When a file holds both
  pairs (virtus YAML does) they must agree.
* ``CamRotationMatrix``/``CamTranslationVector`` (optional, some labs' folders): the
  camera's pose in the frame ``R``, ``T`` are given in, X_cam = R_c X_w + T_c; the rig is
  then X_proj = R R_c^T (X_cam - T_c) + T. Without them that frame is the camera's.

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
pairs, see :data:`SIZE_PAIR_NAMES`; always ``(width, height)``), else from
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

import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from virtus.checks import as_float_array, positive_int
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose, check_rotation
from virtus.io.jsonio import write_json
from virtus.io.safeio import MAX_CONFIG_BYTES, parse_json, read_text

#: Names of each calibration quantity in FileStorage nodes and text-file stems (``<name>.txt``),
#: matched ignoring case, ``_`` and ``-``. The first name is the one virtus writes in YAML.
#: ``R``/``T``: X_proj = R X_cam + T; ``proj2cam_*``: X_cam = R X_proj + t; ``cam_R``/``cam_T``:
#: the camera's pose in the frame of ``R``/``T`` (X_cam = R_c X_w + T_c).
CALIBRATION_NAMES: dict[str, tuple[str, ...]] = {
    "camera_matrix": (
        "camera_matrix", "cameraMatrix1", "K1", "M1", "Kc", "K_cam", "cam_K", "camera_K",
        "CamIntrinsicMatrix", "CameraIntrinsicMatrix",
    ),
    "camera_distortion": (
        "camera_distortion", "distortion_coefficients", "distCoeffs", "distCoeffs1", "D1", "Dc",
        "cam_kc", "cam_dist", "camera_dist", "CamDistortion", "CamDistortionCoefficients",
        "CamDistortionCoeffs", "CameraDistortion", "CameraDistortionCoefficients",
    ),
    "camera_size": ("camera_size", "imageSize", "camera_image_size", "cam_size"),
    "projector_matrix": (
        "projector_matrix", "cameraMatrix2", "K2", "M2", "Kp", "K_proj", "proj_K",
        "projector_K", "ProjIntrinsicMatrix", "ProjectorIntrinsicMatrix",
    ),
    "projector_distortion": (
        "projector_distortion", "distCoeffs2", "D2", "Dp", "proj_kc", "proj_dist",
        "projector_dist", "ProjDistortion", "ProjDistortionCoefficients",
        "ProjDistortionCoeffs", "ProjectorDistortion", "ProjectorDistortionCoefficients",
    ),
    "projector_size": ("projector_size", "projector_image_size", "proj_size"),
    "R": ("R", "cam2proj_R", "ProjRotationMatrix"),
    "T": ("T", "cam2proj_t", "ProjTranslationVector"),
    "proj2cam_R": ("proj2cam_R",),
    "proj2cam_t": ("proj2cam_t",),
    "cam_R": ("CamRotationMatrix",),
    "cam_T": ("CamTranslationVector",),
}  # fmt: skip
#: Image sizes given as two scalar nodes (width, height), same matching.
SIZE_PAIR_NAMES: dict[str, tuple[tuple[str, str], ...]] = {
    "camera_size": (
        ("image_width", "image_height"),
        ("camera_width", "camera_height"),
        ("cam_width", "cam_height"),
    ),
    "projector_size": (("projector_width", "projector_height"), ("proj_width", "proj_height")),
}
#: Names of the node stating the units of the translations (FileStorage).
UNITS_NAMES = ("units", "unit")
#: Metres per unit, and the spellings accepted for each unit (case-insensitive).
METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}
UNIT_SPELLINGS = {
    "m": ("m", "meter", "meters", "metre", "metres"),
    "cm": ("cm", "centimeter", "centimeters", "centimetre", "centimetres"),
    "mm": ("mm", "millimeter", "millimeters", "millimetre", "millimetres"),
}
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
    "or a folder (or a .txt file in it) with the paper code's text files"
)
_SEPARATORS = re.compile(r"[\s,;]+")


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
    path : a rig ``.json``, an OpenCV FileStorage ``.yaml``/``.yml``/``.xml``, or a folder of
        the paper code's text files (or a ``.txt`` file inside that folder).
    units : ``"m"``, ``"cm"`` or ``"mm"``: the unit of the file's translations when it
        states none; must agree with a unit the file states. Text folders default to mm.
    camera_size, projector_size : ``(width, height)`` in pixels, for files that hold no image
        sizes (e.g. ``stereoCalibrate`` results, text folders); must agree with sizes a file
        holds.

    Returns
    -------
    The rig: intrinsics (pixels, OpenCV distortion order) and ``proj2cam`` in metres.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist, or a text folder lacks a required file.
    InputError
        Anything else wrong with the file or the arguments; the message names the file and
        key, what was expected and what came.
    """
    unit = None if units is None else _unit_name("units", units)
    sizes = (_given_size("camera_size", camera_size), _given_size("projector_size", projector_size))
    source = Path(path)
    if not source.exists():
        raise FileNotFoundError(2, "no such calibration file or folder", str(source))
    if source.is_file() and source.suffix.lower() == ".txt":
        source = source.parent
    if source.is_dir():
        return _load_txt_folder(source, unit, *sizes)
    suffix = source.suffix.lower()
    if suffix == ".json":
        return _load_json(source, unit, *sizes)
    if suffix in _FILESTORAGE_SUFFIXES:
        return _load_filestorage(source, unit, *sizes)
    raise InputError(f"calibration {source}", _ACCEPTED, f"a {suffix or 'suffix-less'} file")


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
    unit = None if units is None else _unit_name("units", units)
    sizes = (_given_size("camera_size", camera_size), _given_size("projector_size", projector_size))
    return _load_filestorage(source, unit, *sizes)


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


# -- the three readers ----------------------------------------------------------------------

_Found = dict[str, tuple[str, Any]]  # quantity -> (name in the file, raw value)


def _load_json(
    path: Path, units: str | None, camera_size: tuple | None, projector_size: tuple | None
) -> Rig:
    source = f"calibration {path}"
    data = parse_json(_read_text(path), source, expect=dict)
    rig = data
    if "camera" not in data and isinstance(data.get("rig"), Mapping):  # capture.json
        rig = data["rig"]
    stated = rig.get("units", data.get("units"))
    scale = _metres_per_unit(source, None if stated is None else ("units", stated), units)
    rig = dict(rig, units="m")
    for device, given in (("camera", camera_size), ("projector", projector_size)):
        entry = rig.get(device)
        if isinstance(entry, Mapping):
            size = None
            if "width" in entry or "height" in entry:
                size = (f"{device}.width/height", [entry.get("width"), entry.get("height")])
            width, height = _image_size(source, device, size, given)
            rig[device] = dict(entry, width=width, height=height)
    pose = rig.get("proj2cam")
    if isinstance(pose, Mapping) and "t" in pose:
        t = _vector(f"{source}: proj2cam.t", pose["t"], 3)
        rig["proj2cam"] = dict(pose, t=t * scale)
    try:
        return Rig.from_dict(rig)
    except InputError as error:
        raise InputError(f"{source}: {error.name}", error.expected, error.got) from None


def _load_filestorage(
    path: Path, units: str | None, camera_size: tuple | None, projector_size: tuple | None
) -> Rig:
    source = f"calibration {path}"
    text = _read_text(path)
    what = "an OpenCV FileStorage YAML or XML file"
    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as error:
        raise InputError(
            source, what, f"a file OpenCV cannot parse ({_first_line(error)})"
        ) from None
    try:
        root = storage.root() if storage.isOpened() else None
        if root is None or not root.isMap():
            raise InputError(source, what + " with named top-level nodes", "none")
        nodes = {key: storage.getNode(key) for key in root.keys()}
        stated = None
        for key, node in nodes.items():
            if _normalize(key) in UNITS_NAMES:
                if stated is not None or not node.isString():
                    raise InputError(f"{source}: {key}", "one units string (m, cm or mm)", key)
                stated = (key, node.string())
        scale = _metres_per_unit(source, stated, units)
        items = {
            key: (key, lambda node=node, key=key: _node_value(f"{source}: {key}", node))
            for key, node in nodes.items()
        }
        found = _collect(source, items)
    except cv2.error as error:
        raise InputError(source, what, f"unreadable nodes ({_first_line(error)})") from None
    finally:
        storage.release()
    return _assemble(source, found, scale, camera_size, projector_size)


def _load_txt_folder(
    folder: Path, units: str | None, camera_size: tuple | None, projector_size: tuple | None
) -> Rig:
    source = f"calibration {folder}"
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".txt" and p.is_file())
    items = {
        file.name: (file.stem, lambda file=file: _read_table(f"{source}/{file.name}", file))
        for file in files
    }
    found = _collect(source, items)
    for quantity in ("camera_matrix", "projector_matrix", "R", "T"):
        if quantity not in found:
            raise FileNotFoundError(
                2,
                f"no {PAPER_TXT_FILES[quantity]} (or <name>.txt for another name of the "
                f"{quantity}: {', '.join(CALIBRATION_NAMES[quantity])}) in the calibration folder",
                str(folder),
            )
    scale = METRES_PER_UNIT[units or PAPER_TXT_UNITS]
    return _assemble(source, found, scale, camera_size, projector_size)


# -- from named values to a rig -------------------------------------------------------------


def _collect(source: str, items: Mapping[str, tuple[str, Callable[[], Any]]]) -> _Found:
    """Match ``items`` (name in the file -> (key to match, loader)) to the quantities.

    Only matched items are loaded. Two names of one quantity is an error (which to trust?).
    """
    by_key: dict[str, list[str]] = {}
    for name, (key, _) in items.items():
        by_key.setdefault(_normalize(key), []).append(name)

    def lookup(quantity: str, aliases: tuple[str, ...]) -> str | None:
        keys = dict.fromkeys(_normalize(alias) for alias in aliases)  # unique, in order
        names = [name for key in keys for name in by_key.get(key, [])]
        if len(names) > 1:
            raise InputError(source, f"one of {', '.join(aliases)} ({quantity})", names)
        return names[0] if names else None

    found: _Found = {}
    for quantity, aliases in CALIBRATION_NAMES.items():
        name = lookup(quantity, aliases)
        if name is not None:
            found[quantity] = (name, items[name][1]())
    for quantity, pairs in SIZE_PAIR_NAMES.items():
        for pair in pairs:
            width, height = (lookup(quantity, (alias,)) for alias in pair)
            if width is None and height is None:
                continue
            if width is None or height is None:
                raise InputError(source, f"both {pair[0]} and {pair[1]}", f"{width or height} only")
            if quantity in found:
                raise InputError(source, f"one {quantity}", [found[quantity][0], width, height])
            found[quantity] = (f"{width}/{height}", [items[width][1](), items[height][1]()])
    return found


def _assemble(
    source: str,
    found: _Found,
    metres_per_unit: float,
    camera_size: tuple[int, int] | None,
    projector_size: tuple[int, int] | None,
) -> Rig:
    """Validate the values of ``found`` (named by their key in ``source``) and build the rig."""

    def require(quantity: str) -> tuple[str, Any]:
        if quantity not in found:
            names = ", ".join(CALIBRATION_NAMES[quantity])
            raise InputError(source, f"a {quantity} node (one of {names})", "none")
        return found[quantity]

    devices = []
    for device, given in (("camera", camera_size), ("projector", projector_size)):
        k_key, k_value = require(f"{device}_matrix")
        K = _matrix33(f"{source}: {k_key}", k_value)  # noqa: N806
        d_key, d_value = found.get(f"{device}_distortion", ("", None))
        dist = np.zeros(0) if d_value is None else _vector(f"{source}: {d_key}", d_value)
        width, height = _image_size(source, device, found.get(f"{device}_size"), given)
        try:
            devices.append(Intrinsics.from_opencv(K, dist, width, height))
        except InputError as error:
            key = d_key if error.name == "dist" else k_key
            raise InputError(f"{source}: {key} ({error.name})", error.expected, error.got) from None

    poses = {}
    for pose, r_name, t_name in (
        ("proj2cam", "proj2cam_R", "proj2cam_t"),
        ("cam2proj", "R", "T"),
        ("world2cam", "cam_R", "cam_T"),
    ):
        if r_name in found or t_name in found:
            (r_key, r_value), (t_key, t_value) = require(r_name), require(t_name)
            r_label = f"{source}: {r_key}"
            rotation = check_rotation(r_label, _matrix33(r_label, r_value))
            translation = _vector(f"{source}: {t_key}", t_value, 3) * metres_per_unit
            poses[pose] = Pose(rotation, translation)
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
    return Rig(Camera(devices[0]), Projector(devices[1]), proj2cam)


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
    size = _given_size(f"{source}: {key}", _vector(f"{source}: {key}", value, 2).tolist())
    if given is not None and size != given:
        raise InputError(f"{source}: {key}", f"the {device}_size given, {given}", size)
    return size


def _metres_per_unit(source: str, stated: tuple[str, object] | None, given: str | None) -> float:
    """Metres per unit of the file's translations: ``stated`` (key, value) by the file, else
    ``given`` (a unit name); a file stating none with none given is refused."""
    unit = given
    if stated is not None:
        key, value = stated
        unit = _unit_name(f"{source}: {key}", value)
        if given is not None and unit != given:
            raise InputError(f"{source}: {key}", f"the units given ({given}) or none", unit)
    if unit is None:
        raise InputError(
            source,
            "units stated in the file or given (pass --units mm or --units m)",
            "a file that states no units",
        )
    return METRES_PER_UNIT[unit]


# -- values ---------------------------------------------------------------------------------


def _matrix33(name: str, value: object) -> np.ndarray:
    array = as_float_array(name, value)
    if array.shape != (3, 3):
        raise InputError(name, "a 3 x 3 matrix (9 numbers in 3 rows of 3)", f"shape {array.shape}")
    return array


def _vector(name: str, value: object, length: int | None = None) -> np.ndarray:
    """A vector written as one row, one column or a flat list; ``(length,)`` float64."""
    array = as_float_array(name, value)
    if array.ndim not in (1, 2) or (array.ndim == 2 and min(array.shape) != 1):
        want = "a vector" if length is None else f"a vector of {length} numbers"
        raise InputError(name, f"{want} (one row or one column)", f"shape {array.shape}")
    array = array.ravel()
    if length is not None and array.size != length:
        raise InputError(name, f"{length} numbers", f"{array.size} numbers")
    return array


def _given_size(name: str, value: object) -> tuple[int, int] | None:
    if value is None:
        return None
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise InputError(name, "(width, height) in pixels", value)
    return positive_int(f"{name} width", value[0]), positive_int(f"{name} height", value[1])


def _unit_name(name: str, value: object) -> str:
    text = value.strip().lower() if isinstance(value, str) else None
    for unit, spellings in UNIT_SPELLINGS.items():
        if text in spellings:
            return unit
    raise InputError(name, "units 'm', 'cm' or 'mm'", value)


def _normalize(name: str) -> str:
    return name.lower().replace("_", "").replace("-", "")


# -- text -----------------------------------------------------------------------------------


def _read_text(path: Path) -> str:
    """The file's text (:func:`virtus.io.safeio.read_text`: bounded, UTF-8, no NUL), non-empty."""
    text = read_text(path, "calibration", max_bytes=MAX_CONFIG_BYTES)
    if not text.strip():
        raise InputError(f"calibration {path}", "a calibration file", "an empty file")
    return text


def _read_table(name: str, path: Path) -> np.ndarray:
    """A text file of numbers as a 2-D float64 table (rows = lines); may hold NaN."""
    rows = []
    for number, line in enumerate(_read_text(path).splitlines(), 1):
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


def _node_value(name: str, node: Any, depth: int = 0) -> Any:
    """A FileStorage node as an array, nested lists of numbers, a number or a string."""
    if node.isMap():
        # An opencv-matrix (rows, cols, data) or opencv-nd-matrix (sizes, data), read here
        # rather than by node.mat(), which crashes the process on inconsistent sizes
        # (OpenCV 5.0, e.g. "cols: -1").
        keys = set(node.keys())
        if "data" not in keys or not ({"rows", "cols"} <= keys or "sizes" in keys) or depth:
            raise InputError(name, "an opencv-matrix, a list of numbers or a number", "a map")
        if "sizes" in keys:
            sizes = _node_value(name, node.getNode("sizes"), depth + 1)
        else:
            sizes = [_node_value(name, node.getNode(key), depth + 1) for key in ("rows", "cols")]
        data = as_float_array(name, _node_value(name, node.getNode("data"), depth + 1))
        shape = as_float_array(name, sizes).ravel()
        if data.ndim != 1 or np.any(shape < 1) or np.any(shape % 1) or shape.prod() != data.size:
            got = f"sizes {shape.tolist()} and {data.size} numbers"
            raise InputError(name, "an opencv-matrix whose data fills its rows x cols", got)
        return data.reshape(shape.astype(int))
    if node.isSeq():
        if depth >= 2:
            raise InputError(name, "a matrix (lists nested at most twice)", "deeper nesting")
        return [_node_value(name, node.at(i), depth + 1) for i in range(node.size())]
    if node.isInt() or node.isReal():
        return node.real()
    if node.isString():
        return node.string()
    return None


def _first_line(error: BaseException) -> str:
    """The gist of an OpenCV error (the ``cv2.error`` behind a ``SystemError`` if any)."""
    error = error.__cause__ or error
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    # "OpenCV(5.0.0) /path/persistence.cpp:767: error: (-215:Assertion failed) ..." -> "(-215..."
    return lines[-1].split(" error: ", 1)[-1] if lines else type(error).__name__
