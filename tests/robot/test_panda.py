"""The built-in Panda against yourdfpy on a URDF written from the same published table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import FK_AGREEMENT_M, FLOAT64_EXACT
from virtus.robot.model import builtin_robot
from virtus.robot.panda import PANDA_LOWER, PANDA_READY_Q, PANDA_UPPER, panda_tree

URDF = Path(__file__).resolve().parents[2] / "examples" / "robots" / "panda.urdf"


def test_known_poses() -> None:
    tree = panda_tree()
    # q = 0: the arm stands straight up; the flange is 0.333 + 0.316 + 0.384 - 0.107 m high
    # and 0.088 m forward, the hand's z axis points down.
    hand = tree.fk(np.zeros(7))["panda_hand"]
    np.testing.assert_allclose(hand[:3, 3], [0.088, 0.0, 0.926], atol=FLOAT64_EXACT)
    np.testing.assert_allclose(hand[:3, 2], [0.0, 0.0, -1.0], atol=FLOAT64_EXACT)
    # Franka's "ready" pose puts the fingertip centre at (0.307, 0, 0.487) m
    ready = tree.fk([0, -np.pi / 4, 0, -3 * np.pi / 4, 0, np.pi / 2, np.pi / 4])
    np.testing.assert_allclose(ready["panda_hand_tcp"][:3, 3], [0.3069, 0.0, 0.4869], atol=1e-4)


def test_fk_agrees_with_yourdfpy_on_1000_configurations() -> None:
    yourdfpy = pytest.importorskip("yourdfpy")
    model = yourdfpy.URDF.load(str(URDF), load_meshes=False, build_scene_graph=True)
    tree = panda_tree()
    assert tuple(model.actuated_joint_names) == tree.joint_names
    np.testing.assert_array_equal(tree.lower, PANDA_LOWER)
    np.testing.assert_array_equal(tree.upper, PANDA_UPPER)
    q = tree.random_q(np.random.default_rng(21), 1000)
    ours = tree.fk(q)
    links = [f"panda_link{i}" for i in range(1, 9)] + ["panda_hand", "panda_hand_tcp"]
    worst = 0.0
    for k in range(len(q)):
        model.update_cfg(q[k])
        for link in links:
            theirs = model.get_transform(link, "panda_link0")
            worst = max(worst, float(np.abs(ours[link][k] - theirs).max()))
    assert worst <= FK_AGREEMENT_M


def test_capsules_clear_at_the_paper_pose_and_collide_when_folded() -> None:
    robot = builtin_robot("panda")
    assert robot.clearance(PANDA_READY_Q) > 0.05
    folded = np.array([0.0, 0.0, 0.0, -3.0, 0.0, 0.0, 0.0])  # elbow fully bent: hand at base
    assert robot.in_collision(folded)
    meshes = robot.meshes(PANDA_READY_Q)
    assert all(m.is_watertight for m in meshes)
    top = max(m.bounds[1][2] for m in meshes)
    assert 0.5 < top < 1.0  # the arm's height at that pose, metres
