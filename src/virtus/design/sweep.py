"""``virtus design``: the predicted noise of a scanner over variants of its rig, fringes,
sensor and projector.

Each variant (:mod:`virtus.design.variants`) is the base scanner with the varied keys
applied, looking at a target -- a matte plane facing the camera at the working distance
(``plane``), or a 100 mm sphere there before it (``sphere``). Its prediction is one
noise-free ground-truth pass (:func:`virtus.design.modulation.signal_pass`) on the camera
resampled to about ``grid`` pixels a side with one sample at each pixel centre, then the
uncertainty model (:func:`virtus.uncertainty.predict_uncertainty`): nothing noisy is
rendered, and the per-pixel answers hold for the full-resolution camera at the sampled
points (radiance and the triangulation Jacobian do not depend on the pixel size; the
averaging of the fringes over a full-resolution pixel's footprint, <0.5 % of ``B`` on the
paper's rig at T = 18 px, is left out).

Output directory (owned through :func:`virtus.io.runs.claim_run`, command ``design``)::

    OUT/run.json, OUT/.virtus.lock     the run record and lock
    OUT/variants/NNNN.json             one finished variant's row and the config digest
    OUT/design.csv, OUT/design.json    the table (one row a variant; :data:`FIGURES` and
                                       the varied keys' values), written at the end
    OUT/figures/FIGURE__KEY.png        each figure against each varied key (one line per
                                       combination of the other keys)
    OUT/acceptance/NNNN/               with ``acceptance``: each variant's rendered VDI/VDE
                                       2634-2 acceptance test, its own run
                                       (:func:`virtus.design.acceptance.acceptance_test`);
                                       its maxima join the row (:data:`ACCEPTANCE_FIGURES`)

**Resumable**: ``resume=True`` keeps every finished variant (its file must carry this
run's config digest) and predicts only the others. Variants run here, in ``workers``
spawned processes, or as Ray tasks (``ray_address``, as datasets do:
:func:`virtus.data.raycluster.connect_ray`, :func:`~virtus.data.raycluster.run_tasks`).
Every variant is built and its rig checked (the projector must light at least
:data:`virtus.design.variants.MIN_OVERLAP` of the camera's field on the target) before the
directory is claimed: bad input writes nothing.
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive_int
from virtus.design.modulation import predict_pass, signal_pass
from virtus.design.variants import (
    MIN_OVERLAP,
    Variant,
    overlap_fraction,
    parse_vary,
    variants,
    with_coarse_camera,
)
from virtus.errors import InputError, VirtusError
from virtus.io.runs import claim_run, config_digest
from virtus.io.safeio import read_json
from virtus.reconstruct import as_use
from virtus.scanner import Scanner

__all__ = [
    "ACCEPTANCE_FIGURES",
    "ACCEPTANCE_OPTIONS",
    "COMMAND",
    "FIGURES",
    "TARGETS",
    "design_target",
    "plot_design",
    "predict_variant",
    "run_design",
]

#: The job's name in ``run.json``.
COMMAND = "design"
#: Targets a variant looks at.
TARGETS = ("plane", "sphere")
#: Figures of merit of a variant (columns of the table; each drawn against each key).
FIGURES = (
    "sigma_depth_um_median", "sigma_depth_um_p95", "sigma_u_p_px_median", "sigma_u_p_px_p95",
)  # fmt: skip
#: Figures of the rendered acceptance test a row gets with ``acceptance`` (mm, the largest
#: magnitude over the positions).
ACCEPTANCE_FIGURES = ("P_F_mm", "P_S_mm", "SD_mm", "F_mm")
#: Keywords of :func:`virtus.design.acceptance.acceptance_test` a sweep passes on.
ACCEPTANCE_OPTIONS = ("volume", "limits", "positions", "calibration", "board",
                      "calibration_poses", "rng")  # fmt: skip
#: Other columns of a row.
_COLUMNS = ("variant", "exposure_dn_per_radiance", "predicted_fraction", "sigma_point_um_median")
RESULT_FILES = ("design.csv", "design.json")
LAYOUT = (*RESULT_FILES, "variants/*.json", "figures/*.png")
#: Largest ``grid`` (camera samples a side).
MAX_GRID = 512
#: Sphere target: radius (m) and the plane behind it (m beyond the working distance).
SPHERE_RADIUS_M = 0.05
_SPHERE_BACKDROP_M = 0.3


def design_target(kind: str, distance: float) -> Any:
    """The target scene: a matte Lambertian plane (albedo 0.8) facing the camera at
    ``distance`` metres, 4 x distance wide; ``sphere`` adds a 100 mm sphere centred at that
    distance and moves the plane 0.3 m behind it."""
    from virtus.geometry.transforms import Pose
    from virtus.scene.model import Material, PlaneObject, Scene, SphereObject

    if kind not in TARGETS:
        raise InputError("--target", f"one of {', '.join(TARGETS)}", kind)
    matte = Material(albedo=0.8, specular=0.0)
    if kind == "plane":
        plane = PlaneObject((4 * distance, 4 * distance), Pose(np.eye(3), (0, 0, distance)), matte)
        return Scene(objects=[], background=plane)
    back = distance + _SPHERE_BACKDROP_M
    plane = PlaneObject((4 * back, 4 * back), Pose(np.eye(3), (0, 0, back)), matte)
    return Scene(objects=[SphereObject(SPHERE_RADIUS_M, (0, 0, distance), matte)],
                 background=plane)  # fmt: skip


def predict_variant(
    base: Scanner,
    variant: Variant,
    target: str,
    grid: int,
    use: str,
    acceptance: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One variant's row: build it, trace its target once, predict (module docstring);
    with ``acceptance`` (keywords of :func:`virtus.design.acceptance.acceptance_test` and
    ``out_dir``: the directory of all variants' tests) also run its acceptance test."""
    scanner, distance = variant.build(base)
    coarse = with_coarse_camera(scanner, grid)
    passed = signal_pass(coarse, design_target(target, distance))
    prediction = predict_pass(passed, use=use)
    summary = prediction.summary()
    lit = passed.gt.mask
    row: dict[str, Any] = dict(variant.values)
    row["variant"] = variant.index
    row["exposure_dn_per_radiance"] = passed.exposure
    row["predicted_fraction"] = float(prediction.mask.sum() / max(1, lit.size))
    for name in (*FIGURES, "sigma_point_um_median"):
        row[name] = summary[name]
    if acceptance is not None:
        row.update(_acceptance_figures(scanner, variant, acceptance))
    return row


