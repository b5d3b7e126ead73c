"""Scanning: capture -> decode -> reconstruct, on a capture directory or a scene.

* :func:`decode_capture` decodes the frames of a capture directory into projector
  coordinates and writes ``decoded/`` (see :mod:`virtus.pipeline.layout`).
* :func:`reconstruct_capture` triangulates them with the capture's rig or a calibration
  file and writes the point map and ``points.ply``.
* :func:`scan` renders a scene with the true rig (the virtual sensor), saves the capture,
  then decodes and reconstructs it -- with calibrated parameters when a calibration is given.

Points are in the camera frame, metres. Reconstruction drops pixels next to depth
discontinuities (mixed pixels at silhouettes; :func:`virtus.reconstruct.depth_edge_mask`).
"""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.capture import MANIFEST, Capture
from virtus.devices import Rig
from virtus.errors import VirtusError
from virtus.jsonio import write_json
from virtus.patterns import DecodeResult
from virtus.pipeline import layout
from virtus.ply import write_ply
from virtus.reconstruct import (
    Use,
    depth_edge_mask,
    normals_from_points,
    points_from_decoded,
    valid_points,
)
from virtus.safeio import load_npy, read_json
from virtus.scanner import Scanner
from virtus.transforms import Pose

__all__ = [
    "Reconstruction",
    "ScanResult",
    "ScanSettings",
    "decode_capture",
    "load_decoded",
    "load_rig_file",
    "reconstruct",
    "reconstruct_capture",
    "scan",
]

#: Default fringe modulation threshold of decoding, a fraction of full scale.
DEFAULT_MIN_MODULATION = 0.02
#: Depth-discontinuity filter default, in pixel footprints (see ``depth_edge_mask``).
EDGE_MAX_STEP = 20.0


@dataclass(frozen=True)
class ScanSettings:
    """How a capture is reconstructed, and the seed of its rendering (how it is rendered is
    the :class:`~virtus.scanner.Scanner`'s business)."""

    use: Use = "uv"
    """Projector coordinates used by triangulation: ``"uv"``, ``"u"`` or ``"v"``."""
    edge_max_step: float | None = EDGE_MAX_STEP
    """Depth-discontinuity filter in pixel footprints; None keeps every decoded pixel."""
    seed: int = 0
    """Seed of the capture's counter-based noise streams (>= 0)."""

    def to_dict(self) -> dict[str, Any]:
        """Every setting by name (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """A triangulated camera image.

    Attributes
    ----------
    points : (H, W, 3) float64, camera frame, metres; NaN where there is no point.
    edges : (H, W) bool, pixels dropped by the depth-discontinuity filter.
    rig : the rig the points were triangulated with.
    """

    points: np.ndarray
    edges: np.ndarray
    rig: Rig

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool, pixels with a point."""
        return np.isfinite(self.points).all(axis=-1)

    @property
    def depth(self) -> np.ndarray:
        """(H, W) float64 camera-frame z, metres, NaN where there is no point."""
        return self.points[..., 2]

    def cloud(self) -> np.ndarray:
        """(N, 3) float64 valid points in row-major pixel order, camera frame, metres."""
        return valid_points(self.points)[0]

    def save(self, directory: str | Path, ply_path: str | Path | None = None) -> Path:
        """Write ``reconstruction/*.npy`` under ``directory`` and the PLY; returns the PLY path.

        ``ply_path`` defaults to ``directory/points.ply``.
        """
        root = Path(directory)
        folder = root / layout.RECONSTRUCTION_DIR
        folder.mkdir(parents=True, exist_ok=True)
        np.save(folder / "points.npy", self.points)
        np.save(folder / "depth.npy", self.depth)
        np.save(folder / "mask.npy", self.mask)
        self.rig.save_json(folder / "rig.json")
        normals = normals_from_points(self.points)
        ok = self.mask & np.isfinite(normals).all(axis=-1)
        target = Path(ply_path) if ply_path is not None else root / layout.POINTS_PLY
        return write_ply(
            target,
            self.points[ok],
            normals=normals[ok],
            frame="camera",
            comments=(f"virtus reconstruction, {int(ok.sum())} points",),
        )


