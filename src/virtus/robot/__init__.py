"""The sensor on a robot: arms, kinematics, eye-in-hand scans, hand-eye calibration.

* :mod:`~virtus.robot.chain` -- kinematic trees: forward kinematics, Jacobians, limits.
* :mod:`~virtus.robot.panda` -- the built-in Franka Panda (published DH table, offline).
* :mod:`~virtus.robot.urdf` -- any robot from a URDF (yourdfpy; ``package://`` resolver).
* :mod:`~virtus.robot.model` -- a robot: tree, collision capsules, meshes for the renderer.
* :mod:`~virtus.robot.ik` -- multi-start inverse kinematics; unreachable targets refused.
* :mod:`~virtus.robot.config` -- the robot file: base, mount (link, link2cam), rig.
* :mod:`~virtus.robot.capture` -- captures from the robot (arm in the scene, q recorded).
* :mod:`~virtus.robot.planning` -- FPP coverage, greedy view planning, trajectory files.
* :mod:`~virtus.robot.scan` -- the ``robot-scan`` job: capture, merge by FK, ICP, C2M.
* :mod:`~virtus.robot.handeye` / :mod:`~virtus.robot.handeye_job` -- hand-eye calibration.

Units: metres and radians; transforms are named by frames (``cam2world`` maps camera
points into the world; ``link2base`` is a link's pose in the robot's base frame).
"""

from virtus.robot.capture import capture_at, scene_with_robot
from virtus.robot.chain import Joint, KinematicTree
from virtus.robot.config import RobotSetup, load_robot_file
from virtus.robot.handeye import HAND_EYE_MODES, HandEyeResult, check_motion, solve_handeye
from virtus.robot.handeye_job import handeye_from_captures, load_robot_poses
from virtus.robot.ik import IKResult, Unreachable, solve_ik
from virtus.robot.model import BUILTIN_ROBOTS, Robot, builtin_robot
from virtus.robot.planning import (
    CoverageSettings,
    ViewPlan,
    load_trajectory,
    plan_views,
    save_trajectory,
)
from virtus.robot.scan import RobotScanResult, robot_scan
from virtus.robot.urdf import load_urdf, parse_package_paths

__all__ = [
    "BUILTIN_ROBOTS",
    "HAND_EYE_MODES",
    "CoverageSettings",
    "HandEyeResult",
    "IKResult",
    "Joint",
    "KinematicTree",
    "Robot",
    "RobotScanResult",
    "RobotSetup",
    "Unreachable",
    "ViewPlan",
    "builtin_robot",
    "capture_at",
    "check_motion",
    "handeye_from_captures",
    "load_robot_file",
    "load_robot_poses",
    "load_trajectory",
    "load_urdf",
    "parse_package_paths",
    "plan_views",
    "robot_scan",
    "save_trajectory",
    "scene_with_robot",
    "solve_handeye",
    "solve_ik",
]
