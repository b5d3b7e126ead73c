"""Report section of a learning run (``virtus learn train``, then ``virtus learn eval`` in the
same directory, :mod:`virtus.learn`): the architecture and test metrics beside the published
numbers, the loss per epoch, every evaluation's metrics and, where an evaluation saved them,
the predicted, true and error depth maps of its first samples.

Read without torch: only the run's JSON files and ``.npy`` maps (``evaluations/<name>.json``
lists each map with its checksum; a map that no longer matches is refused).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import figures
from virtus.report.html import Page

__all__ = ["EVALUATIONS_DIR", "MAX_EVALUATIONS", "MAX_MAPS", "add_learn", "evaluation_files"]

#: Where ``virtus learn eval`` writes (``<name>.json`` and ``<name>/sample_NNNNNN.npy``).
EVALUATIONS_DIR = "evaluations"
#: Evaluations shown (in name order); a run with more lists the rest by name.
MAX_EVALUATIONS = 8
#: Saved samples drawn per evaluation (``virtus learn eval`` saves 3).
MAX_MAPS = 3
#: Layers of a saved map, in order (:data:`virtus.learn.training.MAP_LAYERS`).
_LAYERS = (("predicted_depth", "depth", "predicted depth"), ("true_depth", "depth", "true depth"),
           ("error", "signed_error", "predicted − true depth"))  # fmt: skip
#: Published object MAE (mm) of FPP-ML-Bench's data (:mod:`virtus.learn.metrics`).
_PUBLISHED = {"unet": 14.54, "phase": 4.46}


def evaluation_files(path: Path) -> list[Path]:
    """The run's evaluation summaries, sorted by name."""
    return sorted((path / EVALUATIONS_DIR).glob("*.json"))


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else math.nan  # fmt: skip


def add_learn(page: Page, path: Path) -> dict[str, Any]:
    """The learning run's sections (module docstring)."""
    from virtus.report.runs import read_run_json

    metrics = read_run_json(path, "metrics.json", "test metrics", ("steps", "architecture"))
    history = read_run_json_list(path, "history.json")
    section = page.section("Training", "training")
    section.table("architecture", metrics["architecture"])
    model = str(metrics["architecture"].get("model", "?")) if isinstance(
        metrics["architecture"], dict) else "?"  # fmt: skip
    test = metrics.get("test")
    if isinstance(test, dict):
        published = _PUBLISHED.get(model)
        section.table("test split (mm, rad)", {**test, "published_object_mae_mm": published})
    else:
        section.note("The store has no test split: no test metrics.")
    epochs = [h for h in history if isinstance(h, dict)]
    if epochs:
        section.figure("loss", figures.bar_chart(
            [f"epoch {h.get('epoch')}" for h in epochs],
            {"train": [_number(h.get("train_loss")) for h in epochs],
             "validation": [_number(h.get("val_loss")) for h in epochs]},
            "loss", "loss per epoch"), "Training and validation loss per epoch.")  # fmt: skip
        header = list(epochs[0])
        section.grid("history", header, [[h.get(k) for k in header] for h in epochs])
    files = evaluation_files(path)
    for file in files[:MAX_EVALUATIONS]:
        _add_evaluation(page, path, file)
    if len(files) > MAX_EVALUATIONS:
        page.section("More evaluations", "more-evaluations").note(
            "Not shown: " + ", ".join(f.stem for f in files[MAX_EVALUATIONS:])
        )
    if not files:
        page.section("Evaluations", "evaluations").note(
            f"No evaluation yet: run `virtus learn eval {path} --store STORE`."
        )
    return metrics


def read_run_json_list(path: Path, name: str) -> list[Any]:
    """A JSON list of the run (``history.json``); missing or not a list: refused."""
    from virtus.io.safeio import read_json
    from virtus.report.runs import NotReportable

    try:
        return read_json(path / name, name, expect=list)
    except FileNotFoundError:
        raise NotReportable(path / name, "missing (removed since the run wrote it?)") from None


def _add_evaluation(page: Page, path: Path, file: Path) -> None:
    from virtus.io.runs import file_digest
    from virtus.io.safeio import load_npy
    from virtus.report.runs import NotReportable, read_run_json

    name = file.stem
    data = read_run_json(path, f"{EVALUATIONS_DIR}/{file.name}", "evaluation", ("samples",))
    section = page.section(f"Evaluation {name}", f"evaluation-{name}")
    section.table("metrics (mm, rad)", {k: v for k, v in data.items() if k != "maps"})
    maps = [m for m in data.get("maps", []) if isinstance(m, dict)]
    if not maps:
        section.note("This evaluation saved no depth maps (an older virtus).")
    for entry in maps[:MAX_MAPS]:
        target = path / EVALUATIONS_DIR / str(entry.get("file"))
        if not target.resolve().is_relative_to((path / EVALUATIONS_DIR).resolve()):
            raise NotReportable(file, f"a map outside the run: {entry.get('file')}")
        if not target.is_file() or file_digest(target) != entry.get("sha256"):
            raise NotReportable(target, "missing or changed since the evaluation wrote it")
        values = load_npy(target, "evaluation map", dtype=np.float32, shape=(3, None, None))
        sample = entry.get("sample")
        for layer, (key, quantity, title) in enumerate(_LAYERS):
            section.figure(
                f"sample-{sample}-{key}",
                figures.image_map(values[layer], quantity, f"sample {sample}: {title}"),
                f"Sample {sample}: {title} (mm); grey: no surface.",
            )
