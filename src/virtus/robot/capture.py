"""Captures taken from a robot: the arm in the scene, the rig at the mount, q recorded.

:func:`scene_with_robot` adds the robot's link meshes at ``q`` to a scene (one STL file,
world frame, metres, written where the caller says), so the arm occludes the object and
shadows the projector's light like any other object. :func:`capture_at` renders one capture
with the camera at ``cam2world = base2world @ link2base(q) @ cam2link`` -- exactly the pose
recorded in ``capture.json`` -- and records the robot's state in the capture's
``provenance["robot"]`` (:meth:`virtus.robot.config.RobotSetup.capture_record`): joint
names and values, the link and its world pose, ``cam2link``, ``base2world`` and
``cam2world``. Loading the capture and rendering again from its stored ``cam2world`` gives
the same frames bit for bit.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from virtus.robot.config import RobotSetup

__all__ = ["ROBOT_MATERIAL", "ROBOT_MESH", "capture_at", "robot_record", "scene_with_robot"]

#: File name of the robot's meshes written next to a capture.
ROBOT_MESH = "robot_links.stl"
#: The arm's paint: a light grey, fairly matte (Franka's white covers).
ROBOT_MATERIAL = {"albedo": 0.7, "roughness": 0.6, "specular": 0.2}


def scene_with_robot(
    scene: Any, setup: RobotSetup, q: object, folder: str | Path, name: str = ROBOT_MESH
) -> Any:
    """``scene`` plus the robot at ``q`` (one mesh object, the STL ``folder/name``)."""
    import trimesh

    from virtus.scene.model import Material, MeshObject

    meshes = setup.scene_meshes(q)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    trimesh.util.concatenate(meshes).export(path)
    robot = MeshObject(path=path, scale_to_m=1.0, material=Material(**ROBOT_MATERIAL))
    return scene.model_copy(update={"objects": (*scene.objects, robot)})


def robot_record(capture: Any) -> dict[str, Any] | None:
    """The ``provenance["robot"]`` record of a capture, or None."""
    record = (capture.provenance or {}).get("robot")
    return record if isinstance(record, dict) else None


def capture_at(
    scanner: Any,
    scene: Any,
    setup: RobotSetup,
    q: object,
    folder: str | Path,
    *,
    seed: int = 0,
    with_robot: bool = True,
) -> Any:
    """Render ``scene`` from the rig on the robot at ``q`` (dof,) (checked against the limits).

    Parameters
    ----------
    scanner : the :class:`virtus.scanner.Scanner`.
    scene : a :class:`virtus.scene.model.Scene` in the world frame of ``setup.base2world``.
    folder : where the robot's mesh goes (e.g. the capture's directory).
    seed : noise seed of the capture.
    with_robot : add the robot's links to the scene (they occlude and shadow).

    Returns
    -------
    A :class:`virtus.capture.Capture` whose ``cam2world`` is ``setup.cam2world(q)`` and
    whose provenance carries the robot record.
    """
    values = setup.robot.tree.check_q(q)
    cam2world = setup.cam2world(values)
    full = scene_with_robot(scene, setup, values, folder) if with_robot else scene
    captured = scanner.capture(full, cam2world=cam2world, rng=seed)
    record = setup.capture_record(values)
    return replace(captured, provenance={**captured.provenance, "robot": record})


def q_of(capture: Any) -> np.ndarray | None:
    """The joint values a capture recorded, or None."""
    record = robot_record(capture)
    return None if record is None else np.asarray(record["q"], dtype=np.float64)
