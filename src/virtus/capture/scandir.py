"""The scan directory: the one owner of its file names, what each holds and how derived
files are tied to their inputs (so every command agrees).

A scan directory is a capture directory (the layout of ``virtus capture``, format
``virtus.capture/2``: :mod:`virtus.capture.capture`) plus the files decoding,
reconstruction and evaluation derive from it. Every file, relative to ``DIR``
(H, W: camera image rows and columns; lengths in metres, OpenCV camera frame: x right,
y down, z forward; projector coordinates in projector pixels, pixel-centre convention):

==============================  ============  ========  ==========  ============================
file                            shape         dtype     unit        frame / meaning
==============================  ============  ========  ==========  ============================
**capture** (:data:`virtus.capture.capture.LAYOUT`, written by ``Capture.save``)
--------------------------------------------------------------------------------------------------
``capture.json``                --            JSON      m           format, units, rig (rig
                                                                    schema, camera frame),
                                                                    cam2world, sequence, sensor,
                                                                    seed, bit depth, render,
                                                                    scene, frame and gt files,
                                                                    provenance (written last)
``frames/NNN.png``              (H, W)        uint8 or  DN          one grey frame per sequence
                                              uint16                step (10/12 bits in 16-bit
                                                                    PNGs, unscaled)
``gt/depth.npy``                (H, W)        float64   m           camera-frame z; NaN no hit
``gt/points.npy``               (H, W, 3)     float64   m           camera frame; NaN no hit
``gt/normals.npy``              (H, W, 3)     float64   unit        camera frame, toward camera
``gt/proj_uv.npy``              (H, W, 2)     float64   proj. px    ``(u_p, v_p)``
``gt/mask.npy``                 (H, W)        bool      --          hit, lit, inside projector
``gt/mask_hit.npy``             (H, W)        bool      --          pixel-centre ray hits
``gt/mask_shadow.npy``          (H, W)        bool      --          hit, projector occluded
``gt/mask_outside.npy``         (H, W)        bool      --          hit, outside projector image
``gt/mask_multibounce.npy``     (H, W)        bool      --          indirect light dominates
``gt/mask_saturated.npy``       (H, W)        bool      --          full scale in some frame
``scene_assets/*.npy``          texture       float     albedo      in-memory scene textures
**decoded/** (:func:`save_decoded`; :data:`DECODED_FILES`)
--------------------------------------------------------------------------------------------------
``decoded/phase_v.npy``         (H, W)        float64   rad         absolute phase, vertical
                                                                    fringes; NaN invalid
``decoded/phase_h.npy``         (H, W)        float64   rad         absolute phase, horizontal
                                                                    fringes; NaN invalid
``decoded/proj_uv.npy``         (H, W, 2)     float64   proj. px    ``(u_p, v_p)``; NaN invalid
``decoded/mask.npy``            (H, W)        bool      --          decoded in every direction
``decoded/modulation.npy``      (H, W)        float64   DN          fringe amplitude ``B``
``decoded/flagged.npy``         (H, W)        bool      --          valid, fringe order suspect
``decoded/summary.json``        --            JSON      share       valid and flagged shares,
                                                                    modulation percentiles
``decoded/source.json``         --            JSON      --          tie (below), written last
**reconstruction/** (:func:`save_reconstruction`; :data:`RECONSTRUCTION_FILES`)
--------------------------------------------------------------------------------------------------
``reconstruction/points.npy``   (H, W, 3)     float64   m           camera frame; NaN no point
``reconstruction/depth.npy``    (H, W)        float64   m           camera-frame z; NaN no point
``reconstruction/mask.npy``     (H, W)        bool      --          pixels with a point
``reconstruction/rig.json``     --            JSON      m           the rig triangulated with
                                                                    (rig schema)
``reconstruction/source.json``  --            JSON      --          tie (below), written last
``points.ply``                  N points      binary    m           camera frame, with normals
                                              PLY                   (toward the camera)
**evaluation** (``virtus evaluate``)
--------------------------------------------------------------------------------------------------
``evaluation.json``             --            JSON      mm          C2M per mesh, tie (below)
==============================  ============  ========  ==========  ============================

**Derived files** (:data:`DERIVED_FILES`: ``decoded/``, ``reconstruction/``, ``points.ply``,
``evaluation.json``) are tied to their inputs by checksums; each tie is removed first and
written last, so a partly replaced set is stale:

* ``decoded/source.json``: ``capture_sha256`` (:func:`frames_checksum`: SHA-256 of
  ``capture.json`` and every frame file) and the decode ``options``. A checksum that no
  longer matches makes ``decoded/`` stale: :func:`load_decoded` returns None and it is
  decoded again.
* ``reconstruction/source.json``: ``capture_sha256``, ``use``, ``edge_max_step``,
  ``rig_sha256`` (of ``rig.json``'s content) and ``ply_sha256`` (of ``points.ply``). A
  ``points.ply`` it does not name, or frames it was not made from, are stale:
  :func:`check_points_current` refuses them (``virtus evaluate``).
* ``evaluation.json``: ``cloud_sha256``, the SHA-256 of the cloud it measured; a new
  ``points.ply`` of another cloud removes it.

:data:`SCAN_LAYOUT` (the capture's files and the derived ones) is what a job that owns a scan
directory claims (:func:`virtus.io.runs.claim_run`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.capture.capture import LAYOUT as CAPTURE_LAYOUT
from virtus.capture.capture import MANIFEST, Capture
from virtus.errors import InputError, VirtusError
from virtus.io.jsonio import write_json
from virtus.io.ply import write_ply
from virtus.io.runs import (
    atomic_write,
    atomic_write_files,
    config_digest,
    file_digest,
    write_json_atomic,
)
from virtus.io.safeio import load_npy, read_json

if TYPE_CHECKING:
    from virtus.geometry.devices import Rig
    from virtus.patterns import DecodeResult

__all__ = [
    "capture_dirs",
    "DECODED_DIR",
    "DECODED_FILES",
    "DECODED_SOURCE",
    "DECODE_SUMMARY",
    "DERIVED_FILES",
    "EVALUATION_JSON",
    "POINTS_PLY",
    "RECONSTRUCTION_DIR",
    "RECONSTRUCTION_FILES",
    "RECONSTRUCTION_SOURCE",
    "SCAN_LAYOUT",
    "check_points_current",
    "frames_checksum",
    "load_decoded",
    "save_decoded",
    "save_reconstruction",
]

DECODED_DIR = "decoded"
DECODED_FILES = ("phase_v", "phase_h", "proj_uv", "mask", "modulation", "flagged")
DECODE_SUMMARY = "summary.json"
DECODED_SOURCE = "source.json"
RECONSTRUCTION_DIR = "reconstruction"
POINTS_PLY = "points.ply"
EVALUATION_JSON = "evaluation.json"
#: ``reconstruction/`` files, and the one that ties them to their inputs (written last).
RECONSTRUCTION_FILES = ("points.npy", "depth.npy", "mask.npy", "rig.json")
RECONSTRUCTION_SOURCE = "source.json"
#: Every file the pipeline derives inside a capture directory (relative names).
DERIVED_FILES = (
    *(f"{DECODED_DIR}/{name}.npy" for name in DECODED_FILES),
    f"{DECODED_DIR}/{DECODE_SUMMARY}",
    f"{DECODED_DIR}/{DECODED_SOURCE}",
    *(f"{RECONSTRUCTION_DIR}/{name}" for name in RECONSTRUCTION_FILES),
    f"{RECONSTRUCTION_DIR}/{RECONSTRUCTION_SOURCE}",
    POINTS_PLY,
    EVALUATION_JSON,
)
#: Files of a scan directory: an earlier run's when found without a ``run.json``.
SCAN_LAYOUT = (*CAPTURE_LAYOUT, *DERIVED_FILES)


def frames_checksum(capture: Capture) -> str:
    """SHA-256 of a saved capture's manifest and frame files: what its derived files
    (``decoded/``) were computed from."""
    if capture.path is None or not capture.frame_files:
        raise VirtusError("frames_checksum: the capture has not been saved")
    digest = hashlib.sha256((capture.path / MANIFEST).read_bytes())
    for path in capture.frame_files:
        digest.update(path.read_bytes())
    return digest.hexdigest()


def save_decoded(directory: str | Path, decoded: DecodeResult, source: dict[str, Any]) -> Path:
    """Write ``decoded/`` (arrays, ``summary.json``) atomically and ``source.json`` last,
    which ties them to the capture's checksum and the decode options (it is removed first,
    so a partly replaced folder is stale); returns the folder."""
    folder = Path(directory) / DECODED_DIR
    (folder / DECODED_SOURCE).unlink(missing_ok=True)
    summary = decoded.summary()

    def write(staging: Path) -> None:
        for name in DECODED_FILES:
            np.save(staging / f"{name}.npy", getattr(decoded, name))
        write_json(staging / DECODE_SUMMARY, summary)

    names = [f"{name}.npy" for name in DECODED_FILES] + [DECODE_SUMMARY]
    atomic_write_files(folder, names, write)
    write_json_atomic(folder / DECODED_SOURCE, source)
    return folder


def load_decoded(
    capture_dir: str | Path, capture: Capture | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(proj_uv (H, W, 2), mask (H, W))`` from ``decoded/``, or None when there is none or
    it was decoded from other frames than the capture holds now (stale). Files that claim to
    be current but are malformed (truncated, pickled, wrong shape) raise
    :class:`~virtus.errors.InputError`."""
    folder = Path(capture_dir) / DECODED_DIR
    source_file = folder / DECODED_SOURCE
    if not source_file.is_file():
        return None
    capture = capture or Capture.load(capture_dir)
    source = read_json(source_file, "decoded/source.json", expect=dict)
    if source.get("capture_sha256") != frames_checksum(capture):
        return None
    cam = capture.rig.camera.intrinsics
    proj_uv = load_npy(
        folder / "proj_uv.npy",
        "decoded proj_uv",
        dtype=np.float64,
        shape=(cam.height, cam.width, 2),
    )
    mask = load_npy(folder / "mask.npy", "decoded mask", dtype=bool, shape=(cam.height, cam.width))
    return proj_uv, mask


