"""The capture job: write one capture into a run directory (``virtus capture``, ``virtus
import``).

* :func:`capture_scene` renders a scene with the virtual scanner for one pose.
* :func:`import_images` turns a folder of camera images from a real bench, its pattern
  sequence and its calibration into the same capture, without ground truth.
* :func:`capture_job` is what both share: claim the directory, make the capture, save it.

The layout written is that of :mod:`virtus.capture.scandir` (``capture.json``,
``frames/``, ``gt/`` for a rendered capture), so ``virtus decode`` and ``virtus
reconstruct`` work on either.

**Ownership.** Each job owns its output directory (:func:`virtus.io.runs.claim_run`, command
``capture`` or ``import``, :data:`virtus.capture.scandir.SCAN_LAYOUT`): another run's
directory is refused unless ``overwrite``, which removes that run's files first; ``resume``
keeps a complete capture (same settings and inputs). Every input is read and checked before
the directory is claimed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from virtus.calib.sources import CalibrationSources
from virtus.capture.capture import MANIFEST, Capture
from virtus.capture.scandir import DERIVED_FILES, SCAN_LAYOUT
from virtus.checks import positive
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.io.runs import RunDirectory, claim_run
from virtus.patterns import PatternSequence
from virtus.scanner import Scanner

__all__ = [
    "CaptureResult",
    "ImportResult",
    "builtin_scene_in_run",
    "capture_job",
    "capture_scene",
    "complete_capture",
    "import_images",
    "save_capture",
]

#: The jobs' names in ``run.json``.
CAPTURE_COMMAND = "capture"
IMPORT_COMMAND = "import"


# --- the core: one capture into a run directory ----------------------------------------------


def complete_capture(directory: Path) -> Capture | None:
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


def builtin_scene_in_run(run: RunDirectory, name: str) -> Any:
    """A built-in scene whose asset files (``freeform.stl``) the run owns."""
    from virtus.scene.builtin import builtin_scene

    if name == "freeform":
        run.own("freeform.stl")
    return builtin_scene(name, run.path)


def capture_job(
    out_dir: str | Path,
    command: str,
    config: dict[str, Any],
    make: Callable[[RunDirectory], Capture],
    *,
    inputs: dict[str, str | Path] | None = None,
    overwrite: bool = False,
    resume: bool = False,
) -> Capture:
    """Run a job that writes one capture into ``out_dir``: claim the directory
    (:func:`virtus.io.runs.claim_run` with ``command``, ``config``, ``inputs`` and
    :data:`~virtus.capture.scandir.SCAN_LAYOUT`), call ``make(run)`` for the capture and
    save it (:func:`save_capture`). A resumed run keeps a complete capture and returns it.
    Check every input before calling: nothing may fail between the claim and ``make``."""
    with claim_run(
        out_dir, command, config, inputs=inputs, layout=SCAN_LAYOUT, overwrite=overwrite,
        resume=resume,
    ) as run:  # fmt: skip
        capture = complete_capture(run.path) if run.resumed else None
        if capture is None:
            capture = make(run)
            save_capture(run, "", capture)
        return capture


# --- virtus capture --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class CaptureResult:
    """Outcome of :func:`capture_scene`.

    Attributes
    ----------
    directory : the capture directory.
    capture : the capture written (or the complete one a resumed run kept).
    timing_s : seconds: ``render_s`` (0 when a complete capture was kept) and ``write_s``
        (everything else: claiming, writing PNGs and ground truth).
    """

    directory: Path
    capture: Capture
    timing_s: dict[str, float] = field(default_factory=dict)


def capture_scene(
    scanner: Scanner,
    scene: str | Path | None,
    out_dir: str | Path,
    *,
    seed: int = 0,
    overwrite: bool = False,
    resume: bool = False,
) -> CaptureResult:
    """Render ``scene`` with ``scanner`` for one pose and write the capture into ``out_dir``.

    Parameters
    ----------
    scanner : the virtual scanner.
    scene : a scene file (YAML, or USD: :func:`virtus.pipeline.inputs.load_scene`), the name
        of a built-in scene (:data:`virtus.scene.builtin.BUILTIN_SCENES`, unless a file of
        that name exists; its assets are written into the run's directory), or None: the
        paper's sphere (:func:`virtus.scene.model.default_scene`).
    out_dir : the capture directory, owned by the run (``run.json``, lock,
        :data:`~virtus.capture.scandir.SCAN_LAYOUT`).
    seed : seed of the capture's noise streams (>= 0).
    overwrite : remove an earlier run's files in ``out_dir`` first.
    resume : finish the run recorded in ``out_dir`` (same settings): a complete capture is
        kept.

    Raises
    ------
    InputError, VirtusError : a bad seed, scene or scanner (all before anything is claimed,
        rendered or written); ``out_dir`` in use or holding another run's files.
    """
    from virtus.pipeline.inputs import load_scene
    from virtus.scene.builtin import BUILTIN_SCENES
    from virtus.scene.model import default_scene
    from virtus.sensor import as_seed

    # Every check before anything is claimed, rendered or written.
    seed = as_seed(seed)
    builtin = scene is not None and str(scene) in BUILTIN_SCENES and not Path(scene).is_file()
    if scene is None:
        the_scene: Any = default_scene()
    elif builtin:
        the_scene = str(scene)  # built into the run's directory by the run
    else:
        the_scene = load_scene(scene)
    scanner.check(the_scene)
    config = {
        "scanner": scanner.to_dict(),
        "scene": str(scene) if scene is not None else "default",
        "seed": seed,
    }
    timing: dict[str, float] = {}

    def render(run: RunDirectory) -> Capture:
        built = builtin_scene_in_run(run, the_scene) if builtin else the_scene
        start = time.perf_counter()
        captured = scanner.capture(built, rng=seed)
        timing["render_s"] = time.perf_counter() - start
        return captured

    start = time.perf_counter()
    captured = capture_job(
        out_dir,
        CAPTURE_COMMAND,
        config,
        render,
        inputs={"scene": scene} if scene is not None and not builtin else None,
        overwrite=overwrite,
        resume=resume,
    )
    total = time.perf_counter() - start
    render_s = timing.get("render_s", 0.0)
    return CaptureResult(
        Path(out_dir), captured, {"render_s": render_s, "write_s": total - render_s}
    )


# --- virtus import ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ImportResult:
    """Outcome of :func:`import_images`.

    Attributes
    ----------
    directory : the capture directory.
    capture : the capture written (or the complete one a resumed run kept).
    sequence : the pattern sequence describing the frames.
    rig : the calibration read (a placeholder rig for an import without a calibration).
    sources : where each parameter of ``rig`` came from
        (:class:`~virtus.calib.sources.CalibrationSources`; also in ``capture.json`` as
        ``calibration_source``).
    """

    directory: Path
    capture: Capture
    sequence: PatternSequence
    rig: Rig
    sources: CalibrationSources


def import_images(
    images: str | Path,
    sequence_file: str | Path,
    calibration: str | Path | None,
    out_dir: str | Path,
    *,
    units: str | None = None,
    bit_depth: int | None = None,
    camera_size: tuple[int, int] | None = None,
    pixel_size_um: float | None = None,
    overwrite: bool = False,
    resume: bool = False,
) -> ImportResult:
    """Import camera images from a real bench as a capture in ``out_dir`` (the layout of
    :func:`capture_scene`, without ground truth).

    Parameters
    ----------
    images : a folder of 8/10/12/16-bit PNG, TIFF or BMP frames (natural order), or, when the
        sequence file lists its own images, the folder they are in (else the sequence file's).
    sequence_file : the pattern sequence file (YAML/JSON) describing the frames.
    calibration : a calibration file (:func:`virtus.calib.io.load_calibration_report`); image
        sizes it lacks are taken from the frames and the sequence. None: captures for
        calibrating the bench (e.g. board poses for ``virtus calibrate --captures``): the rig
        is a placeholder (:func:`virtus.calib.sources.uncalibrated_rig`: the real image
        sizes, a nominal K, no baseline) recorded as uncalibrated, so ``virtus decode``
        works and ``virtus reconstruct`` asks for ``--calibration``.
    out_dir : the capture directory, owned by the run (``run.json`` with the inputs'
        checksums).
    units : length unit of a calibration file that states none (``"mm"`` or ``"m"``);
        refused without a calibration.
    bit_depth : the camera's ADC bits; None: the smallest that holds the data.
    camera_size : ``(width, height)`` of the camera, for a calibration that lacks it; must
        match the images (and a size the file states).
    pixel_size_um : the camera's pixel pitch, micrometres (> 0), recorded in
        ``capture.json`` (``camera_pixel_size_m``) for a digital twin.
    overwrite, resume : as for :func:`capture_scene`.

    Raises
    ------
    InputError, VirtusError : unreadable or inconsistent inputs (all read and checked before
        ``out_dir`` is claimed); ``out_dir`` in use or holding another run's files.
    """
    from virtus.capture.capture import import_capture
    from virtus.io.images import list_images, read_image
    from virtus.patterns import load_sequence_file

    images, sequence_file = Path(images), Path(sequence_file)
    seq, listed = load_sequence_file(sequence_file)
    if listed:
        base = images if images.is_dir() else sequence_file.parent
        files: Path | list[Path] = [base / name for name in listed]
    else:
        files = images
    # The camera size is needed to read the paper code's text files, which lack it.
    first = read_image(files[0] if isinstance(files, list) else list_images(files)[0])
    size = _camera_size((first.shape[1], first.shape[0]), camera_size)
    pitch_m = None if pixel_size_um is None else positive("--pixel-size-um", pixel_size_um) * 1e-6
    rig, sources = _import_rig(calibration, units, size, camera_size is not None, seq)
    # Every input is read and checked before OUT is claimed.
    imported = import_capture(
        files, seq, rig, bit_depth=bit_depth, calibration_source=sources.to_dict(),
        camera_pixel_size_m=pitch_m,
    )  # fmt: skip
    image_files = files if isinstance(files, list) else list_images(files)
    inputs: dict[str, str | Path] = {"sequence": sequence_file}
    if calibration is not None and Path(calibration).is_dir():
        inputs.update({f"calibration/{f.name}": f for f in sorted(Path(calibration).iterdir())
                       if f.is_file()})  # fmt: skip
    elif calibration is not None:
        inputs["calibration"] = calibration
        inputs.update({f"calibration/{Path(f).name}": f for f in sources.files[1:]})
    inputs.update({f"image/{i:04d}": f for i, f in enumerate(image_files)})
    config: dict[str, Any] = {
        "images": [str(f) for f in image_files],
        "sequence": str(sequence_file),
        "calibration": None if calibration is None else str(calibration),
        "units": units,
        "bit_depth": bit_depth,
    }
    if camera_size is not None:
        config["camera_size"] = list(size)
    if pixel_size_um is not None:
        config["pixel_size_um"] = pixel_size_um
    capture = capture_job(
        out_dir, IMPORT_COMMAND, config, lambda run: imported, inputs=inputs,
        overwrite=overwrite, resume=resume,
    )  # fmt: skip
    return ImportResult(Path(out_dir), capture, seq, rig, sources)


def _camera_size(images: tuple[int, int], given: tuple[int, int] | None) -> tuple[int, int]:
    """The camera size (width, height): the images', which ``--camera-size`` must match."""
    from virtus.calib.formats import given_size

    size = given_size("--camera-size", given)
    if size is not None and size != images:
        raise InputError(
            "--camera-size", f"the images' size {images[0]},{images[1]}", f"{size[0]},{size[1]}"
        )
    return images


def _import_rig(
    calibration: str | Path | None,
    units: str | None,
    camera_size: tuple[int, int],
    size_given: bool,
    seq: PatternSequence,
) -> tuple[Rig, CalibrationSources]:
    """The rig of an import and its record: read from ``calibration`` (sizes it lacks from
    the images and the sequence, said so in the record), or the placeholder rig."""
    from virtus.calib.io import load_calibration_report
    from virtus.calib.sources import uncalibrated_rig
    from virtus.reconstruct import check_baseline

    projector_size = (seq.width, seq.height)
    if calibration is None:
        if units is not None:
            raise InputError("--units", "a --calibration whose translations they are", units)
        return uncalibrated_rig(camera_size, projector_size)
    calibration = Path(calibration)
    rig, sources = load_calibration_report(
        calibration, units=units, camera_size=camera_size, projector_size=projector_size
    )
    if (rig.projector.width, rig.projector.height) != projector_size:
        raise InputError(
            "--sequence",
            f"patterns for the calibration's {rig.projector.width}x{rig.projector.height} "
            "px projector",
            f"{seq.width}x{seq.height} px",
        )
    check_baseline(rig, f"calibration {calibration}")
    camera = "--camera-size" if size_given else "the images"
    said = {
        "camera": f"{camera} ({camera_size[0]}x{camera_size[1]})",
        "projector": f"the pattern sequence ({projector_size[0]}x{projector_size[1]})",
    }
    devices = {
        device: dict(values, size=said[device]) if values["size"].startswith("given") else values
        for device, values in (("camera", sources.camera), ("projector", sources.projector))
    }
    return rig, replace(sources, **devices)
