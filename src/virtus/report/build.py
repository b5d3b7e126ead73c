"""``virtus report``: one self-contained HTML page for the directory of any run.

:func:`write_report` checks the directory (:func:`virtus.report.runs.check_run`), builds the
page for its kind in memory, and only then writes it (atomically), so a refused directory
leaves nothing behind. What each kind shows:

* every kind: the run's record (command, status, virtus version), configuration, scanner
  and, where the run keeps them, timings and versions;
* ``demo``: links between its parts, the metrics beside the paper, the calibration, the
  sphere scan's frames and decode, the sphere's radial error (Fig. 5d) and the 3D view
  coloured by radial error;
* ``calibrate``: :mod:`virtus.report.calibration`;
* ``capture`` / ``scan`` (and ``decode``, ``reconstruct``, ``evaluate`` in them): frames,
  decode, the fit of the scene's sphere as the demo fits it (Fig. 5d) when there is one,
  C2M (Fig. 6c) when evaluated, the 3D view (coloured by C2M distance when evaluated, else
  by depth);
* ``turntable``: merged-cloud C2M and 3D view; ``ablation``, ``twin``, ``dataset``:
  :mod:`virtus.report.others`;
* ``acceptance``, ``predict``, ``design``: :mod:`virtus.report.design`; ``robot-scan``:
  :mod:`virtus.report.robot`; ``learn`` (train, and the evaluations in it):
  :mod:`virtus.report.learn`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import design, learn, others, robot, scan
from virtus.report.calibration import add_calibration
from virtus.report.html import Page
from virtus.report.runs import RunInfo, check_run, read_run_json

__all__ = ["REPORT_FILE", "Report", "build_page", "describe", "write_report"]

#: The report's file name inside a run directory (the default output).
REPORT_FILE = "report.html"


@dataclass(frozen=True)
class Report:
    """A written report: its file, the run's kind, the ids of its figures and its size."""

    path: Path
    kind: str
    figures: tuple[str, ...]
    n_bytes: int


def _record_section(page: Page, info: RunInfo) -> None:
    section = page.section("Run record", "run")
    record = info.record
    section.table(
        "run",
        [("directory", str(info.path)), ("kind", info.kind), ("command", info.command),
         ("status", record.get("status", "-")),
         ("virtus version", record.get("virtus_version", "-"))],
    )  # fmt: skip
    config = record.get("config")
    if isinstance(config, dict) and config:
        scanner = config.get("scanner")
        rest = {k: v for k, v in config.items() if k != "scanner"}
        if rest:
            section.table("configuration", rest)
        if isinstance(scanner, dict):
            section.table("scanner", {k: v for k, v in scanner.items() if k != "sequence"})
    timing = info.path / "timing.json"
    if timing.is_file():
        section.table("timing (s)", read_run_json(info.path, "timing.json", "timing"))


def _points_map(path: Path) -> np.ndarray:
    """``reconstruction/points.npy`` of a capture directory, (H, W, 3) metres."""
    from virtus.io.safeio import load_npy

    capture = read_run_json(path, "capture.json", "capture description", ("rig",))
    camera = capture["rig"]["camera"]
    return load_npy(
        path / "reconstruction" / "points.npy",
        "reconstructed points",
        dtype=np.float64,
        shape=(int(camera["height"]), int(camera["width"]), 3),
    )


def _demo(page: Page, info: RunInfo) -> None:
    from virtus.io.safeio import load_npy

    path = info.path
    metrics = read_run_json(path, "metrics.json", "demo metrics",
                            ("calibration", "sphere", "timing"))  # fmt: skip
    links = page.section("Parts of the demo", "parts")
    files = ["metrics.json", "calibration/calibration.json", "scan/capture.json",
             "scan/points.ply", "ideal/metrics.json", "ideal/report.html"]  # fmt: skip
    links.links("files of the run (open beside this page; ideal/: the ideal reference, when "
                "it ran)", [(name, name) for name in files if (path / name).is_file()])  # fmt: skip
    results = page.section("Results beside the paper", "results")
    results.table("calibration", {k: v for k, v in metrics["calibration"].items()
                                  if k != "truth_error"})  # fmt: skip
    results.table("paper", metrics.get("paper", {}))
    results.table("targets", metrics.get("targets", {}))
    results.table("timing (s)", metrics["timing"])
    if metrics.get("sphere_true_rig"):
        results.table("sphere reconstructed with the true rig (mm)", metrics["sphere_true_rig"])
    versions = metrics.get("provenance", {}).get("versions")
    if isinstance(versions, dict):
        results.table("versions", versions)
    add_calibration(page, path / "calibration", "Calibration")
    scan.add_capture(page, path / "scan", "Sphere scan: frames")
    scan.add_decode(page, path / "scan", "Decode")
    shape = _points_map(path / "scan").shape[:2]
    error = load_npy(path / "scan" / "sphere_radial_error.npy", "sphere radial error map",
                     dtype=np.float64, shape=shape)  # fmt: skip
    scan.add_sphere(page, metrics["sphere"], error, "Sphere fit")
    threshold = float(metrics["sphere"]["threshold_mm"])
    points = _points_map(path / "scan").reshape(-1, 3)
    scan.add_cloud(
        page,
        points,
        error.reshape(-1) * 1e3,
        "signed_error",
        "3D view",
        "reconstructed points; colour: sphere radial error, grey: not on the sphere",
        limits=(-threshold, threshold),  # the error map's scale
    )
    # the page's own parts (known now that they are built) before the files
    later = page.sections[page.sections.index(links) + 1 :]
    files = links.blocks.pop()
    links.links("parts of this page", [(part.title, f"#{part.key}") for part in later])
    links.blocks.append(files)