def reconstruct(
    rig: Rig,
    proj_uv: object,
    mask: object | None = None,
    *,
    use: Use = "uv",
    edge_max_step: float | None = EDGE_MAX_STEP,
) -> Reconstruction:
    """Triangulate a decoded image and drop depth-discontinuity pixels.

    Parameters
    ----------
    rig : rig to triangulate with (true or calibrated).
    proj_uv : (H, W, 2) float, decoded projector coordinates, NaN where invalid.
    mask : (H, W) bool, optional decode mask.
    use : see :func:`virtus.reconstruct.triangulate`.
    edge_max_step : see :func:`virtus.reconstruct.depth_edge_mask`; None disables the filter.
    """
    points = points_from_decoded(rig, proj_uv, mask, use=use)
    edges = np.zeros(points.shape[:2], dtype=bool)
    if edge_max_step is not None:
        edges = depth_edge_mask(points, rig.camera.intrinsics.fx, edge_max_step)
        points[edges] = np.nan
    return Reconstruction(points, edges, rig)


def load_rig_file(path: str | Path, like: Rig | None = None, *, units: str | None = None) -> Rig:
    """Read a rig from any calibration file :func:`virtus.calib.io.load_calibration` reads;
    image sizes a file lacks (the paper code's text files) are taken from ``like`` (e.g. the
    capture's rig). ``units``: the length unit of a file that states none."""
    from virtus.calib.io import load_calibration

    sizes = {}
    if like is not None:
        cam, proj = like.camera.intrinsics, like.projector.intrinsics
        sizes = {
            "camera_size": (cam.width, cam.height),
            "projector_size": (proj.width, proj.height),
        }
    return load_calibration(path, units=units, **sizes)


# --- capture directories -------------------------------------------------------------------


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
    """Write ``decoded/`` (arrays, ``summary.json``) and ``source.json`` last, which ties
    them to the capture's checksum and the decode options; returns the folder."""
    folder = Path(directory) / layout.DECODED_DIR
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    for name in layout.DECODED_FILES:
        np.save(folder / f"{name}.npy", getattr(decoded, name))
    write_json(folder / layout.DECODE_SUMMARY, decoded.summary())
    write_json(folder / layout.DECODED_SOURCE, source)
    return folder


def decode_capture(
    capture_dir: str | Path,
    *,
    save: bool = True,
    min_modulation: float = DEFAULT_MIN_MODULATION,
    saturation_level: float | None = None,
    repair: bool = False,
) -> DecodeResult:
    """Decode a capture directory's frames into projector coordinates.

    Parameters
    ----------
    capture_dir : a capture directory (``virtus capture``, ``virtus import``, a scan).
    save : write ``decoded/`` (see :mod:`virtus.pipeline.layout`) with ``summary.json``
        and ``source.json`` (the capture's checksum and these options).
    min_modulation : fringe modulation threshold, a fraction of the capture's full scale.
    saturation_level : digital number at and above which a pixel is saturated (invalid);
        None disables the check.
    repair : repair pixels whose fringe order disagrees with the wrapped phase.

    Returns
    -------
    The sequence's ``DecodeResult`` (``proj_uv`` (H, W, 2), ``phase_v``, ``phase_h``,
    ``mask``, ``flagged``, ``summary()``, ...).
    """
    capture = Capture.load(capture_dir)
    options = {
        "min_modulation": min_modulation,
        "saturation_level": saturation_level,
        "repair": repair,
    }
    decoded = capture.decode(**options)
    if save:
        source = {"capture_sha256": frames_checksum(capture), "options": options}
        save_decoded(capture_dir, decoded, source)
    return decoded


