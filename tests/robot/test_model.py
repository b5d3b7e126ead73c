"""Robots: which capsule pairs the self-collision check looks at."""

from __future__ import annotations

import numpy as np

from virtus.robot.model import MIN_JOINTS_APART, builtin_robot


def test_only_bodies_three_joints_apart_are_checked() -> None:
    robot = builtin_robot("panda")
    links = [c.link for c in robot.capsules]
    index = {f"panda_link{i}": i for i in range(9)} | {"panda_hand": 7}  # hand rides link 7
    apart = [abs(index[links[i]] - index[links[j]]) for i, j in robot.collision_pairs]
    assert min(apart) == MIN_JOINTS_APART
    expected = sum(
        1
        for i in range(len(links))
        for j in range(i + 1, len(links))
        if abs(index[links[i]] - index[links[j]]) >= MIN_JOINTS_APART
    )
    assert len(robot.collision_pairs) == expected


def test_clearance_is_batched_and_signed() -> None:
    robot = builtin_robot("panda")
    q = robot.tree.random_q(np.random.default_rng(0), 50)
    batch = robot.clearance(q)
    one = np.array([robot.clearance(row) for row in q])
    np.testing.assert_allclose(batch, one)
    assert np.all(robot.in_collision(q) == (batch < 0))