def _capture_like(page: Page, info: RunInfo) -> None:
    from virtus.io.ply import read_ply
    from virtus.paper import C2M_MAE_MM

    path = info.path
    scan.add_capture(page, path, "Frames")
    scan.add_decode(page, path, "Decode")
    if (path / "reconstruction" / "points.npy").is_file():
        fitted = _scene_sphere_fit(path)
        if fitted is not None:
            scan.add_sphere(page, *fitted, "Sphere fit")
    evaluation = path / "evaluation.json"
    data = None
    if evaluation.is_file():
        data = read_run_json(path, "evaluation.json", "evaluation", ("meshes",))
        scan.add_c2m(page, list(data["meshes"]), "Cloud-to-mesh distance", C2M_MAE_MM)
    ply = path / "points.ply"
    if ply.is_file():
        points = read_ply(ply).points
        if data is None:
            scan.add_cloud(page, points, None, "depth", "3D view",
                           "points.ply, camera frame; colour: depth")  # fmt: skip
        else:
            scan.add_cloud(page, points, _c2m_values(path, points, data), "signed_error",
                           "3D view", "points.ply, camera frame; colour: signed distance to "
                           "the mesh after ICP, grey: not near a mesh")  # fmt: skip
    else:
        page.section("3D view").note(f"Not reconstructed: run `virtus reconstruct {path}`.")


#: Sphere fit of a scan (the demo's settings): region of interest and inlier threshold.
_SPHERE_ROI_MARGIN = 0.1
_SPHERE_THRESHOLD_M = 1e-3


def _scene_sphere_fit(path: Path) -> tuple[dict[str, Any], np.ndarray] | None:
    """The fit of the first sphere of a rendered scan's scene to its reconstruction, as the
    demo fits it (its ``metrics.json`` ``sphere`` block, mm, and the (H, W) radial error
    map, m); None when the scene has no sphere."""
    from virtus.capture.capture import Capture
    from virtus.metrology import sphere_roi_fit
    from virtus.scene.model import SphereObject

    capture = Capture.load(path)
    objects = capture.scene.all_objects() if capture.scene is not None else []
    sphere = next((o for o in objects if isinstance(o, SphereObject)), None)
    if sphere is None:
        return None
    centre_cam = capture.cam2world.inverse().apply(np.asarray([sphere.center_m]))[0]
    fit, error_map = sphere_roi_fit(_points_map(path), centre_cam, sphere.radius_m,
                                    roi_margin=_SPHERE_ROI_MARGIN,
                                    threshold_m=_SPHERE_THRESHOLD_M, rng=0)  # fmt: skip
    radius_true_mm = sphere.radius_m * 1e3
    block = {
        "radius_true_mm": radius_true_mm,
        "radius_mm": fit.radius * 1e3,
        "radius_error_mm": fit.radius * 1e3 - radius_true_mm,
        "fit_rms_mm": fit.rms * 1e3,
        "inlier_ratio": fit.inlier_ratio,
        "n_points": int(fit.inliers.size),
        "threshold_mm": fit.threshold * 1e3,
        "center_mm": (fit.center * 1e3).tolist(),
        "center_true_mm": (centre_cam * 1e3).tolist(),
        "radial_error_histogram_mm": fit.hist.to_dict(1e3),
        "reconstructed_with": "the scan's rig (reconstruction/rig.json)",
    }
    return block, error_map


