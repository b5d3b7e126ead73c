"""Ablation: what each surface, light and sensor effect does to a measurement, cell by cell.

Like the paper code's ablation mode (materials x ambient light), but measured: every cell
renders the paper's 100 mm-radius sphere before a wall with one material, one ambient level
and one realism setting, decodes it, and reports

* the decoded projector-coordinate error against the exact ground truth (px RMS, and as
  phase of the finest period, rad RMS), over pixels valid in both and away from depth
  discontinuities (a silhouette pixel mixes two surfaces: that is sampling, not an effect),
  and the share of those pixels off by half a period or more (order errors);
* the sphere fit of the points triangulated with the true rig (radius error, fit RMS,
  inlier ratio), so the effect on a metrology result is seen, not just on the phase.

The table is written as ``ablation.csv`` and ``ablation.json`` and drawn as
``ablation.png`` (radius error and phase error per cell).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, VirtusError
from virtus.jsonio import write_json
from virtus.pipeline.demo import sphere_roi_fit
from virtus.pipeline.scan import EDGE_MAX_STEP, reconstruct
from virtus.projection import PROJECTOR_PRESETS
from virtus.reconstruct import depth_edge_mask
from virtus.scanner import Scanner
from virtus.sensor import SENSOR_PRESETS

#: Sphere materials: (roughness, specular, metal) of :class:`virtus.scene.Material`.
MATERIALS: dict[str, dict[str, Any]] = {
    "matte": {"roughness": 0.95, "specular": 0.15},
    "glossy": {"roughness": 0.3, "specular": 0.8},
    "metal": {"roughness": 0.3, "metal": True},
    "reflective": {"roughness": 0.05, "metal": True},
}
#: Ambient light levels (relative radiance: 1 = a white projector on albedo 1 at 1 m).
AMBIENTS = {"dark": 0.0, "ambient": 0.3}
#: Realism settings: each changes the scanner from the ideal one.
REALISM: dict[str, Callable[[Scanner], Scanner]] = {
    "ideal": lambda s: s,
    "sensor": lambda s: s.with_(sensor=SENSOR_PRESETS["imx174"]),
    "gamma": lambda s: s.with_(
        projector=PROJECTOR_PRESETS["lightcrafter"].with_(precompensate=False)
    ),
    "projector": lambda s: s.with_(projector=PROJECTOR_PRESETS["lightcrafter"]),
    "interreflection": lambda s: s.with_(bounces=2),
    "all": lambda s: s.with_(
        sensor=SENSOR_PRESETS["imx174"], projector=PROJECTOR_PRESETS["lightcrafter"], bounces=2
    ),
}
#: Columns of the table, in order.
COLUMNS = (
    "material", "ambient", "realism", "valid_fraction", "proj_error_rms_px", "phase_error_rms_rad",
    "order_error_fraction", "flagged_fraction", "radius_error_mm", "fit_rms_mm", "inlier_ratio",
    "note",
)  # fmt: skip


@dataclass(frozen=True)
class AblationCell:
    """One cell's setting."""

    material: str
    ambient: str
    realism: str


def _choose(names: list[str] | None, table: dict[str, Any], what: str) -> list[str]:
    if names is None:
        return list(table)
    unknown = [n for n in names if n not in table]
    if unknown or not names:
        raise InputError(what, f"names among {list(table)}", unknown or names)
    return list(dict.fromkeys(names))


def sphere_scene(material: str, ambient: str) -> Any:
    """The demo's scene (100 mm sphere at 1 m before a wall) with this sphere material and
    ambient level."""
    from virtus.scene import Material, Scene, SphereObject, default_scene

    base = default_scene()
    sphere = next(o for o in base.objects if isinstance(o, SphereObject))
    dressed = SphereObject(
        radius_m=sphere.radius_m, center_m=sphere.center_m, material=Material(**MATERIALS[material])
    )
    return Scene(objects=(dressed,), background=base.background, ambient=AMBIENTS[ambient])


