"""The capture: the frames of one pose and everything needed to decode and triangulate them.

A :class:`Capture` is the project's one seam: the renderer makes them
(:meth:`virtus.scanner.Scanner.capture`), :func:`import_capture` makes them from a real
bench's images, and everything downstream (decoding, reconstruction, calibration,
evaluation) only reads them. This module never imports the renderer.

On-disk layout, format ``virtus.capture/2`` (JSON Schema: ``schemas/capture.schema.json``;
lengths in metres, camera frame; projector coordinates in projector pixels)::

    DIR/capture.json        format, units, rig (rig schema), cam2world, sequence
                            (PatternSequence.to_dict), sensor, seed, bit depth, render
                            settings (rendered captures), scene, frame files, gt files,
                            provenance (virtus version, command, source); optional
                            calibration_source (imports: where each rig parameter came
                            from, "calibrated": false for a placeholder rig) and
                            camera_pixel_size_m (imports given the pixel pitch)
    DIR/frames/000.png ...  one 8- or 16-bit grey PNG per frame, in sequence order
                            (10- and 12-bit frames are stored in 16-bit PNGs, unscaled)
    DIR/gt/depth.npy        (H, W) float64, z along the camera axis; NaN where no surface
    DIR/gt/points.npy       (H, W, 3) float64, camera frame; NaN where no surface
    DIR/gt/normals.npy      (H, W, 3) float64 unit normals toward the camera
    DIR/gt/proj_uv.npy      (H, W, 2) float64 projector pixels (u_p, v_p)
    DIR/gt/mask.npy         (H, W) bool: hit, lit by the projector, inside its image
    DIR/gt/mask_hit.npy, mask_shadow.npy, mask_outside.npy   (H, W) bool
    DIR/gt/mask_multibounce.npy (H, W) bool: indirect light outweighs direct light
    DIR/gt/mask_saturated.npy   (H, W) bool: full scale (ADC or full well) in some frame
    DIR/scene_assets/       in-memory textures of the scene, as .npy (if any)

Format ``virtus.capture/1`` (virtus 0.1) is read too: it has no ``cam2world`` (identity),
no sensor and no seed.

Writing is safe against failures: frames and ground truth are each written through a
staging folder and renamed into place (:func:`virtus.io.runs.atomic_write_files`), the
manifest last; an error (disk full, permission denied) removes what the call wrote and
names the path. Jobs that write a capture into an output directory own it through
:func:`virtus.io.runs.claim_run` (:data:`LAYOUT`, :meth:`Capture.file_names`).

Memory: a capture holds every frame at once, and rendering holds the trace's taps; both are
estimated by :func:`capture_bytes` and refused above :data:`MAX_CAPTURE_BYTES` *before*
anything is rendered or read (:func:`check_capture_bytes`).
"""

from __future__ import annotations

import functools
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus import __version__
from virtus.capture.groundtruth import ARRAY_NAMES, GroundTruth
from virtus.errors import InputError, RunConflict, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.images import frame_name, list_images, read_image, read_images, write_frames
from virtus.io.jsonio import write_json
from virtus.io.runs import atomic_write_files
from virtus.io.safeio import is_file, load_npy, read_json
from virtus.patterns import DecodeResult, PatternSequence
from virtus.sensor.camera import BIT_DEPTHS, Sensor

#: Format tag written to ``capture.json``.
CAPTURE_FORMAT = "virtus.capture/2"
#: Format tags read.
READABLE_FORMATS = ("virtus.capture/1", CAPTURE_FORMAT)
#: The capture's manifest file.
MANIFEST = "capture.json"
#: Units recorded in ``capture.json``.
UNITS = {
    "length": "m",
    "frame": "camera frame (OpenCV: x right, y down, z forward)",
    "proj_uv": "projector px (pixel-centre convention)",
    "phase": "rad",
    "frames": "digital numbers",
}
#: Keys of ``capture.json`` (format 2); others are refused.
_KEYS = (
    "format", "virtus_version", "units", "rig", "cam2world", "sequence", "sensor", "seed",
    "bit_depth", "render", "scene", "frames", "gt", "provenance", "extra",
    "calibration_source", "camera_pixel_size_m",
)  # fmt: skip
#: Sub-folders a capture owns (removed when it is overwritten).
_OWNED = ("frames", "gt", "scene_assets")
#: Glob patterns of every file a capture writes (for :func:`virtus.io.runs.claim_run`).
LAYOUT = (MANIFEST, "frames/*.png", "gt/*.npy", "scene_assets/*")
#: Largest memory (bytes) one capture may need: its frames plus the renderer's taps
#: (:func:`capture_bytes`). Twice a 960 x 960 capture of the paper at 16 spp with 8
#: bounces is ~1 GiB; 8 GiB leaves room for the renderer's other buffers on a 16 GiB laptop.
MAX_CAPTURE_BYTES = 8 * 2**30
#: Bytes per trace tap (float32 weight, float32 u_p and v_p), see :mod:`virtus.render.tracing`.
TAP_BYTES = 12