def _c2m_values(path: Path, points: np.ndarray, evaluation: dict[str, Any]) -> np.ndarray:
    """(N,) signed C2M distance (mm) of each point of ``points.ply``, NaN where no mesh is
    near: the evaluation measured again as ``virtus evaluate`` did (same ICP setting), since
    ``evaluation.json`` keeps the statistics, not the distances."""
    from virtus.pipeline.evaluate import MARGIN_M, evaluate_scan

    registered = any(m.get("icp") for m in evaluation["meshes"] if isinstance(m, dict))
    values = np.full(len(points), np.nan)
    for result, mesh in zip(
        evaluate_scan(path, register=registered, save=False), _scene_meshes(path), strict=True
    ):
        low, high = mesh.bounds[0] - MARGIN_M, mesh.bounds[1] + MARGIN_M
        inside = np.all((points >= low) & (points <= high), axis=1)
        values[inside] = result.c2m.distances * 1e3
    return values


def _scene_meshes(path: Path) -> list[Any]:
    from virtus.capture.capture import Capture
    from virtus.pipeline.evaluate import scene_meshes

    return [mesh for _, _, mesh in scene_meshes(Capture.load(path).scene)]


def _turntable(page: Page, info: RunInfo) -> None:
    from virtus.io.ply import read_ply
    from virtus.paper import C2M_MAE_MM

    data = read_run_json(info.path, "turntable.json", "turntable summary", ("n_views",))
    section = page.section("Turntable")
    section.table("views", {k: v for k, v in data.items() if k not in ("c2m", "object2cam")})
    if isinstance(data.get("c2m"), dict):
        entry = dict(data["c2m"], mesh="merged cloud")
        scan.add_c2m(page, [entry], "Cloud-to-mesh distance (merged)", C2M_MAE_MM)
    cloud = read_ply(info.path / "merged.ply")
    scan.add_cloud(page, cloud.points, None, "depth", "3D view",
                   "merged.ply, object frame; colour: z")  # fmt: skip


def _of_path(add: Callable[[Page, Path], None]) -> Callable[[Page, RunInfo], None]:
    """A builder for a kind whose section needs only the run's directory."""
    return lambda page, info: add(page, info.path)


def _predict(page: Page, info: RunInfo) -> None:
    design.add_predict(page, info.path, info.record)


_BUILDERS = {
    "demo": _demo,
    "calibrate": lambda page, info: add_calibration(page, info.path, "Calibration"),
    "capture": _capture_like,
    "scan": _capture_like,
    "turntable": _turntable,
    "ablation": _of_path(others.add_ablation),
    "twin": _of_path(others.add_twin),
    "dataset": _of_path(others.add_dataset),
    "acceptance": _of_path(design.add_acceptance),
    "predict": _predict,
    "design": _of_path(design.add_design),
    "robot-scan": _of_path(robot.add_robot_scan),
    "learn": _of_path(learn.add_learn),
}

_TITLES = {
    "demo": "virtus demo: the paper's sphere experiment",
    "calibrate": "virtus calibrate",
    "capture": "virtus capture",
    "scan": "virtus scan",
    "turntable": "virtus scan --turntable",
    "ablation": "virtus ablation",
    "twin": "virtus twin",
    "dataset": "virtus dataset",
    "acceptance": "virtus acceptance: a virtual VDI/VDE 2634-2 test",
    "predict": "virtus predict: the scanner's predicted noise",
    "design": "virtus design: a sweep of scanner designs",
    "robot-scan": "virtus robot-scan",
    "learn": "virtus learn: a trained fringe-analysis network",
}


def build_page(run_dir: str | Path) -> tuple[Page, RunInfo]:
    """Check ``run_dir`` and build its page in memory (nothing is written)."""
    info = check_run(run_dir)
    page = Page(_TITLES[info.kind], f"report of {info.path.name or info.path}")
    _BUILDERS[info.kind](page, info)
    _record_section(page, info)
    return page, info


def write_report(run_dir: str | Path, out: str | Path | None = None) -> Report:
    """Write the report of ``run_dir`` to ``out`` (default ``run_dir/report.html``).

    Raises
    ------
    InputError : the directory is not a run, a half-finished one, or one whose files were
        changed (:func:`virtus.report.runs.check_run`); ``out`` is not a ``.html`` path in
        an existing directory. Nothing is written then.
    """
    from virtus.errors import InputError
    from virtus.io.runs import atomic_write

    target = Path(out) if out is not None else Path(run_dir) / REPORT_FILE
    if target.suffix.lower() not in (".html", ".htm"):
        raise InputError("--out", "a .html file", str(target))
    if not target.parent.is_dir():
        raise InputError("--out", "a file in an existing directory", str(target))
    page, info = build_page(run_dir)
    text = page.render().encode("utf-8")
    atomic_write(target, lambda tmp: tmp.write_bytes(text))
    return Report(target, info.kind, tuple(page.figures), len(text))


def describe(report: Report) -> dict[str, Any]:
    """JSON-ready summary of a written report."""
    return {"path": str(report.path), "kind": report.kind, "figures": len(report.figures),
            "bytes": report.n_bytes}  # fmt: skip
