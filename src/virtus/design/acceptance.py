"""``virtus acceptance``: a virtual VDI/VDE 2634-2 acceptance test of a scanner.

:func:`acceptance_test` runs the test a customer would run on the real scanner:

1. The measuring volume: given, or derived from the rig (:mod:`virtus.design.volume`), and
   checked against both fields; the artefacts sized and placed in it
   (:mod:`virtus.design.artefacts`: a sphere at 10 positions, a ball bar at 7, a plane at 6).
2. The rig used to reconstruct: by default a **virtual calibration of the same scanner**
   (:func:`virtus.pipeline.calibrate.calibrate_rig`, into ``OUT/calibration/``), as a real
   test uses the calibrated scanner; or the true rig (``"true"``: the figures then show
   the sensor and decoding alone); or a given rig or calibration file.
3. Each position rendered with the scanner (its true rig, sensor, projector model and render
   settings), decoded, triangulated with the rig of step 2 and evaluated
   (:mod:`virtus.design.figures`): P_F and P_S per sphere position, SD per ball-bar position
   (and P_F/P_S of its two spheres, recorded), F per plane position.
4. The maximum magnitude of each figure, and pass/fail against the user's limits (mm).

Output directory (owned through :func:`virtus.io.runs.claim_run`)::

    OUT/run.json                  the run record (configuration, status, files)
    OUT/calibration/              the virtual calibration's own run (absent with a given rig)
    OUT/positions/<name>.json     one position's figures (mm), written as soon as measured
    OUT/acceptance.json           volume, artefacts, rig used, every position, the maxima,
                                  limits and pass/fail (mm)
    OUT/acceptance.csv            one row per position and figure:
                                  feature,position,figure,value_mm

**Reproducible and resumable.** Each position's capture seed derives from the run's seed
and its index; identical runs write identical files. ``resume=True`` continues a run: the
positions already written are read back and not rendered again (a resumed calibration is
the calibration job's own resume), so the result is byte for byte that of an uninterrupted
run.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.design.artefacts import FEATURES as FEATURES_COUNT
from virtus.design.artefacts import ArtefactPosition, Artefacts, artefact_layout
from virtus.design.figures import measure_plane, measure_sphere
from virtus.design.volume import MeasuringVolume, check_volume, volume_from_rig
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.io.runs import RunDirectory, claim_run
from virtus.io.safeio import read_json
from virtus.reconstruct import check_baseline, reconstruct
from virtus.scanner import Scanner
from virtus.sensor.noise import MAX_SEED, as_seed

__all__ = [
    "ACCEPTANCE_CSV",
    "ACCEPTANCE_JSON",
    "FIGURES",
    "AcceptanceResult",
    "acceptance_test",
    "interior",
    "parse_limits",
]

#: The job's name in ``run.json``.
COMMAND = "acceptance"
ACCEPTANCE_JSON = "acceptance.json"
ACCEPTANCE_CSV = "acceptance.csv"
POSITION_DIR = "positions"
CALIBRATION_DIR = "calibration"
LAYOUT = (ACCEPTANCE_JSON, ACCEPTANCE_CSV, f"{POSITION_DIR}/*.json")
#: The figures, the feature that measures each, and what they mean.
FIGURES = {
    "P_F": ("sphere", "probing error form: range of the sphere fit's radial residuals"),
    "P_S": ("sphere", "probing error size: fitted minus calibrated diameter"),
    "SD": ("ball_bar", "sphere-spacing error: measured minus calibrated centre distance"),
    "F": ("plane", "flatness: range of the signed distances to the fitted plane"),
}
#: Largest limit accepted, mm (a limit in metres or micrometres typed as mm is refused).
MAX_LIMIT_MM = 1e4

#: Progress callback: (positions done, positions total, name of the position just done).
Progress = Callable[[int, int, str], None]


def parse_limits(limits: str | Mapping[str, float] | None) -> dict[str, float]:
    """Limits by figure name in mm, from ``"P_F=0.05,SD=0.1"`` or a mapping; names are
    :data:`FIGURES`' (an unknown name, a repeated one or a value that is not a positive
    number is an :class:`InputError` naming ``--limits``)."""
    if limits is None:
        return {}
    expected = f"NAME=MM pairs, NAME one of {', '.join(FIGURES)}, MM > 0 (e.g. P_F=0.05,SD=0.1)"
    if isinstance(limits, Mapping):
        pairs = [(str(k), v) for k, v in limits.items()]
    else:
        pairs = []
        for item in str(limits).split(","):
            name, sep, value = item.partition("=")
            if not sep:
                raise InputError("--limits", expected, limits)
            pairs.append((name.strip(), value.strip()))
    out: dict[str, float] = {}
    for name, value in pairs:
        if name not in FIGURES:
            raise InputError("--limits", expected, f"unknown figure {name!r}")
        if name in out:
            raise InputError("--limits", expected, f"{name} given twice")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise InputError("--limits", expected, f"{name}={value}") from None
        if isinstance(value, bool) or not (0 < number <= MAX_LIMIT_MM):
            raise InputError("--limits", expected, f"{name}={value}")
        out[name] = number
    return {name: out[name] for name in FIGURES if name in out}


@dataclass(frozen=True)
class AcceptanceResult:
    """Outcome of :func:`acceptance_test`: ``summary`` is ``acceptance.json``'s content;
    ``directory`` the run directory."""

    summary: dict[str, Any]
    directory: Path

    @property
    def passed(self) -> bool | None:
        """Whether every limited figure passed (None without limits)."""
        return self.summary["passed"]


def _position_seed(seed: int, name: str) -> int:
    """Capture seed of the position called ``name`` (``"sphere_01"``...): from the run's seed
    and the position's number in the full test, so a position renders the same in a
    shortened run, and independently of the calibration's pose seeds."""
    feature, number = name.rsplit("_", 1)
    index = sum(list(FEATURES_COUNT.values())[: list(FEATURES_COUNT).index(feature)])
    index += int(number) - 1
    state = np.random.SeedSequence([seed, 0xAC, index]).generate_state(1, dtype=np.uint64)
    return int(state[0]) & MAX_SEED


