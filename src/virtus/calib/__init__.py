"""Virtual calibration: circle boards, pose sets, detection, camera/projector/stereo
calibration, comparison with the true rig, calibration files.

Modules (one concept each):

* :mod:`~virtus.calib.board` -- asymmetric circle boards, the paper's scale equations, texture.
* :mod:`~virtus.calib.poses` -- the paper's 18 poses, ``random:N``, field-of-view checks.
* :mod:`~virtus.calib.detect` -- grid detection and sub-pixel circle centroids.
* :mod:`~virtus.calib.projector` -- projector images of the centres (local homographies).
* :mod:`~virtus.calib.solve` -- bias-corrected camera, projector and stereo calibration.
* :mod:`~virtus.calib.truth` -- calibrated minus true parameters.
* :mod:`~virtus.calib.io` -- calibration.json, OpenCV YAML, the paper code's text files.
* :mod:`~virtus.calib.synthetic` -- exact renderer-free board images and projector maps.

The job that renders the poses and calibrates (``virtus calibrate``) is
:mod:`virtus.pipeline.calibrate`: this package never imports the renderer, the scanner or
the pipeline.

Units are SI (metres); board frame: origin at the plane centre, x along the texture
columns, y along its rows, z into the board; ``board2cam`` maps it into the camera frame.
"""

from virtus.calib.board import CircleBoard, board_from_spec
from virtus.calib.io import load_opencv_yaml, load_paper_txt, save_opencv_yaml, save_paper_txt
from virtus.calib.poses import BoardPose, paper_poses, pose_set, random_poses
from virtus.calib.solve import PoseObservation, calibrate_observations
from virtus.calib.truth import truth_error

__all__ = [
    "BoardPose",
    "CircleBoard",
    "PoseObservation",
    "board_from_spec",
    "calibrate_observations",
    "load_opencv_yaml",
    "load_paper_txt",
    "paper_poses",
    "pose_set",
    "random_poses",
    "save_opencv_yaml",
    "save_paper_txt",
    "truth_error",
]
