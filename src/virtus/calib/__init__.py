"""Virtual calibration: circle boards, pose sets, detection, camera/projector/stereo
calibration, comparison with the true rig, calibration files.

Modules (one concept each):

* :mod:`~virtus.calib.board` -- asymmetric circle boards, the paper's scale equations, texture.
* :mod:`~virtus.calib.poses` -- the paper's 18 poses, ``random:N``, field-of-view checks,
  the pose-spread check of a degenerate set.
* :mod:`~virtus.calib.scene` -- the board as a scene (textured plane) and its texture settings.
* :mod:`~virtus.calib.detect` -- grid detection and sub-pixel circle centroids.
* :mod:`~virtus.calib.projector` -- projector images of the centres (local homographies).
* :mod:`~virtus.calib.observe` -- pose observation: a pose's capture -> board points and
  homographies.
* :mod:`~virtus.calib.solve` -- bias-corrected camera, projector and stereo calibration;
  lens models (``distortion``: k1k2p1p2, k3, rational); calibration from correspondences.
* :mod:`~virtus.calib.conditioning` -- parameter uncertainties (reprojection Jacobian) and
  the conditioning check (tilt spread, coverage, focal/principal-point uncertainty).
* :mod:`~virtus.calib.points` -- saved correspondences (per-pose text files, CSV, ``.npz``).
* :mod:`~virtus.calib.truth` -- calibrated minus true parameters.
* :mod:`~virtus.calib.result` -- ``CalibrationResult`` and its files.
* :mod:`~virtus.calib.io` -- calibration.json, OpenCV YAML, the paper code's text files; the
  one reader of a rig or calibration file (also ``.npz`` and mapping files).
* :mod:`~virtus.calib.names` -- how calibration files name each quantity (tables, and
  ``[Cam|Proj] quantity [Left|Right|1|2]`` names).
* :mod:`~virtus.calib.formats` -- reading values per format; the mapping file.
* :mod:`~virtus.calib.sources` -- where each parameter of a rig read came from; the
  placeholder rig of an import without a calibration.
* :mod:`~virtus.calib.synthetic` -- exact renderer-free board images and projector maps.

The job that renders the poses and calibrates (``virtus calibrate``) is
:mod:`virtus.pipeline.calibrate`: this package never imports the renderer, the scanner or
the pipeline.

Units are SI (metres); board frame: origin at the plane centre, x along the texture
columns, y along its rows, z into the board; ``board2cam`` maps it into the camera frame.
"""

from virtus.calib.board import CircleBoard, board_from_spec
from virtus.calib.conditioning import calibration_uncertainty, conditioning_report
from virtus.calib.io import (
    CalibrationFileWarning,
    load_calibration,
    load_calibration_report,
    load_opencv_yaml,
    load_paper_txt,
    load_rig_file,
    save_opencv_yaml,
    save_paper_txt,
)
from virtus.calib.observe import check_sequence, observe_arrays, observe_pose
from virtus.calib.points import PointSet, read_points
from virtus.calib.poses import (
    MIN_POSE_SPREAD_DEG,
    BoardPose,
    check_pose_spread,
    paper_poses,
    pose_set,
    pose_spread_deg,
    random_poses,
)
from virtus.calib.result import CalibrationResult
from virtus.calib.scene import (
    BOARD_BLUR_M,
    BOARD_TEXEL_M,
    CHECKER_BLUR_M,
    board_scene,
    board_texture,
)
from virtus.calib.solve import (
    DISTORTION_MODELS,
    PoseObservation,
    calibrate_correspondences,
    calibrate_observations,
)
from virtus.calib.sources import CalibrationSources, uncalibrated_rig
from virtus.calib.truth import truth_error

__all__ = [
    "BOARD_BLUR_M",
    "BOARD_TEXEL_M",
    "CHECKER_BLUR_M",
    "DISTORTION_MODELS",
    "MIN_POSE_SPREAD_DEG",
    "BoardPose",
    "CalibrationFileWarning",
    "CalibrationResult",
    "CalibrationSources",
    "CircleBoard",
    "PointSet",
    "PoseObservation",
    "board_from_spec",
    "board_scene",
    "board_texture",
    "calibrate_correspondences",
    "calibrate_observations",
    "calibration_uncertainty",
    "check_pose_spread",
    "check_sequence",
    "conditioning_report",
    "load_calibration",
    "load_calibration_report",
    "load_opencv_yaml",
    "load_paper_txt",
    "load_rig_file",
    "observe_arrays",
    "observe_pose",
    "paper_poses",
    "pose_set",
    "pose_spread_deg",
    "random_poses",
    "read_points",
    "save_opencv_yaml",
    "save_paper_txt",
    "truth_error",
    "uncalibrated_rig",
]
