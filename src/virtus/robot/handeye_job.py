"""The hand-eye job (``virtus handeye``): board captures + robot poses -> where the camera is.

Inputs: capture directories of a calibration board (one per robot pose, in order; e.g.
``robot-scan`` views of a board scene), the robot's poses at those captures, and the board.
Each capture's board is detected (:func:`virtus.calib.observe_pose`: circle or corner
centroids, px), its pose ``board2cam`` found by PnP with the capture's camera
(``cv2.solvePnP``) on the centroids with their perspective bias removed (:func:`board_pose`),
and :func:`virtus.robot.handeye.solve_handeye` refines X and the board
pose over every centroid (pixel residuals).

Robot poses file (JSON), either

* ``{"hand2base": [{"R": 3x3, "t": [x, y, z]}, ...]}`` -- the mount link's poses (m), or
* a trajectory file (:mod:`virtus.robot.planning`, joint values), with a robot file that
  turns them into ``hand2base`` by forward kinematics (``--robot``).

Output directory (owned by the run, command ``handeye``): ``handeye.json`` -- the solution
(:meth:`~virtus.robot.handeye.HandEyeResult.to_dict`), the expected errors, the motion
check, per-pose residuals, and, when the captures record the truth (rendered from a robot:
``provenance["robot"]``), the errors against it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, VirtusError
from virtus.geometry.transforms import Pose
from virtus.io.safeio import read_json
from virtus.robot.config import RobotSetup
from virtus.robot.handeye import HAND_EYE_MODES, HandEyeResult, check_motion, solve_handeye

__all__ = ["HANDEYE_JSON", "board_pose", "handeye_from_captures", "load_robot_poses"]

COMMAND = "handeye"
HANDEYE_JSON = "handeye.json"
#: Most poses read from a robot poses file.
MAX_POSES = 10_000
#: Most perspective-bias passes of a circle board's pose (:func:`board_pose`); the passes
#: stop once the bias changes by less than :data:`BIAS_SETTLED_PX`. Each pass shrinks the
#: pose error about a hundredfold: measured on exact area centroids of the 4x7 board from
#: ~0.45 m (biases up to 3.3 px), 1e-5, 1e-7, 6e-10, 5e-12 (rad and m) after 1-4 passes.
BIAS_PASSES = 8
BIAS_SETTLED_PX = 1e-9


def load_robot_poses(path: str | Path, setup: RobotSetup | None = None) -> list[Pose]:
    """The ``hand2base`` poses of a robot poses file (see the module docs)."""
    data = read_json(path, "robot poses", expect=dict)
    if "hand2base" in data:
        rows = data["hand2base"]
        if not isinstance(rows, list) or not 0 < len(rows) <= MAX_POSES:
            raise InputError("robot poses hand2base", f"a list of 1 to {MAX_POSES} poses", rows)
        return [Pose.from_dict(row, f"robot poses hand2base[{i}]") for i, row in enumerate(rows)]
    if "q" in data:
        if setup is None:
            raise InputError("--robot", "a robot file to turn the joint values into poses", None)
        from virtus.robot.planning import load_trajectory

        q = load_trajectory(path, setup)
        tree = setup.robot.tree
        return [Pose.from_matrix(tree.link_pose(row, setup.link)) for row in q]
    raise InputError("robot poses", 'a "hand2base" list or a trajectory ("q")', sorted(data))


def _board_pose(capture: Any, board: Any, name: str) -> tuple[np.ndarray, Pose]:
    from virtus.calib import observe_pose

    seen = observe_pose(capture, board, name)
    problem = seen.problem()
    centroids = None if seen.cam_centroids is None else np.asarray(seen.cam_centroids, float)
    if centroids is None or not np.isfinite(centroids).all():  # the projector's side is
        raise VirtusError(f"handeye: capture {name}: {problem}")  # not needed here
    return board_pose(centroids, board, capture.rig.camera.intrinsics, name)


def board_pose(
    points: np.ndarray, board: Any, intrinsics: Any, name: str = "board"
) -> tuple[np.ndarray, Pose]:
    """The board's pose ``board2cam`` from its detected points, and the points it fits.

    Parameters
    ----------
    points : (K, 2) float64 px, the board's points in ``board.object_points`` order as
        :func:`virtus.calib.observe_pose` gives them (circle boards: the area centroids of
        the circles' images; checkerboards: corners).
    board : the :class:`~virtus.calib.Board`.
    intrinsics : the camera's :class:`~virtus.geometry.optics.Intrinsics`.

    Returns
    -------
    ``(points, board2cam)``: for a circle board the centroids with their perspective bias
    removed (the images of the circles' centres), else ``points``; and the PnP pose.

    Notes
    -----
    The area centroid of a tilted circle's image is not the image of its centre (the near
    half of the circle looks larger). Left in, that bias tilts and shifts each board pose
    with the board's tilt, and hand-eye turns those pose errors into an error of the
    camera's position along its axis: on bench_robot.py's 10 views of the 4x7 board
    (22 mm circles, 0.9 m, up to 25 deg) exact area centroids give board poses off by
    up to 0.003 deg / 0.05 mm and X off by 0.14 mm along the optical axis. The bias is
    computed for the PnP pose (:func:`virtus.calib.solve.centroid_bias`, as the
    calibration does), subtracted and PnP solved again until the bias settles
    (:data:`BIAS_PASSES`): on the same exact centroids X is then within 1e-8 deg and
    1e-10 m of the truth.
    """
    import cv2

    from virtus.calib import CircleBoard
    from virtus.calib.solve import centroid_bias

    K, dist = intrinsics.to_opencv()  # noqa: N806
    guess: dict[str, Any] = {}
    measured = np.asarray(points, np.float64)
    fitted, bias = measured, np.zeros_like(measured)
    for _ in range(1 + (BIAS_PASSES if isinstance(board, CircleBoard) else 0)):
        ok, rvec, tvec = cv2.solvePnP(
            board.object_points, fitted, K, dist, flags=cv2.SOLVEPNP_ITERATIVE, **guess
        )
        if not ok:
            raise VirtusError(f"handeye: capture {name}: no board pose (PnP failed)")
        pose = Pose.from_rotvec(rvec.ravel(), tvec.ravel())
        if not isinstance(board, CircleBoard):
            break
        guess = {"rvec": rvec, "tvec": tvec, "useExtrinsicGuess": True}
        previous, bias = bias, centroid_bias(intrinsics, board, pose)
        fitted = measured - bias
        if np.abs(bias - previous).max() < BIAS_SETTLED_PX:
            break
    return fitted, pose


def handeye_from_captures(
    captures: list[str | Path],
    robot_poses: str | Path,
    board_spec: str,
    out_dir: str | Path,
    *,
    mode: str = "eye_in_hand",
    setup: RobotSetup | None = None,
    min_rotation_deg: float = 10.0,
    overwrite: bool = False,
) -> tuple[HandEyeResult, dict[str, Any]]:
    """Solve hand-eye from board captures (see the module docs); returns the result and
    the record written to ``out_dir/handeye.json``.

    Raises
    ------
    InputError : a capture, pose file or board that cannot be read; pose and capture counts
        that differ; a bad mode -- all before anything is written.
    DegenerateData : degenerate motion (its reason), before anything is written.
    """
    from virtus.calib import board_from_spec
    from virtus.capture.capture import Capture
    from virtus.capture.scandir import capture_dirs
    from virtus.io.runs import claim_run

    if mode not in HAND_EYE_MODES:
        raise InputError("--mode", f"one of {HAND_EYE_MODES}", mode)
    folders = capture_dirs(list(captures))
    hand2base = load_robot_poses(robot_poses, setup)
    if len(hand2base) != len(folders):
        raise InputError(
            "--robot-poses", f"{len(folders)} poses (one per capture)", f"{len(hand2base)} poses"
        )
    moved = hand2base if mode == "eye_in_hand" else [p.inverse() for p in hand2base]
    check_motion(moved, min_rotation_deg)  # degenerate motion: refused before any work
    board = board_from_spec(board_spec)
    loaded = [Capture.load(folder) for folder in folders]
    seen = [_board_pose(c, board, str(f)) for c, f in zip(loaded, folders, strict=True)]
    intrinsics = loaded[0].rig.camera.intrinsics
    result = solve_handeye(
        hand2base,
        [pose for _, pose in seen],
        mode=mode,
        board_points=board.object_points,
        image_points=[points for points, _ in seen],
        intrinsics=intrinsics,
        min_rotation_deg=min_rotation_deg,
    )
    record = result.to_dict()
    record["captures"] = [str(f) for f in folders]
    truth = _truth(loaded, mode)
    if truth is not None:
        delta = truth.inverse() @ result.cam2hand
        record["truth"] = {
            "cam2link": truth.to_dict(),
            "rotation_error_deg": delta.angle_deg,
            "translation_error_mm": float(np.linalg.norm(delta.t) * 1e3),
        }
    config = {
        "captures": record["captures"],
        "robot_poses": str(robot_poses),
        "board": str(board_spec),
        "mode": mode,
        "min_rotation_deg": min_rotation_deg,
    }
    with claim_run(out_dir, COMMAND, config, layout=(HANDEYE_JSON,), overwrite=overwrite) as run:
        run.own(HANDEYE_JSON)
        run.write_json(HANDEYE_JSON, record)
    return result, record


def _truth(captures: list[Any], mode: str) -> Pose | None:
    """The true ``cam2link`` recorded by robot captures (eye-in-hand), else None."""
    if mode != "eye_in_hand":
        return None
    records = [(c.provenance or {}).get("robot") for c in captures]
    if not all(isinstance(r, dict) and "cam2link" in r for r in records):
        return None
    return Pose.from_dict(records[0]["cam2link"], "cam2link")