def capture_bytes(
    n_frames: int, width: int, height: int, bytes_per_value: int, taps_per_pixel: int = 0
) -> int:
    """Memory (bytes) a capture needs: ``frames x pixels x bytes + pixels x taps x 12``.

    Parameters
    ----------
    n_frames : frames in the sequence.
    width, height : camera image size, px.
    bytes_per_value : bytes per digital number (1 for 8-bit frames, 2 for 10-16 bits).
    taps_per_pixel : trace taps per camera pixel (``spp x bounces x aperture samples``;
        0 for imported captures, which are not rendered).
    """
    pixels = int(width) * int(height)
    return int(n_frames) * pixels * int(bytes_per_value) + pixels * int(taps_per_pixel) * TAP_BYTES


def check_capture_bytes(
    n_frames: int,
    width: int,
    height: int,
    bytes_per_value: int,
    taps_per_pixel: int = 0,
    *,
    what: str = "capture",
    budget: int = MAX_CAPTURE_BYTES,
) -> int:
    """:func:`capture_bytes`, or :class:`InputError` above ``budget`` naming what to lower.

    ``what`` names the options the sizes come from in the message (e.g. ``"--spp, camera
    size"``).
    """
    need = capture_bytes(n_frames, width, height, bytes_per_value, taps_per_pixel)
    if need > budget:
        taps = f" + {taps_per_pixel} trace taps per pixel" if taps_per_pixel else ""
        raise InputError(
            f"{what} memory",
            f"at most {budget / 2**30:g} GiB (frames x pixels x bytes + taps x {TAP_BYTES} bytes)",
            f"{need / 2**30:.1f} GiB for {n_frames} frames of {width}x{height} px at "
            f"{bytes_per_value} byte(s){taps}",
        )
    return need


def bit_depth_of(frames: np.ndarray) -> int:
    """The smallest ADC bit depth (8, 10, 12, 16) that holds ``frames`` (uint8 -> 8)."""
    if frames.dtype == np.uint8:
        return 8
    if frames.dtype != np.uint16:
        raise InputError("frames", "uint8 or uint16 digital numbers", frames.dtype)
    peak = int(frames.max()) if frames.size else 0
    return next(bits for bits in BIT_DEPTHS[1:] if peak < 1 << bits)


def _provenance(source: str, command: list[str] | None) -> dict[str, Any]:
    # No time stamp: the same command and seed must give byte-identical files.
    return {
        "virtus_version": __version__,
        "source": source,
        "command": list(sys.argv) if command is None else list(command),
    }


