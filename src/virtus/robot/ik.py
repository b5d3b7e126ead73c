"""Inverse kinematics: joint values that put a link at a target pose.

Multi-start Levenberg-Marquardt on the SE(3) error, all starts of a batch iterated together
(numpy): the error is ``e = (p* - p, w * log(R* R^T))`` in the base frame (metres; the
rotation vector in radians scaled by :data:`ROTATION_WEIGHT_M` metres per radian), the step
``dq = J^T (J J^T + lambda I)^-1 e`` with the geometric Jacobian, ``lambda`` adapted per start
(accepted step: /3; rejected: x4), ``q`` projected onto the joint limits after each step.
A start counts when it reaches the tolerances *and* the configuration is free of
self-collision (:meth:`virtus.robot.model.Robot.in_collision`). The first start is the
caller's ``q0`` (if any), the rest are drawn within the limits from the seeded ``rng``, so
the result is deterministic. Among the starts that count, the one nearest ``q0`` (or the
first) is returned.

A target that no start reaches raises :class:`Unreachable`, which carries the nearest pose
found (collision-free) and its position and rotation distance to the target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from virtus.errors import InputError, VirtusError
from virtus.robot.model import Robot

__all__ = ["IKResult", "Unreachable", "pose_error", "solve_ik"]

#: Metres per radian in the error that is minimised (about the arm's reach / 3).
ROTATION_WEIGHT_M = 0.3
#: Default tolerances: position (m) and rotation (rad) -- far below the metrology's needs.
TOL_M = 1e-9
TOL_RAD = 1e-9


class Unreachable(VirtusError, ValueError):
    """No collision-free configuration within the limits reaches the target.

    Attributes
    ----------
    nearest_q : (dof,) the best configuration found (within limits, collision-free).
    nearest_pose : (4, 4) its ``link2base``.
    position_error_m, rotation_error_rad : its distance to the target.
    """

    def __init__(
        self,
        link: str,
        nearest_q: np.ndarray,
        nearest_pose: np.ndarray,
        position_error_m: float,
        rotation_error_rad: float,
    ) -> None:
        self.nearest_q = nearest_q
        self.nearest_pose = nearest_pose
        self.position_error_m = position_error_m
        self.rotation_error_rad = rotation_error_rad
        super().__init__(
            f"target pose of {link} is unreachable: the nearest reachable pose is "
            f"{position_error_m * 1e3:.3f} mm and {np.degrees(rotation_error_rad):.3f} deg away "
            f"(q = {np.round(nearest_q, 4).tolist()})"
        )


@dataclass(frozen=True)
class IKResult:
    """A solution: ``q`` (dof,) rad/m, its ``link2base`` (4, 4), the remaining errors, the
    start that found it (0 = ``q0`` when given) and its iterations."""

    q: np.ndarray
    link2base: np.ndarray
    position_error_m: float
    rotation_error_rad: float
    start: int
    iterations: int


def pose_error(current: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (..., 3) m and rotation vector (..., 3) rad of ``target @ current^-1``
    (base frame), for poses (..., 4, 4)."""
    dp = target[..., :3, 3] - current[..., :3, 3]
    dR = target[..., :3, :3] @ np.swapaxes(current[..., :3, :3], -1, -2)  # noqa: N806
    shape = dR.shape[:-2]
    dr = Rotation.from_matrix(dR.reshape(-1, 3, 3)).as_rotvec().reshape(*shape, 3)
    return dp, dr