def save_reconstruction(
    directory: str | Path,
    points: np.ndarray,
    normals: np.ndarray,
    rig: Rig,
    ply_path: str | Path | None = None,
    source: dict[str, Any] | None = None,
) -> Path:
    """Write a reconstruction's files (:meth:`virtus.reconstruct.Reconstruction.save`): the
    PLY and, for the directory's own ``points.ply``, ``reconstruction/``; returns the PLY
    path.

    ``points`` (H, W, 3) and ``normals`` (H, W, 3) are camera frame, metres, NaN where
    there is none; ``rig`` is the rig they were triangulated with. The PLY holds the points
    with a point and a normal. ``ply_path`` defaults to ``directory/points.ply``, which is
    written with ``reconstruction/*.npy`` as a pair: ``reconstruction/source.json``
    (``source`` plus the rig's and the PLY's SHA-256) is removed first and written last, so
    a partly replaced pair is stale, and a changed ``points.ply`` removes an
    ``evaluation.json`` of another cloud. Another ``ply_path`` gets only that PLY (the
    directory's pair is left as it is). Every file is written atomically.
    """
    root = Path(directory)
    default = root / POINTS_PLY
    target = Path(ply_path) if ply_path is not None else default
    mask = np.isfinite(points).all(axis=-1)
    ok = mask & np.isfinite(normals).all(axis=-1)

    def write_cloud(tmp: Path) -> None:
        write_ply(
            tmp,
            points[ok],
            normals=normals[ok],
            frame="camera",
            comments=(f"virtus reconstruction, {int(ok.sum())} points",),
        )

    if target.resolve() != default.resolve():
        return atomic_write(target, write_cloud)
    folder = root / RECONSTRUCTION_DIR
    tie = folder / RECONSTRUCTION_SOURCE
    tie.unlink(missing_ok=True)
    rig_dict = rig.to_dict()
    arrays = {"points": points, "depth": points[..., 2], "mask": mask}

    def write_arrays(staging: Path) -> None:
        for name, array in arrays.items():
            np.save(staging / f"{name}.npy", array)
        write_json(staging / "rig.json", rig_dict)

    atomic_write_files(folder, list(RECONSTRUCTION_FILES), write_arrays)
    atomic_write(target, write_cloud)
    digest = file_digest(target)
    _drop_stale_evaluation(root, digest)
    record = dict(source or {})
    record.update({"rig_sha256": config_digest(rig_dict), "ply_sha256": digest})
    write_json_atomic(tie, record)
    return target


