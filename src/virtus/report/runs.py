"""Which kind of run a directory holds, and whether it can be reported: finished, whole and
as its job wrote it.

Kinds (:data:`KINDS`), recognised from the directory's own record:

==============  =========================================================================
kind            recognised by
==============  =========================================================================
``demo``        ``run.json`` command ``demo`` (``metrics.json``, ``calibration/``, ``scan/``)
``calibrate``   command ``calibrate`` or ``calibrate --captures`` (``calibration.json``)
``capture``     command ``capture`` or ``import`` (a capture, perhaps decoded/reconstructed)
``scan``        command ``scan`` (capture + ``decoded/`` + ``points.ply``, perhaps evaluated)
``turntable``   command ``turntable`` (``turntable.json``, ``merged.ply``, ``view_*/``)
``ablation``    command ``ablation`` (``ablation.json``)
``twin``        command ``twin`` (``rig.json``, ``isaac.json``, ``twin.usda`` with usd-core;
                ``validation.json`` and ``validation_maps/`` with ``--validate``); a twin
                written before twins kept a ``run.json``: ``twin.usda`` + ``isaac.json``
``dataset``     ``dataset.json`` (a dataset store)
``acceptance``  command ``acceptance`` (``acceptance.json``, ``acceptance.csv``)
``predict``     command ``predict`` (``summary.json``, the sigma maps, ``mask.npy``)
``design``      command ``design`` (``design.json``, ``design.csv``, ``figures/``)
``robot-scan``  command ``robot-scan`` (``robot_scan.json``, ``merged.ply``, ``views/*``)
``learn``       command ``learn train`` (``metrics.json``, ``history.json``; the
                ``evaluations/`` that ``virtus learn eval`` adds)
==============  =========================================================================

Refused, each with one line naming the problem (:class:`virtus.errors.InputError`):
a path that is no directory or holds no run; a run whose ``run.json`` says ``running`` or
``failed`` (half-finished) or a store with fewer finished samples than requested; a run whose
files were changed or removed since it wrote them (a file its record lists missing, a
decoded or reconstructed set no longer tied to the frames it came from, a JSON file that
does not parse or lacks its keys, an array of the wrong shape).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, VirtusError
from virtus.io.runs import RUN_FILE, RUN_FORMAT, file_digest
from virtus.io.safeio import read_json

__all__ = [
    "KINDS",
    "NotReportable",
    "RunInfo",
    "check_arrays",
    "check_run",
    "check_ties",
    "read_run_json",
]

#: Run kinds a report can be made of.
KINDS = (
    "demo",
    "calibrate",
    "capture",
    "scan",
    "turntable",
    "ablation",
    "twin",
    "dataset",
    "acceptance",
    "predict",
    "design",
    "robot-scan",
    "learn",
)


def _commands() -> dict[str, str]:
    """``run.json`` command -> kind (the names as each job spells them)."""
    from virtus.design import acceptance, predict, sweep
    from virtus.pipeline import ablation, calibrate, capture, demo, scan, turntable, twin
    from virtus.robot import scan as robot_scan

    return {
        acceptance.COMMAND: "acceptance",
        predict.COMMAND: "predict",
        sweep.COMMAND: "design",
        robot_scan.COMMAND: "robot-scan",
        "learn train": "learn",  # virtus.learn.training's (not imported here: it needs torch)
        demo.COMMAND: "demo",
        calibrate.COMMAND: "calibrate",
        calibrate.CAPTURES_COMMAND: "calibrate",
        calibrate.POINTS_COMMAND: "calibrate",
        capture.CAPTURE_COMMAND: "capture",
        capture.IMPORT_COMMAND: "capture",
        scan.COMMAND: "scan",
        turntable.COMMAND: "turntable",
        ablation.COMMAND: "ablation",
        twin.TWIN_COMMAND: "twin",
    }


#: Files each kind must hold (relative to the run directory).
_REQUIRED = {
    "demo": ("metrics.json", "calibration/calibration.json", "scan/capture.json"),
    "calibrate": ("calibration.json",),
    "capture": ("capture.json",),
    "scan": ("capture.json", "points.ply"),
    "turntable": ("turntable.json", "merged.ply"),
    "ablation": ("ablation.json",),
    "twin": ("isaac.json", "rig.json"),
    "dataset": ("dataset.json",),
    "acceptance": ("acceptance.json", "acceptance.csv"),
    "predict": ("summary.json", "mask.npy"),
    "design": ("design.json", "design.csv"),
    "robot-scan": ("robot_scan.json", "merged.ply", "trajectory.json"),
    "learn": ("metrics.json", "history.json", "config.json"),
}


class NotReportable(InputError):
    """A directory that cannot be reported: ``"<path>: <problem>"``, one line."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.name, self.expected, self.got = str(path), "a finished, unchanged run", problem
        VirtusError.__init__(self, f"{path}: {problem}")


