"""Scanning: capture -> decode -> reconstruct, on a capture directory or a scene.

* :func:`decode_capture` decodes the frames of a capture directory into projector
  coordinates and writes ``decoded/`` (see :mod:`virtus.capture.scandir`).
* :func:`reconstruct_capture` triangulates them with the capture's rig or a calibration
  file and writes the point map and ``points.ply``.
* :func:`scan` renders a scene with the true rig (the virtual sensor), saves the capture
  (as the capture job does, :mod:`virtus.pipeline.capture`), then decodes and reconstructs
  it -- with calibrated parameters when a calibration is given.

Points are in the camera frame, metres. Reconstruction
(:func:`virtus.reconstruct.reconstruct`) drops pixels next to depth discontinuities (mixed
pixels at silhouettes; :func:`virtus.reconstruct.depth_edge_mask`).

**Ownership.** :func:`scan` owns its output directory (:func:`virtus.io.runs.claim_run`,
command ``scan``, :data:`virtus.capture.scandir.SCAN_LAYOUT`): another run's directory is
refused unless ``overwrite``, which removes that run's files first (its ``evaluation.json``
included); ``resume`` keeps a complete capture and redoes the fast steps.
:func:`decode_capture` and :func:`reconstruct_capture` write derived files into a capture
directory while holding its lock (:func:`virtus.io.runs.directory_lock`), so they cannot
collide with a run writing it.

**Derived files are tied to their inputs** (:mod:`virtus.capture.scandir`, the one owner of
a scan directory's files). ``decoded/source.json`` holds the capture's checksum
(:func:`~virtus.capture.scandir.frames_checksum`) and the decode options;
``reconstruction/source.json`` holds that capture checksum, the rig's checksum and the
PLY's SHA-256; ``evaluation.json`` holds the PLY's SHA-256. Each is written last, so a
partly replaced set is stale; a stale ``decoded/`` is recomputed, a stale ``points.ply`` is
refused by ``virtus evaluate``, and a new ``points.ply`` removes an ``evaluation.json`` of
another cloud.

**Degenerate results are errors**: a rig whose baseline is below
:data:`virtus.reconstruct.MIN_BASELINE_M`, a decode with no valid pixel (the message says
why: black, saturated or too weak fringes), and a reconstruction with no point.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.calib.io import load_rig_file
from virtus.capture.capture import Capture
from virtus.capture.scandir import (
    DERIVED_FILES,
    POINTS_PLY,
    SCAN_LAYOUT,
    frames_checksum,
    load_decoded,
    save_decoded,
)
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io import check_replaceable
from virtus.io.runs import RunDirectory, claim_run, directory_lock
from virtus.patterns import DecodeResult
from virtus.patterns.decode import check_saturation_level
from virtus.pipeline.capture import builtin_scene_in_run, complete_capture, save_capture
from virtus.reconstruct import (
    DEFAULT_MIN_MODULATION,
    EDGE_MAX_STEP,
    Reconstruction,
    Use,
    check_baseline,
    reconstruct,
)
from virtus.scanner import Scanner

__all__ = [
    "ScanResult",
    "ScanSettings",
    "decode_capture",
    "reconstruct_capture",
    "rig_source",
    "scan",
]

#: The job's name in ``run.json``.
COMMAND = "scan"
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
        from virtus.sensor.noise import as_seed

        if self.use not in ("uv", "u", "v"):
            raise InputError("use", "'uv', 'u' or 'v'", self.use)
        if self.edge_max_step is not None:
            object.__setattr__(self, "edge_max_step", positive("edge_max_step", self.edge_max_step))
        object.__setattr__(self, "seed", as_seed(self.seed))

    def to_dict(self) -> dict[str, Any]:
        """Every setting by name (JSON-ready)."""
        return asdict(self)


def _require_points(recon: Reconstruction, where: object) -> Reconstruction:
    """``recon``, or :class:`VirtusError` when it holds no point."""
    if not recon.mask.any():
        raise VirtusError(
            f"reconstruct: 0 points from {where}: every decoded pixel was behind the camera or "
            "the projector or dropped as a depth edge (check the calibration's proj2cam and "
            "units)"
        )
    return recon


# --- capture directories -------------------------------------------------------------------


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
    elif (level := options.get("saturation_level")) is not None and (
        frames.max(axis=0) >= level
    ).all():
        why = f"every pixel reaches --saturation-level {level:g} in some frame"
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
    # before anything is read: a level outside the frames' range would blame the modulation
    saturation_level = check_saturation_level(
        saturation_level, capture.full_scale, "--saturation-level"
    )
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
        rig; None uses the rig in ``capture.json`` (the true rig of a virtual capture),
        refused for a capture imported without a calibration (a placeholder rig).
    out_ply : PLY path; default ``capture_dir/points.ply``.
    use, edge_max_step : see :func:`virtus.reconstruct.reconstruct`.
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
        if not capture.calibrated:  # imported without a calibration: a placeholder rig
            raise InputError(
                "calibration",
                f"a calibration file (--calibration FILE): {capture_dir} was imported "
                "without one and its rig is a placeholder",
                "none",
            )
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
    _check_ply_target(Path(capture_dir), out_ply)  # before decoding: nothing done in vain
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


def rig_source(capture_dir: str | Path, calibration: str | Path | Rig | None = None) -> str:
    """Where the rig :func:`reconstruct_capture` triangulates ``capture_dir`` with comes
    from, in words: the calibration file given (its path), or the rig in ``capture.json``:
    the true rig of a rendered capture, or the calibration an imported capture was imported
    with (its path, from ``calibration_source``)."""
    if isinstance(calibration, Rig):
        return "a Rig given by the caller"
    if calibration is not None:
        return str(calibration)
    capture = Capture.load(capture_dir)
    manifest = Path(capture_dir) / "capture.json"
    source = capture.calibration_source
    if source is not None:
        imported = source.get("path")
        if not capture.calibrated or not imported:
            return f"{manifest} (a placeholder rig: no calibration was imported)"
        return f"{imported} (imported with the capture; rig in {manifest})"
    if capture.provenance.get("source") == "rendered":
        return f"{manifest} (the true rig it was rendered with)"
    return f"{manifest} (the rig it was saved with)"


def _check_ply_target(capture_dir: Path, out_ply: str | Path | None) -> None:
    """Refuse a PLY path :func:`reconstruct_capture` could not write or should not replace:
    a device, FIFO, socket, directory or symbolic link, a path under a file or in a
    read-only folder, or a name without ``.ply`` (``--out DIR/capture.json`` would replace
    the capture's own manifest)."""
    what = "output PLY (--out)" if out_ply is not None else "output PLY"
    path = check_replaceable(
        Path(out_ply) if out_ply is not None else capture_dir / POINTS_PLY, what
    )
    if path.suffix.lower() != ".ply":
        raise InputError(f"{what} {path}", "a file name ending in .ply", path.name)
    folder = path.parent  # created if missing: its nearest existing ancestor must take it
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"{what} {path}", "a path under a folder", f"{folder.name} is a file")
    if not os.access(folder, os.W_OK | os.X_OK):
        where = folder.name or str(folder)
        raise InputError(f"{what} {path}", "a path in a writable folder", f"{where} is read-only")


def _reconstruction_source(
    capture: Capture, use: str, edge_max_step: float | None
) -> dict[str, Any]:
    return {"capture_sha256": frames_checksum(capture), "use": use, "edge_max_step": edge_max_step}


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
    out_dir : scan directory, owned by the run (``run.json``, lock,
        :data:`~virtus.capture.scandir.SCAN_LAYOUT`).
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
    scanner.check(scene, cam2world)
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


def calibration_rig(calibration: str | Path | Rig | None, scanner: Scanner) -> Rig:
    """The rig to triangulate with: ``scanner``'s (None), a rig, or a calibration file read
    with :func:`virtus.calib.io.load_rig_file`; its baseline checked
    (:func:`virtus.reconstruct.check_baseline`)."""
    if calibration is None:
        used = scanner.rig
    elif isinstance(calibration, Rig):
        used = calibration
    else:
        used = load_rig_file(calibration, scanner.rig)
    return check_baseline(used, "calibration" if calibration is not None else "rig")


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
    capture = complete_capture(directory) if run.resumed else None
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
