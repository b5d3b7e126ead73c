"""The robot file: which robot, where its base stands, and where the rig sits on it.

A robot file is YAML (every key checked; unknown keys are refused)::

    robot: panda                 # built-in ("panda") or a URDF path (relative: to this file)
    package_paths: {}            # URDF package://NAME -> DIR (relative: to this file)
    base2world:                  # the base frame in the world, X_world = R X_base + t (m)
      R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
      t: [0, 0, 0]
    mount:
      link: panda_hand           # the link the rig is fixed to
      link2cam:                  # the camera's pose in that link's frame (m):
        R: [[...]]               #   X_link = R X_cam + t  (virtus's name: cam2link; the key
        t: [0.0, 0.0, 0.05]      #   keeps the issue's parent->child spelling, as ROS tf does)
    rig: null                    # rig JSON (relative: to this file); null = the paper's rig
    home_q: null                 # a configuration for IK's first start (rad), optional

Poses may also be written ``{euler_deg: [rx, ry, rz], seq: xyz, t: [...]}``. The camera's
world pose at joint values ``q`` is::

    cam2world = base2world @ link2base(q) @ cam2link

which :meth:`RobotSetup.cam2world` computes and :meth:`RobotSetup.capture_record` records,
with ``q``, the link's world pose and the robot's source, in every capture's
``provenance["robot"]`` (``capture.json``: no new top-level key, readers unchanged).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.safeio import check_keys, read_yaml
from virtus.robot.ik import IKResult, solve_ik
from virtus.robot.model import BUILTIN_ROBOTS, Robot, builtin_robot

__all__ = ["RobotSetup", "load_robot_file", "parse_pose"]

_KEYS = ("robot", "package_paths", "base2world", "mount", "rig", "home_q")
_MOUNT_KEYS = ("link", "link2cam")
#: Largest distance (m) a pose in a robot file may place anything from the origin.
MAX_REACH_M = 100.0


def parse_pose(value: Any, name: str) -> Pose:
    """``{R, t}`` or ``{euler_deg, [seq,] t}`` (metres, degrees) -> :class:`Pose`."""
    if isinstance(value, Pose):
        return value
    if isinstance(value, Mapping) and "euler_deg" in value:
        check_keys(value, ("euler_deg", "seq", "t"), name)
        try:
            pose = Pose.from_euler(
                str(value.get("seq", "xyz")), value["euler_deg"], t=value.get("t", (0.0, 0.0, 0.0))
            )
        except InputError as error:
            raise InputError(f"{name}.{error.name}", error.expected, error.got) from None
    else:
        if isinstance(value, Mapping):
            check_keys(value, ("R", "t"), name)
        pose = Pose.from_dict(value, name)
    if np.abs(pose.t).max() > MAX_REACH_M:
        raise InputError(f"{name}.t", f"coordinates within +-{MAX_REACH_M:g} m", pose.t.tolist())
    return pose


@dataclass
class RobotSetup:
    """A robot standing in the world with the rig on one of its links.

    Attributes
    ----------
    robot : the robot (kinematics, collision capsules, meshes).
    link : the link the rig is mounted on.
    cam2link : the camera's pose in the link frame (the robot file's ``link2cam``).
    base2world : the robot base's pose in the world.
    rig : the camera-projector rig.
    home_q : IK's preferred first start (dof,), or None.
    source : the robot file's content (recorded with every capture).
    """

    robot: Robot
    link: str
    cam2link: Pose
    base2world: Pose = field(default_factory=Pose.identity)
    rig: Rig | None = None
    home_q: np.ndarray | None = None
    source: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.robot.tree.check_link(self.link)
        if self.home_q is not None:
            self.home_q = self.robot.tree.check_q(self.home_q, "home_q")

    def link2world(self, q: object) -> Pose:
        """The mount link's world pose at ``q`` (dof,), checked against the limits."""
        values = self.robot.tree.check_q(q)
        if values.ndim != 1:
            raise InputError("q", f"{self.robot.tree.dof} joint values", f"shape {values.shape}")
        return self.base2world @ Pose.from_matrix(self.robot.tree.link_pose(values, self.link))

    def cam2world(self, q: object) -> Pose:
        """``base2world @ link2base(q) @ cam2link``."""
        return self.link2world(q) @ self.cam2link

    def capture_record(self, q: object) -> dict[str, Any]:
        """What a capture at ``q`` records (``provenance["robot"]``): joint names and values
        (rad/m), the link and its world pose, ``cam2link``, ``base2world``, ``cam2world``,
        and the robot's source."""
        values = self.robot.tree.check_q(q)
        return {
            "robot": self.robot.source,
            "joint_names": list(self.robot.tree.joint_names),
            "q": [float(v) for v in values],
            "link": self.link,
            "link2world": self.link2world(values).to_dict(),
            "cam2link": self.cam2link.to_dict(),
            "base2world": self.base2world.to_dict(),
            "cam2world": self.cam2world(values).to_dict(),
        }

    def solve_view(self, cam2world: Pose, *, rng: int = 0, **options: Any) -> IKResult:
        """Joint values putting the camera at ``cam2world`` (:func:`~virtus.robot.ik.solve_ik`
        on the mount link; raises :class:`~virtus.robot.ik.Unreachable`)."""
        link2base = self.base2world.inverse() @ cam2world @ self.cam2link.inverse()
        options.setdefault("q0", self.home_q)
        return solve_ik(self.robot, self.link, link2base.matrix, rng=rng, **options)

    def scene_meshes(self, q: object) -> list[Any]:
        """The robot's link meshes at ``q`` in the world (``trimesh.Trimesh``)."""
        return self.robot.meshes(q, self.base2world.matrix)


