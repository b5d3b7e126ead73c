"""Report sections of the runs that are tables of experiments or collections: an ablation
(its heat map, one bar chart per metric, the table), a twin validation (per-pose
differences between the real captures and their re-rendering, as numbers and as the
difference maps the validation stored) and a dataset store (a
gallery of a few samples with their labels).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from virtus.report import figures
from virtus.report.html import Page

__all__ = [
    "GALLERY_SAMPLES",
    "TWIN_MAP_POSES",
    "add_ablation",
    "add_dataset",
    "add_twin",
    "add_twin_maps",
]

#: Samples shown in a dataset store's gallery.
GALLERY_SAMPLES = 4


def _number(value: Any) -> float:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        else math.nan  # fmt: skip


def add_ablation(page: Page, path: Path) -> dict[str, Any]:
    """The ablation's heat map (as the run drew it), bars per metric and the full table."""
    from virtus.report.runs import read_run_json

    data = read_run_json(path, "ablation.json", "ablation table", ("cells",))
    rows = [r for r in data["cells"] if isinstance(r, dict)]
    section = page.section("Ablation")
    heat = path / "ablation.png"
    if heat.is_file():
        from virtus.io.images import image_size

        image_size(heat)  # a PNG header, bounded, before it goes into the page
        section.figure("heat-map", heat.read_bytes(),
                       "The run's heat map (ablation.png): the metrics of every cell.")  # fmt: skip
    names = [f"{r.get('material')}/{r.get('ambient')}/{r.get('realism')}" for r in rows]
    units = data.get("units", {})
    for metric in ("radius_error_mm", "fit_rms_mm", "proj_error_rms_px", "phase_error_rms_rad"):
        values = [_number(r.get(metric)) for r in rows]
        if all(math.isnan(v) for v in values):
            continue
        unit = units.get(metric, "")
        section.figure(
            f"bars-{metric}",
            figures.bar_chart(names, {metric: values}, f"{metric} ({unit})", metric),
            f"{metric} per cell (material / ambient / realism), {unit}.",
        )
    if rows:
        header = list(rows[0])
        section.grid("cells", header, [[r.get(k) for k in header] for r in rows])
    return data


def add_twin(page: Page, path: Path) -> dict[str, Any] | None:
    """The twin's Isaac parameters and, with ``--validate``, the per-pose differences."""
    from virtus.report.runs import read_run_json

    section = page.section("Digital twin")
    isaac = read_run_json(path, "isaac.json", "Isaac parameters")
    section.table("Isaac Sim parameters (isaac.json)", isaac)
    if not (path / "validation.json").is_file():
        section.note("No validation: run `virtus twin CALIBRATION --validate CAPTURES`.")
        return None
    data = read_run_json(path, "validation.json", "twin validation", ("per_pose", "overall"))
    poses = [p for p in data["per_pose"] if isinstance(p, dict)]
    names = [str(p.get("name")) for p in poses]
    section = page.section("Twin validation: real against virtual")
    groups = {
        "image differences (share of full scale)": ("white_rms", "black_rms", "fringe_rms",
                                                    "code_rms"),
        "projector coordinates (projector px)": ("proj_uv_rms_px", "centre_diff_mean_px",
                                                 "centre_diff_max_px"),
        "cloud (mm)": ("cloud_mae_mm", "cloud_rmse_mm", "point_noise_real_mm",
                       "point_noise_twin_mm"),
    }  # fmt: skip
    for index, (label, keys) in enumerate(groups.items()):
        series = {k: [_number(p.get(k)) for p in poses] for k in keys if any(k in p for p in poses)}
        if not series:
            continue
        section.figure(
            f"differences-{index}",
            figures.bar_chart(names, series, label, f"twin - real per pose: {label}"),
            f"Per board pose, the real capture against its re-rendering by the twin: {label}.",
        )
    section.table("overall", data["overall"])
    if poses:
        header = list(poses[0])
        section.grid("per pose", header, [[p.get(k) for k in header] for p in poses])
    add_twin_maps(page, path, data.get("maps"))
    return data


#: Poses whose difference maps a twin report draws (the first ones; the rest are listed).
TWIN_MAP_POSES = 6
#: How each layer of a twin difference map is drawn: (quantity, title).
_TWIN_LAYERS = {
    "white": ("difference", "white frame, real − twin (share of white)"),
    "fringe": ("difference", "first fringe frame, real − twin (share of white)"),
    "code": ("difference", "first code frame, real − twin (share of white)"),
    "proj_uv": ("proj_distance", "|decoded (u_p, v_p) real − twin| (proj. px)"),
}