def _acceptance_figures(
    scanner: Scanner, variant: Variant, options: dict[str, Any]
) -> dict[str, float | None]:
    """The largest magnitude of each acceptance figure (mm) of a variant's rendered test."""
    from virtus.design.acceptance import acceptance_test

    options = dict(options)
    out = Path(options.pop("out_dir")) / f"{variant.index:04d}"
    result = acceptance_test(scanner, out, **options)
    maxima = result.summary.get("maxima", {})
    return {
        f"{name}_mm": (maxima[name]["max_abs_mm"] if name in maxima else None)
        for name in ("P_F", "P_S", "SD", "F")
    }


def _checked(
    base: Scanner, vary: dict[str, list[Any]] | list[str], target: str
) -> tuple[dict[str, list[Any]], list[Variant]]:
    if not isinstance(vary, dict):
        vary = parse_vary(list(vary))
    if target not in TARGETS:
        raise InputError("--target", f"one of {', '.join(TARGETS)}", target)
    chosen = variants(vary)
    for variant in chosen:
        scanner, distance = variant.build(base)
        share = overlap_fraction(scanner.rig, distance)
        if share < MIN_OVERLAP:
            raise InputError(
                f"variant {variant.name}",
                f"a rig whose projector lights at least {MIN_OVERLAP:.0%} of the camera's "
                f"field at {distance:g} m",
                f"{share:.0%} (devices not overlapping)",
            )
        scanner.check()
    return vary, chosen


