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

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.devices import Rig
from virtus.errors import InputError, VirtusError
from virtus.pipeline import layout
from virtus.ply import write_ply
from virtus.reconstruct import (
    Use,
    depth_edge_mask,
    normals_from_points,
    points_from_decoded,
    valid_points,
)

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

#: Depth-discontinuity filter default, in pixel footprints (see ``depth_edge_mask``).
EDGE_MAX_STEP = 20.0


@dataclass(frozen=True)
class ScanSettings:
    """How a scene is captured and reconstructed (written to ``capture.json`` / metrics)."""

    spp: int = 4
    """Renderer supersamples per pixel (a perfect square)."""
    lookup: str = "nearest"
    """Pattern lookup: ``"nearest"`` (DMD pixels, as in calibration) or ``"bilinear"``."""
    bit_depth: int = 8
    """Camera bit depth (8 or 16)."""
    use: Use = "uv"
    """Projector coordinates used by triangulation: ``"uv"``, ``"u"`` or ``"v"``."""
    edge_max_step: float | None = EDGE_MAX_STEP
    """Depth-discontinuity filter in pixel footprints; None keeps every decoded pixel."""
    seed: int = 0
    """Seed of the renderer's sensor stage."""

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


def load_rig_file(path: str | Path, like: Rig | None = None) -> Rig:
    """Read a rig from a calibration file.

    * ``.json``: the rig schema of DESIGN.md section 3 (``calibration.json`` of ``virtus
      calibrate``, ``capture.json``, ``virtus rig info --json``); extra keys are ignored, and a
      ``rig`` key holding the schema is accepted too.
    * ``.yaml`` / ``.yml``: the OpenCV YAML that ``virtus calibrate`` writes.
    * a directory: the paper code's text files (``paper_txt/`` of ``virtus calibrate``), which
      carry no image sizes: they are taken from ``like`` (e.g. the capture's rig), else the
      paper's (camera 960 x 960, projector 912 x 1140).
    """
    source = Path(path)
    if source.is_dir():
        from virtus.calib.io import load_paper_txt

        if like is None:
            return load_paper_txt(source)
        cam, proj = like.camera.intrinsics, like.projector.intrinsics
        return load_paper_txt(source, (cam.width, cam.height), (proj.width, proj.height))
    if not source.is_file():
        raise InputError("calibration", "an existing calibration file or directory", str(source))
    suffix = source.suffix.lower()
    if suffix in (".yaml", ".yml"):
        from virtus.calib.io import load_opencv_yaml

        return load_opencv_yaml(source)
    if suffix != ".json":
        raise InputError(
            "calibration",
            "a .json (rig schema) or OpenCV .yaml file, or a paper_txt/ folder",
            str(source),
        )
    try:
        data = json.loads(source.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise InputError(str(source), "a JSON file", f"invalid JSON ({error})") from None
    if isinstance(data, dict) and "camera" not in data and isinstance(data.get("rig"), dict):
        data = data["rig"]
    return Rig.from_dict(data)


# --- capture directories -------------------------------------------------------------------


def decode_capture(capture_dir: str | Path, *, save: bool = True) -> Any:
    """Decode a capture directory's frames into projector coordinates.

    Parameters
    ----------
    capture_dir : directory written by ``virtus capture`` / :func:`scan`.
    save : write ``decoded/`` (phase_v, phase_h, proj_uv, mask, modulation ``.npy``).

    Returns
    -------
    The sequence's ``DecodeResult`` (``proj_uv`` (H, W, 2), ``phase_v``, ``phase_h``,
    ``mask``, ...).
    """
    from virtus.capture import load_capture

    capture = load_capture(capture_dir, load_gt=False)
    decoded = capture.sequence.decode(capture.frames)
    if save:
        folder = Path(capture_dir) / layout.DECODED_DIR
        folder.mkdir(parents=True, exist_ok=True)
        for name in layout.DECODED_FILES:
            np.save(folder / f"{name}.npy", getattr(decoded, name))
    return decoded


def load_decoded(capture_dir: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """``(proj_uv (H, W, 2), mask (H, W))`` from ``decoded/``, or None if not decoded yet."""
    folder = Path(capture_dir) / layout.DECODED_DIR
    if not (folder / "proj_uv.npy").is_file() or not (folder / "mask.npy").is_file():
        return None
    return np.load(folder / "proj_uv.npy"), np.load(folder / "mask.npy")


def reconstruct_capture(
    capture_dir: str | Path,
    calibration: str | Path | Rig | None = None,
    out_ply: str | Path | None = None,
    *,
    use: Use = "uv",
    edge_max_step: float | None = EDGE_MAX_STEP,
) -> Reconstruction:
    """Triangulate a capture directory (decoding it first if needed).

    Parameters
    ----------
    capture_dir : capture or scan directory.
    calibration : a calibration file (see :func:`load_rig_file`) or a rig; None uses the rig
        in ``capture.json`` (the true rig of a virtual capture).
    out_ply : PLY path; default ``capture_dir/points.ply``.
    use, edge_max_step : see :func:`reconstruct`.
    """
    decoded = load_decoded(capture_dir)
    if decoded is None:
        result = decode_capture(capture_dir)
        decoded = (result.proj_uv, result.mask)
    if isinstance(calibration, Rig):
        rig = calibration
    else:
        from virtus.capture import load_capture

        capture_rig = load_capture(capture_dir, load_gt=False).rig
        rig = capture_rig if calibration is None else load_rig_file(calibration, capture_rig)
    proj_uv, mask = decoded
    cam = rig.camera.intrinsics
    if proj_uv.shape[:2] != (cam.height, cam.width):
        raise VirtusError(
            f"calibration: camera is {cam.width}x{cam.height} px but the capture is "
            f"{proj_uv.shape[1]}x{proj_uv.shape[0]} px"
        )
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
    """

    directory: Path
    reconstruction: Reconstruction
    decoded: Any
    ply_path: Path
    timing_s: dict[str, float] = field(default_factory=dict)


def scan(
    scene: Any,
    out_dir: str | Path,
    *,
    rig: Rig | None = None,
    calibration: str | Path | Rig | None = None,
    settings: ScanSettings | None = None,
    overwrite: bool = False,
) -> ScanResult:
    """Capture ``scene`` with the virtual sensor, then decode and reconstruct it.

    Parameters
    ----------
    scene : a :class:`virtus.scene.Scene`.
    out_dir : scan directory to write (created).
    rig : the true rig that renders the frames (default: the paper's rig).
    calibration : rig or calibration file used for triangulation; None uses ``rig``
        (reconstruction with the true parameters).
    settings : capture and reconstruction settings.
    overwrite : replace an existing capture in ``out_dir``.
    """
    import time

    from virtus.capture import save_capture
    from virtus.devices import default_rig
    from virtus.patterns import default_sequence
    from virtus.render import render

    settings = settings or ScanSettings()
    true_rig = rig or default_rig()
    # Read the calibration before rendering: a bad file must not leave a capture behind.
    if calibration is None:
        used = true_rig
    elif isinstance(calibration, Rig):
        used = calibration
    else:
        used = load_rig_file(calibration)
    proj = true_rig.projector.intrinsics
    sequence = default_sequence(proj.width, proj.height)
    directory = Path(out_dir)
    timing: dict[str, float] = {}

    start = time.perf_counter()
    rendering = render(
        true_rig,
        scene,
        sequence,
        spp=settings.spp,
        lookup=settings.lookup,  # type: ignore[arg-type]
        bit_depth=settings.bit_depth,
        rng=settings.seed,
    )
    extra = {"scan": settings.to_dict()}
    save_capture(
        directory,
        rendering,
        rig=true_rig,
        sequence=sequence,
        scene=scene,
        overwrite=overwrite,
        extra=extra,
    )
    timing["render_s"] = time.perf_counter() - start

    start = time.perf_counter()
    decoded = sequence.decode(rendering.frames)
    folder = directory / layout.DECODED_DIR
    folder.mkdir(parents=True, exist_ok=True)
    for name in layout.DECODED_FILES:
        np.save(folder / f"{name}.npy", getattr(decoded, name))
    timing["decode_s"] = time.perf_counter() - start

    start = time.perf_counter()
    recon = reconstruct(
        used, decoded.proj_uv, decoded.mask, use=settings.use, edge_max_step=settings.edge_max_step
    )
    ply = recon.save(directory)
    timing["reconstruct_s"] = time.perf_counter() - start
    return ScanResult(directory, recon, decoded, ply, timing)
