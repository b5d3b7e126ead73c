"""The calibration job: render a board in many poses with a scanner and calibrate it back,
or calibrate a real rig from its captures.

:func:`calibrate_rig` is the library function behind ``virtus calibrate``;
:func:`calibrate_captures` behind ``virtus calibrate --captures``, which runs the same
detection (:func:`~virtus.calib.observe.observe_pose`) and solver on captures made anywhere
(a real bench through :func:`virtus.capture.capture.import_capture`, or rendered), one
capture of the whole sequence per board pose, and writes the same result files (no truth
comparison: the truth is unknown).

Rendered calibration:

1. The board (:class:`~virtus.calib.board.CircleBoard` or
   :class:`~virtus.calib.board.CheckerBoard`) becomes a textured plane; the poses
   (the paper's 18, ``random:N`` or a list) are checked against both fields.
2. Each pose is captured with the scanner (its rig is the truth; its sequence, projector
   model, sensor and spp are used as they are), with a capture seed derived from the
   run's seed and the pose's index (:func:`pose_seed`).
   :func:`~virtus.calib.observe.observe_pose` detects the circles, refines their centroids
   on the board under uniform light and fits a local camera->projector homography around
   each circle from the decoded projector coordinates.
3. Camera, projector and their pose are solved (:mod:`virtus.calib.solve`) with OpenCV on
   one thread and compared with the true rig (:mod:`virtus.calib.truth`). A degenerate
   pose set (boards all nearly parallel: :func:`~virtus.calib.poses.check_pose_spread`) is
   refused before any pose is rendered, and again on the poses left usable for the solve.

Output directory (``out_dir``; owned by the run through :func:`virtus.io.runs.claim_run`)::

    OUT/run.json             the run record: command, configuration, status, owned files, log
    OUT/.virtus.lock         the lock that keeps a second run out while this one runs
    OUT/episode.json         true rig, scanner, board, poses, capture seeds, settings
                             (written before the first pose)
    OUT/poses/<name>.npz     one finished pose, written as soon as it is observed:
                             board2cam (4, 4) float64 true board pose (board frame -> camera
                             frame, metres), seed (capture seed), episode (SHA-256 of
                             episode.json's content), cam_centroids (N, 2) float64 px,
                             homographies (N, 3, 3) float64 camera px -> projector px
                             (the last two absent when the board was not detected)
    OUT/calibration.json     the result: rig schema (metres) + errors, per-pose residuals,
                             board, poses, settings, truth comparison
    OUT/calibration.yaml     the calibrated rig as OpenCV FileStorage YAML
    OUT/paper_txt/*.txt      the paper code's text files
    OUT/timing.json          seconds spent by this process (render, observe, calibrate)

**Reproducible.** Two runs with the same scanner, board, poses and seed write byte-identical
``calibration.json``, ``calibration.yaml``, ``paper_txt/*``, ``episode.json``, pose files
and ``run.json``: captures are deterministic (counter-based noise), nothing written depends
on time, and the solve runs OpenCV on one thread (its thread pool otherwise changes the
summation order and the last digits). Only ``timing.json`` differs between runs.

**Resumable.** Every file is written atomically and each finished pose at once, so a killed
run loses at most the pose in progress. ``resume=True`` (``virtus calibrate --resume``)
continues it: the configuration must equal the recorded one, finished poses are read back
(each must belong to this episode) and never rendered again, and the result is byte for
byte that of an uninterrupted run. :func:`recalibrate` solves again from the pose files.
"""

from __future__ import annotations

import collections
import contextlib
import re
import time
import warnings
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from virtus.calib import conditioning, points, solve
from virtus.calib.board import Board, board_from_dict, board_from_spec
from virtus.calib.observe import check_sequence, observation_device, observe_pose
from virtus.calib.observers import Observers, observe_timed, observer_pool, observers
from virtus.calib.posefile import load_pose_observation, save_pose_arrays, save_pose_observation
from virtus.calib.poses import BoardPose, check_pose, check_pose_spread, pose_set
from virtus.calib.result import RESULT_FILES, CalibrationResult
from virtus.calib.scene import (
    BOARD_BLUR_M,
    BOARD_TEXEL_M,
    board_scene,
    board_texture,
    board_window,
)
from virtus.calib.solve import MIN_POSES, PoseObservation, calibrate_observations
from virtus.calib.truth import truth_error
from virtus.capture.capture import Capture
from virtus.capture.scandir import capture_dirs
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.io.runs import (
    RunDirectory,
    claim_run,
    config_digest,
    directory_lock,
)
from virtus.io.safeio import read_json
from virtus.scanner import Scanner
from virtus.sensor.noise import MAX_SEED, as_seed

