"""Scanning: capture -> decode -> reconstruct, on a capture directory or a scene.

* :func:`decode_capture` decodes the frames of a capture directory into projector
  coordinates and writes ``decoded/`` (see :mod:`virtus.capture.scandir`).
* :func:`reconstruct_capture` triangulates them with the capture's rig or a calibration
  file and writes the point map and ``points.ply``.
* :func:`scan` renders a scene with the true rig (the virtual sensor), saves the capture,
  then decodes and reconstructs it -- with calibrated parameters when a calibration is given.

Points are in the camera frame, metres. Reconstruction drops pixels next to depth
discontinuities (mixed pixels at silhouettes; :func:`virtus.reconstruct.depth_edge_mask`).

**Ownership.** :func:`scan` owns its output directory (:func:`virtus.io.runs.claim_run`,
command ``scan``, :data:`SCAN_LAYOUT`): another run's directory is refused unless
``overwrite``, which removes that run's files first (its ``evaluation.json`` included);
``resume`` keeps a complete capture and redoes the fast steps. :func:`decode_capture` and
:func:`reconstruct_capture` write derived files into a capture directory while holding its
lock (:func:`virtus.io.runs.directory_lock`), so they cannot collide with a run writing it.

**Derived files are tied to their inputs.** ``decoded/source.json`` holds the capture's
checksum (:func:`frames_checksum`) and the decode options; ``reconstruction/source.json``
holds that capture checksum, the rig's checksum and the PLY's SHA-256; ``evaluation.json``
holds the PLY's SHA-256. Each is written last, so a partly replaced set is stale; a stale
``decoded/`` is recomputed, a stale ``points.ply`` is refused by ``virtus evaluate``, and a
new ``points.ply`` removes an ``evaluation.json`` of another cloud.

**Degenerate results are errors**: a rig whose baseline is below :data:`MIN_BASELINE_M`,
a decode with no valid pixel (the message says why: black, saturated or too weak fringes),
and a reconstruction with no point.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.capture import scandir as layout
from virtus.capture.capture import LAYOUT as CAPTURE_LAYOUT
from virtus.capture.capture import MANIFEST, Capture, check_capture_bytes
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.jsonio import write_json
from virtus.io.ply import write_ply
from virtus.io.runs import (
    RunDirectory,
    atomic_write,
    atomic_write_files,
    claim_run,
    config_digest,
    directory_lock,
    file_digest,
    write_json_atomic,
)
from virtus.io.safeio import load_npy, read_json
from virtus.patterns import DecodeResult
from virtus.reconstruct import (
    Use,
    depth_edge_mask,
    normals_from_points,
    points_from_decoded,
    valid_points,
)
from virtus.scanner import Scanner

__all__ = [
    "DERIVED_FILES",
    "MIN_BASELINE_M",
    "SCAN_LAYOUT",
    "Reconstruction",
    "ScanResult",
    "ScanSettings",
    "check_baseline",
    "check_renderable",
    "capture_job",
    "check_points_current",
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
#: Shortest camera-projector baseline (m) triangulation accepts: below 1 um every depth is
#: undetermined (the rays are parallel); real rigs have 50-300 mm.
MIN_BASELINE_M = 1e-6
#: The job's name in ``run.json``.
COMMAND = "scan"
#: ``reconstruction/`` files, and the one that ties them to their inputs (written last).
RECONSTRUCTION_FILES = ("points.npy", "depth.npy", "mask.npy", "rig.json")
RECONSTRUCTION_SOURCE = "source.json"
#: Every file the pipeline derives inside a capture directory (relative names).
DERIVED_FILES = (
    *(f"{layout.DECODED_DIR}/{name}.npy" for name in layout.DECODED_FILES),
    f"{layout.DECODED_DIR}/{layout.DECODE_SUMMARY}",
    f"{layout.DECODED_DIR}/{layout.DECODED_SOURCE}",
    *(f"{layout.RECONSTRUCTION_DIR}/{name}" for name in RECONSTRUCTION_FILES),
    f"{layout.RECONSTRUCTION_DIR}/{RECONSTRUCTION_SOURCE}",
    layout.POINTS_PLY,
    layout.EVALUATION_JSON,
)
#: Files of a scan directory: an earlier run's when found without a ``run.json``.
SCAN_LAYOUT = (*CAPTURE_LAYOUT, *DERIVED_FILES)
#: Options of the decode :func:`scan` runs (those of ``virtus decode``'s defaults).
SCAN_DECODE_OPTIONS = {
    "min_modulation": DEFAULT_MIN_MODULATION,
    "saturation_level": None,
    "repair": False,
}


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

    def __post_init__(self) -> None:
        from virtus.checks import positive
        from virtus.sensor.camera import as_seed

        if self.use not in ("uv", "u", "v"):
            raise InputError("use", "'uv', 'u' or 'v'", self.use)
        if self.edge_max_step is not None:
            object.__setattr__(self, "edge_max_step", positive("edge_max_step", self.edge_max_step))
        object.__setattr__(self, "seed", as_seed(self.seed))

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

    def save(
        self,
        directory: str | Path,
        ply_path: str | Path | None = None,
        source: dict[str, Any] | None = None,
    ) -> Path:
        """Write the PLY and, for the directory's own ``points.ply``, ``reconstruction/``;
        returns the PLY path.

        ``ply_path`` defaults to ``directory/points.ply``, which is written with
        ``reconstruction/*.npy`` as a pair: ``reconstruction/source.json`` (``source`` plus
        the rig's and the PLY's SHA-256) is removed first and written last, so a partly
        replaced pair is stale, and a changed ``points.ply`` removes an ``evaluation.json``
        of another cloud. Another ``ply_path`` gets only that PLY (the directory's pair is
        left as it is). Every file is written atomically.
        """
        root = Path(directory)
        default = root / layout.POINTS_PLY
        target = Path(ply_path) if ply_path is not None else default
        normals = normals_from_points(self.points)
        ok = self.mask & np.isfinite(normals).all(axis=-1)

        def write_cloud(tmp: Path) -> None:
            write_ply(
                tmp,
                self.points[ok],
                normals=normals[ok],
                frame="camera",
                comments=(f"virtus reconstruction, {int(ok.sum())} points",),
            )

        if target.resolve() != default.resolve():
            return atomic_write(target, write_cloud)
        folder = root / layout.RECONSTRUCTION_DIR
        tie = folder / RECONSTRUCTION_SOURCE
        tie.unlink(missing_ok=True)
        rig = self.rig.to_dict()
        arrays = {"points": self.points, "depth": self.depth, "mask": self.mask}

        def write_arrays(staging: Path) -> None:
            for name, array in arrays.items():
                np.save(staging / f"{name}.npy", array)
            write_json(staging / "rig.json", rig)

        atomic_write_files(folder, list(RECONSTRUCTION_FILES), write_arrays)
        atomic_write(target, write_cloud)
        digest = file_digest(target)
        _drop_stale_evaluation(root, digest)
        record = dict(source or {})
        record.update({"rig_sha256": config_digest(rig), "ply_sha256": digest})
        write_json_atomic(tie, record)
        return target


def _drop_stale_evaluation(directory: Path, ply_digest: str) -> None:
    """Remove ``evaluation.json`` unless it measured the cloud of SHA-256 ``ply_digest``."""
    path = directory / layout.EVALUATION_JSON
    if not path.is_file():
        return
    try:
        current = read_json(path, "evaluation", expect=dict, allow_nan=True).get("cloud_sha256")
    except InputError:
        current = None
    if current != ply_digest:
        path.unlink(missing_ok=True)


def check_baseline(rig: Rig, what: str = "rig") -> Rig:
    """``rig``, or :class:`VirtusError` when its baseline is below :data:`MIN_BASELINE_M`
    (camera and projector at one point: no depth can be triangulated)."""
    baseline = float(np.linalg.norm(rig.proj2cam.t))
    if not baseline >= MIN_BASELINE_M:
        raise VirtusError(
            f"{what}: the camera-projector baseline is {baseline * 1e6:.3g} um, below "
            f"{MIN_BASELINE_M * 1e6:g} um: nothing can be triangulated (proj2cam.t is the "
            "projector's centre in camera coordinates, metres)"
        )
    return rig


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
    rig : rig to triangulate with (true or calibrated); its baseline must be at least
        :data:`MIN_BASELINE_M` (:func:`check_baseline`).
    proj_uv : (H, W, 2) float, decoded projector coordinates, NaN where invalid.
    mask : (H, W) bool, optional decode mask.
    use : see :func:`virtus.reconstruct.triangulate`.
    edge_max_step : see :func:`virtus.reconstruct.depth_edge_mask`; None disables the filter.
    """
    check_baseline(rig)
    points = points_from_decoded(rig, proj_uv, mask, use=use)
    edges = np.zeros(points.shape[:2], dtype=bool)
    if edge_max_step is not None:
        edges = depth_edge_mask(points, rig.camera.intrinsics.fx, edge_max_step)
        points[edges] = np.nan
    return Reconstruction(points, edges, rig)


def _require_points(recon: Reconstruction, where: object) -> Reconstruction:
    """``recon``, or :class:`VirtusError` when it holds no point."""
    if not recon.mask.any():
        raise VirtusError(
            f"reconstruct: 0 points from {where}: every decoded pixel was behind the camera or "
            "the projector or dropped as a depth edge (check the calibration's proj2cam and "
            "units)"
        )
    return recon


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


def check_renderable(scanner: Scanner, scene: Any = None, cam2world: Pose | None = None) -> int:
    """Everything the renderer would refuse only after a job started, checked before it
    claims or renders anything; returns the bytes one capture needs.

    The memory (:func:`virtus.capture.capture.capture_bytes`: frames plus the trace's ``spp x
    bounces x aperture samples`` taps per pixel) against
    :data:`virtus.capture.capture.MAX_CAPTURE_BYTES`; spp a perfect square; the Mitsuba variant's
    name; the light-transport counts; and, given a ``scene``, that every object lies in
    front of the camera placed at ``cam2world``.
    """
    from virtus.render.backend import SUPPORTED_VARIANTS
    from virtus.render.tracing import (
        DEFAULT_APERTURE_SAMPLES,
        MAX_APERTURE_SAMPLES,
        MAX_BOUNCES,
        sample_offsets,
    )

    sample_offsets(scanner.spp)  # a perfect square
    if scanner.variant is not None and scanner.variant not in SUPPORTED_VARIANTS:
        raise InputError("variant", f"one of {', '.join(SUPPORTED_VARIANTS)}", scanner.variant)
    bounces = _count("bounces", scanner.bounces, MAX_BOUNCES)
    if scanner.projector_lens is None:
        aperture = 1
    elif scanner.aperture_samples is None:
        aperture = DEFAULT_APERTURE_SAMPLES
    else:
        aperture = _count("aperture_samples", scanner.aperture_samples, MAX_APERTURE_SAMPLES)
    if scene is not None and not isinstance(scene, str):
        from virtus.render.mitsuba_scene import check_in_front

        with np.errstate(all="ignore"):  # a far-off mesh is refused by name, not warned about
            check_in_front(scene, (cam2world or Pose.identity()).inverse())
    camera = scanner.rig.camera.intrinsics
    return check_capture_bytes(
        len(scanner.sequence),  # type: ignore[arg-type]
        camera.width,
        camera.height,
        np.dtype(scanner.sensor.dtype).itemsize,
        scanner.spp * bounces * aperture,
        what="capture (--spp, --bounces, camera size, sequence length)",
    )


def _count(name: str, value: object, largest: int) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or not (1 <= value <= largest)
    ):
        raise InputError(name, f"an integer in 1..{largest}", value)
    return int(value)


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
    """Write ``decoded/`` (arrays, ``summary.json``) atomically and ``source.json`` last,
    which ties them to the capture's checksum and the decode options (it is removed first,
    so a partly replaced folder is stale); returns the folder."""
    folder = Path(directory) / layout.DECODED_DIR
    (folder / layout.DECODED_SOURCE).unlink(missing_ok=True)
    summary = decoded.summary()

    def write(staging: Path) -> None:
        for name in layout.DECODED_FILES:
            np.save(staging / f"{name}.npy", getattr(decoded, name))
        write_json(staging / layout.DECODE_SUMMARY, summary)

    names = [f"{name}.npy" for name in layout.DECODED_FILES] + [layout.DECODE_SUMMARY]
    atomic_write_files(folder, names, write)
    write_json_atomic(folder / layout.DECODED_SOURCE, source)
    return folder


def _decode_checked(capture: Capture, options: dict[str, Any]) -> DecodeResult:
    """Decode ``capture``; :class:`VirtusError` saying why when no pixel decodes."""
    decoded = capture.decode(**options)
    if decoded.mask.any():
        return decoded
    frames = capture.frames
    full = capture.full_scale
    low, high = int(frames.min()), int(frames.max())
    if high == 0:
        why = "every frame is black (0 DN)"
    elif low >= full:
        why = f"every pixel of every frame is saturated ({full} DN)"
    elif low == high:
        why = f"every frame is one flat value ({low} DN): no fringes"
    else:
        with np.errstate(all="ignore"):
            peak = float(np.nanmax(decoded.modulation)) / full if decoded.modulation.size else 0.0
        why = (
            f"the strongest fringe modulation is {peak:.2%} of full scale ({full} DN), below "
            f"--min-modulation {options.get('min_modulation')} (frames too dark, saturated, "
            "a wrong --bit-depth, or a sequence that does not describe them)"
        )
    where = capture.path if capture.path is not None else "the capture"
    raise VirtusError(f"decode: 0 % of the pixels of {where} decoded: {why}")


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
    save : write ``decoded/`` (see :mod:`virtus.capture.scandir`) with ``summary.json``
        and ``source.json`` (the capture's checksum and these options), holding the
        directory's lock.
    min_modulation : fringe modulation threshold, a fraction of the capture's full scale.
    saturation_level : digital number at and above which a pixel is saturated (invalid);
        None disables the check.
    repair : repair pixels whose fringe order disagrees with the wrapped phase.

    Returns
    -------
    The sequence's ``DecodeResult`` (``proj_uv`` (H, W, 2), ``phase_v``, ``phase_h``,
    ``mask``, ``flagged``, ``summary()``, ...).

    Raises
    ------
    InputError : a malformed capture (``capture.json``, frames, ground truth ``gt/*.npy``).
    VirtusError : no pixel decodes (nothing is written), or the directory is in use.
    """
    capture = Capture.load(capture_dir)
    if capture.has_ground_truth:  # a capture is read whole: a corrupt file is refused
        capture.ground_truth  # noqa: B018
    options = {
        "min_modulation": min_modulation,
        "saturation_level": saturation_level,
        "repair": repair,
    }
    if not save:
        return _decode_checked(capture, options)
    with directory_lock(capture_dir):
        return _decode_and_save(capture, options)


def _decode_and_save(capture: Capture, options: dict[str, Any]) -> DecodeResult:
    decoded = _decode_checked(capture, options)
    source = {"capture_sha256": frames_checksum(capture), "options": options}
    save_decoded(capture.path, decoded, source)  # type: ignore[arg-type]
    return decoded


def load_decoded(
    capture_dir: str | Path, capture: Capture | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(proj_uv (H, W, 2), mask (H, W))`` from ``decoded/``, or None when there is none or
    it was decoded from other frames than the capture holds now (stale). Files that claim to
    be current but are malformed (truncated, pickled, wrong shape) raise
    :class:`~virtus.errors.InputError`."""
    folder = Path(capture_dir) / layout.DECODED_DIR
    source_file = folder / layout.DECODED_SOURCE
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


def reconstruct_capture(
    capture_dir: str | Path,
    calibration: str | Path | Rig | None = None,
    out_ply: str | Path | None = None,
    *,
    use: Use = "uv",
    edge_max_step: float | None = EDGE_MAX_STEP,
    units: str | None = None,
) -> Reconstruction:
    """Triangulate a capture directory (decoding it first if needed or stale), holding its
    lock while it writes.

    Parameters
    ----------
    capture_dir : capture or scan directory.
    calibration : a calibration file (see :func:`virtus.calib.io.load_calibration`) or a
        rig; None uses the rig in ``capture.json`` (the true rig of a virtual capture).
    out_ply : PLY path; default ``capture_dir/points.ply``.
    use, edge_max_step : see :func:`reconstruct`.
    units : length unit of a calibration file that states none (``"mm"`` or ``"m"``).

    Raises
    ------
    VirtusError : a camera size other than the capture's, a zero baseline, no decoded
        pixel, no point, or the directory in use by another run.
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
    check_baseline(
        rig, "calibration" if calibration is not None else f"{capture_dir}/capture.json rig"
    )
    with directory_lock(capture_dir):
        decoded = load_decoded(capture_dir, capture)
        if decoded is None:
            result = _decode_and_save(capture, dict(SCAN_DECODE_OPTIONS))
            decoded = (result.proj_uv, result.mask)
        proj_uv, mask = decoded
        recon = _require_points(
            reconstruct(rig, proj_uv, mask, use=use, edge_max_step=edge_max_step), capture_dir
        )
        recon.save(capture_dir, out_ply, _reconstruction_source(capture, use, edge_max_step))
    return recon


def _reconstruction_source(
    capture: Capture, use: str, edge_max_step: float | None
) -> dict[str, Any]:
    return {"capture_sha256": frames_checksum(capture), "use": use, "edge_max_step": edge_max_step}


def check_points_current(capture: Capture, ply_path: str | Path) -> str:
    """SHA-256 (``"sha256:<hex>"``) of a capture directory's ``points.ply``, checked to be
    the latest reconstruction of the frames the directory holds now.

    Raises
    ------
    VirtusError : ``reconstruction/source.json`` is missing, names another cloud, or was
        made from other frames (stale): run ``virtus reconstruct DIR`` again.
    """
    directory = capture.path
    tie = Path(directory) / layout.RECONSTRUCTION_DIR / RECONSTRUCTION_SOURCE  # type: ignore[arg-type]
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


def _scene_config(scene: Any) -> Any:
    """The scene's description for ``run.json``: its dict, or its name for a built-in."""
    if isinstance(scene, str):
        return scene
    try:
        return scene.to_dict()
    except VirtusError:  # in-memory textures: described by their presence only
        return {"objects": [type(o).__name__ for o in scene.all_objects()], "in_memory": True}


def scan(
    scene: Any,
    out_dir: str | Path,
    *,
    scanner: Scanner | None = None,
    calibration: str | Path | Rig | None = None,
    settings: ScanSettings | None = None,
    overwrite: bool = False,
    resume: bool = False,
    cam2world: Pose | None = None,
) -> ScanResult:
    """Capture ``scene`` with the virtual scanner, then decode and reconstruct it.

    Parameters
    ----------
    scene : a :class:`virtus.scene.model.Scene`, or the name of a built-in scene
        (:data:`virtus.scene.builtin.BUILTIN_SCENES`; its assets are written into the
        run's directory).
    out_dir : scan directory, owned by the run (``run.json``, lock, :data:`SCAN_LAYOUT`).
    scanner : the virtual scanner (its rig is the truth that renders the frames; default:
        the paper's system).
    calibration : rig or calibration file used for triangulation; None uses the scanner's
        rig (reconstruction with the true parameters).
    settings : reconstruction settings and the capture's seed.
    overwrite : remove an earlier run's files in ``out_dir`` first.
    resume : continue the run recorded in ``out_dir`` (same settings): a complete capture
        is kept, decoding and reconstruction are done again.
    cam2world : camera pose in the scene's world frame (default identity).

    Raises
    ------
    InputError, VirtusError : bad arguments, a calibration that cannot be read or has no
        baseline, or a capture over the memory budget -- all before anything is written;
        ``out_dir`` in use or holding another run's files; no decoded pixel or no point.
    """
    from virtus.scene.builtin import BUILTIN_SCENES

    settings = settings or ScanSettings()
    scanner = scanner or Scanner()
    if isinstance(scene, str) and scene not in BUILTIN_SCENES:
        raise InputError("scene", f"a Scene or one of {', '.join(BUILTIN_SCENES)}", scene)
    # Read and check everything before rendering or writing.
    used = calibration_rig(calibration, scanner)
    check_renderable(scanner, scene, cam2world)
    config = {
        "scanner": scanner.to_dict(),
        "scene": _scene_config(scene),
        "calibration": None if calibration is None else used.to_dict(),
        "settings": settings.to_dict(),
        "cam2world": None if cam2world is None else cam2world.to_dict(),
    }
    with claim_run(
        out_dir, COMMAND, config, layout=SCAN_LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        if isinstance(scene, str):
            scene = builtin_scene_in_run(run, scene)
        return scan_into(run, "", scene, scanner, used, settings, cam2world=cam2world)


def builtin_scene_in_run(run: RunDirectory, name: str) -> Any:
    """A built-in scene whose asset files (``freeform.stl``) the run owns."""
    from virtus.scene.builtin import builtin_scene

    if name == "freeform":
        run.own("freeform.stl")
    return builtin_scene(name, run.path)


def calibration_rig(calibration: str | Path | Rig | None, scanner: Scanner) -> Rig:
    """The rig to triangulate with: ``scanner``'s (None), a rig, or a calibration file read
    with :func:`load_rig_file`; its baseline checked (:func:`check_baseline`)."""
    if calibration is None:
        used = scanner.rig
    elif isinstance(calibration, Rig):
        used = calibration
    else:
        used = load_rig_file(calibration, scanner.rig)
    return check_baseline(used, "calibration" if calibration is not None else "rig")


def _complete_capture(directory: Path) -> Capture | None:
    """The capture in ``directory`` if it is complete and readable, else None."""
    if not (directory / MANIFEST).is_file():
        return None
    try:
        capture = Capture.load(directory)
        capture.frames  # noqa: B018 - read (and check) the frames now
    except (InputError, VirtusError, OSError):
        return None
    return capture


def save_capture(run: RunDirectory, sub: str, capture: Capture) -> Path:
    """Save ``capture`` into ``run``'s directory (or its sub-directory ``sub``), replacing
    an earlier capture there and the files derived from it; every file is registered with
    the run first (scene assets, named while saving, right after). Returns the manifest."""
    prefix = f"{sub}/" if sub else ""
    directory = run.file(sub) if sub else run.path
    run.own(*(prefix + name for name in (*capture.file_names(), *DERIVED_FILES)))
    for name in DERIVED_FILES:  # results of an earlier or interrupted attempt
        (directory / name).unlink(missing_ok=True)
    manifest = capture.save(directory, overwrite=True)
    assets = sorted((directory / "scene_assets").glob("*"))
    run.own(*(prefix + p.relative_to(directory).as_posix() for p in assets))
    run.log(f"saved capture {sub or '.'}")
    return manifest


def capture_job(
    out_dir: str | Path,
    command: str,
    config: dict[str, Any],
    make: Any,
    *,
    inputs: dict[str, str | Path] | None = None,
    overwrite: bool = False,
    resume: bool = False,
) -> Capture:
    """Run a job that writes one capture into ``out_dir`` (``virtus capture``, ``virtus
    import``): claim the directory (:func:`virtus.io.runs.claim_run` with ``command``,
    ``config``, ``inputs`` and :data:`SCAN_LAYOUT`), call ``make()`` for the capture and
    save it (:func:`save_capture`). A resumed run keeps a complete capture and returns it.
    Check every input before calling: nothing may fail between the claim and ``make``."""
    with claim_run(
        out_dir, command, config, inputs=inputs, layout=SCAN_LAYOUT, overwrite=overwrite,
        resume=resume,
    ) as run:  # fmt: skip
        capture = _complete_capture(run.path) if run.resumed else None
        if capture is None:
            capture = make()
            save_capture(run, "", capture)
        return capture


def scan_into(
    run: RunDirectory,
    sub: str,
    scene: Any,
    scanner: Scanner,
    rig: Rig,
    settings: ScanSettings,
    *,
    cam2world: Pose | None = None,
) -> ScanResult:
    """Capture, decode and reconstruct one view into ``run``'s directory or its
    sub-directory ``sub`` (``""`` for the directory itself); every file is registered with
    the run before it is written. A resumed run keeps a complete capture there."""
    import time

    prefix = f"{sub}/" if sub else ""
    directory = run.file(sub) if sub else run.path
    timing: dict[str, float] = {}
    start = time.perf_counter()
    capture = _complete_capture(directory) if run.resumed else None
    if capture is None:
        capture = scanner.capture(scene, cam2world=cam2world, rng=settings.seed)
        save_capture(run, sub, capture)
    else:
        run.own(*(prefix + name for name in (*capture.file_names(), *DERIVED_FILES)))
        run.log(f"reused {sub or '.'}")
    timing["render_s"] = time.perf_counter() - start

    start = time.perf_counter()
    decoded = _decode_and_save(capture, dict(SCAN_DECODE_OPTIONS))
    timing["decode_s"] = time.perf_counter() - start

    start = time.perf_counter()
    recon = reconstruct(
        rig, decoded.proj_uv, decoded.mask, use=settings.use, edge_max_step=settings.edge_max_step
    )
    _require_points(recon, directory)
    ply = recon.save(
        directory, source=_reconstruction_source(capture, settings.use, settings.edge_max_step)
    )
    timing["reconstruct_s"] = time.perf_counter() - start
    return ScanResult(directory, recon, decoded, ply, timing, capture)