def _drop_stale_evaluation(directory: Path, ply_digest: str) -> None:
    """Remove ``evaluation.json`` unless it measured the cloud of SHA-256 ``ply_digest``."""
    path = directory / EVALUATION_JSON
    if not path.is_file():
        return
    try:
        current = read_json(path, "evaluation", expect=dict, allow_nan=True).get("cloud_sha256")
    except InputError:
        current = None
    if current != ply_digest:
        path.unlink(missing_ok=True)


def check_points_current(capture: Capture, ply_path: str | Path) -> str:
    """SHA-256 (``"sha256:<hex>"``) of a capture directory's ``points.ply``, checked to be
    the latest reconstruction of the frames the directory holds now.

    Raises
    ------
    VirtusError : ``reconstruction/source.json`` is missing, names another cloud, or was
        made from other frames (stale): run ``virtus reconstruct DIR`` again.
    """
    directory = capture.path
    tie = Path(directory) / RECONSTRUCTION_DIR / RECONSTRUCTION_SOURCE  # type: ignore[arg-type]
    again = f"run `virtus reconstruct {directory}` again"
    if not tie.is_file():
        raise VirtusError(f"{ply_path} is not tied to this capture (no {tie}); {again}")
    source = read_json(tie, "reconstruction source", expect=dict)
    digest = file_digest(ply_path)
    if source.get("ply_sha256") != digest:
        raise VirtusError(f"{ply_path} is stale: it is not the cloud {tie} records; {again}")
    if source.get("capture_sha256") != frames_checksum(capture):
        raise VirtusError(
            f"{ply_path} is stale: it was reconstructed from other frames than {directory} "
            f"holds now; {again}"
        )
    return digest


def capture_dirs(paths: list[str | Path]) -> list[Path]:
    """Capture directories from paths that are capture directories (holding
    ``capture.json``) or folders of them (their capture sub-directories, sorted by name).

    Raises
    ------
    InputError : a path that is neither, or no capture at all.
    """
    from virtus.capture.capture import MANIFEST  # capture imports this module

    out: list[Path] = []
    for item in paths:
        path = Path(item)
        if (path / MANIFEST).is_file():
            out.append(path)
            continue
        found = (
            sorted(p for p in path.iterdir() if (p / MANIFEST).is_file()) if path.is_dir() else []
        )
        if not found:
            raise InputError(
                "captures",
                f"capture directories (holding {MANIFEST}) or folders of them",
                str(path),
            )
        out.extend(found)
    if not out:
        raise InputError("captures", "at least one capture directory", "none")
    return out