def solve_ik(
    robot: Robot,
    link: str,
    target: np.ndarray,
    *,
    q0: object | None = None,
    rng: np.random.Generator | int | None = 0,
    starts: int = 64,
    batch: int = 16,
    max_iter: int = 150,
    tol_m: float = TOL_M,
    tol_rad: float = TOL_RAD,
    check_collision: bool = True,
) -> IKResult:
    """Joint values putting ``link`` at ``target`` (``link2base``, (4, 4), metres).

    Parameters
    ----------
    robot : the robot; ``link`` one of its links.
    q0 : first start and preference (nearest solution wins), within the limits; optional.
    rng : seed of the other starts.
    starts, batch : starts in all, and how many are iterated together.
    max_iter : iterations per batch.
    tol_m, tol_rad : what counts as reached.
    check_collision : refuse self-colliding solutions.

    Raises
    ------
    Unreachable : no start reached the target (the nearest pose is in the error).
    InputError : a bad link, target or ``q0``.
    """
    tree = robot.tree
    tree.check_link(link)
    goal = np.asarray(target, dtype=np.float64)
    if goal.shape != (4, 4) or not np.all(np.isfinite(goal)):
        raise InputError("target", "a finite (4, 4) pose", np.shape(goal))
    generator = np.random.default_rng(rng)
    seeds = tree.random_q(generator, max(int(starts), 1))
    if q0 is not None:
        seeds[0] = tree.check_q(q0, "q0")
    lower = np.where(np.isfinite(tree.lower), tree.lower, -np.inf)
    upper = np.where(np.isfinite(tree.upper), tree.upper, np.inf)
    best: tuple[float, np.ndarray] | None = None
    for first in range(0, len(seeds), max(int(batch), 1)):
        q = seeds[first : first + batch].copy()
        live = np.ones(len(q), dtype=bool)  # starts still worth iterating
        used = np.zeros(len(q), dtype=np.int64)
        while True:
            q[live], its = _iterate(
                tree, link, goal, q[live], lower, upper, max_iter - int(used.max()), tol_m, tol_rad
            )
            used[live] += its
            pose = tree.link_pose(q, link)
            dp, dr = pose_error(pose, goal)
            ep, er = np.linalg.norm(dp, axis=-1), np.linalg.norm(dr, axis=-1)
            free = ~robot.in_collision(q) if check_collision else np.ones(len(q), bool)
            reached = (ep <= tol_m) & (er <= tol_rad)
            ok = reached & free
            if np.any(ok):
                index = np.flatnonzero(ok)
                if q0 is not None:
                    order = np.argsort(np.abs(q[index] - seeds[0]).sum(axis=1), kind="stable")
                    index = index[order]
                k = int(index[0])
                return IKResult(q[k], pose[k], float(ep[k]), float(er[k]), first + k, int(used[k]))
            live &= ~reached  # reached but colliding: that start is spent
            if not np.any(live) or used.max() >= max_iter:
                break
        cost = np.where(free, ep + ROTATION_WEIGHT_M * er, np.inf)
        k = int(np.argmin(cost))
        if np.isfinite(cost[k]) and (best is None or cost[k] < best[0]):
            best = (float(cost[k]), q[k].copy())
    if best is None:
        raise Unreachable(link, seeds[0], tree.link_pose(seeds[0], link), np.inf, np.inf)
    nearest = tree.link_pose(best[1], link)
    dp, dr = pose_error(nearest, goal)
    raise Unreachable(link, best[1], nearest, float(np.linalg.norm(dp)), float(np.linalg.norm(dr)))


def _iterate(tree, link, goal, q, lower, upper, max_iter, tol_m, tol_rad):  # noqa: ANN001, ANN202
    """LM iterations of a batch of starts ``q`` (S, dof) until one of them reaches the
    tolerances or ``max_iter`` have run; returns (q, iterations used)."""
    weight = np.array([1.0, 1.0, 1.0, ROTATION_WEIGHT_M, ROTATION_WEIGHT_M, ROTATION_WEIGHT_M])
    damping = np.full(len(q), 1e-3)
    iterations = np.zeros(len(q), dtype=np.int64)

    def error(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dp, dr = pose_error(pose, goal)
        done = (np.linalg.norm(dp, axis=-1) <= tol_m) & (np.linalg.norm(dr, axis=-1) <= tol_rad)
        return np.concatenate([dp, dr], axis=-1) * weight, done

    pose, J = tree.jacobian(q, link)  # noqa: N806
    e, done = error(pose)
    for _ in range(max(max_iter, 0)):
        if np.any(done):
            break
        active = ~done
        Jw = J[active] * weight[:, None]  # noqa: N806
        A = Jw @ np.swapaxes(Jw, -1, -2) + damping[active, None, None] * np.eye(6)  # noqa: N806
        step = np.einsum(
            "sij,sj->si", np.swapaxes(Jw, -1, -2), np.linalg.solve(A, e[active][..., None])[..., 0]
        )
        trial = np.clip(q[active] + step, lower, upper)
        t_pose, t_J = tree.jacobian(trial, link)  # noqa: N806
        t_e, t_done = error(t_pose)
        better = np.linalg.norm(t_e, axis=-1) < np.linalg.norm(e[active], axis=-1)
        idx = np.flatnonzero(active)
        take = idx[better]
        q[take], J[take], e[take] = trial[better], t_J[better], t_e[better]
        done[take] = t_done[better]
        damping[take] = np.maximum(damping[take] / 3.0, 1e-12)
        damping[idx[~better]] = np.minimum(damping[idx[~better]] * 4.0, 1e6)
        iterations[idx] += 1
    return q, iterations
