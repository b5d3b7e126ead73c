"""A calibration's result: the calibrated rig, its errors, the poses, and the files it is
saved as (``calibration.json``, ``calibration.yaml``, ``paper_txt/``).

``calibration.json`` is the rig schema (metres, DESIGN.md section 3) plus the calibration
fields of :meth:`CalibrationResult.to_dict` (errors, poses, and how well the data determine
the parameters: ``uncertainty`` and ``conditioning``, :mod:`virtus.calib.conditioning`);
``calibration.yaml`` is the rig as OpenCV FileStorage YAML and ``paper_txt/*.txt`` the
paper code's text files (:mod:`virtus.calib.io`). The calibration job
(:mod:`virtus.pipeline.calibrate`) makes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virtus import paper
from virtus.calib.board import Board
from virtus.calib.io import PAPER_TXT_FILES, save_opencv_yaml, save_paper_txt
from virtus.calib.poses import BoardPose
from virtus.geometry.devices import Rig
from virtus.io.runs import atomic_write, atomic_write_files, write_json_atomic

__all__ = [
    "CALIBRATION_FILE",
    "PAPER_RMS_PX",
    "PAPER_TXT_DIR",
    "RESULT_FILES",
    "YAML_FILE",
    "CalibrationResult",
]

#: The paper's reported numbers (DESIGN.md section 4), for summaries.
PAPER_RMS_PX = paper.RMS_PX
#: File names of a saved result, relative to its directory.
CALIBRATION_FILE = "calibration.json"
YAML_FILE = "calibration.yaml"
PAPER_TXT_DIR = "paper_txt"
#: Files the result writes (:meth:`CalibrationResult.save`), relative to the directory.
RESULT_FILES = (
    CALIBRATION_FILE,
    YAML_FILE,
    *(f"{PAPER_TXT_DIR}/{name}" for name in PAPER_TXT_FILES.values()),
)


@dataclass
class CalibrationResult:
    """Outcome of :func:`virtus.pipeline.calibrate.calibrate_rig`.

    Attributes
    ----------
    rig : the calibrated rig.
    rms_px : RMS reprojection error (px): ``camera``, ``projector`` (single-device
        calibrations, bias-corrected points) and ``stereo`` (joint refinement, both devices).
    per_pose : per used pose: name, RMS per device, calibrated ``board2cam`` (from the
        joint refinement, consistent with ``rig``).
    truth_error : :func:`virtus.calib.truth.truth_error` against the true rig (or None).
    board : the board (None: calibrated from correspondences with their own object points).
    poses : every pose that was captured (including dropped ones).
    dropped_poses : name -> reason.
    settings : how the episode ran (poses spec, spp, pixel model, sensor, seed, ...).
    true_rig : the rig that rendered the images, if known.
    timing_s : seconds spent by this process (``render_s``, ``observe_s``,
        ``calibrate_s``); not part of :meth:`to_dict`, which must not depend on the run.
    uncertainty : standard deviations of the parameters
        (:func:`~virtus.calib.conditioning.calibration_uncertainty`; empty if not computed).
    conditioning : the conditioning check: values, levels, warnings
        (:func:`~virtus.calib.conditioning.conditioning_report`; empty if not computed).
    """

    rig: Rig
    rms_px: dict[str, float]
    per_pose: list[dict[str, Any]]
    truth_error: dict[str, Any] | None
    board: Board | None
    poses: list[BoardPose]
    dropped_poses: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    true_rig: Rig | None = None
    timing_s: dict[str, float] = field(default_factory=dict)
    uncertainty: dict[str, Any] = field(default_factory=dict)
    conditioning: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The ``calibration.json`` content: rig schema (metres) + calibration fields."""
        data = self.rig.to_dict()
        data.update(
            {
                "rms_px": self.rms_px,
                "paper_rms_px": PAPER_RMS_PX,
                "per_pose": self.per_pose,
                "dropped_poses": self.dropped_poses,
                "board": None if self.board is None else self.board.to_dict(),
                "poses": [p.to_dict() for p in self.poses],
                "settings": self.settings,
            }
        )
        if self.truth_error is not None:
            data["truth_error"] = self.truth_error
        if self.true_rig is not None:
            data["true_rig"] = self.true_rig.to_dict()
        for key in ("uncertainty", "conditioning"):
            if getattr(self, key):
                data[key] = getattr(self, key)
        return data

    def save(self, path: str | Path) -> Path:
        """Write ``calibration.json`` (or the given ``.json`` file) and return its path.

        A directory path gets :data:`RESULT_FILES`: ``calibration.json``, the OpenCV YAML
        (``calibration.yaml``) and the paper code's text files (``paper_txt/``), each
        written atomically, ``calibration.json`` last.
        """
        path = Path(path)
        if path.suffix.lower() == ".json":
            return write_json_atomic(path, self.to_dict())
        extras = {f"rms_{k}_px": v for k, v in self.rms_px.items()}
        atomic_write(path / YAML_FILE, lambda tmp: save_opencv_yaml(self.rig, tmp, extras))
        atomic_write_files(
            path / PAPER_TXT_DIR,
            list(PAPER_TXT_FILES.values()),
            lambda staging: save_paper_txt(self.rig, staging),
        )
        return write_json_atomic(path / CALIBRATION_FILE, self.to_dict())