def _measure(position: ArtefactPosition, points: np.ndarray, sizes: Artefacts) -> dict[str, Any]:
    """One position's figures (mm) from its point map."""
    data = position.to_dict()
    if position.feature == "plane":
        data.update(measure_plane(points, position.plane2cam, position.plane_size_m,  # type: ignore[arg-type]
                                  position.name).to_dict())  # fmt: skip
        return data
    fits = [
        measure_sphere(points, c, position.radius_m, f"{position.name} sphere {i + 1}")  # type: ignore[arg-type]
        for i, c in enumerate(position.centres_m)
    ]
    spheres = [fit.to_dict(sizes.sphere_diameter_m) for fit in fits]
    if position.feature == "sphere":
        data.update(spheres[0])
    else:
        distance = float(np.linalg.norm(fits[1].centre_m - fits[0].centre_m))
        data["SD_mm"] = 1e3 * (distance - sizes.bar_length_m)
        data["distance_mm"] = 1e3 * distance
        data["spheres"] = spheres
    return data


def _run_position(
    scanner: Scanner, rig: Rig, position: ArtefactPosition, sizes: Artefacts, seed: int
) -> dict[str, Any]:
    capture = scanner.capture(position.scene(), rng=seed, command=[])
    decoded = capture.decode()
    recon = reconstruct(rig, decoded.proj_uv, interior(decoded.mask))
    data = _measure(position, recon.points, sizes)
    data["seed"] = seed
    return data


