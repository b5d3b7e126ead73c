"""Ablation: what each surface, light and sensor effect does to a measurement, cell by cell.

Like the paper code's ablation mode (materials x ambient light), but measured: every cell
renders the paper's 100 mm-radius sphere before a wall with one material, one ambient level
(:mod:`virtus.scene.presets`) and one realism setting, decodes it, and reports

* the decoded projector-coordinate error against the exact ground truth (px RMS, and as
  phase of the finest period, rad RMS), over pixels valid in both and away from depth
  discontinuities (a silhouette pixel mixes two surfaces: that is sampling, not an effect),
  and the share of those pixels off by half a period or more (order errors);
* the sphere fit of the points triangulated with the true rig (radius error, fit RMS,
  inlier ratio), so the effect on a metrology result is seen, not just on the phase.

The table is written as ``ablation.csv`` and ``ablation.json`` and drawn as
``ablation.png`` (radius error and phase error per cell).

Output directory (owned by the run through :func:`virtus.io.runs.claim_run`, command
``ablation``)::

    OUT/run.json, OUT/.virtus.lock        the run record and lock (see virtus.io.runs)
    OUT/cells/<material>-<ambient>-<realism>.json   one finished cell's row (written as soon as
                                          the cell is measured) and the run's config digest
    OUT/ablation.csv, ablation.json, ablation.png   the table, written at the end

**Resumable**: ``resume=True`` (``virtus ablation --resume``) keeps every finished cell
(its file must belong to this run's configuration) and measures only the others; a cell
is a whole capture, so at most one is lost when a run is killed. At most :data:`MAX_CELLS`
cells (every combination of the tables), each checked against the capture memory budget
before anything is rendered.
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, VirtusError
from virtus.io.runs import RunDirectory, claim_run, config_digest
from virtus.io.safeio import read_json
from virtus.metrology import sphere_roi_fit
from virtus.reconstruct import EDGE_MAX_STEP, depth_edge_mask, reconstruct
from virtus.scanner import Scanner
from virtus.scene.presets import AMBIENTS, MATERIALS, sphere_scene
from virtus.sensor.camera import SENSOR_PRESETS
from virtus.sensor.projector import PROJECTOR_PRESETS

__all__ = [
    "COLUMNS",
    "REALISM",
    "AblationCell",
    "ablation_cells",
    "plot_ablation",
    "run_ablation",
    "run_cell",
]

#: Realism settings: each changes the scanner from the ideal one.
REALISM: dict[str, Callable[[Scanner], Scanner]] = {
    "ideal": lambda s: s,
    "sensor": lambda s: s.with_(sensor=SENSOR_PRESETS["imx174"]),
    "gamma": lambda s: s.with_(
        projector=PROJECTOR_PRESETS["lightcrafter"].with_(precompensate=False)
    ),
    "projector": lambda s: s.with_(projector=PROJECTOR_PRESETS["lightcrafter"]),
    "interreflection": lambda s: s.with_(render=s.render.with_(bounces=2)),
    "all": lambda s: s.with_(
        sensor=SENSOR_PRESETS["imx174"],
        projector=PROJECTOR_PRESETS["lightcrafter"],
        render=s.render.with_(bounces=2),
    ),
}
#: Most cells of one run: every combination of the tables.
MAX_CELLS = len(MATERIALS) * len(AMBIENTS) * len(REALISM)
#: The job's name in ``run.json``.
COMMAND = "ablation"
#: Result files (relative), and the folder of the per-cell files.
RESULT_FILES = ("ablation.csv", "ablation.json", "ablation.png")
CELL_DIR = "cells"
#: Files of the job (an earlier run's when found without a ``run.json``).
LAYOUT = (*RESULT_FILES, f"{CELL_DIR}/*.json")
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

    @property
    def file(self) -> str:
        """The cell's result file, relative to the run's directory."""
        return f"{CELL_DIR}/{self.material}-{self.ambient}-{self.realism}.json"


def _choose(names: list[str] | None, table: dict[str, Any], what: str) -> list[str]:
    if names is None:
        return list(table)
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise InputError(what, f"a list of names among {list(table)}", names)
    unknown = [n for n in names if n not in table]
    if unknown or not names:
        raise InputError(what, f"names among {list(table)}", unknown[:5] or names)
    return list(dict.fromkeys(names))


def run_cell(scanner: Scanner, cell: AblationCell, *, seed: int = 0) -> dict[str, Any]:
    """Render, decode and measure one cell (see the module docstring)."""
    from virtus.scene.model import SphereObject

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
        fit, _ = sphere_roi_fit(recon.points, sphere.center_m, sphere.radius_m, rng=seed)
        row.update(
            radius_error_mm=(fit.radius - sphere.radius_m) * 1e3,
            fit_rms_mm=fit.rms * 1e3,
            inlier_ratio=fit.inlier_ratio,
        )
    except VirtusError as error:  # e.g. a mirror sphere returns too few points
        row.update(radius_error_mm=nan, fit_rms_mm=nan, inlier_ratio=nan, note=str(error))
    return row


def ablation_cells(
    materials: list[str] | None = None,
    ambients: list[str] | None = None,
    realism: list[str] | None = None,
) -> list[AblationCell]:
    """The cells of materials x ambient levels x realism settings (default: all), checked:
    known names, at most :data:`MAX_CELLS` cells."""
    cells = [
        AblationCell(m, a, r)
        for m in _choose(materials, MATERIALS, "materials (--materials)")
        for a in _choose(ambients, AMBIENTS, "ambients (--ambient)")
        for r in _choose(realism, REALISM, "realism (--realism)")
    ]
    if len(cells) > MAX_CELLS:  # cannot happen with de-duplicated names; the bound is stated
        raise InputError("ablation cells", f"at most {MAX_CELLS}", len(cells))
    return cells


def run_ablation(
    out_dir: str | Path,
    scanner: Scanner | None = None,
    *,
    materials: list[str] | None = None,
    ambients: list[str] | None = None,
    realism: list[str] | None = None,
    seed: int = 0,
    progress: Callable[[int, int, AblationCell], None] | None = None,
    overwrite: bool = False,
    resume: bool = False,
) -> list[dict[str, Any]]:
    """Run every cell of materials x ambient levels x realism settings.

    Parameters
    ----------
    out_dir : directory owned by the run (layout in the module docstring).
    scanner : the ideal scanner the realism settings modify (default: the paper's system).
    materials, ambients, realism : names to run (default: all of
        :data:`virtus.scene.presets.MATERIALS`, :data:`virtus.scene.presets.AMBIENTS`,
        :data:`REALISM`).
    seed : seed of the noise streams and the sphere fit.
    progress : called before each cell as ``progress(index, total, cell)``.
    overwrite : remove an earlier run's files first.
    resume : continue the run in ``out_dir``: finished cells are kept.

    Returns
    -------
    One dict per cell with :data:`COLUMNS`.

    Raises
    ------
    InputError : unknown names, or a cell's capture over the memory budget (before anything
        is written).
    VirtusError : ``out_dir`` in use or holding another run's files.
    """
    from virtus.sensor.noise import as_seed

    scanner = scanner or Scanner()
    cells = ablation_cells(materials, ambients, realism)
    seed = as_seed(seed)
    for name in dict.fromkeys(c.realism for c in cells):
        REALISM[name](scanner).check()
    config = {
        "scanner": scanner.to_dict(),
        "cells": [[c.material, c.ambient, c.realism] for c in cells],
        "seed": seed,
    }
    with claim_run(
        out_dir, COMMAND, config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        return _run_cells(run, scanner, cells, seed, config_digest(config), progress)


def _run_cells(
    run: RunDirectory,
    scanner: Scanner,
    cells: list[AblationCell],
    seed: int,
    episode: str,
    progress: Callable[[int, int, AblationCell], None] | None,
) -> list[dict[str, Any]]:
    run.own(*(cell.file for cell in cells), *RESULT_FILES)
    rows, start = [], time.perf_counter()
    for index, cell in enumerate(cells):
        if progress is not None:
            progress(index, len(cells), cell)
        if run.resumed and run.file(cell.file).is_file():
            rows.append(_load_cell(run.file(cell.file), cell, episode))
            run.log(f"reused {cell.file}")
            continue
        row = run_cell(scanner, cell, seed=seed)
        run.write_json(cell.file, {"episode": episode, "row": row}, allow_nan=True)
        run.log(f"measured {cell.file}")
        rows.append(row)
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=COLUMNS)
    writer.writeheader()
    writer.writerows(rows)
    run.write("ablation.csv", lambda tmp: tmp.write_text(text.getvalue(), newline=""))
    report = {
        "units": {"radius_error_mm": "mm", "fit_rms_mm": "mm",
                  "proj_error_rms_px": "projector px", "phase_error_rms_rad": "rad"},
        "scanner": scanner.to_dict(), "seed": seed, "cells": rows,
        "time_s": round(time.perf_counter() - start, 2),
    }  # fmt: skip
    run.write_json("ablation.json", report, allow_nan=True)
    run.write("ablation.png", lambda tmp: plot_ablation(rows, tmp))
    return rows


def _load_cell(path: Path, cell: AblationCell, episode: str) -> dict[str, Any]:
    """A finished cell's row, checked to belong to this run's configuration."""
    data = read_json(path, "ablation cell", expect=dict, allow_nan=True)
    row = data.get("row")
    if data.get("episode") != episode or not isinstance(row, dict) or set(row) != set(COLUMNS):
        raise VirtusError(
            f"{path} was made by another ablation configuration; remove it or start again "
            "with --overwrite"
        )
    if (row["material"], row["ambient"], row["realism"]) != (
        cell.material, cell.ambient, cell.realism
    ):  # fmt: skip
        raise VirtusError(f"{path} holds another cell; remove it or start again with --overwrite")
    return row


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
