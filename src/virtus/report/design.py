"""Report sections of the design runs (:mod:`virtus.design`): a virtual VDI/VDE 2634-2
acceptance test (``virtus acceptance``), a noise prediction (``virtus predict``) and a design
sweep (``virtus design``).

* acceptance: the maxima of P_F, P_S, SD and F beside their limits with pass/fail, each
  figure per position as bars, the measuring volume, the artefacts, the rig used (and the
  virtual calibration's own section when the test calibrated), every position's numbers;
* predict: the summary and the predicted σ maps (projector px for ``u_p``/``v_p``, µm for
  depth and point) with the pixels that have a prediction;
* design: the variants' table and the figures the sweep drew (``figures/*.png``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import figures
from virtus.report.html import Page

__all__ = ["FIGURE_KEYS", "add_acceptance", "add_design", "add_predict", "predict_shape"]

#: Acceptance figures and the key each position stores its value under (mm).
FIGURE_KEYS = {"P_F": "P_F_mm", "P_S": "P_S_mm", "SD": "SD_mm", "F": "F_mm"}

#: Predicted maps drawn: file stem -> (quantity, scale to its unit, title).
_PREDICT_MAPS = {
    "sigma_u_p": ("sigma_px", 1.0, "σ of the decoded projector column u_p"),
    "sigma_v_p": ("sigma_px", 1.0, "σ of the decoded projector row v_p"),
    "sigma_depth": ("sigma_um", 1e6, "σ of the depth z"),
    "sigma_point": ("sigma_um", 1e6, "σ of the point (√ trace of its covariance)"),
}


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else math.nan  # fmt: skip


def add_acceptance(page: Page, path: Path) -> dict[str, Any]:
    """The acceptance test's verdict, figures per position and settings."""
    from virtus.report.calibration import add_calibration
    from virtus.report.runs import read_run_json

    data = read_run_json(path, "acceptance.json", "acceptance result",
                         ("maxima", "limits", "passed", "positions"))  # fmt: skip
    section = page.section("Acceptance test (VDI/VDE 2634-2, virtual)", "acceptance")
    verdict = "no limits given" if not data["limits"] else (
        "PASSED" if data["passed"] else "FAILED")  # fmt: skip
    complete = (
        "complete" if data.get("complete") else "shortened (--positions): not a complete test"
    )
    section.note(f"Result: {verdict}; {complete}; rig used: {data.get('rig', {}).get('kind')}.")
    rows = []
    for name, row in data["maxima"].items():
        limit = data["limits"].get(name) if isinstance(data["limits"], dict) else None
        row = row if isinstance(row, dict) else {}
        result = "-" if limit is None else ("pass" if limit.get("passed") else "FAIL")
        rows.append([name, data.get("figures", {}).get(name, ""), row.get("n"),
                     row.get("value_mm"), None if limit is None else limit.get("limit_mm"),
                     result])  # fmt: skip
    section.grid("largest magnitude of each figure (mm)",
                 ["figure", "meaning", "positions", "value", "limit", "result"], rows)  # fmt: skip
    positions = [p for p in data["positions"] if isinstance(p, dict)]
    for name, key in FIGURE_KEYS.items():
        measured = [p for p in positions if key in p]
        if not measured:
            continue
        limit = data["limits"].get(name, {}).get("limit_mm") if isinstance(
            data["limits"], dict) else None  # fmt: skip
        caption = f"{name} at each position (mm)" + (
            "" if limit is None else f"; limit ±{limit:g} mm")  # fmt: skip
        section.figure(
            f"figure-{name}",
            figures.bar_chart(
                [str(p.get("name")) for p in measured],
                {name: [_number(p.get(key)) for p in measured]},
                f"{name} (mm)",
                f"{name} per position",
            ),  # fmt: skip
            caption + ".",
        )
    header = ["name", "feature", *FIGURE_KEYS.values(), "n_points", "n_excluded"]
    section.grid("positions (mm)", header, [[p.get(k) for k in header] for p in positions])
    settings = page.section("Measuring volume, artefacts and rig", "acceptance-settings")
    for key in ("volume", "artefacts", "rig"):
        if isinstance(data.get(key), dict):
            settings.table(key, data[key])
    if (path / "calibration" / "calibration.json").is_file():
        add_calibration(page, path / "calibration", "Virtual calibration of the scanner")
    return data


def predict_shape(path: Path, record: dict[str, Any]) -> tuple[int, int]:
    """The camera image size ``(H, W)`` of the predict run in ``path``, from its record's
    scanner."""
    from virtus.report.runs import NotReportable

    try:
        camera = record["config"]["scanner"]["rig"]["camera"]
        return int(camera["height"]), int(camera["width"])
    except (KeyError, TypeError, ValueError):
        raise NotReportable(path / "run.json", "no scanner camera size in its config") from None


def add_predict(page: Page, path: Path, record: dict[str, Any]) -> dict[str, Any]:
    """The prediction's summary and its σ maps (read with the camera's size)."""
    from virtus.io.safeio import load_npy
    from virtus.report.runs import read_run_json

    summary = read_run_json(path, "summary.json", "prediction summary", ("pixels",))
    shape = predict_shape(path, record)
    section = page.section("Predicted noise", "prediction")
    section.table("summary (px: projector pixels, um: micrometres)", summary)
    mask = load_npy(path / "mask.npy", "prediction mask", dtype=bool, shape=shape)
    for stem, (quantity, scale, title) in _PREDICT_MAPS.items():
        values = load_npy(path / f"{stem}.npy", stem, dtype=np.float64, shape=shape) * scale
        if not np.isfinite(values).any():
            section.note(f"{stem}: no prediction (NaN everywhere; e.g. not coded).")
            continue
        section.figure(stem, figures.image_map(values, quantity, title),
                       f"{title}; grey: no prediction.")  # fmt: skip
    section.figure(
        "mask",
        figures.mask_overlay(
            np.ones(shape), [(mask, "#1f77b4", "predicted")], "pixels with a prediction"
        ),  # fmt: skip
        "Pixels with a prediction (a surface lit by the projector, not saturated).",
    )
    return summary


def add_design(page: Page, path: Path) -> dict[str, Any]:
    """The sweep's table and its figures (as the run drew them)."""
    from virtus.io.images import image_size
    from virtus.report.runs import read_run_json

    data = read_run_json(path, "design.json", "design table", ("keys", "variants"))
    section = page.section("Design sweep", "design")
    section.note(f"Varied keys: {', '.join(map(str, data['keys']))}; units: "
                 + "; ".join(f"{k}: {v}" for k, v in data.get("units", {}).items()))  # fmt: skip
    rows = [r for r in data["variants"] if isinstance(r, dict)]
    if rows:
        header = list(rows[0])
        section.grid("variants", header, [[r.get(k) for k in header] for r in rows])
    drawn = page.section("Figures against each varied key", "design-figures")
    for png in sorted((path / "figures").glob("*.png")):
        image_size(png)  # a PNG header, bounded, before it goes into the page
        figure, _, key = png.stem.partition("__")
        drawn.figure(f"sweep-{png.stem}", png.read_bytes(),
                     f"{figure} against {key} (figures/{png.name}).")  # fmt: skip
    if not drawn.blocks:
        drawn.note("The sweep drew no figure (one variant per key).")
    return data