def load_robot_file(
    path: str | Path, package_paths: Mapping[str, Path] | None = None
) -> RobotSetup:
    """Read and check a robot file (see the module docs).

    ``package_paths`` (e.g. from ``--package-path``) add to and override the file's own.
    """
    file = Path(path).expanduser()
    data = read_yaml(file, "robot file", expect=dict)
    check_keys(data, _KEYS, "robot file")
    for key in ("robot", "mount"):
        if key not in data:
            raise InputError(f"robot file {key}", "this required key", "nothing")
    here = file.parent
    packages: dict[str, Path] = {}
    extra = data.get("package_paths") or {}
    if not isinstance(extra, Mapping):
        raise InputError("robot file package_paths", "a mapping NAME: DIR", extra)
    for name, folder in extra.items():
        folder = Path(str(folder)).expanduser()
        packages[str(name)] = folder if folder.is_absolute() else here / folder
    packages.update(package_paths or {})
    robot = _robot(data["robot"], here, packages)
    mount = data["mount"]
    if not isinstance(mount, Mapping):
        raise InputError("robot file mount", "a mapping {link, link2cam}", mount)
    check_keys(mount, _MOUNT_KEYS, "robot file mount")
    if "link" not in mount:
        raise InputError("robot file mount.link", "this required key", "nothing")
    link = str(mount["link"])
    if link not in robot.tree.link_names:
        raise InputError(
            "robot file mount.link",
            f"a link of {robot.tree.name} ({', '.join(robot.tree.link_names)})",
            link,
        )
    cam2link = parse_pose(
        mount.get("link2cam", {"R": np.eye(3), "t": [0, 0, 0]}), "robot file mount.link2cam"
    )
    base = data.get("base2world")
    base2world = Pose.identity() if base is None else parse_pose(base, "robot file base2world")
    rig = None
    if data.get("rig") is not None:
        from virtus.calib import load_rig_file

        rig_path = Path(str(data["rig"])).expanduser()
        rig_path = rig_path if rig_path.is_absolute() else here / rig_path
        if not rig_path.is_file():
            raise InputError("robot file rig", "an existing rig JSON", str(rig_path))
        rig = load_rig_file(rig_path, units="m" if rig_path.suffix.lower() == ".json" else None)
    home = data.get("home_q")
    try:
        return RobotSetup(
            robot,
            link,
            cam2link,
            base2world,
            rig,
            None if home is None else np.asarray(home, dtype=np.float64),
            {"path": str(file), **data},
        )
    except (TypeError, ValueError) as error:
        if isinstance(error, InputError):
            raise InputError(f"robot file {error.name}", error.expected, error.got) from None
        raise InputError("robot file home_q", "a list of joint values", home) from None


def _robot(value: Any, here: Path, packages: Mapping[str, Path]) -> Robot:
    if not isinstance(value, str) or not value:
        raise InputError("robot file robot", f"one of {BUILTIN_ROBOTS} or a URDF path", value)
    if value in BUILTIN_ROBOTS:
        return builtin_robot(value)
    urdf = Path(value).expanduser()
    urdf = urdf if urdf.is_absolute() else here / urdf
    if urdf.suffix.lower() != ".urdf":
        raise InputError("robot file robot", f"one of {BUILTIN_ROBOTS} or a .urdf path", value)
    from virtus.robot.urdf import load_urdf

    return load_urdf(urdf, packages)
