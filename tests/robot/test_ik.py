"""Inverse kinematics: reachable targets reached, unreachable ones refused with a distance."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tolerances import IK_POSITION_M, IK_ROTATION_RAD
from virtus.robot.ik import Unreachable, pose_error, solve_ik
from virtus.robot.model import builtin_robot
from virtus.robot.panda import PANDA_READY_Q


def test_ik_reaches_99_percent_of_200_random_reachable_targets() -> None:
    robot = builtin_robot("panda")
    tree = robot.tree
    q = tree.random_q(np.random.default_rng(2021), 400)
    q = q[~robot.in_collision(q)][:200]  # reachable: FK of collision-free configurations
    targets = tree.fk(q)["panda_hand"]
    reached = 0
    for k, target in enumerate(targets):
        try:
            result = solve_ik(robot, "panda_hand", target, rng=k)
        except Unreachable:
            continue
        dp, dr = pose_error(tree.link_pose(result.q, "panda_hand"), target)
        assert np.linalg.norm(dp) <= IK_POSITION_M and np.linalg.norm(dr) <= IK_ROTATION_RAD
        assert np.all(result.q >= tree.lower) and np.all(result.q <= tree.upper)
        assert not robot.in_collision(result.q)
        reached += 1
    assert reached >= 198


def test_ik_is_deterministic_and_prefers_the_given_start() -> None:
    robot = builtin_robot("panda")
    target = robot.tree.link_pose(PANDA_READY_Q, "panda_hand")
    first = solve_ik(robot, "panda_hand", target, rng=7)
    again = solve_ik(robot, "panda_hand", target, rng=7)
    np.testing.assert_array_equal(first.q, again.q)
    near = solve_ik(robot, "panda_hand", target, q0=PANDA_READY_Q + 0.05)
    # a 7-joint arm: the start slides along the self-motion to a nearby solution
    assert near.start == 0 and np.abs(near.q - PANDA_READY_Q).max() < 0.02


def test_unreachable_target_is_refused_with_the_nearest_pose() -> None:
    robot = builtin_robot("panda")
    target = np.eye(4)
    target[:3, 3] = (1.5, 0.0, 0.5)  # the Panda reaches 0.855 m from its shoulder
    with pytest.raises(Unreachable, match=r"unreachable: the nearest reachable pose is") as info:
        solve_ik(robot, "panda_hand", target, starts=16)
    error = info.value
    assert 0.4 < error.position_error_m < 0.8  # ~1.5 m - reach
    dp, _ = pose_error(error.nearest_pose, target)
    assert np.linalg.norm(dp) == pytest.approx(error.position_error_m)
    assert not robot.in_collision(error.nearest_q)
    robot.tree.check_q(error.nearest_q)
