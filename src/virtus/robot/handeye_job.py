"""The hand-eye job (``virtus handeye``): board captures + robot poses -> where the camera is.

Inputs: capture directories of a calibration board (one per robot pose, in order; e.g.
``robot-scan`` views of a board scene), the robot's poses at those captures, and the board.
Each capture's board is detected (:func:`virtus.calib.observe_pose`: circle or corner
centroids, px), its pose ``board2cam`` found by PnP with the capture's camera
(``cv2.solvePnP``), and :func:`virtus.robot.handeye.solve_handeye` refines X and the board
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

__all__ = ["HANDEYE_JSON", "handeye_from_captures", "load_robot_poses"]

COMMAND = "handeye"
HANDEYE_JSON = "handeye.json"
#: Most poses read from a robot poses file.
MAX_POSES = 10_000


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
    import cv2

    from virtus.calib import observe_pose

    seen = observe_pose(capture, board, name)
    problem = seen.problem()
    centroids = None if seen.cam_centroids is None else np.asarray(seen.cam_centroids, float)
    if centroids is None or not np.isfinite(centroids).all():  # the projector's side is
        raise VirtusError(f"handeye: capture {name}: {problem}")  # not needed here
    K, dist = capture.rig.camera.intrinsics.to_opencv()  # noqa: N806
    ok, rvec, tvec = cv2.solvePnP(
        board.object_points, centroids, K, dist, flags=cv2.SOLVEPNP_ITERATIVE
    )
    if not ok:
        raise VirtusError(f"handeye: capture {name}: no board pose (PnP failed)")
    return centroids, Pose.from_rotvec(rvec.ravel(), tvec.ravel())


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