def load_decoded(capture_dir: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """``(proj_uv (H, W, 2), mask (H, W))`` from ``decoded/``, or None when there is none or
    it was decoded from other frames than the capture holds now (stale)."""
    folder = Path(capture_dir) / layout.DECODED_DIR
    source_file = folder / layout.DECODED_SOURCE
    if not source_file.is_file():
        return None
    source = read_json(source_file, "decoded/source.json", expect=dict)
    if source.get("capture_sha256") != frames_checksum(Capture.load(capture_dir)):
        return None
    return (
        load_npy(folder / "proj_uv.npy", "decoded proj_uv"),
        load_npy(folder / "mask.npy", "decoded mask"),
    )


def reconstruct_capture(
    capture_dir: str | Path,
    calibration: str | Path | Rig | None = None,
    out_ply: str | Path | None = None,
    *,
    use: Use = "uv",
    edge_max_step: float | None = EDGE_MAX_STEP,
    units: str | None = None,
) -> Reconstruction:
    """Triangulate a capture directory (decoding it first if needed or stale).

    Parameters
    ----------
    capture_dir : capture or scan directory.
    calibration : a calibration file (see :func:`virtus.calib.io.load_calibration`) or a
        rig; None uses the rig in ``capture.json`` (the true rig of a virtual capture).
    out_ply : PLY path; default ``capture_dir/points.ply``.
    use, edge_max_step : see :func:`reconstruct`.
    units : length unit of a calibration file that states none (``"mm"`` or ``"m"``).
    """
    capture = Capture.load(capture_dir)
    if isinstance(calibration, Rig):
        rig = calibration
    elif calibration is None:
        rig = capture.rig
    else:
        rig = load_rig_file(calibration, capture.rig, units=units)
    cam = rig.camera.intrinsics
    expected = (capture.rig.camera.height, capture.rig.camera.width)
    if expected != (cam.height, cam.width):
        raise VirtusError(
            f"calibration: camera is {cam.width}x{cam.height} px but the capture is "
            f"{expected[1]}x{expected[0]} px"
        )
    decoded = load_decoded(capture_dir)
    if decoded is None:
        result = decode_capture(capture_dir)
        decoded = (result.proj_uv, result.mask)
    proj_uv, mask = decoded
    recon = reconstruct(rig, proj_uv, mask, use=use, edge_max_step=edge_max_step)
    recon.save(capture_dir, out_ply)
    return recon


@dataclass(frozen=True, eq=False)
class ScanResult:
    """Outcome of :func:`scan`.

    Attributes
    ----------
    directory : the scan directory (capture + decoded + reconstruction + PLY).
    reconstruction : the triangulated image.
    decoded : the sequence's DecodeResult.
    ply_path : the written point cloud.
    timing_s : seconds per step (render, decode, reconstruct).
    capture : the rendered capture (frames, ground truth).
    """

    directory: Path
    reconstruction: Reconstruction
    decoded: Any
    ply_path: Path
    timing_s: dict[str, float] = field(default_factory=dict)
    capture: Capture | None = None


def scan(
    scene: Any,
    out_dir: str | Path,
    *,
    scanner: Scanner | None = None,
    calibration: str | Path | Rig | None = None,
    settings: ScanSettings | None = None,
    overwrite: bool = False,
    cam2world: Pose | None = None,
) -> ScanResult:
    """Capture ``scene`` with the virtual scanner, then decode and reconstruct it.

    Parameters
    ----------
    scene : a :class:`virtus.scene.Scene`.
    out_dir : scan directory to write (created).
    scanner : the virtual scanner (its rig is the truth that renders the frames; default:
        the paper's system).
    calibration : rig or calibration file used for triangulation; None uses the scanner's
        rig (reconstruction with the true parameters).
    settings : reconstruction settings and the capture's seed.
    overwrite : replace an existing capture in ``out_dir``.
    cam2world : camera pose in the scene's world frame (default identity).
    """
    import time

    settings = settings or ScanSettings()
    scanner = scanner or Scanner()
    # Read the calibration before rendering: a bad file must not leave a capture behind.
    if calibration is None:
        used = scanner.rig
    elif isinstance(calibration, Rig):
        used = calibration
    else:
        used = load_rig_file(calibration, scanner.rig)
    directory = Path(out_dir)
    timing: dict[str, float] = {}

    start = time.perf_counter()
    capture = scanner.capture(scene, cam2world=cam2world, rng=settings.seed)
    capture.save(directory, overwrite=overwrite)
    for stale in (layout.RECONSTRUCTION_DIR, layout.DECODED_DIR):
        shutil.rmtree(directory / stale, ignore_errors=True)
    for stale in (layout.POINTS_PLY, layout.EVALUATION_JSON):
        (directory / stale).unlink(missing_ok=True)
    timing["render_s"] = time.perf_counter() - start

    start = time.perf_counter()
    decoded = capture.decode()
    source = {
        "capture_sha256": frames_checksum(capture),
        "options": {"min_modulation": DEFAULT_MIN_MODULATION, "saturation_level": None,
                    "repair": False},
    }  # fmt: skip
    save_decoded(directory, decoded, source)
    timing["decode_s"] = time.perf_counter() - start

    start = time.perf_counter()
    recon = reconstruct(
        used, decoded.proj_uv, decoded.mask, use=settings.use, edge_max_step=settings.edge_max_step
    )
    ply = recon.save(directory)
    timing["reconstruct_s"] = time.perf_counter() - start
    return ScanResult(directory, recon, decoded, ply, timing, capture)