def _check_acceptance(options: dict[str, Any]) -> None:
    """What :func:`virtus.design.acceptance.acceptance_test` would refuse only after the
    sweep started: unknown keywords, limits, the calibration."""
    from virtus.design.acceptance import parse_limits

    unknown = sorted(set(options) - set(ACCEPTANCE_OPTIONS))
    if unknown:
        raise InputError("acceptance options", f"keywords among {ACCEPTANCE_OPTIONS}", unknown)
    parse_limits(options.get("limits"))
    calibration = options.get("calibration", "virtual")
    if isinstance(calibration, str | Path) and calibration not in ("virtual", "true"):
        if not Path(calibration).is_file():
            raise InputError("--acceptance-calibration", "virtual, true or a file", calibration)


def run_design(
    out_dir: str | Path,
    scanner: Scanner | None = None,
    *,
    vary: dict[str, list[Any]] | list[str],
    target: str = "plane",
    grid: int = 64,
    use: str = "uv",
    workers: int = 1,
    ray_address: str | None = None,
    acceptance: bool = False,
    acceptance_options: dict[str, Any] | None = None,
    overwrite: bool = False,
    resume: bool = False,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Predict every variant of a sweep (module docstring).

    Parameters
    ----------
    out_dir : directory owned by the run.
    scanner : the base scanner (default: the paper's system).
    vary : ``{key: [values]}`` or ``["KEY=V1,V2", ...]``
        (:func:`~virtus.design.variants.parse_vary`).
    target : ``plane`` or ``sphere`` (:func:`design_target`).
    grid : camera samples along the longer side (1..:data:`MAX_GRID`).
    use : which decoded coordinates triangulate (``uv``, ``u``, ``v``).
    workers : worker processes (1 = here).
    ray_address : run the variants as Ray tasks on this cluster (``auto``, ``local`` or
        ``host:port``) instead.
    acceptance : also render each variant's acceptance test (slow: a virtual calibration
        and 23 positions a variant, unless ``acceptance_options`` say otherwise).
    acceptance_options : keywords of :func:`virtus.design.acceptance.acceptance_test`
        (``calibration``, ``positions``, ``limits``, ``rng``...).
    overwrite, resume : as every job (:func:`virtus.io.runs.claim_run`).
    progress : called as each variant finishes: ``progress(done, total, row)``.

    Returns
    -------
    The rows, in variant order.
    """
    scanner = scanner or Scanner()
    grid = positive_int("grid", grid)
    if grid > MAX_GRID:
        raise InputError("grid", f"at most {MAX_GRID} camera samples a side", grid)
    workers = positive_int("workers", workers)
    use = as_use(use).value
    vary, chosen = _checked(scanner, vary, target)
    if acceptance:
        _check_acceptance(acceptance_options or {})
    ray = None
    if ray_address is not None:
        from virtus.data.raycluster import connect_ray

        ray = connect_ray(ray_address)
    config = {
        "scanner": scanner.to_dict(), "vary": vary, "target": target, "grid": grid, "use": use,
    }  # fmt: skip
    if acceptance:
        config["acceptance"] = {k: str(v) for k, v in (acceptance_options or {}).items()}
    digest = config_digest(config)
    with claim_run(
        out_dir, COMMAND, config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        start = time.perf_counter()
        rows: dict[int, dict[str, Any]] = {}
        todo = []
        for variant in chosen:
            if run.resumed and run.file(variant.file).is_file():
                rows[variant.index] = _load_row(run.file(variant.file), variant, digest)
            else:
                todo.append(variant)
        run.own(*(v.file for v in chosen), *RESULT_FILES)
        tests = None
        if acceptance:
            tests = {**(acceptance_options or {}), "out_dir": str(run.file("acceptance")),
                     "resume": run.resumed, "overwrite": overwrite}  # fmt: skip
        args = (scanner, target, grid, use, tests)
        for row in _execute(todo, args, workers, ray):
            variant = chosen[row["variant"]]
            run.write_json(variant.file, {"episode": digest, "row": row}, allow_nan=True)
            rows[variant.index] = row
            if progress is not None:
                progress(len(rows), len(chosen), row)
        table = [rows[v.index] for v in chosen]
        figures = (*FIGURES, *ACCEPTANCE_FIGURES) if acceptance else FIGURES
        _write_results(run, table, list(vary), config, figures, time.perf_counter() - start)
        return table


def _task(
    base: Scanner, variant: Variant, target: str, grid: int, use: str, tests: Any
) -> dict[str, Any]:
    return predict_variant(base, variant, target, grid, use, tests)


def _execute(todo: list[Variant], args: tuple, workers: int, ray: Any) -> Iterator[dict[str, Any]]:
    base, target, grid, use, tests = args
    if ray is not None:
        from virtus.data.raycluster import run_tasks

        by_index = {v.index: v for v in todo}
        yield from run_tasks(
            ray, _task, lambda i: (base, by_index[i], target, grid, use, tests), list(by_index),
            max(2 * workers, 2 * int(ray.cluster_resources().get("CPU", 1))),
        )  # fmt: skip
        return
    if workers == 1 or len(todo) <= 1:
        for variant in todo:
            yield _task(base, variant, target, grid, use, tests)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # Spawned, not forked: a forked copy of a process that has started the renderer's
    # threads may deadlock.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = [pool.submit(_task, base, v, target, grid, use, tests) for v in todo]
        for future in as_completed(futures):
            yield future.result()


def _load_row(path: Path, variant: Variant, digest: str) -> dict[str, Any]:
    data = read_json(path, "design variant", expect=dict, allow_nan=True)
    row = data.get("row")
    if data.get("episode") != digest or not isinstance(row, dict):
        raise VirtusError(
            f"{path} was made by another design configuration; remove it or start again "
            "with --overwrite"
        )
    if row.get("variant") != variant.index:
        raise VirtusError(
            f"{path} holds another variant; remove it or start again with --overwrite"
        )
    return row


def _write_results(
    run: Any,
    rows: list[dict[str, Any]],
    keys: list[str],
    config: dict[str, Any],
    figures: tuple[str, ...],
    seconds: float,
) -> None:
    columns = [*keys, *_COLUMNS, *figures]
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    run.write("design.csv", lambda tmp: tmp.write_text(text.getvalue(), newline=""))
    report = {
        "units": {"sigma_depth_um": "micrometres (camera-frame z)",
                  "sigma_u_p_px": "projector px", "sigma_point_um": "micrometres",
                  "*_mm": "millimetres (acceptance figures, largest magnitude)"},
        "keys": keys, "config": config, "variants": rows, "time_s": round(seconds, 2),
    }  # fmt: skip
    run.write_json("design.json", report, allow_nan=True)
    for figure in figures:
        for key in keys:
            name = f"figures/{figure}__{key}.png"
            run.write(name, lambda tmp, f=figure, k=key: plot_design(rows, keys, f, k, tmp))


def plot_design(
    rows: list[dict[str, Any]], keys: list[str], figure: str, key: str, path: Path
) -> Path:
    """``figure`` against ``key``'s values, one line per combination of the other keys."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    others = [k for k in keys if k != key]
    values = list(dict.fromkeys(r[key] for r in rows))
    numeric = all(isinstance(v, int | float) for v in values)
    axis_of = {v: (v if numeric else i) for i, v in enumerate(values)}
    lines: dict[tuple, list[tuple[Any, Any]]] = {}
    for row in rows:
        label = tuple(row[k] for k in others)
        value = row[figure]
        lines.setdefault(label, []).append((axis_of[row[key]], np.nan if value is None else value))
    fig, axis = plt.subplots(figsize=(5.5, 3.8))
    for label, points in list(lines.items())[:12]:
        points.sort(key=lambda p: p[0])
        name = ", ".join(f"{k}={v}" for k, v in zip(others, label, strict=True)) or None
        axis.plot([p[0] for p in points], [p[1] for p in points], "o-", label=name)
    if not numeric:
        axis.set_xticks(range(len(values)), [str(v) for v in values])
    axis.set_xlabel(key)
    axis.set_ylabel(figure)
    axis.grid(alpha=0.3)
    if others:
        axis.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