def interior(mask: np.ndarray) -> np.ndarray:
    """``mask`` (H, W) bool without its outline: pixels with an undecoded 8-neighbour (or on
    the image border) are left out. An artefact's outline pixels are only partly covered, so
    their decoded projector coordinates are those of an off-centre part of the pixel while
    triangulation uses its centre ray: millimetres of error, not the scanner's."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, np.ones((3, 3), dtype=bool), border_value=False)


def _figure_rows(positions: list[dict[str, Any]]) -> list[tuple[str, str, str, float]]:
    rows = []
    for data in positions:
        for figure, (feature, _) in FIGURES.items():
            if data["feature"] == feature:
                rows.append((feature, data["name"], figure, data[f"{figure}_mm"]))
    return rows


def _summary(positions: list[dict[str, Any]], limits: dict[str, float]) -> dict[str, Any]:
    maxima: dict[str, Any] = {}
    for figure in FIGURES:
        values = [row[3] for row in _figure_rows(positions) if row[2] == figure]
        if values:
            worst = max(values, key=abs)  # the signed value of the largest magnitude
            maxima[figure] = {"max_abs_mm": abs(worst), "value_mm": worst, "n": len(values)}
    verdicts = {}
    for figure, limit in limits.items():
        if figure in maxima:
            ok = maxima[figure]["max_abs_mm"] <= limit
            verdicts[figure] = {"limit_mm": limit, "passed": ok}
    passed = all(v["passed"] for v in verdicts.values()) if verdicts else None
    return {"maxima": maxima, "limits": verdicts, "passed": passed}


def _calibrated_rig(
    scanner: Scanner, calibration: Any, run: RunDirectory, options: dict[str, Any],
) -> tuple[Rig, dict[str, Any]]:  # fmt: skip
    """The rig to reconstruct with, and its description for acceptance.json."""
    if isinstance(calibration, Rig):
        return calibration, {"kind": "given"}
    if calibration == "true":
        return scanner.rig, {"kind": "true"}
    from virtus.pipeline.calibrate import calibrate_rig

    folder = run.file(CALIBRATION_DIR)
    resume = (folder / "run.json").is_file() and not options["overwrite"]
    result = calibrate_rig(
        scanner,
        board=options["board"],
        poses=options["poses"],
        rng=options["seed"],
        out_dir=folder,
        resume=resume,
        overwrite=options["overwrite"],
    )
    info = {"kind": "virtual calibration", "directory": CALIBRATION_DIR,
            "rms_px": result.rms_px, "truth_error": result.truth_error}  # fmt: skip
    return result.rig, info


def _check(
    scanner: Scanner, volume: MeasuringVolume | None, positions: int | None, calibration: Any
) -> tuple[MeasuringVolume, Artefacts, list[ArtefactPosition], Any]:
    if not isinstance(scanner, Scanner):
        raise InputError("scanner", "a virtus.scanner.Scanner", type(scanner).__name__)
    if volume is None:
        volume = volume_from_rig(scanner.rig, scanner.render)
    elif not isinstance(volume, MeasuringVolume):
        raise InputError("volume", "a MeasuringVolume or None", type(volume).__name__)
    check_volume(volume, scanner.rig)
    sizes, layout = artefact_layout(volume, scanner.rig, positions)
    for position in layout:
        scanner.check(position.scene())
    if isinstance(calibration, str | Path) and calibration not in ("virtual", "true"):
        from virtus.calib.io import load_rig_file

        path = Path(calibration)
        if not path.is_file():
            raise InputError("--calibration", "an existing calibration file", str(path))
        calibration = load_rig_file(
            path, scanner.rig, units="m" if path.suffix == ".json" else None
        )
    if isinstance(calibration, Rig):
        check_baseline(calibration, "calibration")
    elif calibration not in ("virtual", "true"):
        raise InputError(
            "calibration", "'virtual', 'true', a Rig or a calibration file", calibration
        )
    return volume, sizes, layout, calibration


def acceptance_test(
    scanner: Scanner,
    out_dir: str | Path,
    *,
    volume: MeasuringVolume | None = None,
    limits: str | Mapping[str, float] | None = None,
    positions: int | None = None,
    calibration: str | Path | Rig = "virtual",
    board: str = "7x13",
    calibration_poses: str = "paper",
    rng: np.random.Generator | int | None = None,
    overwrite: bool = False,
    resume: bool = False,
    progress: Progress | None = None,
) -> AcceptanceResult:
    """Run a virtual VDI/VDE 2634-2 acceptance test of ``scanner`` (module docstring).

    Parameters
    ----------
    scanner : the virtual scanner (its rig is the truth that renders every capture).
    out_dir : the run directory (layout in the module docstring).
    volume : the measuring volume (camera frame); None derives it from the rig.
    limits : limits in mm by figure (``"P_F=0.05,SD=0.1"`` or a mapping), see
        :func:`parse_limits`; None: no pass/fail.
    positions : measure only the first ``positions`` (1-10) of each feature (a shortened
        test, recorded as not ``complete``); None: all 10 + 7 + 6.
    calibration : ``"virtual"`` (calibrate the scanner first), ``"true"`` (its true rig), a
        :class:`~virtus.geometry.devices.Rig` or a calibration file (rig schema, metres).
    board, calibration_poses : the virtual calibration's board and poses
        (:func:`~virtus.pipeline.calibrate.calibrate_rig`'s ``board`` and ``poses``).
    rng : the run's seed (int >= 0; None = 0): the calibration's and every position's.
    overwrite, resume : replace an earlier run in ``out_dir``, or continue it.
    progress : called as ``progress(done, total, name)`` after each position, and as
        ``progress(0, total, "virtual calibration")`` before a virtual calibration.

    Raises
    ------
    InputError : bad limits, positions, volume (outside a field, too flat), calibration --
        all before anything is written.
    VirtusError : ``out_dir`` in use or holding another run; an artefact not seen.
    """
    limit_values = parse_limits(limits)
    volume, sizes, layout, calibration = _check(scanner, volume, positions, calibration)
    seed = as_seed(rng)
    options = {"board": board, "poses": calibration_poses, "seed": seed, "overwrite": overwrite}
    if calibration == "virtual":
        from virtus.calib.board import board_from_spec
        from virtus.pipeline.calibrate import check_pose_spec

        options["board"] = board_from_spec(board)
        options["poses"] = check_pose_spec(calibration_poses)
    config = {
        "scanner": scanner.to_dict(),
        "volume": volume.to_dict(),
        "positions": positions,
        "limits": limit_values,
        "calibration": calibration.to_dict() if isinstance(calibration, Rig) else calibration,
        "board": options["board"].to_dict() if calibration == "virtual" else None,
        "calibration_poses": options["poses"] if calibration == "virtual" else None,
        "seed": seed,
    }
    with claim_run(
        out_dir, COMMAND, config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        if calibration == "virtual" and progress is not None:
            progress(0, len(layout), "virtual calibration")
        rig, rig_info = _calibrated_rig(scanner, calibration, run, options)
        results = []
        for index, position in enumerate(layout):
            name = f"{POSITION_DIR}/{position.name}.json"
            path = run.file(name)
            if run.resumed and path.is_file():
                data = read_json(path, "position", expect=dict)
                run.own(name)
            else:
                data = _run_position(
                    scanner, rig, position, sizes, _position_seed(seed, position.name)
                )
                run.write_json(name, data)
            results.append(data)
            if progress is not None:
                progress(index + 1, len(layout), position.name)
        summary = {
            "standard": "VDI/VDE 2634 Part 2 (virtual)",
            "complete": positions is None,
            "units": "mm",
            "volume": volume.to_dict(),
            "artefacts": sizes.to_dict(),
            "rig": {**rig_info, "rig": rig.to_dict()},
            "figures": {k: v[1] for k, v in FIGURES.items()},
            **_summary(results, limit_values),
            "positions": results,
        }
        run.write_json(ACCEPTANCE_JSON, summary)
        run.write(ACCEPTANCE_CSV, lambda p: p.write_text(_csv(results)))
    return AcceptanceResult(summary, Path(out_dir))


def _csv(positions: list[dict[str, Any]]) -> str:
    lines = ["feature,position,figure,value_mm"]
    for feature, name, figure, value in _figure_rows(positions):
        lines.append(f"{feature},{name},{figure},{value!r}")
    return "\n".join(lines) + "\n"