__all__ = [
    "MAX_RANDOM_POSES",
    "calibrate_captures",
    "calibrate_points",
    "calibrate_rig",
    "check_pose_spec",
    "recalibrate",
]

#: Most poses of ``random:N`` (each pose is a full capture: 200 are ~10,000 frames).
MAX_RANDOM_POSES = 200
#: The job's name in ``run.json``.
COMMAND = "calibrate"
#: File names in the output directory (layout in the module docstring; the result's files,
#: :data:`~virtus.calib.result.RESULT_FILES`, are :mod:`virtus.calib.result`'s).
EPISODE_FILE = "episode.json"
POSE_DIR = "poses"
TIMING_FILE = "timing.json"
#: Everything the job may write: an earlier run's files without a ``run.json``.
LAYOUT = (*RESULT_FILES, EPISODE_FILE, TIMING_FILE, f"{POSE_DIR}/*.npz")

#: Progress callback: (poses done, poses total, name of the pose just finished).
Progress = Callable[[int, int, str], None]


# -- capture seeds (poses are observed by :mod:`virtus.calib.observers`) -------------------


def pose_seed(seed: int, index: int) -> int:
    """Capture seed of pose ``index`` (0-based) of a run seeded with ``seed``: 63 bits of
    ``SeedSequence([seed, index])``, so poses get independent noise streams and a resumed
    run renders a pose exactly as the first run would have."""
    state = np.random.SeedSequence([seed, index]).generate_state(1, dtype=np.uint64)
    return int(state[0]) & MAX_SEED


# -- the episode ----------------------------------------------------------------------------


def check_pose_spec(spec: str) -> str:
    """``spec`` if it is ``"paper"`` or ``"random:N"`` with ``MIN_POSES <= N <=``
    :data:`MAX_RANDOM_POSES`, else :class:`InputError` (checked before anything is done)."""
    text = str(spec).strip().lower()
    match = re.fullmatch(r"random:(\d{1,9})", text)
    if text == "paper" or (match and MIN_POSES <= int(match.group(1)) <= MAX_RANDOM_POSES):
        return text
    raise InputError(
        "poses", f"'paper' or 'random:N' with {MIN_POSES} <= N <= {MAX_RANDOM_POSES}", spec
    )


def _pose_list(
    poses: str | list[BoardPose], rig: Rig, board: Board, seed: int, check: bool
) -> list[BoardPose]:
    if isinstance(poses, str):
        return pose_set(poses, rig, board, np.random.default_rng(seed))
    pose_list = list(poses)
    names = [getattr(p, "name", None) for p in pose_list]
    if not all(isinstance(p, BoardPose) for p in pose_list) or not pose_list:
        raise InputError("poses", "'paper', 'random:N' or a non-empty list of BoardPose", poses)
    # Names become file names (poses/<name>.npz): no separators, no hidden files.
    bad = [n for n in names if not re.fullmatch(r"[^./\\\x00][^/\\\x00]{0,99}", n)]
    if bad or len(set(names)) != len(names):
        raise InputError("poses", "unique pose names usable as file names", bad or names)
    if check:
        for pose in pose_list:
            check_pose(rig, board, pose)
    return pose_list


