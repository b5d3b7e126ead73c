"""Capture directories: the frames of one pose, the rig, the patterns, the scene, ground truth.

Layout (all lengths in metres, camera frame; projector coordinates in projector pixels)::

    DIR/capture.json        format, units, rig (DESIGN.md rig schema), pattern sequence
                            (PatternSequence.to_dict), scene, render settings (spp, lookup,
                            exposure, bit depth, Mitsuba variant), frame files, gt files
    DIR/frames/000.png ...  one 8- or 16-bit grey PNG per frame, in sequence order
    DIR/gt/depth.npy        (H, W) float64, z along the camera axis; NaN where no surface
    DIR/gt/points.npy       (H, W, 3) float64, camera frame; NaN where no surface
    DIR/gt/normals.npy      (H, W, 3) float64 unit normals toward the camera
    DIR/gt/proj_uv.npy      (H, W, 2) float64 projector pixels (u_p, v_p)
    DIR/gt/mask.npy         (H, W) bool: hit, lit by the projector, inside its image
    DIR/gt/mask_hit.npy, mask_shadow.npy, mask_outside.npy   (H, W) bool
    DIR/scene_assets/       in-memory textures of the scene, as .npy (if any)

PNG encoding dominates the cost of writing; frames are written with OpenCV at a low
compression level on a thread pool (OpenCV releases the GIL while encoding).
"""

from __future__ import annotations

import json
import os
import shutil
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus import __version__
from virtus.checks import positive_int
from virtus.devices import Rig
from virtus.errors import InputError, VirtusError
from virtus.jsonio import write_json
from virtus.render.groundtruth import ARRAY_NAMES

#: Format tag of ``capture.json``.
CAPTURE_FORMAT = "virtus.capture/1"
#: Ground-truth arrays written to ``gt/`` (``mask`` = hit & lit & inside): the names of
#: :meth:`virtus.render.GroundTruth.arrays` (importing virtus.render loads neither Mitsuba
#: nor Dr.Jit: render.backend imports them when a variant is chosen).
GT_NAMES = ARRAY_NAMES
#: Units recorded in ``capture.json``.
UNITS = {
    "length": "m",
    "frame": "camera frame (OpenCV: x right, y down, z forward)",
    "proj_uv": "projector px (pixel-centre convention)",
    "phase": "rad",
    "frames": "digital numbers",
}


@dataclass(frozen=True, eq=False)
class Capture:
    """A capture directory read back by :func:`load_capture`.

    Attributes
    ----------
    frames : (F, H, W) uint8 or uint16 frames in sequence order.
    rig : the rig that rendered them (camera frame = world frame of the capture).
    sequence : the pattern sequence (``virtus.patterns.PatternSequence``).
    scene : the scene (``virtus.scene.Scene``) or None when the file holds none.
    gt : ground-truth arrays by name (see :data:`GT_NAMES`); empty if not loaded/present.
    metadata : the rest of ``capture.json`` (units, render settings, versions).
    path : the directory.
    """

    frames: np.ndarray
    rig: Rig
    sequence: Any
    scene: Any
    gt: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    @property
    def ground_truth(self) -> Any:
        """The ground truth as a :class:`virtus.render.GroundTruth` (phase(), mask)."""
        from virtus.render.groundtruth import GroundTruth

        if not self.gt:
            raise VirtusError(f"{self.path}: this capture has no ground truth (gt/)")
        return GroundTruth.from_arrays(self.gt)


def _frame_name(index: int) -> str:
    return f"{index:03d}.png"


def _pool_size(workers: int | None) -> int:
    """Threads for PNG encoding/decoding: ``workers`` (>= 1), or the number of CPUs."""
    if workers is None:
        return os.cpu_count() or 1
    return positive_int("workers", workers)


def write_frames(
    directory: str | Path,
    frames: np.ndarray,
    *,
    compression: int = 1,
    workers: int | None = None,
) -> list[Path]:
    """Write (F, H, W) uint8/uint16 frames as ``000.png ...`` into ``directory``.

    Parameters
    ----------
    compression : PNG (zlib) level 0-9; 1 is several times faster than OpenCV's default 3
        for a few percent larger files.
    workers : encoding threads (default: the number of CPUs).
    """
    import cv2

    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype not in (np.uint8, np.uint16):
        raise InputError(
            "frames", "a (F, H, W) uint8 or uint16 array", f"{frames.dtype} {frames.shape}"
        )
    if not 0 <= compression <= 9:
        raise InputError("compression", "a PNG compression level 0-9", compression)
    threads = _pool_size(workers)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / _frame_name(i) for i in range(len(frames))]
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]

    def write(index: int) -> None:
        if not cv2.imwrite(str(paths[index]), frames[index], params):
            raise OSError(f"could not write {paths[index]}")

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(write, range(len(frames))))
    return paths


