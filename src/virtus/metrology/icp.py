"""Point-to-plane ICP registration of a point cloud to a triangle mesh.

Each iteration pairs every cloud point with its exact closest point on the mesh
(:class:`~virtus.metrology.proximity.MeshIndex`) and minimises the squared distances to the
tangent planes there, linearised in a small rotation (Chen and Medioni, 1992; Low, 2004):
a 6x6 normal-equation solve per iteration. Pairs farther than ``max_distance`` are ignored,
which keeps background points and gross outliers out of the estimate.

The result is ``cloud2mesh``: the pose that maps cloud-frame points into the mesh frame
(``X_mesh = R @ X_cloud + t``), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from virtus.checks import as_points, as_rng, positive, positive_int
from virtus.errors import DegenerateData, InputError
from virtus.geometry.transforms import Pose
from virtus.metrology.proximity import ClosestPoints, MeshIndex

__all__ = ["IcpResult", "icp_to_mesh"]

#: After the first iteration, points farther than this many ``max_distance`` are dropped.
_KEEP_FACTOR = 4.0


@dataclass(frozen=True)
class IcpResult:
    """Result of :func:`icp_to_mesh`.

    Attributes
    ----------
    cloud2mesh : maps cloud-frame points into the mesh frame.
    rms : RMS point-to-plane distance of the used pairs at the end, metres.
    inlier_ratio : fraction of the (sub-sampled) points paired within ``max_distance``.
    iterations : iterations run.
    converged : the last update was below the tolerances.
    """

    cloud2mesh: Pose
    rms: float
    inlier_ratio: float
    iterations: int
    converged: bool


def icp_to_mesh(
    points: object,
    mesh: trimesh.Trimesh | MeshIndex,
    init: Pose | None = None,
    *,
    max_distance: float | None = None,
    max_iterations: int = 50,
    tol_translation: float = 1e-8,
    tol_rotation: float = 1e-8,
    tol_relative_rms: float = 1e-5,
    max_points: int | None = 20_000,
    rng: np.random.Generator | int | None = 0,
) -> IcpResult:
    """Register ``points`` to ``mesh`` by point-to-plane ICP.

    Parameters
    ----------
    points : (N, 3) float, metres, cloud frame (e.g. the camera frame), N >= 6.
    mesh : the reference surface in its own frame (metres), or a prepared :class:`MeshIndex`.
    init : initial ``cloud2mesh``; identity when None. ICP is local: the initial pose should
        put the cloud within a few millimetres and degrees of the mesh.
    max_distance : pairs farther apart than this (metres) are ignored; None uses every pair.
    max_iterations : iteration cap.
    tol_translation, tol_rotation : stop when an update moves less than these (metres,
        radians).
    tol_relative_rms : also stop when the RMS distance changes by less than this fraction
        between iterations (noisy clouds can creep along flat valleys of the cost).
    max_points : a random subset of this many points drives the registration (None: all).
    rng : random generator or seed for the subset.

    Returns
    -------
    :class:`IcpResult`.
    """
    pts = as_points("points", points, 3)
    if pts.shape[0] < 6:
        raise InputError("points", "at least 6 points", f"{pts.shape[0]} points")
    index = mesh if isinstance(mesh, MeshIndex) else MeshIndex(mesh)
    pose = Pose.identity() if init is None else init
    if not isinstance(pose, Pose):
        raise InputError("init", "a virtus.geometry.transforms.Pose (cloud2mesh) or None", init)
    if max_distance is not None:
        max_distance = positive("max_distance", max_distance)
    max_iterations = positive_int("max_iterations", max_iterations)
    tol_t = positive("tol_translation", tol_translation)
    tol_r = positive("tol_rotation", tol_rotation)
    tol_rms = positive("tol_relative_rms", tol_relative_rms)
    if max_points is not None:
        max_points = positive_int("max_points", max_points, minimum=6)
        if pts.shape[0] > max_points:
            pts = pts[as_rng(rng).choice(pts.shape[0], max_points, replace=False)]

    converged = False
    rms = np.nan
    ratio = 0.0
    iteration = 0
    for iteration in range(1, max_iterations + 1):  # noqa: B007 - reported below
        moved = pose.apply(pts)
        near = index.query(moved, exact=False)
        use = np.ones(len(pts), dtype=bool)
        if max_distance is not None:
            use = np.abs(near.distances) <= max_distance
        ratio = float(use.mean())
        if use.sum() < 6:
            raise DegenerateData(
                f"ICP: only {int(use.sum())} points within {max_distance} m of the mesh; "
                "is the initial pose close enough?"
            )
        if iteration == 1 and max_distance is not None:
            # Points far from the mesh (background, clutter) will not come within reach in
            # later small steps: drop them so they cost no further closest-point queries.
            near_enough = np.abs(near.distances) <= _KEEP_FACTOR * max_distance
            pts, moved, use = pts[near_enough], moved[near_enough], use[near_enough]
            near = _subset(near, near_enough)
        p, q, n = moved[use], near.points[use], near.normals[use]
        residual = np.einsum("ij,ij->i", p - q, n)
        previous, rms = rms, float(np.sqrt(np.mean(residual**2)))
        if abs(previous - rms) <= tol_rms * rms:
            converged = True
            break
        # Linearised update: rotation w (small angles) and translation v minimise
        # sum ((p + w x p + v - q) . n)^2 -> rows [p x n, n] . [w, v] = -(p - q) . n.
        # Centre p for conditioning (rotation about the centroid).
        centre = p.mean(axis=0)
        A = np.concatenate([np.cross(p - centre, n), n], axis=1)  # noqa: N806
        try:
            x = np.linalg.solve(A.T @ A, -A.T @ residual)
        except np.linalg.LinAlgError:
            raise DegenerateData(
                "ICP: the surface does not constrain all 6 degrees of freedom"
            ) from None
        w, v = x[:3], x[3:]
        rot = Rotation.from_rotvec(w).as_matrix()
        step = Pose(rot, centre + v - rot @ centre)
        pose = step @ pose
        if np.linalg.norm(w) < tol_r and np.linalg.norm(v) < tol_t:
            converged = True
            break
    return IcpResult(pose, rms, ratio, iteration, converged)


def _subset(near: ClosestPoints, keep: np.ndarray) -> ClosestPoints:
    return ClosestPoints(
        near.points[keep], near.distances[keep], near.faces[keep], near.normals[keep]
    )
