"""Calibration files: virtus JSON, OpenCV FileStorage YAML, the paper code's text files.

* ``calibration.json``: the rig schema of DESIGN.md section 3 (metres) plus calibration
  fields (errors, per-pose residuals, board, truth comparison); :meth:`Rig.load_json`
  reads it back as a rig.
* OpenCV FileStorage YAML (:func:`save_opencv_yaml` / :func:`load_opencv_yaml`):
  ``camera_matrix``, ``camera_distortion``, ``camera_size``, ``projector_matrix``,
  ``projector_distortion``, ``projector_size``, and the extrinsics both ways:
  ``proj2cam_R``, ``proj2cam_t`` (X_cam = R X_proj + t) and OpenCV's stereoCalibrate
  convention ``R``, ``T`` (X_proj = R X_cam + T). Translations in metres (``units: m``).
* The paper code's tab-separated text files (:func:`save_paper_txt` /
  :func:`load_paper_txt`): ``CamIntrinsicMatrix.txt``, ``CamDistortion.txt``,
  ``ProjIntrinsicMatrix.txt``, ``ProjDistortion.txt`` (3 x 3 matrices and 1 x N rows), and
  ``ProjRotationMatrix.txt``, ``ProjTranslationVector.txt``: the projector's pose as
  OpenCV's stereoCalibrate gives it with the camera first, X_proj = R X_cam + T, **T in
  millimetres** (the unit of the paper's code). Image sizes are not part of these files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from virtus.devices import Camera, Projector, Rig
from virtus.errors import InputError
from virtus.jsonio import write_json
from virtus.optics import Intrinsics
from virtus.transforms import Pose

#: File names of the paper code's calibration text files.
PAPER_TXT_FILES = {
    "cam_k": "CamIntrinsicMatrix.txt",
    "cam_dist": "CamDistortion.txt",
    "proj_k": "ProjIntrinsicMatrix.txt",
    "proj_dist": "ProjDistortion.txt",
    "rotation": "ProjRotationMatrix.txt",
    "translation": "ProjTranslationVector.txt",
}
#: Millimetres per metre (the paper's text files hold translations in mm).
MM_PER_M = 1000.0


def save_json(data: dict[str, Any], path: str | Path) -> Path:
    """Write a calibration dict (rig schema + extras) as indented JSON; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_json(path, data)


# -- OpenCV FileStorage ---------------------------------------------------------------------


def save_opencv_yaml(rig: Rig, path: str | Path, extras: dict[str, float] | None = None) -> Path:
    """Write ``rig`` as an OpenCV FileStorage YAML file (metres); ``extras``: scalar fields."""
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


def load_opencv_yaml(path: str | Path) -> Rig:
    """Read a rig written by :func:`save_opencv_yaml` (``proj2cam_*`` or OpenCV ``R``/``T``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such file", str(path))
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:

        def mat(key: str) -> np.ndarray | None:
            node = storage.getNode(key)
            return None if node.empty() else node.mat()

        units = storage.getNode("units")
        if not units.empty() and units.string() != "m":
            raise InputError(f"{path}: units", '"m"', units.string())
        devices = []
        for prefix in ("camera", "projector"):
            K, dist, size = (
                mat(f"{prefix}_matrix"),
                mat(f"{prefix}_distortion"),
                mat(  # noqa: N806
                    f"{prefix}_size"
                ),
            )
            if K is None or size is None:
                raise InputError(str(path), f"{prefix}_matrix and {prefix}_size", "missing")
            size = size.ravel()
            dist = np.zeros(5) if dist is None else dist.ravel()
            devices.append(Intrinsics.from_opencv(K, dist, int(size[0]), int(size[1])))
        r, t = mat("proj2cam_R"), mat("proj2cam_t")
        if r is not None and t is not None:
            proj2cam = Pose(r, t.ravel())
        else:
            r, t = mat("R"), mat("T")
            if r is None or t is None:
                raise InputError(str(path), "proj2cam_R/proj2cam_t or R/T", "missing")
            proj2cam = Pose(r, t.ravel()).inverse()
    finally:
        storage.release()
    return Rig(Camera(devices[0]), Projector(devices[1]), proj2cam)


# -- the paper code's text files ------------------------------------------------------------


def _write_matrix(path: Path, matrix: np.ndarray) -> None:
    rows = np.atleast_2d(matrix)
    path.write_text("\n".join("\t".join(repr(float(v)) for v in row) for row in rows) + "\n")


def _read_matrix(path: Path, shape: tuple[int, ...] | None) -> np.ndarray:
    if not path.is_file():
        raise FileNotFoundError(2, "no such file", str(path))
    try:
        rows = [
            [float(v) for v in line.split()]
            for line in path.read_text().splitlines()
            if line.strip()
        ]
        matrix = np.array(rows, dtype=np.float64)
    except ValueError:
        raise InputError(str(path), "tab-separated numbers", "unparsable text") from None
    if shape is not None and matrix.size != int(np.prod(shape)):
        raise InputError(str(path), f"{int(np.prod(shape))} numbers", matrix.size)
    return matrix if shape is None else matrix.reshape(shape)


def save_paper_txt(rig: Rig, directory: str | Path) -> Path:
    """Write the paper code's six text files into ``directory`` (T in millimetres)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    cam2proj = rig.cam2proj
    _write_matrix(directory / PAPER_TXT_FILES["cam_k"], rig.camera.intrinsics.K)
    _write_matrix(directory / PAPER_TXT_FILES["cam_dist"], rig.camera.intrinsics.dist_array)
    _write_matrix(directory / PAPER_TXT_FILES["proj_k"], rig.projector.intrinsics.K)
    _write_matrix(directory / PAPER_TXT_FILES["proj_dist"], rig.projector.intrinsics.dist_array)
    _write_matrix(directory / PAPER_TXT_FILES["rotation"], cam2proj.R)
    _write_matrix(directory / PAPER_TXT_FILES["translation"], cam2proj.t * MM_PER_M)
    return directory


def load_paper_txt(
    directory: str | Path,
    camera_size: tuple[int, int] = (960, 960),
    projector_size: tuple[int, int] = (912, 1140),
) -> Rig:
    """Read the paper code's text files (T in mm) as a rig; sizes are (width, height) px."""
    directory = Path(directory)
    cam_k = _read_matrix(directory / PAPER_TXT_FILES["cam_k"], (3, 3))
    cam_d = _read_matrix(directory / PAPER_TXT_FILES["cam_dist"], None).ravel()
    proj_k = _read_matrix(directory / PAPER_TXT_FILES["proj_k"], (3, 3))
    proj_d = _read_matrix(directory / PAPER_TXT_FILES["proj_dist"], None).ravel()
    rotation = _read_matrix(directory / PAPER_TXT_FILES["rotation"], (3, 3))
    translation = _read_matrix(directory / PAPER_TXT_FILES["translation"], (3,)) / MM_PER_M
    return Rig(
        Camera(Intrinsics.from_opencv(cam_k, cam_d, *camera_size)),
        Projector(Intrinsics.from_opencv(proj_k, proj_d, *projector_size)),
        Pose(rotation, translation).inverse(),
    )
