"""A calibration episode: capture every board pose with the renderer, then calibrate.

:func:`calibrate_rig` is the library entry point behind ``virtus calibrate``:

1. The board (:class:`CircleBoard`) becomes a textured plane; the poses (paper's 18 or
   ``random:N``) are checked against both fields.
2. Each pose is rendered with the full pattern sequence (52 frames by default: fringes and
   Gray codes in both directions, white, black). The circles are detected in the white
   frame and refined on the mean of the phase-shift frames; the sequence is decoded to
   projector coordinates and a local camera->projector homography is fitted around every
   circle.
3. The run's inputs go to ``out_dir/episode.json`` first and each finished pose to
   ``out_dir/poses/<name>.npz`` at once, so a late failure never loses finished poses
   (:func:`recalibrate` solves again from them); then everything is calibrated
   (:mod:`virtus.calib.solve`) and compared with the true rig (:mod:`virtus.calib.truth`).
"""

from __future__ import annotations

import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus import paper
from virtus.calib.board import CircleBoard, board_from_spec
from virtus.calib.detect import find_grid, refine_centres
from virtus.calib.io import save_json, save_opencv_yaml, save_paper_txt
from virtus.calib.poses import BoardPose, check_pose, pose_set
from virtus.calib.projector import local_homographies
from virtus.calib.solve import PoseObservation, StereoCalibration, calibrate_observations
from virtus.calib.truth import truth_error
from virtus.checks import as_rng, positive_int
from virtus.devices import Rig
from virtus.errors import InputError

#: The paper's reported numbers (DESIGN.md section 4), for summaries.
PAPER_RMS_PX = paper.RMS_PX
#: Gaussian softening (m, board plane) of the printed circles' edges, like slight lens
#: defocus: with 4 spp the centroid error falls from ~0.005 px to ~0.001 px (measured on
#: exact synthetic images); a symmetric blur leaves every circle's centroid in place.
BOARD_BLUR_M = 2e-4
#: Texel size (m) of the board texture: about a quarter of a camera pixel at 0.9 m.
BOARD_TEXEL_M = 1e-4
#: Name of the result file in the output directory.
CALIBRATION_FILE = "calibration.json"
#: Inputs of a run (true rig, board, poses, settings), written before the capture starts.
EPISODE_FILE = "episode.json"