@dataclass(frozen=True)
class RunInfo:
    """A checked run directory.

    Attributes
    ----------
    path : the directory.
    kind : one of :data:`KINDS`.
    command : the command that made it (``run.json``'s, or ``twin`` / ``dataset``).
    record : ``run.json``'s content (empty for twins and stores).
    """

    path: Path
    kind: str
    command: str
    record: dict[str, Any]


def read_run_json(path: Path, name: str, what: str, keys: tuple[str, ...] = ()) -> dict:
    """A JSON object of a run, read by the guarded reader, with ``keys`` present; a file
    that does not parse or lacks a key is named as changed since the run wrote it."""
    file = path / name
    try:
        data = read_json(file, what, expect=dict)
    except FileNotFoundError:
        raise NotReportable(
            file, f"the run's {what} is missing (removed since it was written?)"
        ) from None
    missing = [key for key in keys if key not in data]
    if missing:
        raise NotReportable(file, f"{what} without {', '.join(missing)}: edited since the run?")
    return data


def _kind(path: Path) -> tuple[str, str, dict[str, Any]]:
    if not path.is_dir():
        raise NotReportable(path, "not a directory (expected the directory of a virtus run)")
    if (path / RUN_FILE).is_file():
        record = read_run_json(path, RUN_FILE, "run record", ("format", "command", "status"))
        if record.get("format") != RUN_FORMAT:
            raise NotReportable(path / RUN_FILE, f"not a {RUN_FORMAT} record")
        command, commands = str(record["command"]), _commands()
        if command not in commands:
            raise NotReportable(path, f"a `virtus {command}` run, which has no report")
        return commands[command], command, record
    if (path / "dataset.json").is_file():
        return "dataset", "dataset", {}
    if (path / "twin.usda").is_file():
        return "twin", "twin", {}
    raise NotReportable(
        path, f"not a virtus run (no {RUN_FILE}, no dataset store's dataset.json, no twin.usda)"
    )


def check_run(path: str | Path) -> RunInfo:
    """Recognise and check a run directory (see the module docstring).

    Raises
    ------
    InputError : not a run, a half-finished run, or a run whose files were changed.
    """
    path = Path(path)
    kind, command, record = _kind(path)
    status = record.get("status")
    if record and status != "complete":
        error = f" ({record['error']})" if record.get("error") else ""
        raise NotReportable(
            path, f"a half-finished `virtus {command}` run (status {status}{error}); finish it "
            "with --resume first",
        )  # fmt: skip
    for name in _REQUIRED[kind]:
        if not (path / name).is_file():
            raise NotReportable(path / name, f"missing, though a finished {command} run has it "
                                "(removed or moved since the run?)")  # fmt: skip
    _check_listed(path, kind, record)
    if kind in ("scan", "capture"):
        check_ties(path)
        check_arrays(path)
    if kind == "demo":
        check_ties(path / "scan")
        check_arrays(path / "scan", ("sphere_radial_error.npy",))
    if kind == "dataset":
        _check_store(path)
    if kind == "robot-scan":
        _check_views(path)
    return RunInfo(path, kind, command, record)