@dataclass(frozen=True, eq=False)
class Capture:
    """The frames of one pose of a camera-projector rig, and how to read them.

    Attributes
    ----------
    sequence : the projected pattern sequence (frame ``i`` of ``frames`` shows frame ``i``).
    rig : the rig that took the frames (for a rendered capture: the true rig).
    frames : (F, H, W) uint8 or uint16 digital numbers in sequence order; read from disk on
        first access for a loaded capture.
    cam2world : pose of the camera in the scene's world frame (identity when unknown).
    bit_depth : ADC bits of the digital numbers (8, 10, 12 or 16); full scale
        ``2**bit_depth - 1``.
    sensor : the camera model that rendered the frames; None for imported captures.
    seed : seed of the sensor's noise streams; None for imported captures.
    scene : the rendered scene (``virtus.scene.model.Scene``), if known.
    render : how the frames were rendered (spp, projector pixel model, exposure, variant);
        empty for imported captures.
    provenance : virtus version, source (``"rendered"`` or ``"imported"``), command line.
    path : the directory it was loaded from or saved to, if any.
    calibration_source : for an imported capture, where each parameter of ``rig`` came from
        (:meth:`virtus.calib.sources.CalibrationSources.to_dict`); ``"calibrated": False``
        marks a placeholder rig (imported without a calibration: decode, calibrate from it,
        never triangulate with it). None: the rig is the true or given one.
    camera_pixel_size_m : the camera's pixel pitch, metres, when given (for a digital twin).
    """

    sequence: PatternSequence
    rig: Rig
    frame_data: np.ndarray | None = field(default=None, repr=False)
    cam2world: Pose = field(default_factory=Pose.identity)
    bit_depth: int | None = None
    sensor: Sensor | None = None
    seed: int | None = None
    scene: Any = None
    gt_data: GroundTruth | None = field(default=None, repr=False)
    render: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    frame_files: tuple[Path, ...] = field(default=(), repr=False)
    gt_files: dict[str, Path] = field(default_factory=dict, repr=False)
    calibration_source: dict[str, Any] | None = None
    camera_pixel_size_m: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.sequence, PatternSequence):
            raise InputError("sequence", "a PatternSequence", type(self.sequence).__name__)
        if not isinstance(self.rig, Rig):
            raise InputError("rig", "a Rig", type(self.rig).__name__)
        if self.frame_data is None and not self.frame_files:
            raise InputError("frames", "frames or frame files", None)
        count = len(self.frame_files) if self.frame_data is None else len(self.frame_data)
        if count != len(self.sequence):
            raise InputError(
                "frames", f"{len(self.sequence)} frames (one per sequence frame)", count
            )
        if self.frame_data is not None:
            self._check_frames(self.frame_data)
            if self.bit_depth is None:
                object.__setattr__(self, "bit_depth", bit_depth_of(self.frame_data))
        if self.bit_depth not in BIT_DEPTHS:
            raise InputError("bit_depth", f"one of {BIT_DEPTHS}", self.bit_depth)
        if self.calibration_source is not None and not isinstance(self.calibration_source, dict):
            raise InputError("calibration_source", "an object or None", self.calibration_source)
        pitch = self.camera_pixel_size_m
        if pitch is not None and (
            isinstance(pitch, bool)
            or not isinstance(pitch, int | float)
            or not 0 < pitch < float("inf")
        ):
            raise InputError("camera_pixel_size_m", "a positive number of metres or None", pitch)

    @property
    def calibrated(self) -> bool:
        """False for a capture imported without a calibration (its rig is a placeholder)."""
        return (self.calibration_source or {}).get("calibrated", True) is not False

    def _check_frames(self, frames: np.ndarray) -> None:
        if frames.ndim != 3 or frames.dtype not in (np.uint8, np.uint16):
            raise InputError(
                "frames",
                "(F, H, W) uint8 or uint16 digital numbers",
                f"{frames.dtype} {frames.shape}",
            )
        cam = self.rig.camera.intrinsics
        if frames.shape[1:] != (cam.height, cam.width):
            raise InputError(
                "frames",
                f"{cam.width}x{cam.height} px images (the rig's camera)",
                f"{frames.shape[2]}x{frames.shape[1]} px",
            )

    # --- data ---------------------------------------------------------------------------

    @functools.cached_property
    def frames(self) -> np.ndarray:
        """(F, H, W) uint8 or uint16 frames in sequence order (read on first access)."""
        if self.frame_data is not None:
            return self.frame_data
        frames = read_images(self.frame_files)
        self._check_frames(frames)
        if self.bit_depth is not None and int(frames.max()) > (1 << self.bit_depth) - 1:
            raise InputError("frames", f"values <= {(1 << self.bit_depth) - 1}", int(frames.max()))
        return frames

    @property
    def full_scale(self) -> int:
        """Largest digital number of the frames, ``2**bit_depth - 1``."""
        return (1 << int(self.bit_depth)) - 1  # type: ignore[arg-type]

    @property
    def has_ground_truth(self) -> bool:
        """True when the capture carries ground truth (rendered captures)."""
        return self.gt_data is not None or bool(self.gt_files)

    @functools.cached_property
    def ground_truth(self) -> GroundTruth:
        """Exact per-pixel geometry (:class:`virtus.capture.groundtruth.GroundTruth`), read on first
        access; :class:`VirtusError` for a capture without ground truth."""
        if self.gt_data is not None:
            return self.gt_data
        if not self.gt_files:
            raise VirtusError(f"{self.path or 'capture'}: this capture has no ground truth")
        cam = self.rig.camera.intrinsics
        missing = [path for path in self.gt_files.values() if not is_file(path)]
        if missing:
            where, root = (self.path / MANIFEST, self.path) if self.path else ("capture", None)
            names = [p.relative_to(root).as_posix() if root else str(p) for p in missing[:3]]
            raise InputError(f"{where}", "the ground-truth files it lists", f"missing {names}")
        arrays = {}
        for name, path in self.gt_files.items():
            array = load_npy(path, f"ground truth {name}")
            if array.shape[:2] != (cam.height, cam.width):
                raise InputError(
                    f"ground truth {name} {path}",
                    f"an array of {cam.width}x{cam.height} px (the rig's camera)",
                    f"shape {array.shape}",
                )
            arrays[name] = array
        return GroundTruth.from_arrays(arrays)

    def decode(self, **options: Any) -> DecodeResult:
        """Decode the frames (``PatternSequence.decode``) at this capture's full scale;
        ``options``: ``min_modulation``, ``saturation_level``, ... of that method."""
        return self.sequence.decode(self.frames, full_scale=self.full_scale, **options)

    def __eq__(self, other: object) -> bool:
        """Equal frames, rig, pose, bit depth, sensor, sequence and seed."""
        if not isinstance(other, Capture):
            return NotImplemented
        return (
            self.sequence == other.sequence
            and self.rig.to_dict() == other.rig.to_dict()
            and self.cam2world == other.cam2world
            and self.bit_depth == other.bit_depth
            and self.sensor == other.sensor
            and self.seed == other.seed
            and np.array_equal(self.frames, other.frames)
            and self.frames.dtype == other.frames.dtype
        )

    __hash__ = None  # type: ignore[assignment]

    # --- files --------------------------------------------------------------------------

    def to_dict(self, directory: Path, frame_files: list[Path]) -> dict[str, Any]:
        """The ``capture.json`` content for this capture saved in ``directory``."""
        scene = None
        if self.scene is not None:
            scene = self.scene.to_dict(asset_dir=directory / "scene_assets", relative_to=directory)
        frames = self.frames
        data = {
            "format": CAPTURE_FORMAT,
            "virtus_version": __version__,
            "units": UNITS,
            "rig": self.rig.to_dict(),
            "cam2world": self.cam2world.to_dict(),
            "sequence": self.sequence.to_dict(),
            "sensor": None if self.sensor is None else self.sensor.to_dict(),
            "seed": self.seed,
            "bit_depth": self.bit_depth,
            "render": self.render or None,
            "scene": scene,
            "frames": {
                "count": int(frames.shape[0]),
                "height": int(frames.shape[1]),
                "width": int(frames.shape[2]),
                "dtype": str(frames.dtype),
                "files": [path.relative_to(directory).as_posix() for path in frame_files],
            },
            "gt": (
                {name: f"gt/{name}.npy" for name in ARRAY_NAMES} if self.has_ground_truth else None
            ),
            "provenance": self.provenance,
        }
        if self.calibration_source is not None:
            data["calibration_source"] = self.calibration_source
        if self.camera_pixel_size_m is not None:
            data["camera_pixel_size_m"] = float(self.camera_pixel_size_m)
        return data

    def file_names(self) -> list[str]:
        """Relative names of the files :meth:`save` writes (scene assets, named by the scene
        when saved, excepted): the manifest, ``frames/NNN.png`` and ``gt/<name>.npy``."""
        names = [MANIFEST, *(f"frames/{frame_name(i)}" for i in range(len(self.sequence)))]
        if self.has_ground_truth:
            names += [f"gt/{name}.npy" for name in ARRAY_NAMES]
        return names

    def save(
        self,
        directory: str | Path,
        *,
        overwrite: bool = False,
        compression: int = 1,
        workers: int | None = None,
    ) -> Path:
        """Write the capture (layout in the module docstring); returns ``capture.json``.

        An existing capture in ``directory`` raises :class:`VirtusError` unless
        ``overwrite``, which removes its manifest first (so a capture replaced half-way never
        looks complete), then its frames, ground truth and assets. Frames and ground truth
        are written through staging folders, the manifest last; on any error the files this
        call wrote are removed and the error names the path.
        ``compression``, ``workers``: PNG settings (:func:`virtus.io.images.write_frames`).
        """
        directory = Path(directory)
        manifest = directory / MANIFEST
        if manifest.exists():
            if not overwrite:
                raise RunConflict(
                    f"{directory} already holds a capture "
                    "(pass overwrite=True, or --overwrite on the command line)"
                )
            manifest.unlink()
        for sub in _OWNED:
            shutil.rmtree(directory / sub, ignore_errors=True)
        frames = self.frames
        frame_names = [frame_name(i) for i in range(len(frames))]
        try:
            directory.mkdir(parents=True, exist_ok=True)
            paths = atomic_write_files(
                directory / "frames",
                frame_names,
                lambda staging: write_frames(
                    staging, frames, compression=compression, workers=workers
                ),
            )
            if self.has_ground_truth:
                arrays = self.ground_truth.arrays()
                atomic_write_files(
                    directory / "gt",
                    [f"{name}.npy" for name in arrays],
                    lambda staging: [np.save(staging / f"{n}.npy", a) for n, a in arrays.items()],
                )
            # The manifest is written last: a capture.json means a complete capture.
            written = write_json(manifest, self.to_dict(directory, paths), indent=1)
        except BaseException:
            for sub in _OWNED:
                shutil.rmtree(directory / sub, ignore_errors=True)
            raise
        object.__setattr__(self, "path", directory)
        object.__setattr__(self, "frame_files", tuple(paths))
        return written

    @classmethod
    def load(cls, directory: str | Path) -> Capture:
        """Read a capture directory (frames and ground truth are read on first access)."""
        from virtus.scene.model import Scene

        directory = Path(directory)
        manifest = directory / MANIFEST
        if not manifest.is_file():
            raise InputError("capture", f"a directory holding {MANIFEST}", str(directory))
        data = read_json(manifest, "capture.json", expect=dict)
        version = data.get("format")
        if version not in READABLE_FORMATS:
            raise InputError(f"{manifest} format", " or ".join(READABLE_FORMATS), version)
        if version == CAPTURE_FORMAT:
            unknown = sorted(set(data) - set(_KEYS))
            if unknown:
                raise InputError(str(manifest), f"keys among {list(_KEYS)}", f"unknown {unknown}")
        for key in ("rig", "sequence", "frames"):
            if not isinstance(data.get(key), dict):
                raise InputError(f"{manifest} {key}", "an object", data.get(key))
        rig = Rig.from_dict(data["rig"])
        sequence = PatternSequence.from_dict(data["sequence"])
        files = data["frames"].get("files")
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            raise InputError(f"{manifest} frames.files", "a list of file names", files)
        frame_files = tuple(_inside(directory, name, "frames.files") for name in files)
        gt_entry = data.get("gt") or {}
        if not isinstance(gt_entry, dict):
            raise InputError(f"{manifest} gt", "an object of file names", gt_entry)
        gt_files = {str(k): _inside(directory, v, "gt") for k, v in gt_entry.items()}
        missing = [str(p) for p in frame_files if not is_file(p)]
        if missing:
            raise InputError(f"{manifest}", "the files it lists", f"missing {missing[:3]}")
        if not any(is_file(path) for path in gt_files.values()):
            # ground truth removed (gt/ deleted to share the frames): a capture without it;
            # decoding and reconstruction need none. A part of it missing is a damaged
            # capture, refused when the ground truth is read.
            gt_files = {}
        sensor = Sensor.from_dict(data["sensor"]) if data.get("sensor") else None
        bit_depth = data.get("bit_depth")
        if bit_depth is None:  # format 1: 8 or 16 from the file dtype
            bit_depth = (
                sensor.bit_depth
                if sensor
                else (16 if data["frames"].get("dtype") == "uint16" else 8)
            )
        scene = Scene.from_dict(data["scene"], base_dir=directory) if data.get("scene") else None
        cam2world = (
            Pose.from_dict(data["cam2world"], "cam2world")
            if data.get("cam2world")
            else Pose.identity()
        )
        seed = data.get("seed")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise InputError(f"{manifest} seed", "a non-negative integer or null", seed)
        return cls(
            sequence=sequence,
            rig=rig,
            cam2world=cam2world,
            bit_depth=bit_depth,
            sensor=sensor,
            seed=seed,
            scene=scene,
            render=data.get("render") or {},
            provenance=data.get("provenance") or {},
            path=directory,
            frame_files=frame_files,
            gt_files=gt_files,
            calibration_source=_optional(data, "calibration_source", dict, manifest),
            camera_pixel_size_m=_optional(data, "camera_pixel_size_m", float, manifest),
        )


