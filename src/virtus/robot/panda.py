"""The built-in Franka Emika Panda, from Franka's published kinematic parameters (offline).

Kinematics: Franka's documented modified (Craig) Denavit-Hartenberg table (Franka Control
Interface documentation, "Robot and interface specifications": *Denavit-Hartenberg
parameters*), one row per joint ``i``::

    joint   a_{i-1} (m)   d_i (m)   alpha_{i-1} (rad)
    1        0             0.333      0
    2        0             0          -pi/2
    3        0             0.316       pi/2
    4        0.0825        0           pi/2
    5       -0.0825        0.384      -pi/2
    6        0             0           pi/2
    7        0.088         0           pi/2
    flange   0             0.107       0           (panda_link8, fixed)

``link_{i-1} -> link_i`` is ``RotX(alpha) @ TransX(a) @ RotZ(q_i) @ TransZ(d)``, i.e. a fixed
origin ``TransX(a) @ RotX(alpha) @ TransZ(d)`` followed by a turn about the child's z axis.
``panda_hand`` is the flange turned by -pi/4 about z (as in Franka's description package);
``panda_hand_tcp`` lies 0.1034 m further along the hand's z axis (between the fingertips).

Joint limits (rad), from the same page: q1, q3, q5, q7 in [-2.8973, 2.8973]; q2 in
[-1.7628, 1.7628]; q4 in [-3.0718, -0.0698]; q6 in [-0.0175, 3.7525].

Link geometry: hand-sized capsules (:data:`PANDA_CAPSULES`, a few cm larger than the arm's
covers, never smaller), good enough for occlusion, shadows and a conservative self-collision
check; they are not Franka's meshes.
"""

from __future__ import annotations

import numpy as np

from virtus.robot.chain import Joint, KinematicTree
from virtus.robot.shapes import Capsule

__all__ = [
    "PANDA_CAPSULES",
    "PANDA_DH",
    "PANDA_LOWER",
    "PANDA_READY_Q",
    "PANDA_UPPER",
    "dh_origin",
    "panda_tree",
]

#: Modified DH rows ``(a_{i-1}, d_i, alpha_{i-1})`` in metres and radians: joints 1-7, flange.
PANDA_DH: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
    (0.0, 0.107, 0.0),
)
#: Joint limits, rad (Franka's specification).
PANDA_LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
PANDA_UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
#: The paper code's ``factory_arm`` configuration (rad).
PANDA_READY_Q = np.array([0.0, 0.85, 0.0, -1.7, 0.0, 2.55, 0.785])
#: Distance from the hand's frame to the point between the fingertips, metres.
HAND_TCP_M = 0.1034

#: Capsules per link, link frame, metres (see the module docs: approximate, conservative).
PANDA_CAPSULES: tuple[Capsule, ...] = (
    Capsule("panda_link0", (-0.04, 0.0, 0.03), (0.0, 0.0, 0.15), 0.09),
    Capsule("panda_link1", (0.0, 0.0, -0.19), (0.0, 0.0, -0.03), 0.065),
    Capsule("panda_link2", (0.0, 0.0, -0.06), (0.0, 0.0, 0.06), 0.065),
    Capsule("panda_link2", (0.0, -0.03, 0.0), (0.0, -0.15, 0.0), 0.06),
    Capsule("panda_link3", (0.0, 0.0, -0.17), (0.0, 0.0, -0.04), 0.06),
    Capsule("panda_link4", (0.0, 0.0, -0.055), (0.0, 0.0, 0.055), 0.06),
    Capsule("panda_link4", (-0.03, 0.06, 0.0), (-0.08, 0.13, 0.0), 0.055),
    Capsule("panda_link5", (0.0, 0.0, -0.22), (0.0, 0.0, -0.07), 0.055),
    Capsule("panda_link6", (0.0, 0.0, -0.04), (0.0, 0.0, 0.04), 0.06),
    Capsule("panda_link7", (0.0, 0.0, -0.02), (0.0, 0.0, 0.07), 0.05),
    Capsule("panda_hand", (0.0, -0.08, 0.03), (0.0, 0.08, 0.03), 0.035),
    Capsule("panda_hand", (0.0, 0.0, 0.06), (0.0, 0.0, 0.09), 0.02),
)


def dh_origin(a: float, d: float, alpha: float) -> np.ndarray:
    """The fixed part ``TransX(a) @ RotX(alpha) @ TransZ(d)`` of a modified-DH row, (4, 4)."""
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [1.0, 0.0, 0.0, a],
            [0.0, c, -s, -s * d],
            [0.0, s, c, c * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def panda_tree() -> KinematicTree:
    """The Panda's links ``panda_link0`` (base) ... ``panda_link8`` (flange), ``panda_hand``
    and ``panda_hand_tcp``; seven revolute joints ``panda_joint1`` ... ``panda_joint7``."""
    joints = []
    for i, (a, d, alpha) in enumerate(PANDA_DH[:7]):
        joints.append(
            Joint(
                f"panda_joint{i + 1}",
                "revolute",
                f"panda_link{i}",
                f"panda_link{i + 1}",
                dh_origin(a, d, alpha),
                np.array([0.0, 0.0, 1.0]),
                float(PANDA_LOWER[i]),
                float(PANDA_UPPER[i]),
            )
        )
    joints.append(
        Joint("panda_joint8", "fixed", "panda_link7", "panda_link8", dh_origin(*PANDA_DH[7]))
    )
    hand = np.eye(4)
    c, s = np.cos(-np.pi / 4), np.sin(-np.pi / 4)
    hand[:2, :2] = [[c, -s], [s, c]]
    joints.append(Joint("panda_hand_joint", "fixed", "panda_link8", "panda_hand", hand))
    tcp = np.eye(4)
    tcp[2, 3] = HAND_TCP_M
    joints.append(Joint("panda_hand_tcp_joint", "fixed", "panda_hand", "panda_hand_tcp", tcp))
    return KinematicTree("panda", joints)