def _check_listed(path: Path, kind: str, record: dict[str, Any]) -> None:
    """Every file the run's record owns is there, except derived files a capture owns
    before they are made (decode, reconstruct, evaluate come later, if ever)."""
    from virtus.capture.scandir import DERIVED_FILES

    depth = {"demo": 1, "turntable": 1, "robot-scan": 2}.get(kind, 0)
    for name in record.get("files", []):
        # a demo's scan/..., a turntable's view_N/..., a robot scan's views/NNN/...
        inner = name.split("/", depth)[-1]
        if name in DERIVED_FILES or inner in DERIVED_FILES:
            continue
        if not (path / name).is_file():
            raise NotReportable(path / name, "missing, though the run's record lists it "
                                "(removed since the run wrote it?)")  # fmt: skip


def check_ties(path: Path) -> None:
    """A capture directory's derived files still belong to its frames: ``decoded/`` and
    ``points.ply`` were made from the frames and ``capture.json`` the directory holds now."""
    from virtus.capture.capture import Capture
    from virtus.capture.scandir import (
        DECODED_DIR,
        DECODED_SOURCE,
        EVALUATION_JSON,
        POINTS_PLY,
        check_points_current,
        frames_checksum,
    )

    capture = Capture.load(path)
    tie = path / DECODED_DIR / DECODED_SOURCE
    if tie.is_file():
        source = read_json(tie, "decoded/source.json", expect=dict)
        if source.get("capture_sha256") != frames_checksum(capture):
            raise NotReportable(
                path, "frames or capture.json changed since decoding (decoded/ is stale); run "
                f"`virtus decode {path}` again",
            )  # fmt: skip
    evaluation = path / EVALUATION_JSON
    if evaluation.is_file():
        recorded = read_json(evaluation, "evaluation", expect=dict).get("cloud_sha256")
        ply = path / POINTS_PLY
        if not ply.is_file() or recorded != file_digest(ply):
            raise NotReportable(
                evaluation, "measured another cloud (points.ply changed since); run "
                f"`virtus evaluate {path}` again",
            )  # fmt: skip
    if (path / POINTS_PLY).is_file():
        try:
            check_points_current(capture, path / POINTS_PLY)
        except InputError:
            raise
        except VirtusError as error:
            raise NotReportable(path / POINTS_PLY, str(error)) from None


#: Arrays of a capture directory the report reads: name -> (dtype, trailing shape).
_ARRAYS = {
    "decoded/phase_v.npy": (np.float64, ()),
    "decoded/phase_h.npy": (np.float64, ()),
    "decoded/modulation.npy": (np.float64, ()),
    "decoded/mask.npy": (bool, ()),
    "decoded/flagged.npy": (bool, ()),
    "reconstruction/points.npy": (np.float64, (3,)),
    "sphere_radial_error.npy": (np.float64, ()),
}


def check_arrays(path: Path, required: tuple[str, ...] = ()) -> None:
    """The arrays of a capture directory the report reads have the camera's image size and
    their dtype (each read by the guarded reader, which also bounds its size); ``required``
    ones must be there."""
    from virtus.io.safeio import load_npy

    capture = read_run_json(path, "capture.json", "capture description", ("rig",))
    try:
        camera = capture["rig"]["camera"]
        size = (int(camera["height"]), int(camera["width"]))
    except (KeyError, TypeError, ValueError):
        raise NotReportable(path / "capture.json", "no camera image size in its rig") from None
    for name, (dtype, trailing) in _ARRAYS.items():
        if (path / name).is_file() or name in required:
            load_npy(path / name, name, dtype=dtype, shape=(*size, *trailing))


def _check_store(path: Path) -> None:
    from virtus.data import DatasetStore

    store = DatasetStore.open(path)
    done = len(store.samples())
    if done < store.num_samples:
        raise NotReportable(
            path, f"a half-finished dataset store ({done} of {store.num_samples} samples); "
            "finish it with `virtus dataset generate` first",
        )  # fmt: skip


def _check_views(path: Path) -> None:
    """Each view of a robot scan is a whole capture directory whose derived files still
    belong to its frames."""
    from virtus.report.robot import RESULT_JSON, view_dirs

    data = read_run_json(path, RESULT_JSON, "robot scan summary", ("views",))
    for view in view_dirs(path, data):
        if not view.resolve().is_relative_to(path.resolve()):
            raise NotReportable(path / RESULT_JSON, f"a view outside the run: {view}")
        check_ties(view)
        check_arrays(view)