def _episode(
    scanner: Scanner,
    board: Board,
    pose_list: list[BoardPose],
    poses: str | list[BoardPose],
    seed: int,
    fix_intrinsics: bool,
) -> dict[str, Any]:
    """The ``episode.json`` content: everything that determines the run's results."""
    settings = {
        "poses": poses if isinstance(poses, str) else "custom",
        "n_poses": len(pose_list),
        "frames_per_pose": len(scanner.sequence),  # type: ignore[arg-type]
        "spp": scanner.render.spp,
        "lookup": scanner.projector.pixel.value,
        "projector": scanner.projector.to_dict(),
        "sensor": scanner.sensor.to_dict(),
        "seed": seed,
        "fix_intrinsics": fix_intrinsics,
        "board_blur_m": BOARD_BLUR_M,
        "board_texel_m": BOARD_TEXEL_M,
    }
    return {
        "true_rig": scanner.rig.to_dict(),
        "scanner": scanner.to_dict(),
        "board": board.to_dict(),
        "poses": [p.to_dict() for p in pose_list],
        "pose_seeds": [pose_seed(seed, i) for i in range(len(pose_list))],
        "settings": settings,
    }


def _solve(
    episode: dict[str, Any],
    board: Board,
    pose_list: list[BoardPose],
    observations: list[PoseObservation],
    timing: dict[str, float],
) -> CalibrationResult:
    start = time.perf_counter()
    true_rig = Rig.from_dict(episode["true_rig"])
    cam, prj = true_rig.camera.intrinsics, true_rig.projector.intrinsics
    with solve.opencv_single_thread():
        solved = calibrate_observations(
            board,
            observations,
            (cam.width, cam.height),
            (prj.width, prj.height),
            fix_intrinsics=episode["settings"]["fix_intrinsics"],
            distortion=episode["settings"].get("distortion", solve.DEFAULT_DISTORTION),
        )
    check_pose_spread([pose for pose in pose_list if pose.name in solved.used_poses])
    conditioning.warn_conditioning(solved.conditioning)
    timing["calibrate_s"] = time.perf_counter() - start
    return CalibrationResult(
        rig=solved.rig,
        rms_px=solved.rms_px,
        per_pose=solved.per_pose,
        truth_error=truth_error(solved.rig, true_rig),
        board=board,
        poses=pose_list,
        dropped_poses=solved.dropped_poses,
        settings=episode["settings"],
        true_rig=true_rig,
        timing_s=timing,
        uncertainty=solved.uncertainty,
        conditioning=solved.conditioning,
    )


