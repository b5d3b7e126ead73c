"""Pose trajectories: sequences of ``object2cam`` poses a scan visits.

* :func:`turntable_poses` -- a virtual turntable whose axis is vertical (parallel to the
  camera's y axis, image down) and passes through the object's origin: view ``k`` of ``N``
  turns the object by ``theta_k = 2 pi k / N``,
  ``object2cam_k = Pose(R_y(theta_k) @ R_0, c)`` (``R_0``, ``c``: view 0's rotation and the
  object's origin in the camera frame).

Metres, OpenCV camera frame.
"""

from __future__ import annotations

import numpy as np

from virtus import paper
from virtus.checks import positive_int
from virtus.geometry.transforms import Pose

__all__ = ["turntable_poses"]


def turntable_poses(n_views: int, start: Pose | None = None) -> list[Pose]:
    """``object2cam`` of each view: turns of ``2 pi k / n_views`` about the vertical axis.

    Parameters
    ----------
    n_views : number of views (>= 1).
    start : object2cam of view 0; the turntable axis (parallel to the camera's y axis)
        passes through its translation, the object's origin. Default: no rotation, origin on
        the camera axis at the working distance (:data:`virtus.paper.WORKING_DISTANCE_M`),
        where :data:`~virtus.scene.builtin.FREEFORM_CENTRE_M` puts the free-form object.
    """
    n = positive_int("n_views", n_views)
    start = start or Pose(np.eye(3), (0.0, 0.0, paper.WORKING_DISTANCE_M))
    c = start.t
    r0 = start.R
    poses = []
    for k in range(n):
        theta = 2.0 * np.pi * k / n
        turn = Pose.from_euler("y", theta, degrees=False).R
        poses.append(Pose(turn @ r0, c))
    return poses
