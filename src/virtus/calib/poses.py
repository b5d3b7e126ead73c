"""Board pose sets for calibration: the paper's 18 poses and seeded random poses, and the
check that a set is not degenerate (:func:`check_pose_spread`).

A board pose is ``board2cam`` (board frame of :mod:`virtus.calib.board` -> camera frame,
metres). Every pose must keep the whole board plane inside both the camera image and the
projector image, in front of both devices and facing both: :func:`check_pose` measures it
with the rig's own models (distortion included) and raises otherwise.

The paper's 18 poses (our table; the paper gives their kinds, not their numbers): the board
centre near the 1 m working distance on the camera axis, fronto-parallel at three distances,
tilts of 15 and 30 degrees about the board's x and y axes, combined tilts and in-plane
rolls, some shifted sideways so the circles cover different parts of both images. Angles
are applied as extrinsic rotations about the camera's x, then y, then z axis (scipy
``"xyz"``); ``t`` is the board centre in the camera frame.

===  ==================  ======  ======  ======  ========================
 #   name                 rx deg  ry deg  rz deg  t (m)
===  ==================  ======  ======  ======  ========================
 1   front_1000               0       0       0  (0, 0, 1.00)
 2   front_0900               0       0       0  (0, 0, 0.90)
 3   front_1100               0       0       0  (0, 0, 1.10)
 4   tilt_x+15              +15       0       0  (0, 0, 1.00)
 5   tilt_x-15              -15       0       0  (0, 0, 1.00)
 6   tilt_y+15                0     +15       0  (0, 0, 1.00)
 7   tilt_y-15                0     -15       0  (0, 0, 1.00)
 8   tilt_x+30              +30       0       0  (0, 0, 1.00)
 9   tilt_x-30              -30       0       0  (0, 0, 1.00)
10   tilt_y+30                0     +30       0  (0, 0, 1.00)
11   tilt_y-30                0     -30       0  (0, 0, 1.00)
12   tilt_xy+15+15          +15     +15       0  (-0.04, -0.04, 0.95)
13   tilt_xy-15+15          -15     +15       0  (-0.04, +0.04, 0.95)
14   tilt_xy+15-15          +15     -15       0  (+0.04, -0.04, 1.05)
15   tilt_xy-15-15          -15     -15       0  (+0.04, +0.04, 1.05)
16   roll+20_x+30           +30       0     +20  (+0.05, 0, 1.00)
17   roll-20_y+30             0     +30     -20  (-0.05, 0, 1.00)
18   roll+45_xy-30+15       -30     +15     +45  (0, +0.04, 0.95)
===  ==================  ======  ======  ======  ========================
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from virtus.calib.board import CircleBoard
from virtus.checks import as_rng, positive_int
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose

#: (name, (rx, ry, rz) degrees, t metres) of the paper's 18 poses (see module docstring).
PAPER_POSE_TABLE: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float]], ...] = (
    ("front_1000", (0, 0, 0), (0.0, 0.0, 1.00)),
    ("front_0900", (0, 0, 0), (0.0, 0.0, 0.90)),
    ("front_1100", (0, 0, 0), (0.0, 0.0, 1.10)),
    ("tilt_x+15", (15, 0, 0), (0.0, 0.0, 1.00)),
    ("tilt_x-15", (-15, 0, 0), (0.0, 0.0, 1.00)),
    ("tilt_y+15", (0, 15, 0), (0.0, 0.0, 1.00)),
    ("tilt_y-15", (0, -15, 0), (0.0, 0.0, 1.00)),
    ("tilt_x+30", (30, 0, 0), (0.0, 0.0, 1.00)),
    ("tilt_x-30", (-30, 0, 0), (0.0, 0.0, 1.00)),
    ("tilt_y+30", (0, 30, 0), (0.0, 0.0, 1.00)),
    ("tilt_y-30", (0, -30, 0), (0.0, 0.0, 1.00)),
    ("tilt_xy+15+15", (15, 15, 0), (-0.04, -0.04, 0.95)),
    ("tilt_xy-15+15", (-15, 15, 0), (-0.04, 0.04, 0.95)),
    ("tilt_xy+15-15", (15, -15, 0), (0.04, -0.04, 1.05)),
    ("tilt_xy-15-15", (-15, -15, 0), (0.04, 0.04, 1.05)),
    ("roll+20_x+30", (30, 0, 20), (0.05, 0.0, 1.00)),
    ("roll-20_y+30", (0, 30, -20), (-0.05, 0.0, 1.00)),
    ("roll+45_xy-30+15", (-30, 15, 45), (0.0, 0.04, 0.95)),
)

#: Margin (px) the board plane keeps from every image edge, so detection windows and the
#: phase neighbourhoods of the outer circles stay inside both images.
FIELD_MARGIN_PX = 8.0

#: Ranges of random poses: board-centre distance (m), tilt about x and y (deg), roll (deg).
RANDOM_DISTANCE_M = (0.85, 1.15)
RANDOM_TILT_DEG = 35.0
RANDOM_ROLL_DEG = 45.0
#: Smallest allowed largest angle between the normals of the usable board poses. With every
#: board (nearly) parallel the focal length is not observable (Zhang's method). Measured on
#: three 7x13 poses with 0.01 px centroid noise: fx off by 4400 % at 0 deg, 21 % at 0.7 deg,
#: 3-6 % at 1.4 deg, ~1 % at 2.8 deg, 0.2-0.6 % at 7 deg; the paper's poses span 60 deg.
MIN_POSE_SPREAD_DEG = 5.0


@dataclass(frozen=True)
class BoardPose:
    """A named board pose: ``board2cam`` maps board-frame points into the camera frame."""

    name: str
    board2cam: Pose

    def to_dict(self) -> dict:
        """JSON-ready ``{name, board2cam: {R, t}}`` (metres)."""
        return {"name": self.name, "board2cam": self.board2cam.to_dict()}

    @classmethod
    def from_dict(cls, data: dict) -> BoardPose:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(data, dict) or "name" not in data or "board2cam" not in data:
            raise InputError("pose", "an object with name and board2cam", data)
        return cls(str(data["name"]), Pose.from_dict(data["board2cam"], "board2cam"))


def _edge_points(board: CircleBoard, per_side: int = 16) -> np.ndarray:
    """Points along the plane's outline, (4 * per_side, 3), board frame (curved by distortion)."""
    corners = board.plane_corners
    s = np.linspace(0.0, 1.0, per_side, endpoint=False)[:, None]
    return np.concatenate([corners[k] + s * (corners[(k + 1) % 4] - corners[k]) for k in range(4)])


