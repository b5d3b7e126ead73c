"""A robot: its kinematic tree, its collision capsules and the meshes the renderer sees.

:func:`builtin_robot` gives the offline Panda; :func:`virtus.robot.urdf.load_urdf` gives any
robot from a URDF. Self-collision is checked between the capsules of *bodies* (links joined
by fixed joints form one body) that are at least :data:`MIN_JOINTS_APART` actuated joints
apart: neighbours touch at their shared joint by construction.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.robot.chain import KinematicTree
from virtus.robot.shapes import Capsule, capsule_mesh, segment_distances

__all__ = ["BUILTIN_ROBOTS", "MIN_JOINTS_APART", "Robot", "builtin_robot"]

#: Bodies this many actuated joints apart or more are checked against each other.
MIN_JOINTS_APART = 3
#: Names accepted by :func:`builtin_robot`.
BUILTIN_ROBOTS = ("panda",)


@dataclass
class Robot:
    """A robot arm.

    Attributes
    ----------
    tree : links, joints, limits, forward kinematics.
    capsules : collision shapes (link frames).
    visuals : ``link -> [trimesh.Trimesh in the link frame]``, called lazily; None: the
        capsules are drawn.
    source : where it came from (``{"builtin": "panda"}`` or ``{"urdf": path}``), recorded
        with every capture.
    """

    tree: KinematicTree
    capsules: tuple[Capsule, ...]
    visuals: Callable[[], dict[str, list[Any]]] | None = None
    source: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for capsule in self.capsules:
            self.tree.check_link(capsule.link)
        bodies = _bodies(self.tree)
        depth = _joint_depths(self.tree)
        pairs = []
        for i, a in enumerate(self.capsules):
            for j in range(i + 1, len(self.capsules)):
                b = self.capsules[j]
                apart = _joints_apart(self.tree, bodies, depth, a.link, b.link)
                if apart >= MIN_JOINTS_APART:
                    pairs.append((i, j))
        self._pairs = np.array(pairs, dtype=np.int64).reshape(-1, 2)

    @property
    def collision_pairs(self) -> np.ndarray:
        """(P, 2) int64 indices into :attr:`capsules` of the pairs the check looks at."""
        return self._pairs

    def clearance(self, q: object) -> np.ndarray:
        """Smallest surface distance between checked capsule pairs at ``q`` (..., dof),
        metres (negative: they overlap); ``inf`` when no pair is checked."""
        values = np.asarray(q, dtype=np.float64)
        if len(self._pairs) == 0:
            return np.full(values.shape[:-1], np.inf)
        poses = self.tree.fk(values)
        ends = [c.ends_world(poses[c.link]) for c in self.capsules]
        p0 = np.stack([e[0] for e in ends], axis=-2)  # (..., C, 3)
        p1 = np.stack([e[1] for e in ends], axis=-2)
        radii = np.array([c.radius for c in self.capsules])
        i, j = self._pairs[:, 0], self._pairs[:, 1]
        gaps = segment_distances(p0[..., i, :], p1[..., i, :], p0[..., j, :], p1[..., j, :])
        return np.min(gaps - radii[i] - radii[j], axis=-1)

    def in_collision(self, q: object) -> np.ndarray:
        """True where the configuration ``q`` (..., dof) collides with itself."""
        return self.clearance(q) < 0.0

    def meshes(self, q: object, base2world: np.ndarray | None = None) -> list[Any]:
        """The robot's link meshes at ``q`` (dof,) in the world (``trimesh.Trimesh``, metres)."""
        values = self.tree.check_q(q)
        poses = self.tree.fk(values)
        place = np.eye(4) if base2world is None else np.asarray(base2world, dtype=np.float64)
        out = []
        if self.visuals is None:
            for capsule in self.capsules:
                out.append(capsule_mesh(capsule, place @ poses[capsule.link]))
            return out
        for link, meshes in self.visuals().items():
            for mesh in meshes:
                placed = mesh.copy()
                placed.apply_transform(place @ poses[link])
                out.append(placed)
        return out


def builtin_robot(name: str) -> Robot:
    """A robot virtus ships (:data:`BUILTIN_ROBOTS`), offline."""
    if name != "panda":
        raise InputError("robot", f"one of {BUILTIN_ROBOTS} or a URDF path", name)
    from virtus.robot.panda import PANDA_CAPSULES, panda_tree

    return Robot(panda_tree(), PANDA_CAPSULES, None, {"builtin": "panda"})


def _bodies(tree: KinematicTree) -> dict[str, str]:
    """link -> the name of its body's first link (links joined by fixed joints share one)."""
    body = {tree.root: tree.root}
    for joint in tree.joints:
        body[joint.child] = body[joint.parent] if joint.kind == "fixed" else joint.child
    return body


def _joint_depths(tree: KinematicTree) -> dict[str, int]:
    depth = {tree.root: 0}
    for joint in tree.joints:
        depth[joint.child] = depth[joint.parent] + (joint.kind != "fixed")
    return depth


def _joints_apart(
    tree: KinematicTree, bodies: dict[str, str], depth: dict[str, int], a: str, b: str
) -> int:
    """Actuated joints on the tree path between links ``a`` and ``b``."""
    if bodies[a] == bodies[b]:
        return 0
    ancestors_a = {j.child for j in tree.chain(a)} | {tree.root}
    common = tree.root
    for joint in tree.chain(b):
        if joint.child in ancestors_a:
            common = joint.child
    return depth[a] + depth[b] - 2 * depth[common]