def _optional(data: dict[str, Any], key: str, kind: type, manifest: Path) -> Any:
    """``data[key]`` if present and not null (a ``dict``, or a ``float`` from a number)."""
    value = data.get(key)
    if value is None:
        return None
    if kind is float and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind):
        want = "an object" if kind is dict else "a number"
        raise InputError(f"{manifest} {key}", f"{want} or null", value)
    return value


def _inside(directory: Path, name: object, what: str) -> Path:
    """``directory / name`` for a relative name that stays inside ``directory``."""
    if (
        not isinstance(name, str)
        or not name
        or Path(name).is_absolute()
        or ".." in Path(name).parts
    ):
        raise InputError(f"capture.json {what}", "relative file names inside the capture", name)
    return directory / name


def import_capture(
    images: str | Path | list[str | Path],
    sequence: PatternSequence,
    rig: Rig,
    *,
    bit_depth: int | None = None,
    cam2world: Pose | None = None,
    command: list[str] | None = None,
    calibration_source: dict[str, Any] | None = None,
    camera_pixel_size_m: float | None = None,
) -> Capture:
    """A capture from camera images taken on a real bench (or by another renderer).

    Parameters
    ----------
    images : a folder (its PNG/TIFF/BMP files in natural order: ``img2`` before ``img10``)
        or an explicit list of image files, one per sequence frame, in sequence order.
    sequence : what the projector showed.
    rig : the bench's calibration (camera size must match the images).
    bit_depth : the camera's ADC bits (8, 10, 12, 16); default: 8 for 8-bit images, else
        the smallest of 10, 12, 16 that holds the largest value (a 12-bit camera stores
        its numbers unscaled in 16-bit files). It sets the full scale that decoding's
        thresholds are relative to.
    cam2world : the camera pose, if known.
    command : the command line to record (default ``sys.argv``).
    calibration_source : where the rig's parameters came from (``capture.json``'s
        ``calibration_source``; ``"calibrated": False`` for a placeholder rig).
    camera_pixel_size_m : the camera's pixel pitch, metres, if known.
    """
    files = list_images(images) if isinstance(images, str | Path) else [Path(p) for p in images]
    if len(files) != len(sequence):
        raise InputError(
            "images", f"{len(sequence)} images (one per sequence frame)", f"{len(files)} images"
        )
    first = read_image(files[0])
    check_capture_bytes(len(files), first.shape[1], first.shape[0], first.itemsize, what="images")
    frames = read_images(files)
    found = bit_depth_of(frames)
    if bit_depth is None:
        bit_depth = found
    elif bit_depth not in BIT_DEPTHS or (1 << bit_depth) - 1 < int(frames.max()):
        raise InputError(
            "bit_depth",
            f"one of {BIT_DEPTHS} holding the largest value {int(frames.max())}",
            bit_depth,
        )
    if frames.dtype == np.uint8 and bit_depth != 8:
        raise InputError("bit_depth", "8 for 8-bit images", bit_depth)
    return Capture(
        sequence=sequence,
        rig=rig,
        frame_data=frames,
        cam2world=cam2world or Pose.identity(),
        bit_depth=bit_depth,
        provenance={
            **_provenance("imported", command),
            "images": [str(p) for p in files],
        },
        calibration_source=calibration_source,
        camera_pixel_size_m=camera_pixel_size_m,
    )


def rendered_provenance(command: list[str] | None = None) -> dict[str, Any]:
    """Provenance of a capture made by the renderer."""
    return _provenance("rendered", command)