def pose_problem(
    rig: Rig, board: CircleBoard, board2cam: Pose, margin_px: float = FIELD_MARGIN_PX
) -> str | None:
    """Why ``board2cam`` is not a usable pose (``None`` if it is).

    Checks, for camera and projector: every point of the plane's outline lies in front of the
    device and projects inside its image with ``margin_px`` to spare, and the board's printed
    face (its -z side) faces the device.
    """
    edge_cam = board2cam.apply(_edge_points(board))
    normal_cam = board2cam.R[:, 2]  # board +z (into the board), camera frame
    devices = (
        ("camera", rig.camera.intrinsics, edge_cam, -board2cam.t, normal_cam),
        (
            "projector",
            rig.projector.intrinsics,
            rig.cam2proj.apply(edge_cam),
            rig.proj2cam.t - board2cam.t,
            normal_cam,
        ),
    )
    for device, intrinsics, points, to_device, normal in devices:
        if (points[:, 2] <= 0).any():
            return f"the board reaches behind the {device}"
        if np.dot(to_device, normal) >= 0:
            return f"the {device} sees the back of the board"
        uv = intrinsics.project(points)
        low = -0.5 + margin_px
        high = np.array([intrinsics.width, intrinsics.height]) - 0.5 - margin_px
        if not np.isfinite(uv).all() or (uv < low).any() or (uv > high).any():
            return f"the board leaves the {device} image (margin {margin_px:g} px)"
    return None


def check_pose(
    rig: Rig, board: CircleBoard, pose: BoardPose, margin_px: float = FIELD_MARGIN_PX
) -> None:
    """Raise :class:`VirtusError` naming ``pose`` if it is not inside both devices' fields."""
    problem = pose_problem(rig, board, pose.board2cam, margin_px)
    if problem is not None:
        raise VirtusError(f"pose {pose.name!r}: {problem}")