def run_cell(scanner: Scanner, cell: AblationCell, *, seed: int = 0) -> dict[str, Any]:
    """Render, decode and measure one cell (see the module docstring)."""
    from virtus.scene import SphereObject

    scene = sphere_scene(cell.material, cell.ambient)
    configured = REALISM[cell.realism](scanner)
    capture = configured.capture(scene, rng=seed)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a flagged decode is a result here, not a problem
        decoded = capture.decode()
    gt = capture.ground_truth
    edges = depth_edge_mask(gt.points, scanner.rig.camera.intrinsics.fx, EDGE_MAX_STEP)
    both = decoded.mask & gt.mask & ~edges
    row: dict[str, Any] = {"material": cell.material, "ambient": cell.ambient,
                           "realism": cell.realism, "note": ""}  # fmt: skip
    row["valid_fraction"] = float(decoded.mask[gt.mask].mean()) if gt.mask.any() else 0.0
    row["flagged_fraction"] = float(decoded.flagged[decoded.mask].mean()) if both.any() else 0.0
    nan = float("nan")
    if both.any():
        error = decoded.proj_uv[both] - gt.proj_uv[both]
        period = min(p for d in capture.sequence.directions for p in capture.sequence.periods(d))
        row["proj_error_rms_px"] = float(np.sqrt(np.mean(error**2)))
        row["phase_error_rms_rad"] = row["proj_error_rms_px"] * 2 * np.pi / period
        row["order_error_fraction"] = float(np.mean(np.abs(error).max(axis=1) >= period / 2))
    else:
        row.update(proj_error_rms_px=nan, phase_error_rms_rad=nan, order_error_fraction=nan)
    sphere = next(o for o in scene.objects if isinstance(o, SphereObject))
    try:
        recon = reconstruct(scanner.rig, decoded.proj_uv, decoded.mask)
        fit, _ = sphere_roi_fit(recon, sphere.center_m, sphere.radius_m, rng=seed)
        row.update(
            radius_error_mm=(fit.radius - sphere.radius_m) * 1e3,
            fit_rms_mm=fit.rms * 1e3,
            inlier_ratio=fit.inlier_ratio,
        )
    except VirtusError as error:  # e.g. a mirror sphere returns too few points
        row.update(radius_error_mm=nan, fit_rms_mm=nan, inlier_ratio=nan, note=str(error))
    return row


def run_ablation(
    out_dir: str | Path,
    scanner: Scanner | None = None,
    *,
    materials: list[str] | None = None,
    ambients: list[str] | None = None,
    realism: list[str] | None = None,
    seed: int = 0,
    progress: Callable[[int, int, AblationCell], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every cell of materials x ambient levels x realism settings.

    Parameters
    ----------
    out_dir : directory for ``ablation.csv``, ``ablation.json`` and ``ablation.png``.
    scanner : the ideal scanner the realism settings modify (default: the paper's system).
    materials, ambients, realism : names to run (default: all of :data:`MATERIALS`,
        :data:`AMBIENTS`, :data:`REALISM`).
    seed : seed of the noise streams and the sphere fit.
    progress : called before each cell as ``progress(index, total, cell)``.

    Returns
    -------
    One dict per cell with :data:`COLUMNS`.
    """
    scanner = scanner or Scanner()
    cells = [
        AblationCell(m, a, r)
        for m in _choose(materials, MATERIALS, "materials")
        for a in _choose(ambients, AMBIENTS, "ambients")
        for r in _choose(realism, REALISM, "realism")
    ]
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    rows, start = [], time.perf_counter()
    for index, cell in enumerate(cells):
        if progress is not None:
            progress(index, len(cells), cell)
        rows.append(run_cell(scanner, cell, seed=seed))
    with (root / "ablation.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    write_json(
        root / "ablation.json",
        {"units": {"radius_error_mm": "mm", "fit_rms_mm": "mm", "proj_error_rms_px": "projector px",
                   "phase_error_rms_rad": "rad"},
         "scanner": scanner.to_dict(), "seed": seed, "cells": rows,
         "time_s": round(time.perf_counter() - start, 2)},
    )  # fmt: skip
    plot_ablation(rows, root / "ablation.png")
    return rows


def plot_ablation(rows: list[dict[str, Any]], path: Path) -> Path:
    """Two heat maps (radius error in mm, phase error in rad): rows material x ambient,
    columns realism."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = list(dict.fromkeys((r["material"], r["ambient"]) for r in rows))
    settings = list(dict.fromkeys(r["realism"] for r in rows))
    index = {(r["material"], r["ambient"], r["realism"]): r for r in rows}
    figure, axes = plt.subplots(1, 2, figsize=(4 + 1.6 * len(settings), 1.5 + 0.45 * len(lines)))
    panels = (
        (axes[0], "radius_error_mm", "sphere radius error (mm)"),
        (axes[1], "phase_error_rms_rad", "phase error RMS (rad)"),
    )
    for axis, key, title in panels:
        grid = np.array([[index[(m, a, s)][key] for s in settings] for m, a in lines], float)
        image = axis.imshow(np.abs(grid), cmap="viridis", aspect="auto")
        axis.set_xticks(range(len(settings)), settings, rotation=30)
        axis.set_yticks(range(len(lines)), [f"{m}, {a}" for m, a in lines])
        for (i, j), value in np.ndenumerate(grid):
            axis.text(j, i, "-" if np.isnan(value) else f"{value:.3g}", ha="center",
                      va="center", color="w", fontsize=7)  # fmt: skip
        axis.set_title(title)
        figure.colorbar(image, ax=axis)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return path
