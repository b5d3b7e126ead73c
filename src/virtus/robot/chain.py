"""Kinematic trees: links joined by fixed, revolute and prismatic joints.

One engine computes forward kinematics and geometric Jacobians for every robot virtus knows:
the built-in Panda (:mod:`virtus.robot.panda`, from Franka's published DH table) and robots
read from a URDF (:mod:`virtus.robot.urdf`). Conventions:

* A link's pose is ``link2base`` (4x4, metres): it maps points of the link frame into the
  robot's base frame (the root link's frame), ``X_base = R @ X_link + t``.
* A joint connects ``parent`` to ``child``: ``child2parent = origin @ motion(q)``, where
  ``origin`` is the joint's fixed ``(4, 4)`` placement in the parent frame (URDF
  ``<origin>``) and ``motion`` turns about (revolute) or slides along (prismatic) the unit
  ``axis`` given in the child frame, by ``q`` radians or metres.
* ``q`` lists the actuated joints in :attr:`KinematicTree.joint_names` order; batched
  inputs ``(..., n)`` give batched poses ``(..., 4, 4)``.
* Jacobians are geometric, in the base frame: rows ``(v_x, v_y, v_z, w_x, w_y, w_z)``, the
  velocity of the link origin (m/s) and its angular velocity (rad/s) per unit joint speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from virtus.errors import InputError

__all__ = ["Joint", "KinematicTree", "rotation_about"]

#: Joint kinds the engine moves (``fixed`` joints have no entry in ``q``).
JOINT_KINDS = ("fixed", "revolute", "prismatic")


def rotation_about(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about the unit ``axis`` (3,) by ``angle`` (...,) rad
    (Rodrigues' formula)."""
    angle = np.asarray(angle, dtype=np.float64)
    k = np.asarray(axis, dtype=np.float64)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])  # noqa: N806
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


@dataclass(frozen=True)
class Joint:
    """One joint of a kinematic tree.

    Attributes
    ----------
    name : the joint's name (URDF ``<joint name>``).
    kind : ``"fixed"``, ``"revolute"`` or ``"prismatic"``.
    parent, child : link names; ``child2parent = origin @ motion(q)``.
    origin : (4, 4) float64, the child frame at ``q = 0`` in the parent frame (metres).
    axis : (3,) float64 unit axis in the child frame (ignored for fixed joints).
    lower, upper : limits of ``q`` (rad or m); ``-inf``/``inf`` for a continuous joint.
    """

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    lower: float = -np.inf
    upper: float = np.inf

    def __post_init__(self) -> None:
        if self.kind not in JOINT_KINDS:
            raise InputError(f"joint {self.name}", f"a kind of {JOINT_KINDS}", self.kind)
        origin = np.asarray(self.origin, dtype=np.float64)
        if origin.shape != (4, 4) or not np.all(np.isfinite(origin)):
            raise InputError(f"joint {self.name} origin", "a finite (4, 4) matrix", origin.shape)
        axis = np.asarray(self.axis, dtype=np.float64).reshape(3)
        norm = float(np.linalg.norm(axis))
        if self.kind != "fixed" and not norm > 0:
            raise InputError(f"joint {self.name} axis", "a non-zero axis", axis.tolist())
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "axis", axis / norm if norm > 0 else axis)
        if not self.lower <= self.upper:
            raise InputError(
                f"joint {self.name} limits", "lower <= upper", (self.lower, self.upper)
            )

    def motion(self, q: np.ndarray) -> np.ndarray:
        """``(..., 4, 4)`` motion of the joint at ``q`` (...,) in the child frame."""
        q = np.asarray(q, dtype=np.float64)
        T = np.broadcast_to(np.eye(4), (*q.shape, 4, 4)).copy()  # noqa: N806
        if self.kind == "revolute":
            T[..., :3, :3] = rotation_about(self.axis, q)
        elif self.kind == "prismatic":
            T[..., :3, 3] = q[..., None] * self.axis
        return T