def paper_poses(rig: Rig, board: CircleBoard) -> list[BoardPose]:
    """The paper's 18 poses (module table), each checked against both fields of ``rig``."""
    poses = [
        BoardPose(name, Pose.from_euler("xyz", angles, degrees=True, t=t))
        for name, angles, t in PAPER_POSE_TABLE
    ]
    for pose in poses:
        check_pose(rig, board, pose)
    return poses


def random_poses(
    rig: Rig,
    board: CircleBoard,
    n: int,
    rng: np.random.Generator | int | None = None,
    max_tries: int = 1000,
) -> list[BoardPose]:
    """``n`` seeded random poses inside the common camera-projector field.

    The board centre is drawn on camera rays through the central 60 % of the image at a
    distance in :data:`RANDOM_DISTANCE_M`, tilts uniform in +-:data:`RANDOM_TILT_DEG` about
    x and y, roll uniform in +-:data:`RANDOM_ROLL_DEG`; draws failing :func:`pose_problem`
    are rejected (at most ``max_tries`` per pose, then :class:`VirtusError`).
    """
    n = positive_int("n", n)
    gen = as_rng(rng)
    cam = rig.camera.intrinsics
    poses: list[BoardPose] = []
    for index in range(n):
        for _ in range(positive_int("max_tries", max_tries)):
            pixel = np.array([[cam.width, cam.height]]) * gen.uniform(0.2, 0.8, size=(1, 2))
            ray = cam.unproject(pixel - 0.5)[0]
            distance = gen.uniform(*RANDOM_DISTANCE_M)
            t = ray * distance / ray[2]
            angles = (
                gen.uniform(-RANDOM_TILT_DEG, RANDOM_TILT_DEG),
                gen.uniform(-RANDOM_TILT_DEG, RANDOM_TILT_DEG),
                gen.uniform(-RANDOM_ROLL_DEG, RANDOM_ROLL_DEG),
            )
            board2cam = Pose.from_euler("xyz", angles, degrees=True, t=t)
            if pose_problem(rig, board, board2cam) is None:
                poses.append(BoardPose(f"random_{index + 1:03d}", board2cam))
                break
        else:
            raise VirtusError(
                f"no random pose inside the common field after {max_tries} tries "
                f"(board {board.plane_size_m[0]:g} x {board.plane_size_m[1]:g} m too large?)"
            )
    return poses


def pose_set(
    spec: str, rig: Rig, board: CircleBoard, rng: np.random.Generator | int | None = None
) -> list[BoardPose]:
    """Poses from a spec: ``"paper"`` (the 18 poses) or ``"random:N"`` (seeded by ``rng``)."""
    text = str(spec).strip().lower()
    if text == "paper":
        return paper_poses(rig, board)
    match = re.fullmatch(r"random:(\d+)", text)
    if match is None:
        raise InputError("poses", "'paper' or 'random:N'", spec)
    return random_poses(rig, board, int(match.group(1)), rng)


def pose_spread_deg(poses: list[BoardPose]) -> float:
    """Largest angle (deg) between the normals (board z axes) of a set of board poses."""
    normals = np.array([pose.board2cam.R[:, 2] for pose in poses])
    cosines = np.clip(normals @ normals.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cosines.min())))


def check_pose_spread(poses: list[BoardPose]) -> None:
    """Refuse a degenerate pose set: every board (nearly) parallel to the others.

    The check uses the poses the boards were rendered in (the job knows them exactly). The
    solved poses cannot serve: with parallel boards the solve runs off to a wrong focal
    length whose board poses may tilt by anything (measured 0.06-130 deg), and OpenCV's
    standard deviation of fx stays tiny there (measured 1e-12-1e-4 relative). Sets that pass
    are checked again after the solve (:mod:`virtus.calib.conditioning`: a warning below a
    10 deg spread, and the focal length's uncertainty from the solve's own Jacobian).

    Raises
    ------
    VirtusError : the largest angle between the boards' normals is below
        :data:`MIN_POSE_SPREAD_DEG` (see there why).
    """
    spread = pose_spread_deg(poses)
    if spread < MIN_POSE_SPREAD_DEG:
        raise VirtusError(
            f"calibration: the {len(poses)} usable board poses are nearly parallel "
            f"(largest angle between their normals {spread:.2f} deg < "
            f"{MIN_POSE_SPREAD_DEG:g} deg), so the focal lengths cannot be determined; "
            "add poses tilted by 10-30 deg"
        )
