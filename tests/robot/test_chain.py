"""Kinematic trees: Jacobians against finite differences, limits, links."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tolerances import JACOBIAN_FD
from virtus.errors import InputError
from virtus.robot.chain import Joint, KinematicTree
from virtus.robot.panda import panda_tree


def _fd_jacobian(tree: KinematicTree, q: np.ndarray, link: str, h: float = 1e-6) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    J = np.zeros((6, tree.dof))  # noqa: N806
    for i in range(tree.dof):
        dq = np.zeros(tree.dof)
        dq[i] = h
        plus, minus = tree.link_pose(q + dq, link), tree.link_pose(q - dq, link)
        J[:3, i] = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
        J[3:, i] = Rotation.from_matrix(plus[:3, :3] @ minus[:3, :3].T).as_rotvec() / (2 * h)
    return J


@pytest.mark.parametrize("link", ["panda_link4", "panda_hand_tcp"])
def test_jacobian_matches_finite_differences(link: str) -> None:
    tree = panda_tree()
    rng = np.random.default_rng(3)
    for q in tree.random_q(rng, 5):
        _, J = tree.jacobian(q, link)  # noqa: N806
        np.testing.assert_allclose(J, _fd_jacobian(tree, q, link), atol=JACOBIAN_FD)
    # joints after the link do not move it
    _, J = tree.jacobian(tree.random_q(rng, 1)[0], "panda_link4")  # noqa: N806
    assert np.all(J[:, 4:] == 0)


def test_prismatic_joint_and_batched_fk() -> None:
    slide = Joint("slide", "prismatic", "base", "carriage", np.eye(4), (1.0, 0.0, 0.0), 0.0, 1.0)
    turn = np.eye(4)
    turn[2, 3] = 0.5
    spin = Joint("spin", "revolute", "carriage", "arm", turn, (0.0, 0.0, 1.0), -3.0, 3.0)
    tree = KinematicTree("toy", [spin, slide])  # any order: parents sorted first
    assert tree.joint_names == ("slide", "spin")
    q = np.array([[0.25, 0.0], [0.5, np.pi / 2]])
    arm = tree.fk(q)["arm"]
    np.testing.assert_allclose(arm[:, :3, 3], [[0.25, 0.0, 0.5], [0.5, 0.0, 0.5]])
    np.testing.assert_allclose(arm[1, :3, 0], [0.0, 1.0, 0.0], atol=1e-15)
    _, J = tree.jacobian(q[1], "arm")  # noqa: N806
    np.testing.assert_allclose(J[:, 0], [1, 0, 0, 0, 0, 0])


def test_limits_and_links_are_checked() -> None:
    tree = panda_tree()
    with pytest.raises(InputError, match=r"q joint panda_joint4: expected a value within"):
        tree.check_q([0, 0, 0, 0.5, 0, 1, 0])
    with pytest.raises(InputError, match=r"7 joint values"):
        tree.check_q([0, 0, 0])
    with pytest.raises(InputError, match=r"link: expected a link of panda .* got 'tool0'"):
        tree.check_link("tool0")
    with pytest.raises(InputError, match="one root link"):
        KinematicTree(
            "two",
            [Joint("a", "fixed", "x", "y", np.eye(4)), Joint("b", "fixed", "u", "v", np.eye(4))],
        )