class KinematicTree:
    """Links and joints of a robot, with forward kinematics and Jacobians.

    Parameters
    ----------
    name : the robot's name.
    joints : every joint; each link except the root is the child of exactly one joint.
    """

    def __init__(self, name: str, joints: list[Joint]) -> None:
        self.name = name
        children = [j.child for j in joints]
        parents = {j.parent for j in joints}
        roots = sorted(parents - set(children))
        if len(set(children)) != len(children):
            raise InputError(f"robot {name}", "each link the child of one joint", children)
        if len(roots) != 1:
            raise InputError(f"robot {name}", "one root link", roots or "a cycle")
        self.root = roots[0]
        by_parent: dict[str, list[Joint]] = {}
        for joint in joints:
            by_parent.setdefault(joint.parent, []).append(joint)
        ordered: list[Joint] = []  # parents before children
        stack = [self.root]
        while stack:
            link = stack.pop()
            for joint in reversed(by_parent.get(link, [])):
                ordered.append(joint)
                stack.append(joint.child)
        self.joints: tuple[Joint, ...] = tuple(ordered)
        self.link_names: tuple[str, ...] = (self.root, *(j.child for j in ordered))
        moving = [j for j in ordered if j.kind != "fixed"]
        self.joint_names: tuple[str, ...] = tuple(j.name for j in moving)
        self.lower = np.array([j.lower for j in moving], dtype=np.float64)
        self.upper = np.array([j.upper for j in moving], dtype=np.float64)
        self._index = {j.name: i for i, j in enumerate(moving)}
        self._parent_joint = {j.child: j for j in ordered}

    @property
    def dof(self) -> int:
        """Number of actuated joints (length of ``q``)."""
        return len(self.joint_names)

    # -- checks ----------------------------------------------------------------------------

    def check_link(self, link: str) -> str:
        """``link`` if the robot has it, else :class:`InputError` listing the links."""
        if link not in self.link_names:
            raise InputError("link", f"a link of {self.name} ({', '.join(self.link_names)})", link)
        return link

    def check_q(self, q: object, name: str = "q", *, tol: float = 1e-9) -> np.ndarray:
        """``q`` as float64 ``(..., dof)`` within the joint limits (``tol`` rad/m of slack),
        else :class:`InputError` naming the first joint out of range."""
        try:
            values = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(name, f"{self.dof} joint values", q) from None
        if values.ndim == 0 or values.shape[-1] != self.dof:
            raise InputError(
                name,
                f"{self.dof} joint values ({', '.join(self.joint_names)})",
                f"shape {values.shape}",
            )
        if not np.all(np.isfinite(values)):
            raise InputError(name, "finite joint values", "NaN or infinity")
        low = values < self.lower - tol
        high = values > self.upper + tol
        bad = np.flatnonzero(np.any((low | high).reshape(-1, self.dof), axis=0))
        if bad.size:
            i = int(bad[0])
            worst = values.reshape(-1, self.dof)[:, i]
            got = worst[np.argmax(np.abs(worst - np.clip(worst, self.lower[i], self.upper[i])))]
            raise InputError(
                f"{name} joint {self.joint_names[i]}",
                f"a value within [{self.lower[i]:.4f}, {self.upper[i]:.4f}]",
                float(got),
            )
        return values

    # -- kinematics ------------------------------------------------------------------------

    def fk(self, q: object) -> dict[str, np.ndarray]:
        """Every link's ``link2base`` at ``q`` (..., dof): name -> (..., 4, 4) float64.

        ``q`` is not checked against the limits (see :meth:`check_q`)."""
        values = np.asarray(q, dtype=np.float64)
        batch = values.shape[:-1]
        poses = {self.root: np.broadcast_to(np.eye(4), (*batch, 4, 4)).copy()}
        for joint in self.joints:
            placed = poses[joint.parent] @ joint.origin
            if joint.kind != "fixed":
                placed = placed @ joint.motion(values[..., self._index[joint.name]])
            poses[joint.child] = placed
        return poses

    def link_pose(self, q: object, link: str) -> np.ndarray:
        """``link2base`` (..., 4, 4) of one link at ``q`` (..., dof)."""
        return self._chain_poses(np.asarray(q, dtype=np.float64), self.check_link(link))[-1][1]

    def chain(self, link: str) -> list[Joint]:
        """The joints from the root to ``link``, root first."""
        path: list[Joint] = []
        current = self.check_link(link)
        while current != self.root:
            joint = self._parent_joint[current]
            path.append(joint)
            current = joint.parent
        return path[::-1]

    def _chain_poses(self, q: np.ndarray, link: str) -> list[tuple[Joint | None, np.ndarray]]:
        batch = q.shape[:-1]
        T = np.broadcast_to(np.eye(4), (*batch, 4, 4)).copy()  # noqa: N806
        out: list[tuple[Joint | None, np.ndarray]] = [(None, T)]
        for joint in self.chain(link):
            T = T @ joint.origin  # noqa: N806
            if joint.kind != "fixed":
                T = T @ joint.motion(q[..., self._index[joint.name]])  # noqa: N806
            out.append((joint, T))
        return out

    def jacobian(self, q: object, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Geometric Jacobian of ``link``'s origin at ``q`` (..., dof), base frame.

        Returns
        -------
        pose : (..., 4, 4) ``link2base``.
        J : (..., 6, dof) rows (v, w); columns of joints off the link's chain are zero.
        """
        values = np.asarray(q, dtype=np.float64)
        poses = self._chain_poses(values, self.check_link(link))
        end = poses[-1][1]
        J = np.zeros((*values.shape[:-1], 6, self.dof))  # noqa: N806
        for joint, T in poses[1:]:  # noqa: N806
            if joint is None or joint.kind == "fixed":
                continue
            i = self._index[joint.name]
            axis = T[..., :3, :3] @ joint.axis
            if joint.kind == "revolute":
                J[..., :3, i] = np.cross(axis, end[..., :3, 3] - T[..., :3, 3])
                J[..., 3:, i] = axis
            else:
                J[..., :3, i] = axis
        return end, J

    def random_q(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` configurations drawn uniformly within the limits (continuous joints:
        within +-pi), (count, dof) float64."""
        low = np.where(np.isfinite(self.lower), self.lower, -np.pi)
        high = np.where(np.isfinite(self.upper), self.upper, np.pi)
        return low + rng.random((count, self.dof)) * (high - low)
