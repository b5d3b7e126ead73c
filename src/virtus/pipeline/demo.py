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

``DIR`` is owned by the run (:func:`virtus.io.runs.claim_run`, command ``demo``): another
run's directory is refused unless ``overwrite``; ``resume`` continues an interrupted demo
(finished calibration poses and a complete sphere capture are kept). ``DIR/calibration/``
is the calibration job's own run directory (its ``run.json``), owned by the demo's run.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field
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

__all__ = ["PAPER", "DemoConfig", "DemoResult", "run_demo"]

#: The paper's reported numbers.
PAPER = paper.DEMO
#: What the demo promises (issue "End to end").
TARGETS = {"radius_error_mm": 0.05, "inlier_ratio": 0.98, "total_s": 120.0}
#: The job's name in ``run.json``.
COMMAND = "demo"
#: Sub-directories: the calibration run and the sphere scan.
CALIBRATION_DIR = "calibration"
SCAN_DIR = "scan"
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
    """Outcome of :func:`run_demo`: ``metrics`` is the content of ``metrics.json``."""

    out_dir: Path
    metrics: dict[str, Any]
    sphere: SphereFit
    calibration: Any


def run_demo(
    out_dir: str | Path = "virtus-demo",
    config: DemoConfig | None = None,
    *,
    progress: Any = None,
    scanner: Scanner | None = None,
    overwrite: bool = False,
    resume: bool = False,
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

    Returns
    -------
    :class:`DemoResult`; ``DIR/metrics.json``, ``DIR/calibration/calibration.json`` and
    ``DIR/scan/`` written.
    """
    from virtus.pipeline.calibrate import check_pose_spec

    config = config or DemoConfig()
    scanner = scanner or Scanner()
    check_pose_spec(config.poses)
    check_baseline(scanner.rig)
    scanner.check()
    run_config = {"config": config.to_dict(), "scanner": scanner.to_dict()}
    with claim_run(
        out_dir, COMMAND, run_config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        return _run(run, config, scanner, progress)


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
    run.write_json(METRICS_FILE, metrics, allow_nan=True)
    return DemoResult(root, metrics, fit, calibration)


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
