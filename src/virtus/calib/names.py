"""Names of calibration quantities as calibration files spell them, and the one matcher
that gives a name (a FileStorage node, an ``.npz`` key, a text file's stem) its role.

A name is compared ignoring case and the separators ``_``, ``-``, ``.`` and spaces
(:func:`normalize`), first with the table :data:`CALIBRATION_NAMES` (the spellings of known
tools), then as a **structured name** ``[device] quantity [side]`` (:func:`name_role`):

* device: ``Cam``, ``Camera`` (the camera) or ``Proj``, ``Projector`` (the projector);
* quantity: the intrinsic matrix (:data:`QUANTITY_WORDS` ``"matrix"``: ``IntrinsicMatrix``,
  ``Intrinsics``, ``Intrinsic``, ``Matrix``, ``Mtx``, ``Int``, ``K``), the distortion
  (``DistortionCoefficients``, ``DistortionCoeffs``, ``Distortion``, ``DistCoeffs``, ``Dist``,
  ``Kc`` as in Bouguet's toolbox, ``D``), the rotation (``RotationMatrix``, ``Rotation``,
  ``Rot``, ``R``), the translation (``TranslationVector``, ``Translation``, ``Trans``,
  ``Tvec``, ``T``), the image size (``ImageSize``, ``Size``: width, height);
* side: ``Left`` or ``1`` -- the first device of a stereo pair, **the camera**; ``Right`` or
  ``2`` -- the second device, **the projector** (OpenCV ``stereoCalibrate`` with the camera
  first, as ``K1 D1 K2 D2 R T``). The side decides the device: ``CamIntrinsicMatrixRight``
  is the projector's matrix (a stereo tool's "right camera"), ``ProjIntrinsicMatrixLeft``
  contradicts itself and matches nothing.
* **except beside projector names**: when the names of one source (a folder's file stems, a
  file's keys; :func:`name_roles`) include a projector-prefixed quantity (``Proj...``,
  ``Projector...``), the projector is named, and a ``Cam...`` name with any side is **the
  camera**: the side then says which camera of a stereo bench the lab kept, not which
  device. A LightCrafter lab's folder (kimthyung/3D_Reconstruction_with_Fringe_pattern,
  ``CalibrationDataDistortion/``) holds ``CamIntrinsicMatrixRight.txt``,
  ``CamDistortionCoefficientsRight.txt``, ``CamRotationMatrixRight.txt`` (the identity),
  ``CamTranslationVectorRight.txt`` (zero) beside ``ProjIntrinsicMatrix.txt``,
  ``ProjDistortionCoefficients.txt``, ``ProjRotationMatrix.txt``,
  ``ProjTranslationVector.txt``: its only camera is its "Right" one. A second camera
  (``Cam...Left`` and ``Cam...Right`` beside ``Proj...``) is then two files for one quantity,
  refused by the reader.

A rotation or translation of a device is its pose in the file's reference frame,
X_device = R X_ref + T (the paper code's ``ProjRotationMatrix``; ``CamRotationMatrixRight``
of a stereo folder: the second device in the first's frame): the projector's is ``R``/``T``
of :data:`CALIBRATION_NAMES`, the camera's ``cam_R``/``cam_T``. A one-letter quantity
(``K``, ``D``, ``R``, ``T``) needs a device or a ``Left``/``Right`` side: ``R1``, ``R2``,
``P1``, ``P2`` of ``stereoRectify`` are rectification matrices, not poses, and ``K1 D1 K2
D2`` are in the table.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

__all__ = [
    "CALIBRATION_NAMES",
    "QUANTITY_WORDS",
    "SHAPE_NAMES",
    "SIZE_PAIR_NAMES",
    "UNITS_NAMES",
    "name_role",
    "name_roles",
    "normalize",
    "side_read_as_camera",
]

#: Names of each calibration quantity in FileStorage nodes, ``.npz`` keys and text-file stems
#: (``<name>.txt``), matched by :func:`normalize`. The first name is the one virtus writes in
#: YAML. ``R``/``T``: X_proj = R X_cam + T; ``proj2cam_*``: X_cam = R X_proj + t;
#: ``cam_R``/``cam_T``: the camera's pose in the frame of ``R``/``T`` (X_cam = R_c X_w + T_c).
#: ``cam_int ... rotation translation`` (with ``img_shape``, :data:`SHAPE_NAMES`) are the
#: nodes of kamino410's procam-calibration (``calibration_result.xml``: "rotation/translation
#: from camera to projector"); ``mtx dist`` those of OpenCV's calibration tutorial.
CALIBRATION_NAMES: dict[str, tuple[str, ...]] = {
    "camera_matrix": (
        "camera_matrix", "cameraMatrix1", "K1", "M1", "Kc", "K_cam", "cam_K", "camera_K",
        "CamIntrinsicMatrix", "CameraIntrinsicMatrix", "cam_int", "cam_mtx", "camera_mtx",
        "mtx",
    ),
    "camera_distortion": (
        "camera_distortion", "distortion_coefficients", "distCoeffs", "distCoeffs1", "D1", "Dc",
        "cam_kc", "cam_dist", "camera_dist", "CamDistortion", "CamDistortionCoefficients",
        "CamDistortionCoeffs", "CameraDistortion", "CameraDistortionCoefficients", "dist",
        "dist_coeffs",
    ),
    "camera_size": ("camera_size", "imageSize", "camera_image_size", "cam_size"),
    "projector_matrix": (
        "projector_matrix", "cameraMatrix2", "K2", "M2", "Kp", "K_proj", "proj_K",
        "projector_K", "ProjIntrinsicMatrix", "ProjectorIntrinsicMatrix", "proj_int",
        "proj_mtx", "projector_mtx",
    ),
    "projector_distortion": (
        "projector_distortion", "distCoeffs2", "D2", "Dp", "proj_kc", "proj_dist",
        "projector_dist", "ProjDistortion", "ProjDistortionCoefficients",
        "ProjDistortionCoeffs", "ProjectorDistortion", "ProjectorDistortionCoefficients",
    ),
    "projector_size": ("projector_size", "projector_image_size", "proj_size"),
    "R": ("R", "cam2proj_R", "ProjRotationMatrix", "rotation"),
    "T": ("T", "cam2proj_t", "ProjTranslationVector", "translation"),
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
#: Image sizes written as a NumPy shape, **(height, width)** (``img_shape`` of kamino410's
#: procam-calibration is ``cv2.imread(...).shape``), same matching.
SHAPE_NAMES: dict[str, tuple[str, ...]] = {
    "camera_size": ("img_shape", "image_shape", "cam_shape", "camera_shape"),
    "projector_size": ("proj_shape", "projector_shape"),
}
#: Names of the node stating the units of the translations (FileStorage, ``.npz``).
UNITS_NAMES = ("units", "unit")
#: Quantity words of structured names (normalized), longest first within each quantity.
QUANTITY_WORDS: dict[str, tuple[str, ...]] = {
    "matrix": (
        "intrinsicmatrix", "intrinsicsmatrix", "intrinsics", "intrinsic", "matrix", "mtx",
        "int", "k",
    ),
    "distortion": (
        "distortioncoefficients", "distortioncoefficient", "distortioncoeffs",
        "distortioncoeff", "distortion", "distcoeffs", "distcoeff", "dist", "kc", "d",
    ),
    "rotation": ("rotationmatrix", "rotation", "rot", "r"),
    "translation": ("translationvector", "translation", "trans", "tvec", "t"),
    "size": ("imagesize", "size"),
}  # fmt: skip
_DEVICES = (("camera", "camera"), ("cam", "camera"), ("projector", "projector"),
            ("proj", "projector"))  # fmt: skip
_SIDES = (("left", "camera"), ("right", "projector"), ("1", "camera"), ("2", "projector"))
_SEPARATORS = re.compile(r"[\s_.\-]+")


def normalize(name: str) -> str:
    """``name`` in lower case without ``_``, ``-``, ``.`` and white space."""
    return _SEPARATORS.sub("", name).lower()


def _table() -> dict[str, str]:
    table: dict[str, str] = {}
    for quantity, aliases in CALIBRATION_NAMES.items():
        for alias in aliases:
            key = normalize(alias)
            if table.setdefault(key, quantity) != quantity:
                raise AssertionError(f"{alias!r} names both {table[key]} and {quantity}")
    return table


_TABLE = _table()
_SHAPES = {normalize(alias): q for q, aliases in SHAPE_NAMES.items() for alias in aliases}
_PAIRS = {
    normalize(alias): (quantity, index, side)
    for quantity, pairs in SIZE_PAIR_NAMES.items()
    for index, pair in enumerate(pairs)
    for side, alias in enumerate(pair)
}


def name_roles(names: Iterable[str]) -> dict[str, tuple[str | None, str]]:
    """The role of each of ``names``, the names of one source (a folder's file stems, a
    file's keys), read together: :func:`name_role` of each, with ``projector_named`` True
    when one of them is a projector's by its device prefix (``Proj...``; module docstring).
    """
    keys = list(dict.fromkeys(names))
    named = any(
        _device(normalize(key))[0] == "projector" and name_role(key)[0] is not None for key in keys
    )
    return {key: name_role(key, projector_named=named) for key in keys}


def side_read_as_camera(name: str) -> str:
    """The side (``"Right"`` or ``"2"``) of a camera-prefixed ``name`` that only a
    projector-named source reads as the camera's (:func:`name_roles`), else ``""``; for the
    note saying so."""
    device, rest = _device(normalize(name))
    if device != "camera":
        return ""
    side = next((s for s, d in _SIDES if rest.endswith(s) and d == "projector"), "")
    return {"right": "Right", "2": "2"}.get(side, "")


def name_role(name: str, *, projector_named: bool = False) -> tuple[str | None, str]:
    """The role of ``name`` and why.

    ``projector_named``: the source also names the projector by a ``Proj...`` prefix, so a
    ``Cam...`` name with a side is the camera's (module docstring; :func:`name_roles`).

    ``(quantity, "")`` for a quantity of :data:`CALIBRATION_NAMES`; ``("camera_shape", "")``
    or ``("projector_shape", "")`` for a (height, width) shape of :data:`SHAPE_NAMES`;
    ``("pair:<quantity>:<index>:<side>", "")`` for one node of pair ``index`` of
    :data:`SIZE_PAIR_NAMES` (side 0: width, 1: height); ``("units", "")``; or ``(None,
    reason)`` for a name that matches nothing (the reason, for a warning)."""
    key = normalize(name)
    if key in _TABLE:
        return _TABLE[key], ""
    if key in _SHAPES:
        return _SHAPES[key].replace("_size", "_shape"), ""
    if key in _PAIRS:
        quantity, index, side = _PAIRS[key]
        return f"pair:{quantity}:{index}:{side}", ""
    if key in UNITS_NAMES:
        return "units", ""
    return _structured(key, projector_named)


def _device(key: str) -> tuple[str | None, str]:
    """The device a normalized name starts with (``None`` if none) and the rest."""
    prefixed = [(d, key[len(p) :]) for p, d in _DEVICES if key.startswith(p)]
    return prefixed[0] if prefixed else (None, key)


def _structured(key: str, projector_named: bool = False) -> tuple[str | None, str]:
    """The role of a normalized ``[device] quantity [side]`` name (module docstring)."""
    device, rest = _device(key)
    suffixed = [(d, rest[: -len(s)]) for s, d in _SIDES if rest.endswith(s)]
    side, word = suffixed[0] if suffixed else (None, rest)
    quantity = next((q for q, words in QUANTITY_WORDS.items() if word in words), None)
    if quantity is None:
        return None, "not a name of a calibration quantity"
    if device is None and side is None:
        return None, f"{quantity} of which device? (no Cam/Proj prefix, no Left/Right suffix)"
    if device is None and len(word) == 1 and rest[-1:] in ("1", "2"):
        return None, f"a one-letter {quantity} with a 1/2 suffix (a rectification matrix?)"
    if device == "projector" and side == "camera":
        return None, "names the projector (Proj) and the camera (Left/1) at once"
    which = "camera" if device == "camera" and projector_named else side or device
    if quantity in ("rotation", "translation"):
        letter = "R" if quantity == "rotation" else "T"
        return (letter if which == "projector" else f"cam_{letter}"), ""
    return f"{which}_{quantity}", ""
