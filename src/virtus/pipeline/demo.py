"""The main job: the paper's sphere experiment with virtually calibrated parameters.

:func:`run_demo` does, on built-in defaults:

1. virtual calibration of the paper's rig with its 18 board poses
   (:func:`virtus.pipeline.calibrate.calibrate_rig`) -> ``DIR/calibration/``;
2. capture of the 100 mm-radius sphere scene with the true rig -> ``DIR/scan/`` (the layout
   of ``virtus capture``, plus ``decoded/``);
3. reconstruction with the *calibrated* parameters -> ``DIR/scan/points.ply`` (metres,
   camera frame);
4. robust sphere fit on the points of the sphere's region of interest
   (:func:`virtus.metrology.sphere.sphere_roi_fit`) -> radius, error, inlier ratio, fit RMS;
   the same fit with the true rig is reported for reference;
5. ``DIR/metrics.json`` (metrics, the config used, provenance) next to the paper's numbers.

When the scanner differs *physically* from the ideal one (its sensor, projector or render
settings differ in a parameter, not only in a name: :func:`ideal_reference`), the same
demo runs again with the ideal sensor and projector in ``DIR/ideal/`` (a demo of its own),
so what the realism costs is measured; ``metrics.json``'s ``ideal_reference`` records
whether it ran and why. The default demo is ideal: one experiment.

``DIR`` is owned by the run (:func:`virtus.io.runs.claim_run`, command ``demo``): another
run's directory is refused unless ``overwrite``; ``resume`` continues an interrupted demo
(finished calibration poses and a complete sphere capture are kept). ``DIR/calibration/``
is the calibration job's own run directory (its ``run.json``), owned by the demo's run.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from virtus import paper
from virtus.capture.scandir import SCAN_LAYOUT
from virtus.io.runs import RunDirectory, claim_run
from virtus.metrology import SphereFit, sphere_roi_fit
from virtus.pipeline.scan import ScanSettings, scan_into
from virtus.reconstruct import check_baseline, reconstruct
from virtus.scanner import Scanner

__all__ = ["IDEAL_DIR", "PAPER", "DemoConfig", "DemoResult", "IdealReference",
           "ideal_reference", "run_demo"]  # fmt: skip

#: The paper's reported numbers.
PAPER = paper.DEMO
#: What the demo promises (issue "End to end").
TARGETS = {"radius_error_mm": 0.05, "inlier_ratio": 0.98, "total_s": 120.0}
#: The job's name in ``run.json``.
COMMAND = "demo"
#: Sub-directories: the calibration run and the sphere scan.
CALIBRATION_DIR = "calibration"
SCAN_DIR = "scan"
#: Sub-directory of the ideal reference (a demo of its own), run for a realistic scanner.
IDEAL_DIR = "ideal"
METRICS_FILE = "metrics.json"
ERROR_MAP_FILE = f"{SCAN_DIR}/sphere_radial_error.npy"
#: Files of the job (an earlier run's when found without a ``run.json``).
LAYOUT = (
    METRICS_FILE,
    ERROR_MAP_FILE,
    f"{CALIBRATION_DIR}/calibration.json",
    *(f"{SCAN_DIR}/{pattern}" for pattern in SCAN_LAYOUT),
)


@dataclass(frozen=True)
class DemoConfig:
    """Settings of :func:`run_demo` (written to ``metrics.json``)."""

    poses: str = "paper"
    """Calibration board poses: ``"paper"`` (the paper's 18) or ``"random:N"``."""
    board: str = "7x13"
    """Asymmetric circle board ROWSxCOLS."""
    scan: ScanSettings = field(default_factory=ScanSettings)
    """Reconstruction of the sphere."""
    sphere_threshold_m: float = 1e-3
    """MSAC inlier threshold of the sphere fit (m). About 3x the point noise of sharp DMD
    pixels (fit RMS ~0.3 mm): farther points are gross errors (mixed or mis-decoded pixels)."""
    roi_margin: float = 0.1
    """Region of interest: points within ``(1 + roi_margin) * r`` of the scene's nominal
    sphere centre are the sphere's (an operator's crop; the fit itself is free)."""
    seed: int = 0
    """Seed of the random parts (pose sets ``random:N``, RANSAC sampling)."""

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["scan"] = self.scan.to_dict()
        return data


@dataclass(frozen=True, eq=False)
class DemoResult:
    """Outcome of :func:`run_demo`: ``metrics`` is the content of ``metrics.json``;
    ``reference`` the ideal reference's (``DIR/ideal/metrics.json``), or None where it did
    not run."""

    out_dir: Path
    metrics: dict[str, Any]
    sphere: SphereFit
    calibration: Any
    reference: dict[str, Any] | None = None


#: Keys of a device model's ``to_dict`` that are labels, not physics (never compared).
_LABELS = frozenset({"name"})


@dataclass(frozen=True)
class IdealReference:
    """Whether a demo's scanner needs the ideal reference beside it (:func:`ideal_reference`).

    Attributes
    ----------
    scanner : the ideal scanner: the same rig, sequence, spp and variant, with the ideal
        sensor and projector (:class:`~virtus.sensor.camera.Sensor` and
        :class:`~virtus.sensor.projector.ProjectorModel` defaults), direct light, pinholes.
    differences : the physical parameters in which the demo's scanner differs from it, as
        ``"sensor.dark_noise_e: 6.8 (ideal: 0.0)"``; empty when it is the ideal one.
    """

    scanner: Scanner
    differences: tuple[str, ...]

    @property
    def needed(self) -> bool:
        """Whether the scanner differs physically from the ideal one."""
        return bool(self.differences)

    @property
    def reason(self) -> str:
        """Why the reference runs or not, in words."""
        if not self.needed:
            return (
                "the scanner is physically the ideal one: its sensor, projector and render "
                "settings equal the ideal models parameter by parameter (names are not compared)"
            )
        shown = "; ".join(self.differences[:8])
        more = f"; and {len(self.differences) - 8} more" if len(self.differences) > 8 else ""
        return f"the scanner differs physically from the ideal one: {shown}{more}"

    def to_dict(self, ran: bool) -> dict[str, Any]:
        """The record in ``metrics.json`` (``ideal_reference``)."""
        return {
            "ran": ran,
            "reason": self.reason,
            "differences": list(self.differences),
            "metrics": f"{IDEAL_DIR}/{METRICS_FILE}" if ran else None,
        }


def ideal_reference(scanner: Scanner) -> IdealReference:
    """The ideal scanner of ``scanner`` and the physical parameters in which they differ:
    the sensor's, the projector's (``to_dict`` less their ``name``, a label) and the render
    settings'. A sensor named ``"ideal"`` with every default parameter is the ideal sensor;
    a sensor named ``"ideal"`` with a noise parameter changed is not."""
    render = scanner.render.with_(
        bounces=1, projector_lens=None, camera_lens=None, aperture_samples=None
    )
    ideal = Scanner(rig=scanner.rig, sequence=scanner.sequence, render=render)
    differences: list[str] = []
    for part in ("sensor", "projector"):
        mine = getattr(scanner, part).to_dict()
        base = getattr(ideal, part).to_dict()
        differences += [
            f"{part}.{key}: {mine.get(key)!r} (ideal: {base.get(key)!r})"
            for key in sorted((set(mine) | set(base)) - _LABELS)
            if mine.get(key) != base.get(key)
        ]
    mine, base = scanner.render.to_dict(), render.to_dict()
    differences += [
        f"render.{key}: {mine[key]!r} (ideal: {base[key]!r})"
        for key in mine
        if mine[key] != base[key]
    ]
    return IdealReference(ideal, tuple(differences))


def run_demo(
    out_dir: str | Path = "virtus-demo",
    config: DemoConfig | None = None,
    *,
    progress: Any = None,
    scanner: Scanner | None = None,
    overwrite: bool = False,
    resume: bool = False,
    reference: bool = True,
) -> DemoResult:
    """Calibrate, capture the sphere, reconstruct with the calibration, fit, report.

    Parameters
    ----------
    out_dir : output directory, owned by the run (see the module docstring).
    config : settings (defaults reproduce the paper's experiment).
    scanner : the virtual scanner that captures the board poses and the sphere -- one
        sensor model for both (default: the paper's system, sharp DMD pixels).
    progress : optional ``progress(step: str)`` callback, and ``progress(step, done, total)``
        during calibration.
    overwrite : remove an earlier run's files in ``out_dir`` first.
    resume : continue the demo in ``out_dir`` (same settings).
    reference : run the ideal reference in ``DIR/ideal/`` when the scanner differs physically
        from the ideal one (:func:`ideal_reference`); ``metrics.json`` records whether it
        ran and why either way.

    Returns
    -------
    :class:`DemoResult`; ``DIR/metrics.json``, ``DIR/calibration/calibration.json`` and
    ``DIR/scan/`` written (and ``DIR/ideal/`` where the reference ran).
    """
    from virtus.pipeline.calibrate import check_pose_spec

    config = config or DemoConfig()
    scanner = scanner or Scanner()
    check_pose_spec(config.poses)
    check_baseline(scanner.rig)
    scanner.check()
    run_config = {"config": config.to_dict(), "scanner": scanner.to_dict()}
    decision = ideal_reference(scanner)
    with claim_run(
        out_dir, COMMAND, run_config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        result = _run(run, config, scanner, progress)
        metrics = dict(result.metrics)
        ideal = None
        if reference and decision.needed:
            (progress or (lambda *args: None))("ideal reference")
            start = time.perf_counter()
            ideal = run_demo(
                run.path / IDEAL_DIR, config, progress=progress, scanner=decision.scanner,
                overwrite=not run.resumed, resume=run.resumed, reference=False,
            ).metrics  # fmt: skip
            metrics["timing"] = {
                **metrics["timing"],
                "ideal_reference_s": round(time.perf_counter() - start, 3),
            }
        record = decision.to_dict(ran=ideal is not None)
        if decision.needed and not reference:
            record["reason"] = f"not requested (reference=False); {decision.reason}"
        metrics["ideal_reference"] = record
        run.write_json(METRICS_FILE, metrics, allow_nan=True)
        return replace(result, metrics=metrics, reference=ideal)


def _run(run: RunDirectory, config: DemoConfig, scanner: Scanner, progress: Any) -> DemoResult:
    """The demo's steps inside its claimed directory (see :func:`run_demo`)."""
    from virtus.pipeline.calibrate import calibrate_rig
    from virtus.scene.model import SphereObject, default_scene

    root = run.path
    say = progress or (lambda *args: None)
    t_start = time.perf_counter()
    timing: dict[str, float] = {}

    true_rig = scanner.rig
    say("calibration")
    start = time.perf_counter()
    calibration = calibrate_rig(
        scanner,
        board=config.board,
        poses=config.poses,
        rng=config.seed,
        progress=lambda done, total, name: say("calibration", done, total),
        out_dir=root / CALIBRATION_DIR,
        overwrite=not run.resumed,
        resume=run.resumed,
    )
    timing["calibration_s"] = time.perf_counter() - start

    say("scan")
    scene = default_scene()
    sphere = next(o for o in scene.objects if isinstance(o, SphereObject))
    start = time.perf_counter()
    scanned = scan_into(
        run, SCAN_DIR, scene, scanner, check_baseline(calibration.rig, "calibration"), config.scan
    )
    timing["scan_s"] = time.perf_counter() - start

    say("sphere fit")
    start = time.perf_counter()
    fit, error_map = sphere_roi_fit(
        scanned.reconstruction.points,
        sphere.center_m,
        sphere.radius_m,
        roi_margin=config.roi_margin,
        threshold_m=config.sphere_threshold_m,
        rng=config.seed,
    )
    run.write(ERROR_MAP_FILE, lambda tmp: np.save(tmp, error_map))
    timing["fit_s"] = time.perf_counter() - start

    # Reference: the same frames triangulated with the true rig (what calibration costs).
    start = time.perf_counter()
    decoded = scanned.decoded
    reference = reconstruct(
        true_rig,
        decoded.proj_uv,
        decoded.mask,
        use=config.scan.use,
        edge_max_step=config.scan.edge_max_step,
    )
    true_fit, _ = sphere_roi_fit(
        reference.points,
        sphere.center_m,
        sphere.radius_m,
        roi_margin=config.roi_margin,
        threshold_m=config.sphere_threshold_m,
        rng=config.seed,
    )
    timing["reference_s"] = time.perf_counter() - start
    timing["total_s"] = time.perf_counter() - t_start

    radius_true_mm = sphere.radius_m * 1e3
    metrics = {
        "calibration": {
            "camera_rms_px": calibration.rms_px["camera"],
            "projector_rms_px": calibration.rms_px["projector"],
            "stereo_rms_px": calibration.rms_px["stereo"],
            "n_poses": len(calibration.poses),
            "dropped_poses": list(calibration.dropped_poses),
            "truth_error": calibration.truth_error,
        },
        "sphere": {
            "radius_true_mm": radius_true_mm,
            "radius_mm": fit.radius * 1e3,
            "radius_error_mm": fit.radius * 1e3 - radius_true_mm,
            "radius_std_mm": fit.radius_std * 1e3,
            "fit_rms_mm": fit.rms * 1e3,
            "inlier_ratio": fit.inlier_ratio,
            "n_points": int(fit.inliers.size),
            "threshold_mm": fit.threshold * 1e3,
            "center_mm": (fit.center * 1e3).tolist(),
            "center_true_mm": [c * 1e3 for c in sphere.center_m],
            "radial_error_histogram_mm": fit.hist.to_dict(1e3),
            "reconstructed_with": "calibrated rig (calibration/calibration.json)",
        },
        "sphere_true_rig": {
            "radius_mm": true_fit.radius * 1e3,
            "radius_error_mm": true_fit.radius * 1e3 - radius_true_mm,
            "fit_rms_mm": true_fit.rms * 1e3,
            "inlier_ratio": true_fit.inlier_ratio,
        },
        "timing": {key: round(value, 3) for key, value in timing.items()}
        | {"scan_steps_s": {k: round(v, 3) for k, v in scanned.timing_s.items()}},
        "paper": PAPER,
        "targets": TARGETS,
        "config": config.to_dict(),
        "scanner": scanner.to_dict(),
        "provenance": _provenance(),
        "files": {
            "calibration": "calibration/calibration.json",
            "capture": "scan/capture.json",
            "points": "scan/points.ply",
            "radial_error_map": "scan/sphere_radial_error.npy",
        },
    }
    return DemoResult(root, metrics, fit, calibration)  # metrics.json: see run_demo


def _provenance() -> dict[str, Any]:
    import os
    import sys
    from importlib.metadata import PackageNotFoundError, version

    versions = {}
    for name in ("virtus-fpp", "numpy", "scipy", "opencv-python-headless", "mitsuba", "drjit",
                 "trimesh"):  # fmt: skip
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = None
    from virtus import __version__

    versions["virtus"] = __version__
    return {
        "versions": versions,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