def read_frames(paths: list[Path], workers: int | None = None) -> np.ndarray:
    """Read grey PNG frames (unchanged bit depth) into a (F, H, W) array; ``workers``: decoding
    threads (default: the number of CPUs)."""
    import cv2

    def read(path: Path) -> np.ndarray:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise InputError("frame", "a readable PNG file", str(path))
        if image.ndim != 2:
            raise InputError(str(path), "a single-channel (grey) image", f"shape {image.shape}")
        return image

    with ThreadPoolExecutor(max_workers=_pool_size(workers)) as pool:
        images = list(pool.map(read, paths))
    shapes = {(image.shape, image.dtype) for image in images}
    if len(shapes) != 1:
        raise InputError("frames", "frames of one size and dtype", sorted(map(str, shapes)))
    return np.stack(images)


def save_capture(
    directory: str | Path,
    rendering: Any,
    *,
    rig: Rig,
    sequence: Any,
    scene: Any = None,
    overwrite: bool = False,
    compression: int = 1,
    workers: int | None = None,
    extra: dict[str, Any] | None = None,
) -> Path:
    """Write a capture directory (see the module docstring for the layout).

    Parameters
    ----------
    directory : target directory (created).
    rendering : a :class:`virtus.render.Rendering` (frames, gt and render settings).
    rig, sequence, scene : what was rendered; ``scene`` may be None.
    overwrite : replace an existing capture in ``directory`` (its frames/ and gt/ files are
        removed first); otherwise an existing ``capture.json`` raises :class:`VirtusError`.
    compression, workers : PNG settings, see :func:`write_frames`.
    extra : more JSON-ready metadata stored under ``"extra"``.

    Returns
    -------
    The path of ``capture.json``.
    """
    directory = Path(directory)
    manifest = directory / "capture.json"
    if manifest.exists():
        if not overwrite:
            raise VirtusError(
                f"{directory} already holds a capture "
                "(pass overwrite=True, or --overwrite on the command line)"
            )
        for sub in ("frames", "gt", "scene_assets"):
            shutil.rmtree(directory / sub, ignore_errors=True)
    directory.mkdir(parents=True, exist_ok=True)
    frames = rendering.frames
    paths = write_frames(directory / "frames", frames, compression=compression, workers=workers)
    gt_dir = directory / "gt"
    gt_dir.mkdir(exist_ok=True)
    arrays = rendering.gt.arrays()
    for name in GT_NAMES:
        np.save(gt_dir / f"{name}.npy", arrays[name])
    scene_data = None
    if scene is not None:
        scene_data = scene.to_dict(asset_dir=directory / "scene_assets", relative_to=directory)
    data = {
        "format": CAPTURE_FORMAT,
        "virtus_version": __version__,
        "units": UNITS,
        "rig": rig.to_dict(),
        "sequence": sequence.to_dict(),
        "scene": scene_data,
        "render": rendering.metadata(),
        "frames": {
            "count": int(frames.shape[0]),
            "height": int(frames.shape[1]),
            "width": int(frames.shape[2]),
            "dtype": str(frames.dtype),
            "files": [str(path.relative_to(directory)) for path in paths],
        },
        "gt": {name: f"gt/{name}.npy" for name in GT_NAMES},
    }
    if extra:
        data["extra"] = extra
    return write_json(manifest, data, indent=1)


def load_capture(directory: str | Path, *, load_gt: bool = True) -> Capture:
    """Read a capture directory written by :func:`save_capture`.

    Parameters
    ----------
    directory : the capture directory (holding ``capture.json``).
    load_gt : read the ``gt/`` arrays (they are large: ~70 MB at 960 x 960).
    """
    from virtus.patterns import PatternSequence
    from virtus.scene import Scene

    directory = Path(directory)
    manifest = directory / "capture.json"
    if not manifest.is_file():
        raise InputError("capture", "a directory with capture.json", str(directory))
    try:
        data = json.loads(manifest.read_text())
    except json.JSONDecodeError as error:
        raise InputError(str(manifest), "valid JSON", error.msg) from None
    if data.get("format") != CAPTURE_FORMAT:
        raise InputError(f"{manifest} format", CAPTURE_FORMAT, data.get("format"))
    rig = Rig.from_dict(data["rig"])
    sequence = PatternSequence.from_dict(data["sequence"])
    scene = Scene.from_dict(data["scene"], base_dir=directory) if data.get("scene") else None
    files = [directory / name for name in data["frames"]["files"]]
    if len(files) != len(sequence):
        raise InputError(f"{manifest} frames", f"{len(sequence)} files (one per frame)", len(files))
    frames = read_frames(files)
    gt: dict[str, np.ndarray] = {}
    if load_gt:
        for name, relative in data.get("gt", {}).items():
            path = directory / relative
            if not path.is_file():
                raise InputError("capture gt", "the files listed in capture.json", str(path))
            gt[name] = np.load(path)
    metadata = {
        key: value for key, value in data.items() if key not in ("rig", "sequence", "scene")
    }
    return Capture(frames, rig, sequence, scene, gt, metadata, directory)