def calibrate_rig(
    scanner: Scanner,
    *,
    board: str | Board = "7x13",
    poses: str | list[BoardPose] = "paper",
    rng: np.random.Generator | int | None = None,
    progress: Progress | None = None,
    out_dir: str | Path | None = None,
    resume: bool = False,
    overwrite: bool = False,
    fix_intrinsics: bool = False,
    check_poses: bool = True,
    processes: int | None = None,
    distortion: str = solve.DEFAULT_DISTORTION,
) -> CalibrationResult:
    """Capture a board in every pose with ``scanner`` and calibrate its rig back.

    Parameters
    ----------
    scanner : the virtual scanner; its rig is the truth, its sequence (phase frames in both
        directions), projector model, sensor and spp make the captures.
    board : a board or a spec for :func:`~virtus.calib.board.board_from_spec` (``"7x13"``,
        ``"checker:6x9,square_mm=20"``, ...).
    poses : ``"paper"``, ``"random:N"`` (3 <= N <= :data:`MAX_RANDOM_POSES`) or a list of
        :class:`BoardPose` with unique names.
    rng : the run's seed (int >= 0; ``None`` = 0; a Generator draws one): seeds the random
        poses and, through :func:`pose_seed`, each pose's capture.
    progress : called after each pose as ``progress(done, total, name)``.
    out_dir : if given, the run owns this directory (layout in the module docstring): each
        finished pose is written at once, the result at the end.
    resume : continue the run in ``out_dir`` (same settings): finished poses are read back,
        the others rendered.
    overwrite : remove an earlier run's files in ``out_dir`` first.
    fix_intrinsics : keep single-device intrinsics in the stereo step.
    check_poses : check a given pose list against both fields first (raise on the first
        pose outside); ``False`` captures them anyway (poses whose board is not fully seen
        are then dropped with a warning).
    processes : worker processes that observe poses while the next render (0: in this
        thread; default None: threads of this process,
        :func:`~virtus.calib.observers.observers`); the result does not depend on it.
    distortion : the lens model of both devices (``"k1k2p1p2"``: k3 fixed at 0; ``"k3"``;
        ``"rational"``: :data:`virtus.calib.solve.DISTORTION_MODELS`).

    Returns
    -------
    :class:`~virtus.calib.result.CalibrationResult`.

    Raises
    ------
    InputError : bad arguments (checked before anything is rendered or written).
    VirtusError : a pose outside the fields, fewer than 3 usable poses, a degenerate pose
        set (:func:`~virtus.calib.poses.check_pose_spread`, before anything is rendered and
        again on the usable poses), or ``out_dir`` in use by another run or holding another
        run's files.
    """
    if not isinstance(scanner, Scanner):
        raise InputError("scanner", "a virtus.scanner.Scanner", type(scanner).__name__)
    if out_dir is None and (resume or overwrite):
        raise InputError("out_dir", "a directory for resume/overwrite", None)
    chosen = observers(processes)
    check_sequence(scanner.sequence)
    if isinstance(poses, str):
        poses = check_pose_spec(poses)  # "Random:6 " and "random:6" are one configuration
    board = board_from_spec(board)
    seed = as_seed(rng)
    pose_list = _pose_list(poses, scanner.rig, board, seed, check_poses)
    check_pose_spread(pose_list)
    episode = _episode(scanner, board, pose_list, poses, seed, bool(fix_intrinsics))
    episode["settings"].update(solve.distortion_setting(distortion))
    if out_dir is None:
        return _run_episode(scanner, board, pose_list, episode, progress, None, chosen)
    config = {
        "scanner": episode["scanner"],
        "board": episode["board"],
        "poses": poses if isinstance(poses, str) else episode["poses"],
        "seed": seed,
        "fix_intrinsics": bool(fix_intrinsics),
        "check_poses": bool(check_poses),
        **solve.distortion_setting(distortion),
    }
    with claim_run(
        out_dir, COMMAND, config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        return _run_episode(scanner, board, pose_list, episode, progress, run, chosen)


def _run_episode(
    scanner: Scanner,
    board: Board,
    pose_list: list[BoardPose],
    episode: dict[str, Any],
    progress: Progress | None,
    run: RunDirectory | None,
    chosen: Observers,
) -> CalibrationResult:
    # One read-only float64 image for every pose (and calibration): the scenes share it,
    # and the renderer its texture.
    texture = board_texture(board)
    digest = config_digest(episode)
    timing = {"render_s": 0.0, "observe_s": 0.0, "calibrate_s": 0.0}
    if run is not None:
        pose_files = [f"{POSE_DIR}/{pose.name}.npz" for pose in pose_list]
        run.own(EPISODE_FILE, *pose_files, *RESULT_FILES, TIMING_FILE)
        # Same bytes as the first run's when resuming (the configuration is the same).
        run.write_json(EPISODE_FILE, episode)
    observations: list[PoseObservation] = []
    # Poses are rendered and decoded here, one after the other (the renderer uses the whole
    # device), and observed (detection on the host; centroids and local homographies on
    # the host, or on the GPU that rendered) in worker threads (or processes) while the
    # next poses render. Results are taken in pose order, so files, log and result are
    # those of a sequential run. Spawned workers observe on the host (each would start a
    # device context of its own).
    pending: collections.deque = collections.deque()
    device = observation_device(scanner.renders_on_gpu) if chosen.kind != "processes" else None

    def finish_oldest() -> None:
        index, pose, seed, job = pending.popleft()
        obs, seconds = job.result()
        timing["observe_s"] += seconds
        observations.append(obs)
        if run is not None:
            name = f"{POSE_DIR}/{pose.name}.npz"
            run.write(
                name, partial(save_pose_observation, pose=pose, seed=seed, episode=digest, obs=obs)
            )
            run.log(f"rendered {pose.name}")
        if progress is not None:
            progress(index + 1, len(pose_list), pose.name)

    with observer_pool(chosen) as pool:
        for index, pose in enumerate(pose_list):
            seed = episode["pose_seeds"][index]
            name = f"{POSE_DIR}/{pose.name}.npz"
            if run is not None and run.resumed and run.file(name).is_file():
                while pending:
                    finish_oldest()
                observations.append(load_pose_observation(run.file(name), pose, seed, digest))
                run.log(f"reused {pose.name}")
                if progress is not None:
                    progress(index + 1, len(pose_list), pose.name)
                continue
            start = time.perf_counter()
            arguments = (*_rendered_view(scanner, board, pose, texture, seed), board)
            timing["render_s"] += time.perf_counter() - start
            job = pool.submit(observe_timed, *arguments, pose.name, device=device)
            pending.append((index, pose, seed, job))
            while len(pending) > chosen.in_flight:  # bounds the poses held in memory
                finish_oldest()
        while pending:
            finish_oldest()
    result = _solve(episode, board, pose_list, observations, timing)
    if run is not None:
        result.save(run.path)
        run.write_json(TIMING_FILE, _timing_record(timing))
    return result


def _rendered_view(
    scanner: Scanner, board: Board, pose: BoardPose, texture: np.ndarray, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Decoded projector coordinates (H, W, 2), background (H, W) and white frame (or None)
    of one pose rendered with ``scanner`` (:meth:`~virtus.scanner.Scanner.decoded_maps`: on
    the device only these maps are formed and copied, not the whole decode).

    On the host, with a white frame to detect the board in and a decode that is per pixel
    (no neighbour check), only the board's window (:func:`~virtus.calib.scene.board_window`,
    about a quarter of the paper's frames) is decoded: its values are those of the whole
    frame's decode, the rest is NaN (coordinates) and 0 (background), and observation
    reads only pixels on the board plane. Should a valid pixel lie on the window's edge
    (the board's image reaching beyond it), the whole frame is decoded instead."""
    scene = board_scene(board, pose, texture)
    sequence = scanner.sequence
    kinds = [frame.kind for frame in sequence.frames]
    window = board_window(scanner.rig.camera.intrinsics, board, pose.board2cam)
    per_pixel = not any(sequence.runs_neighbour_check(d, None, False) for d in sequence.directions)
    if scanner.renders_on_gpu or "white" not in kinds or window is None or not per_pixel:
        view = scanner.decoded_maps(scene, ("proj_uv", "background"), rng=seed)
        return view.maps["proj_uv"], view.maps["background"], view.white
    capture = scanner.capture(scene, rng=seed, command=[])
    white = capture.frames[kinds.index("white")]
    part = sequence.decode(capture.frames[:, window[0], window[1]], full_scale=capture.full_scale)
    valid = np.isfinite(part.proj_uv).any(axis=-1)
    height, width = white.shape
    edges = [
        valid[0] if window[0].start > 0 else None,
        valid[-1] if window[0].stop < height else None,
        valid[:, 0] if window[1].start > 0 else None,
        valid[:, -1] if window[1].stop < width else None,
    ]
    if any(edge is not None and edge.any() for edge in edges):
        decoded = capture.decode()
        return decoded.proj_uv, decoded.background, white
    proj_uv = np.full((height, width, 2), np.nan)
    background = np.zeros((height, width))
    proj_uv[window], background[window] = part.proj_uv, part.background
    return proj_uv, background, white


def _timing_record(timing: dict[str, float]) -> dict[str, Any]:
    return {
        "note": "seconds spent by the process that wrote this file (a resumed run: its "
        "share only); the one file of the run that differs between identical runs",
        "timing_s": timing,
    }


def recalibrate(
    out_dir: str | Path, *, fix_intrinsics: bool | None = None, distortion: str | None = None
) -> CalibrationResult:
    """Calibrate again from the observations a :func:`calibrate_rig` run saved.

    Uses ``out_dir/episode.json`` and every finished ``out_dir/poses/<name>.npz`` (poses
    whose file is missing, e.g. after an interrupted run, are left out with a warning), and
    rewrites the result files (:data:`~virtus.calib.result.RESULT_FILES`) while holding the
    directory's lock.

    Parameters
    ----------
    out_dir : the ``out_dir`` of the run.
    fix_intrinsics : override the run's stereo option (default: as in the run).
    distortion : override the run's lens model (:func:`calibrate_rig`; default: the run's).

    Raises
    ------
    VirtusError : as :func:`calibrate_rig`'s solve; a pose file of another pose.
    """
    out_dir = Path(out_dir)
    with directory_lock(out_dir):
        episode = read_json(out_dir / EPISODE_FILE, "calibration episode", expect=dict)
        for key in ("true_rig", "board", "poses", "settings"):
            if key not in episode:
                raise InputError(f"{out_dir / EPISODE_FILE}", f"a '{key}' entry", "none")
        episode["settings"] = {k: v for k, v in episode["settings"].items() if k != "timing_s"}
        if fix_intrinsics is not None:
            episode["settings"]["fix_intrinsics"] = bool(fix_intrinsics)
        if distortion is not None:
            episode["settings"].pop("distortion", None)
            episode["settings"].update(solve.distortion_setting(distortion))
        board = board_from_dict(episode["board"])
        seeds = episode.get("pose_seeds") or [None] * len(episode["poses"])
        pose_list, observations = [], []
        for item, seed in zip(episode["poses"], seeds, strict=True):
            pose = BoardPose.from_dict(item)
            path = out_dir / POSE_DIR / f"{pose.name}.npz"
            if not path.is_file():
                warnings.warn(
                    f"calibration: pose {pose.name!r} left out: {path} missing", stacklevel=2
                )
                continue
            pose_list.append(pose)
            observations.append(load_pose_observation(path, pose, seed, None))
        timing = {"render_s": 0.0, "observe_s": 0.0, "calibrate_s": 0.0}
        result = _solve(episode, board, pose_list, observations, timing)
        result.save(out_dir)
        return result


# -- calibration from captures (real benches) ------------------------------------------------

#: The job's name in ``run.json`` when it calibrates from captures.
CAPTURES_COMMAND = "calibrate --captures"
#: ``episode.json`` of a calibration from captures: the captures and the board.
CAPTURES_LAYOUT = (*RESULT_FILES, EPISODE_FILE, TIMING_FILE, f"{POSE_DIR}/*.npz")


def _check_captures(captures: list[Capture], names: list[str]) -> tuple[tuple[int, int], ...]:
    """(camera size, projector size) shared by every capture; refuse mixed captures."""
    first = captures[0]
    check_sequence(first.sequence)
    camera = first.rig.camera.intrinsics
    sizes = ((camera.width, camera.height), (first.sequence.width, first.sequence.height))
    for capture, name in zip(captures, names, strict=True):
        cam = capture.rig.camera.intrinsics
        if capture.sequence != first.sequence:
            raise InputError(
                f"capture {name!r}", f"the sequence of capture {names[0]!r}", "another sequence"
            )
        if (cam.width, cam.height) != sizes[0]:
            raise InputError(
                f"capture {name!r}",
                f"{sizes[0][0]}x{sizes[0][1]} px images (as {names[0]!r})",
                f"{cam.width}x{cam.height} px",
            )
    return sizes


def calibrate_captures(
    captures: list[str | Path | Capture],
    *,
    board: str | Board,
    out_dir: str | Path | None = None,
    overwrite: bool = False,
    fix_intrinsics: bool = False,
    progress: Progress | None = None,
    processes: int | None = None,
    distortion: str = solve.DEFAULT_DISTORTION,
) -> CalibrationResult:
    """Calibrate a rig from captures of a board, one capture of the whole sequence per pose.

    The detection and solve are those of :func:`calibrate_rig`
    (:func:`~virtus.calib.observe.observe_pose`,
    :func:`virtus.calib.solve.calibrate_observations`), so captures of rendered poses give
    exactly the calibration the rendered job gives. Poses whose board is not found (or not
    fully decoded) are dropped with a warning naming them.

    Parameters
    ----------
    captures : capture directories (:meth:`Capture.load`; a folder of capture directories
        stands for them, sorted by name) or captures; a pose is named after its directory
        (``pose_NNN`` for an in-memory capture). Every capture must have the same sequence
        (both directions: phase frames, or codes alone as OpenCV's ``GrayCodePattern``) and
        camera size; the projector size is the sequence's. The captures' rigs are not used.
    board : a board or a spec (:func:`~virtus.calib.board.board_from_spec`).
    out_dir : if given, the run owns this directory and writes ``calibration.json``,
        ``calibration.yaml``, ``paper_txt/``, ``episode.json`` (the captures, the board),
        ``poses/<name>.npz`` (the observations) and ``timing.json``.
    overwrite : remove an earlier run's files in ``out_dir`` first.
    fix_intrinsics : keep single-device intrinsics in the stereo step.
    distortion : the lens model (as :func:`calibrate_rig`).
    progress : called after each pose as ``progress(done, total, name)``.
    processes : worker processes that read, decode and observe the poses side by side
        (default None: threads of this process; 0: one after the other, here). The files and
        the result do not depend on it.

    Returns
    -------
    :class:`~virtus.calib.result.CalibrationResult` with ``truth_error`` None and ``poses``
    the solved board poses (``board2cam``, metres) of the poses used.

    Raises
    ------
    InputError : no captures, captures of different sequences or sizes, a sequence without
        both directions, a bad board spec, a capture that cannot be read.
    VirtusError : fewer than 3 usable poses (naming the dropped ones), a degenerate pose
        set, ``out_dir`` in use by another run.
    """
    board = board_from_spec(board)
    chosen = observers(processes)
    loaded: list[Capture] = []
    names: list[str] = []
    paths: list[Path | None] = []
    items: list[Any] = list(captures)
    if not items:
        raise InputError("captures", "at least one capture", "none")
    if all(isinstance(item, str | Path) for item in items):
        items = capture_dirs(items)
    for index, item in enumerate(items):
        capture = item if isinstance(item, Capture) else Capture.load(item)
        loaded.append(capture)
        paths.append(capture.path)
        names.append(capture.path.name if capture.path is not None else f"pose_{index + 1:03d}")
    if len(set(names)) != len(names):
        raise InputError("captures", "captures with distinct directory names", names)
    camera_size, projector_size = _check_captures(loaded, names)
    episode = {
        "source": "captures",
        "captures": [None if p is None else str(p) for p in paths],
        "names": names,
        "board": board.to_dict(),
        "camera_size": list(camera_size),
        "projector_size": list(projector_size),
        "sequence": loaded[0].sequence.to_dict(),
        "fix_intrinsics": bool(fix_intrinsics),
        **solve.distortion_setting(distortion),
    }
    if out_dir is None:
        return _run_captures(loaded, names, board, episode, progress, None, chosen)
    inputs = {
        f"capture {name}": Path(path) / "capture.json"
        for name, path in zip(names, paths, strict=True)
        if path is not None
    }
    with claim_run(
        out_dir,
        CAPTURES_COMMAND,
        episode,
        inputs=inputs,
        layout=CAPTURES_LAYOUT,
        overwrite=overwrite,
    ) as run:
        return _run_captures(loaded, names, board, episode, progress, run, chosen)


def _record_observed(run: RunDirectory | None, name: str, obs: PoseObservation) -> None:
    """Write a captured pose's observation (``poses/<name>.npz``) and log it."""
    if run is None:
        return
    arrays = {
        key: value
        for key, value in (("cam_centroids", obs.cam_centroids), ("homographies", obs.homographies))
        if value is not None
    }
    run.write(f"{POSE_DIR}/{name}.npz", partial(save_pose_arrays, arrays=arrays))
    run.log(f"observed {name}")


def _observe_capture_timed(capture: Capture, board: Board, name: str) -> tuple[Any, float]:
    """:func:`~virtus.calib.observe.observe_pose` (frames read and decoded too) and the
    seconds it took."""
    start = time.perf_counter()
    return observe_pose(capture, board, name), time.perf_counter() - start


def _run_captures(
    captures: list[Capture],
    names: list[str],
    board: Board,
    episode: dict[str, Any],
    progress: Progress | None,
    run: RunDirectory | None,
    chosen: Observers,
) -> CalibrationResult:
    timing = {"render_s": 0.0, "observe_s": 0.0, "calibrate_s": 0.0}
    if run is not None:
        run.own(EPISODE_FILE, *(f"{POSE_DIR}/{n}.npz" for n in names), *RESULT_FILES, TIMING_FILE)
        run.write_json(EPISODE_FILE, episode)
    observations = []
    with observer_pool(chosen) as pool:
        # Poses are observed side by side, at most two per worker in flight (each holds its
        # frames), and taken in pose order: the files and log are a sequential run's.
        in_flight = max(1, 2 * chosen.count)
        jobs: collections.deque = collections.deque()
        for index, name in enumerate(names):
            while len(jobs) < in_flight and index + len(jobs) < len(names):
                k = index + len(jobs)
                jobs.append(pool.submit(_observe_capture_timed, captures[k], board, names[k]))
            obs, seconds = jobs.popleft().result()
            timing["observe_s"] += seconds
            observations.append(obs)
            _record_observed(run, name, obs)
            if progress is not None:
                progress(index + 1, len(captures), name)
    start = time.perf_counter()
    with solve.opencv_single_thread():
        solved = calibrate_observations(
            board,
            observations,
            tuple(episode["camera_size"]),  # type: ignore[arg-type]
            tuple(episode["projector_size"]),  # type: ignore[arg-type]
            fix_intrinsics=episode["fix_intrinsics"],
            distortion=episode.get("distortion", solve.DEFAULT_DISTORTION),
        )
    poses = [
        BoardPose(p["name"], pose)
        for p, pose in zip(solved.per_pose, solved.board2cam, strict=True)
    ]
    # The true poses are unknown: the solved ones measure the spread (a degenerate set
    # solves to a wrong focal length, but its boards stay nearly parallel).
    check_pose_spread(poses)
    conditioning.warn_conditioning(solved.conditioning)
    timing["calibrate_s"] = time.perf_counter() - start
    settings = {k: v for k, v in episode.items() if k in ("source", "captures", *_SOLVER_KEYS)}
    settings.update(n_poses=len(captures), frames_per_pose=len(captures[0].sequence))
    result = CalibrationResult(
        rig=solved.rig,
        rms_px=solved.rms_px,
        per_pose=solved.per_pose,
        truth_error=None,
        board=board,
        poses=poses,
        dropped_poses=solved.dropped_poses,
        settings=settings,
        timing_s=timing,
        uncertainty=solved.uncertainty,
        conditioning=solved.conditioning,
    )
    if run is not None:
        result.save(run.path)
        run.write_json(TIMING_FILE, _timing_record(timing))
    return result


# -- calibration from saved correspondences -------------------------------------------------

#: The job's name in ``run.json`` when it calibrates from saved correspondences.
POINTS_COMMAND = "calibrate --from-points"
#: Solver options that calibrations from captures or points record in their settings.
_SOLVER_KEYS = ("fix_intrinsics", "distortion")


def calibrate_points(
    source: str | Path,
    *,
    board: str | Board | None = None,
    sizes: Any = None,
    out_dir: str | Path | None = None,
    overwrite: bool = False,
    fix_intrinsics: bool = False,
    distortion: str = solve.DEFAULT_DISTORTION,
) -> CalibrationResult:
    """Calibrate a rig from saved correspondences (``virtus calibrate --from-points``):
    :func:`virtus.calib.points.read_points` reads ``source`` (layouts there), ``board`` and
    ``sizes``; :meth:`~virtus.calib.points.PointSet.calibrate` solves, checks and warns. An
    ``out_dir`` (not holding ``source``) gets :func:`calibrate_captures`'s files but the pose
    files; other arguments and errors as there."""
    solver = {"fix_intrinsics": bool(fix_intrinsics), **solve.distortion_setting(distortion)}
    point_set = points.read_points(source, board=board, sizes=sizes)
    config = {**point_set.describe(), **solver}
    owned = (*RESULT_FILES, EPISODE_FILE, TIMING_FILE)
    run_dir: Any = contextlib.nullcontext(None)
    if out_dir is not None:
        point_set.check_output(out_dir)
        claim = partial(claim_run, inputs=point_set.inputs, layout=owned, overwrite=overwrite)
        run_dir = claim(out_dir, POINTS_COMMAND, config)
    with run_dir as run:
        if run is not None:
            run.own(*owned)
            run.write_json(EPISODE_FILE, config)
        start = time.perf_counter()
        with solve.opencv_single_thread():
            result = point_set.calibrate(**solver)
        result.timing_s = {"render_s": 0.0, "observe_s": 0.0}
        result.timing_s["calibrate_s"] = time.perf_counter() - start
        if run is not None:
            result.save(run.path)
            run.write_json(TIMING_FILE, _timing_record(result.timing_s))
        return result
