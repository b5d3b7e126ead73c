"""Pose files of a calibration run: ``poses/<name>.npz``, one per observed board pose, so a
killed run resumes where it stopped and a recalibration needs no images.

Arrays: ``board2cam`` (4, 4) float64, the board pose in the camera frame (metres) the pose was
rendered at; ``seed`` () int64, its capture seed; ``episode`` () str, the digest of the run's
scanner, board and poses; ``cam_centroids`` (N, 2) float64, the board features in camera
pixels; ``homographies`` (N, 3, 3) float64, each feature's local camera-to-projector
homography. Read back with the bounded reader (:func:`virtus.io.safeio.load_npz`) and
checked against the pose it should belong to.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.calib.poses import BoardPose
from virtus.calib.solve import PoseObservation
from virtus.errors import InputError, RunConflict
from virtus.io.safeio import load_npz

__all__ = ["load_pose_observation", "save_pose_arrays", "save_pose_observation"]


def save_pose_observation(
    path: Path, *, pose: BoardPose, seed: int, episode: str, obs: PoseObservation
) -> None:
    """Write one pose's observation (``obs``) with what it was made for: the board pose
    (``board2cam``, 4x4, metres), the capture ``seed`` and the ``episode`` digest."""
    arrays: dict[str, np.ndarray] = {
        "board2cam": pose.board2cam.matrix,
        "seed": np.array(seed, dtype=np.int64),
        "episode": np.array(episode),
    }
    if obs.cam_centroids is not None:
        arrays["cam_centroids"] = obs.cam_centroids
    if obs.homographies is not None:
        arrays["homographies"] = obs.homographies
    np.savez(path, **arrays)


def load_pose_observation(
    path: Path, pose: BoardPose, seed: int | None, episode: str | None
) -> PoseObservation:
    """Read a pose file, checking it belongs to this pose (and episode, when given)."""
    arrays = load_npz(path, "pose file")
    board2cam = arrays.get("board2cam")
    mismatch = None
    if board2cam is None or not np.array_equal(board2cam, pose.board2cam.matrix):
        mismatch = "another board pose"
    elif seed is not None and _scalar(arrays.get("seed"), np.integer) != seed:
        mismatch = "another capture seed"
    elif episode is not None and _scalar(arrays.get("episode"), np.str_) != episode:
        mismatch = "another episode (scanner, board or poses)"
    if mismatch:
        raise RunConflict(
            f"{path} was made for {mismatch} than this run's pose {pose.name!r}; remove it "
            "or start again with --overwrite"
        )
    for name, tail in (("cam_centroids", (2,)), ("homographies", (3, 3))):
        array = arrays.get(name)  # (N, *tail) floats, or absent
        if array is not None and (array.shape[1:] != tail or array.ndim != len(tail) + 1
                                  or array.dtype.kind != "f"):  # fmt: skip
            want = f"(N, {', '.join(map(str, tail))}) floats"
            raise InputError(f"pose file {path}: {name}", want, f"{array.dtype} {array.shape}")
    return PoseObservation(pose.name, arrays.get("cam_centroids"), arrays.get("homographies"))


def _scalar(array: np.ndarray | None, kind: type) -> Any:
    """The value of a 0-d array of dtype ``kind`` (``np.integer``, ``np.str_``), else None."""
    ok = array is not None and array.shape == () and np.issubdtype(array.dtype, kind)
    return array.item() if ok else None


def save_pose_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a pose file of named arrays (the captures path records its observations so)."""
    np.savez(path, **arrays)
