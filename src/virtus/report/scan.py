"""Report sections of a capture directory (:mod:`virtus.capture.scandir`): example frames,
the decode (wrapped and absolute phase, modulation, valid and flagged pixels), the sphere's
radial error (the paper's Fig. 5d), cloud-to-mesh distances (Fig. 6c) and the 3D view.

Each function adds one section to a :class:`~virtus.report.html.Page` from files the run
wrote (read with the guarded readers, shapes checked against ``capture.json``); nothing is
recomputed but what a figure needs (a wrapped phase from the absolute one).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import figures
from virtus.report.html import Page
from virtus.report.viewer import pack_cloud

__all__ = [
    "add_c2m",
    "add_capture",
    "add_cloud",
    "add_decode",
    "add_sphere",
    "c2m_rows",
]

#: Frame kinds shown as examples, in order (the first frame of each kind found).
_EXAMPLE_KINDS = ("phase", "gray", "binary", "white", "black")


def _capture_json(path: Path) -> dict[str, Any]:
    from virtus.report.runs import read_run_json

    return read_run_json(path, "capture.json", "capture description", ("rig", "sequence"))


def _size(capture: dict[str, Any]) -> tuple[int, int]:
    camera = capture["rig"].get("camera", {}) if isinstance(capture["rig"], dict) else {}
    return int(camera.get("height", 0)), int(camera.get("width", 0))


def add_capture(page: Page, path: Path, title: str = "Capture") -> None:
    """Example frames of the capture (one per frame kind) and its description."""
    from virtus.capture.capture import Capture
    from virtus.io.images import read_image

    capture = Capture.load(path)
    section = page.section(title)
    described = capture.sequence.to_dict()["frames"]
    shown: set[str] = set()
    for index, frame in enumerate(described):
        kind = f"{frame.get('kind')}"
        if kind not in _EXAMPLE_KINDS or kind in shown or index >= len(capture.frame_files):
            continue
        shown.add(kind)
        image = read_image(capture.frame_files[index])
        detail = ", ".join(
            f"{k} {v}" for k, v in frame.items() if k in ("direction", "period", "step", "bit")
        )
        section.figure(
            f"frame-{kind}",
            figures.image_map(
                image,
                "intensity",
                f"frame {index}: {kind}",
                limits=(0.0, float(capture.full_scale)),
            ),  # fmt: skip
            f"Captured frame {index} ({kind}{', ' + detail if detail else ''}), digital numbers "
            f"(full scale {capture.full_scale}).",
        )
    camera = capture.rig.camera.intrinsics
    section.table(
        "capture",
        [
            ("camera image (W x H px)", f"{camera.width} x {camera.height}"),
            ("frames", len(capture.frame_files)),
            ("bit depth", capture.bit_depth),
            ("seed", capture.seed),
            ("ground truth", capture.has_ground_truth),
        ],
    )


def _load_map(path: Path, name: str, shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    from virtus.io.safeio import load_npy

    return load_npy(path / name, name, dtype=dtype, shape=shape)


def add_decode(page: Page, path: Path, title: str = "Decode") -> dict[str, Any] | None:
    """Phase maps, modulation and masks of ``decoded/`` with its summary; a note when the
    capture was not decoded. Returns the decode summary (or None)."""
    from virtus.capture import scandir

    section = page.section(title)
    folder = path / scandir.DECODED_DIR
    if not (folder / scandir.DECODED_SOURCE).is_file():
        section.note(f"Not decoded: run `virtus decode {path}` and report again.")
        return None
    height, width = _size(_capture_json(path))
    maps = {
        name: _load_map(folder, f"{name}.npy", (height, width), np.float64)
        for name in ("phase_v", "phase_h", "modulation")
    }
    mask = _load_map(folder, "mask.npy", (height, width), bool)
    flagged = _load_map(folder, "flagged.npy", (height, width), bool)
    summary = _decode_summary(folder)
    for direction, label in (("v", "vertical fringes"), ("h", "horizontal fringes")):
        phase = maps[f"phase_{direction}"]
        wrapped = np.angle(np.exp(1j * phase))
        section.figure(
            f"wrapped-phase-{direction}",
            figures.image_map(
                wrapped, "wrapped_phase", f"wrapped phase, {label}", limits=(-np.pi, np.pi)
            ),  # fmt: skip
            f"Wrapped phase of the {label}, rad in [-pi, pi); grey: not decoded.",
        )
        section.figure(
            f"absolute-phase-{direction}",
            figures.image_map(phase, "absolute_phase", f"absolute phase, {label}"),
            f"Absolute (unwrapped) phase of the {label}, rad: 2 pi u_p / T.",
        )
    section.figure(
        "modulation",
        figures.image_map(maps["modulation"], "modulation", "fringe modulation B"),
        "Fringe amplitude B (DN): low where the surface is dark, shadowed or oblique.",
    )
    section.figure(
        "valid-and-flagged",
        figures.mask_overlay(
            maps["modulation"],
            [(mask & ~flagged, "#2ca02c", "valid"), (flagged, "#d62728", "flagged")],
            "valid and flagged pixels",
        ),
        "Green: decoded in every direction; red: valid but with a suspect fringe order.",
    )
    if summary:
        section.table("decode summary (shares of the image)", summary)
    return summary


def _decode_summary(folder: Path) -> dict[str, Any]:
    from virtus.capture import scandir
    from virtus.io.safeio import read_json

    file = folder / scandir.DECODE_SUMMARY
    return read_json(file, "decode summary", expect=dict) if file.is_file() else {}


def add_sphere(
    page: Page, sphere: dict[str, Any], error_map_m: np.ndarray | None, title: str = "Sphere"
) -> None:
    """The sphere fit as the paper's Fig. 5d shows it: the radial error over the image and
    its histogram with the fit (radius, error, inliers). ``sphere``: the demo's
    ``metrics.json`` ``sphere`` block (mm); ``error_map_m``: (H, W) radial error, metres,
    NaN outside the fit."""
    section = page.section(title)
    if error_map_m is not None:
        section.figure(
            "radial-error-map",
            figures.image_map(
                error_map_m * 1e3,
                "signed_error",
                "sphere radial error",
                limits=(-sphere["threshold_mm"], sphere["threshold_mm"]),
            ),  # fmt: skip
            "Radial distance of each point to the fitted sphere minus its radius (mm), over "
            "the camera image; grey: not on the sphere or outside the fit's region.",
        )
    hist = sphere.get("radial_error_histogram_mm")
    if isinstance(hist, dict) and "counts" in hist and "edges" in hist:
        note = (
            f"radius {sphere['radius_mm']:.4f} mm (true {sphere['radius_true_mm']:.1f})\n"
            f"error {sphere['radius_error_mm']:+.4f} mm\n"
            f"fit RMS {sphere['fit_rms_mm']:.4f} mm\n"
            f"inliers {sphere['inlier_ratio']:.2%} of {sphere['n_points']}"
        )
        threshold = sphere["threshold_mm"]
        section.figure(
            "radial-error-histogram",
            figures.histogram_chart(
                hist["counts"],
                hist["edges"],
                "radial error (mm)",
                "sphere radial error",
                marks=((-threshold, "inlier threshold"), (threshold, "")),
                note=note,
            ),  # fmt: skip
            "Histogram of the radial errors with the fitted radius, its error against the "
            "true sphere and the inlier share (the paper's Fig. 5d).",
        )
    section.table("sphere fit (mm)", {k: v for k, v in sphere.items()
                                      if k != "radial_error_histogram_mm"})  # fmt: skip


def c2m_rows(evaluation: dict[str, Any]) -> list[list[Any]]:
    """One row per mesh: name, points, MAE, RMSE, mean, p50/p95/p99 and max |d| (mm)."""
    rows = []
    for mesh in evaluation.get("meshes", []):
        rows.append([Path(str(mesh.get("mesh", "?"))).name, mesh.get("n_points"),
                     mesh.get("mae_mm"), mesh.get("rmse_mm"), mesh.get("mean_mm"),
                     mesh.get("p50_abs_mm"), mesh.get("p95_abs_mm"), mesh.get("p99_abs_mm"),
                     mesh.get("max_abs_mm")])  # fmt: skip
    return rows


def add_c2m(
    page: Page,
    entries: list[dict[str, Any]],
    title: str,
    paper_mae_mm: float,
    registration: str = "after ICP",
) -> None:
    """Cloud-to-mesh histograms and percentiles (the paper's Fig. 6c), one per mesh entry
    (``evaluation.json``'s ``meshes``, a turntable's ``c2m``, a robot scan's); the captions
    say how the cloud was registered to the mesh (``registration``)."""
    section = page.section(title)
    for index, entry in enumerate(entries):
        hist = entry.get("histogram_mm", {})
        if not ("counts" in hist and "edges" in hist):
            continue
        name = Path(str(entry.get("mesh", f"mesh {index}"))).name
        note = (
            f"MAE {entry['mae_mm']:.4f} mm\nRMSE {entry['rmse_mm']:.4f} mm\n"
            f"p95 |d| {entry['p95_abs_mm']:.4f} mm\npaper MAE {paper_mae_mm:.2f} mm"
        )
        section.figure(
            f"c2m-histogram-{index}",
            figures.histogram_chart(
                hist["counts"],
                hist["edges"],
                "signed distance to the mesh (mm)",
                f"cloud-to-mesh distance: {name}",
                marks=((entry.get("mean_mm", 0.0), "mean"),),
                note=note,
            ),  # fmt: skip
            f"Signed cloud-to-mesh distances of {entry.get('n', entry.get('n_points'))} points "
            f"against {name} {registration} (the paper's Fig. 6c).",
        )
    header = ["mesh", "points", "MAE", "RMSE", "mean", "p50 |d|", "p95 |d|", "p99 |d|", "max |d|"]
    rows = c2m_rows({"meshes": entries})
    section.grid("cloud-to-mesh distance (mm)", header, rows)


def add_cloud(
    page: Page,
    points_m: np.ndarray,
    values: np.ndarray | None,
    quantity: str,
    title: str = "3D view",
    caption: str = "point cloud",
    limits: tuple[float, float] | None = None,
) -> None:
    """The interactive 3D view of a cloud coloured by ``values`` (in ``quantity``'s unit;
    None: by depth), on the colour scale ``limits`` (default: from the values)."""
    section = page.section(title)
    section.cloud("cloud", pack_cloud(points_m, values, quantity, limits=limits), caption)