#: Progress callback: (poses done, poses total, name of the pose just finished).
Progress = Callable[[int, int, str], None]


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate_rig`.

    Attributes
    ----------
    rig : the calibrated rig.
    rms_px : RMS reprojection error (px): ``camera``, ``projector`` (single-device
        calibrations, bias-corrected points) and ``stereo`` (joint refinement, both devices).
    per_pose : per used pose: name, RMS per device, calibrated ``board2cam``.
    truth_error : :func:`virtus.calib.truth.truth_error` against the true rig (or None).
    board : the board.
    poses : every pose that was captured (including dropped ones).
    dropped_poses : name -> reason.
    settings : how the episode ran (poses spec, spp, seed, timings).
    true_rig : the rig that rendered the images, if known.
    """

    rig: Rig
    rms_px: dict[str, float]
    per_pose: list[dict[str, Any]]
    truth_error: dict[str, Any] | None
    board: CircleBoard
    poses: list[BoardPose]
    dropped_poses: dict[str, str] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    true_rig: Rig | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``calibration.json`` content: rig schema (metres) + calibration fields."""
        data = self.rig.to_dict()
        data.update(
            {
                "rms_px": self.rms_px,
                "paper_rms_px": PAPER_RMS_PX,
                "per_pose": self.per_pose,
                "dropped_poses": self.dropped_poses,
                "board": self.board.to_dict(),
                "poses": [p.to_dict() for p in self.poses],
                "settings": self.settings,
            }
        )
        if self.truth_error is not None:
            data["truth_error"] = self.truth_error
        if self.true_rig is not None:
            data["true_rig"] = self.true_rig.to_dict()
        return data

    def save(self, path: str | Path) -> Path:
        """Write ``calibration.json`` (or the given file name) and return its path.

        A directory path gets ``calibration.json`` inside it, plus the OpenCV YAML
        (``calibration.yaml``) and the paper code's text files (``paper_txt/``).
        """
        path = Path(path)
        if path.suffix.lower() != ".json":
            directory = path
            path = directory / CALIBRATION_FILE
            save_opencv_yaml(
                self.rig,
                directory / "calibration.yaml",
                {f"rms_{k}_px": v for k, v in self.rms_px.items()},
            )
            save_paper_txt(self.rig, directory / "paper_txt")
        return save_json(self.to_dict(), path)


def board_scene(board: CircleBoard, pose: BoardPose, texture: np.ndarray) -> Any:
    """The scene of one pose: the board as a textured plane (world = camera frame)."""
    from virtus.scene import Scene, TexturedPlaneObject

    plane = TexturedPlaneObject(size_m=board.plane_size_m, texture=texture, pose=pose.board2cam)
    return Scene(objects=[plane])


def observe_pose(
    frames: np.ndarray, sequence: Any, board: CircleBoard, name: str
) -> PoseObservation:
    """Detect the circles and fit the projector homographies from one pose's frames.

    Parameters
    ----------
    frames : (F, H, W) camera frames of ``sequence`` (uint8 or float).
    sequence : the pattern sequence (knows its white frame and how to decode itself).
    board : the board.
    name : the pose's name.
    """
    kinds = [frame.kind for frame in sequence.frames]
    if "white" not in kinds:
        raise InputError("sequence", "a sequence with a white frame", kinds)
    white = frames[kinds.index("white")]
    centres = find_grid(white, board)
    if centres is None:
        return PoseObservation(name, None, None)
    # The mean of the phase-shift frames is the board under uniform light (the fringes sum
    # to zero) with each frame's 8-bit rounding averaged out: refining the centroids on it
    # instead of the single white frame cuts their error from 0.0033 to 0.0014 px.
    phase = [i for i, kind in enumerate(kinds) if kind == "phase"]
    uniform = frames[phase].mean(axis=0, dtype=np.float64) if phase else white
    centroids = refine_centres(uniform, board, centres)
    decoded = sequence.decode(frames)
    homographies = local_homographies(decoded.proj_uv, board, centres)
    return PoseObservation(name, centroids, homographies)


def _save_observation(directory: Path, pose: BoardPose, obs: PoseObservation) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {"board2cam": pose.board2cam.matrix}
    if obs.cam_centroids is not None:
        arrays["cam_centroids"] = obs.cam_centroids
    if obs.homographies is not None:
        arrays["homographies"] = obs.homographies
    # Write then rename, so an interrupted run never leaves a truncated pose file.
    partial = directory / f"{pose.name}.partial.npz"
    np.savez(partial, **arrays)
    partial.replace(directory / f"{pose.name}.npz")


def _load_observation(path: Path, name: str) -> PoseObservation:
    with np.load(path) as data:
        return PoseObservation(
            name,
            data["cam_centroids"] if "cam_centroids" in data else None,
            data["homographies"] if "homographies" in data else None,
        )


def calibrate_rig(
    true_rig: Rig,
    *,
    board: str | CircleBoard = "7x13",
    poses: str | list[BoardPose] = "paper",
    spp: int = 4,
    lookup: str = "nearest",
    rng: np.random.Generator | int | None = None,
    progress: Progress | None = None,
    out_dir: str | Path | None = None,
    fix_intrinsics: bool = False,
    check_poses: bool = True,
) -> CalibrationResult:
    """Capture a board in every pose with ``true_rig`` and calibrate it back.

    Parameters
    ----------
    true_rig : the rig that renders the images (its parameters are the truth).
    board : a :class:`CircleBoard` or ``"ROWSxCOLS"`` (paper: 4x7, 5x9, 7x13).
    poses : ``"paper"``, ``"random:N"`` or a list of :class:`BoardPose`.
    spp : renderer supersamples per pixel (a perfect square).
    lookup : the renderer's projector pattern lookup, ``"nearest"`` (sharp DMD pixels) or
        ``"bilinear"``; use the same as for the scans the calibration serves.
    rng : seeds the random poses.
    progress : called after each pose as ``progress(done, total, name)``.
    out_dir : if given, per-pose observations go to ``out_dir/poses/`` as they finish and
        the result to ``out_dir/calibration.json`` (+ YAML and the paper's text files).
    fix_intrinsics : keep single-device intrinsics in the stereo step.
    check_poses : check a given pose list against both fields first (raise on the first
        pose outside); ``False`` captures them anyway (poses whose board is not fully seen
        are then dropped with a warning).

    Returns
    -------
    :class:`CalibrationResult`.

    Raises
    ------
    VirtusError : a pose outside the fields, or fewer than 3 usable poses.
    """
    from virtus.patterns import default_sequence
    from virtus.render import render
    from virtus.render.synthesis import LOOKUPS

    spp = positive_int("spp", spp)
    if lookup not in LOOKUPS:  # checked before any pose is rendered
        raise InputError("lookup", f"one of {LOOKUPS}", lookup)
    board = board_from_spec(board)
    seed = rng if isinstance(rng, int) else None
    gen = as_rng(rng)
    if isinstance(poses, str):
        pose_list = pose_set(poses, true_rig, board, gen)
    else:
        pose_list = list(poses)
        if check_poses:
            for pose in pose_list:
                check_pose(true_rig, board, pose)
    proj = true_rig.projector.intrinsics
    sequence = default_sequence(proj.width, proj.height)
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    timing = {"render_s": 0.0, "observe_s": 0.0, "calibrate_s": 0.0}
    settings: dict[str, Any] = {
        "poses": poses if isinstance(poses, str) else "custom",
        "n_poses": len(pose_list),
        "frames_per_pose": len(sequence),
        "spp": spp,
        "lookup": lookup,
        "seed": seed,
        "fix_intrinsics": fix_intrinsics,
        "board_blur_m": BOARD_BLUR_M,
        "board_texel_m": BOARD_TEXEL_M,
        "timing_s": timing,
    }
    pose_dir = None
    if out_dir is not None:
        # The run's inputs first, so finished poses can be recalibrated after any failure.
        pose_dir = Path(out_dir) / "poses"
        save_json(
            {
                "true_rig": true_rig.to_dict(),
                "board": board.to_dict(),
                "poses": [p.to_dict() for p in pose_list],
                "settings": settings,
            },
            Path(out_dir) / EPISODE_FILE,
        )

    observations = []
    for index, pose in enumerate(pose_list):
        start = time.perf_counter()
        rendering = render(
            true_rig, board_scene(board, pose, texture), sequence, spp=spp, lookup=lookup
        )
        middle = time.perf_counter()
        obs = observe_pose(rendering.frames, sequence, board, pose.name)
        timing["render_s"] += middle - start
        timing["observe_s"] += time.perf_counter() - middle
        observations.append(obs)
        if pose_dir is not None:
            _save_observation(pose_dir, pose, obs)
        if progress is not None:
            progress(index + 1, len(pose_list), pose.name)

    return _solve_episode(true_rig, board, pose_list, observations, settings, out_dir)


def _solve_episode(
    true_rig: Rig,
    board: CircleBoard,
    pose_list: list[BoardPose],
    observations: list[PoseObservation],
    settings: dict[str, Any],
    out_dir: str | Path | None,
) -> CalibrationResult:
    start = time.perf_counter()
    cam, prj = true_rig.camera.intrinsics, true_rig.projector.intrinsics
    solved: StereoCalibration = calibrate_observations(
        board,
        observations,
        (cam.width, cam.height),
        (prj.width, prj.height),
        fix_intrinsics=settings["fix_intrinsics"],
    )
    settings["timing_s"]["calibrate_s"] = time.perf_counter() - start
    result = CalibrationResult(
        rig=solved.rig,
        rms_px=solved.rms_px,
        per_pose=solved.per_pose,
        truth_error=truth_error(solved.rig, true_rig),
        board=board,
        poses=pose_list,
        dropped_poses=solved.dropped_poses,
        settings=settings,
        true_rig=true_rig,
    )
    if out_dir is not None:
        result.save(Path(out_dir))
    return result


def recalibrate(out_dir: str | Path, *, fix_intrinsics: bool | None = None) -> CalibrationResult:
    """Calibrate again from the observations a :func:`calibrate_rig` run saved.

    Uses ``out_dir/episode.json`` and every finished ``out_dir/poses/<name>.npz`` (poses
    whose file is missing, e.g. after an interrupted run, are left out with a warning), and
    rewrites ``out_dir/calibration.json``.

    Parameters
    ----------
    out_dir : the ``out_dir`` of the run.
    fix_intrinsics : override the run's stereo option (default: as in the run).
    """
    out_dir = Path(out_dir)
    episode = json.loads((out_dir / EPISODE_FILE).read_text())
    true_rig = Rig.from_dict(episode["true_rig"])
    board = CircleBoard.from_dict(episode["board"])
    settings = dict(episode["settings"])
    if fix_intrinsics is not None:
        settings["fix_intrinsics"] = bool(fix_intrinsics)
    settings["timing_s"] = {"render_s": 0.0, "observe_s": 0.0, "calibrate_s": 0.0}
    pose_list, observations = [], []
    for item in episode["poses"]:
        pose = BoardPose.from_dict(item)
        path = out_dir / "poses" / f"{pose.name}.npz"
        if not path.is_file():
            warnings.warn(f"calibration: pose {pose.name!r} left out: {path} missing", stacklevel=2)
            continue
        pose_list.append(pose)
        observations.append(_load_observation(path, pose.name))
    return _solve_episode(true_rig, board, pose_list, observations, settings, out_dir)