def add_twin_maps(page: Page, path: Path, maps: Any) -> None:
    """The per-pose difference maps ``validation.json`` lists (``maps``), each checked
    against its checksum; a twin validated before the maps were stored gets a note."""
    from virtus.io.runs import file_digest
    from virtus.io.safeio import load_npy
    from virtus.report.runs import NotReportable

    section = page.section("Twin validation: difference maps per pose", "twin-maps")
    if not isinstance(maps, dict) or not isinstance(maps.get("files"), dict):
        section.note("This validation stored no difference maps (written by an older "
                     "virtus): the per-pose numbers above are all there is.")  # fmt: skip
        return
    layers = [str(name) for name in maps.get("layers", [])]
    entries = list(maps["files"].items())
    section.note(f"Each map averaged over {maps.get('bin')} x {maps.get('bin')} camera pixels; "
                 "grey: pixels not compared (off the board or not decoded in both).")  # fmt: skip
    root = path.resolve()
    for index, (name, entry) in enumerate(entries[:TWIN_MAP_POSES]):
        file = path / str(entry.get("file") if isinstance(entry, dict) else "")
        if not file.resolve().is_relative_to(root) or not file.is_file():
            raise NotReportable(file, "a difference map validation.json lists is missing")
        if file_digest(file) != entry.get("sha256"):
            raise NotReportable(file, "changed since the validation wrote it (checksum)")
        values = load_npy(file, "twin difference maps", dtype=np.float32,
                          shape=(len(layers), None, None))  # fmt: skip
        for layer, key in enumerate(layers):
            quantity, title = _TWIN_LAYERS.get(key, ("difference", key))
            section.figure(f"pose-{index}-{key}",
                           figures.image_map(values[layer], quantity, f"{name}: {title}"),
                           f"Pose {name}: {title}.")  # fmt: skip
    if len(entries) > TWIN_MAP_POSES:
        section.note("Maps not drawn here (in validation_maps/): "
                     + ", ".join(str(n) for n, _ in entries[TWIN_MAP_POSES:]))  # fmt: skip


def add_dataset(page: Page, path: Path) -> dict[str, Any]:
    """The store's summary and a gallery: for the first :data:`GALLERY_SAMPLES` samples,
    one fringe frame, the depth and the wrapped phase, with the sample's labels."""
    from virtus.data import DatasetStore

    store = DatasetStore.open(path)
    info = store.info()
    section = page.section("Dataset store")
    section.table("store", {k: v for k, v in info.items() if k != "path"})
    samples = store.samples()
    gallery = page.section("Gallery")
    arrays = {spec.name for spec in store.layout}
    for index in sorted(samples)[:GALLERY_SAMPLES]:
        meta = samples[index]
        wanted = tuple(n for n in ("frames", "depth", "wrapped", "mask") if n in arrays)
        sample = store.read_sample(index, wanted)
        frames = np.asarray(sample["frames"])
        n_frames = int(meta.get("n_frames", len(frames)))
        frame = frames[0] if n_frames else np.zeros(frames.shape[1:])
        gallery.figure(f"sample-{index}-frame", figures.image_map(
            frame, "intensity", f"sample {index}: frame 0"),
            f"Sample {index} ({meta.get('split')}), first of its {n_frames} frames.")  # fmt: skip
        if "depth" in sample:
            depth = np.asarray(sample["depth"], dtype=np.float64) * 1000.0
            gallery.figure(f"sample-{index}-depth", figures.image_map(
                depth, "depth", f"sample {index}: depth"),
                f"Sample {index}: ground-truth depth (mm), grey: no surface.")  # fmt: skip
        if "wrapped" in sample:
            wrapped = np.asarray(sample["wrapped"], dtype=np.float64)
            wrapped = wrapped[0] if wrapped.ndim == 3 else wrapped
            gallery.figure(f"sample-{index}-wrapped", figures.image_map(
                wrapped, "wrapped_phase", f"sample {index}: wrapped phase",
                limits=(-np.pi, np.pi)), f"Sample {index}: wrapped phase label (rad).")  # fmt: skip
        labels = {
            k: v
            for k, v in meta.items()
            if k in ("index", "split", "group", "seed", "n_frames", "objects", "checksum")
        }
        gallery.table(f"sample {index} labels", labels)
    return info
