"""View-to-view registration of a robot scan's clouds: no mesh needed.

A real robot scan has no mesh to register onto. Its views are placed in the world by the
arm's kinematics (off by the joints' errors) and overlap; point-to-plane ICP of each view
onto the merged cloud of the views before it takes out their misplacement relative to each
other (Chen and Medioni, 1992; the linearised small-angle step of Low, 2004):

1. The views are taken in scan order. The first is the reference; each next view, cropped
   to the region of interest and sub-sampled (seeded), is paired with its nearest reference
   points (``scipy.spatial.cKDTree``) and moved by the rigid motion minimising the
   point-to-plane distances, whose normals come from a plane fitted to each reference
   point's ``neighbours`` nearest reference points (PCA). Pairs farther apart than three
   times the median pair distance (clipped to ``[min_distance_m, max_distance_m]``) are left
   out at each iteration. The registered view then joins the reference.
2. **Anchor.** Registration fixes the views relative to each other, not where the whole
   cloud lies: chaining onto the first view would leave all of them as far off as that
   view's kinematics. With ``anchor="kinematics"`` (the default) the registered cloud is
   moved, as one rigid body, onto the kinematic placement of the same points (Kabsch), so
   the independent per-view errors of the arm average out instead of the first one
   standing for all. ``anchor="first"`` keeps the first view where kinematics put it.

Deterministic: the sub-samples are drawn from ``numpy.random.default_rng(seed)``; the rest
is exact arithmetic in a fixed order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from virtus.errors import InputError
from virtus.geometry.transforms import Pose

__all__ = ["ViewRegistration", "register_views"]

#: Points of each view used to register it (a seeded sub-sample of the view).
VIEW_POINTS = 20_000
#: Largest reference (merged-so-far) cloud; larger ones are sub-sampled, seeded.
REFERENCE_POINTS = 200_000
#: Fewest pairs a view is registered with; with fewer it keeps its kinematic placement.
MIN_PAIRS = 50


@dataclass(frozen=True)
class ViewRegistration:
    """Outcome of :func:`register_views`.

    Attributes
    ----------
    corrections : one world-to-world pose per view: ``corrections[k].apply(cloud_k)`` is
        view ``k`` registered.
    rms_m : per view, RMS point-to-plane distance of its kept pairs after registration
        (0 for the reference, the first view with points in the region; NaN for a view left
        where kinematics put it: too few points or pairs).
    pairs : per view, pairs kept in the last iteration (0: not registered).
    iterations : per view, ICP iterations run.
    """

    corrections: list[Pose]
    rms_m: list[float]
    pairs: list[int]
    iterations: list[int]

    def to_dict(self) -> dict:
        """JSON-ready record (poses as their dicts, distances in mm)."""
        return {
            "corrections": [c.to_dict() for c in self.corrections],
            "rms_mm": [r * 1e3 for r in self.rms_m],
            "pairs": list(self.pairs),
            "iterations": list(self.iterations),
        }


def register_views(
    clouds: list[np.ndarray],
    *,
    region: tuple[np.ndarray, np.ndarray] | None = None,
    max_distance_m: float = 2e-3,
    min_distance_m: float = 5e-5,
    iterations: int = 40,
    neighbours: int = 12,
    view_points: int = VIEW_POINTS,
    reference_points: int = REFERENCE_POINTS,
    anchor: str = "kinematics",
    seed: int = 0,
) -> ViewRegistration:
    """Register overlapping views (world frame, metres) onto each other (module docs).

    Parameters
    ----------
    clouds : per view, (N_k, 3) points in the world as kinematics placed them.
    region : (low, high) corners of the box (world, metres) whose points are registered
        (the scanned object's working volume, e.g. the floor left out); all points if None.
    max_distance_m, min_distance_m : bounds of the pair rejection distance.
    iterations : most ICP iterations per view (stops earlier when a step moves the view by
        less than 1e-9 m or rad).
    neighbours : reference points of each normal's plane fit.
    view_points, reference_points : sub-sample sizes (seeded).
    anchor : ``"kinematics"`` or ``"first"`` (module docs).
    seed : seed of the sub-samples.
    """
    if anchor not in ("kinematics", "first"):
        raise InputError("anchor", "'kinematics' or 'first'", anchor)
    if not 0 < float(min_distance_m) <= float(max_distance_m):
        raise InputError("max_distance_m", "0 < min_distance_m <= max_distance_m", max_distance_m)
    if not 3 <= int(neighbours) <= 100:
        raise InputError("neighbours", "3 to 100 points", neighbours)
    rng = np.random.default_rng([int(seed), 2104])
    if not clouds:
        raise InputError("clouds", "at least one view", "none")
    views = [_subsample(_crop(np.asarray(c, np.float64), region), view_points, rng)
             for c in clouds]  # fmt: skip
    corrections, rms, pairs, runs = [], [], [], []
    reference = np.zeros((0, 3))
    for view in views:
        found = None
        if len(reference) >= int(neighbours) and len(view) >= MIN_PAIRS:
            tree, normals = _reference(reference, int(neighbours), reference_points, rng)
            found = _icp(view, tree, normals, max_distance_m, min_distance_m, iterations)
        # the first view with points is the reference; a view without enough points or
        # pairs (it misses the region, or overlaps nothing yet) stays where kinematics put it
        motion, r, n, i = found or (np.eye(4), 0.0 if not len(reference) else np.nan, 0, 0)
        corrections.append(Pose.from_matrix(motion))
        rms.append(r)
        pairs.append(n)
        runs.append(i)
        reference = np.concatenate([reference, _apply(motion, view)])
    if anchor == "kinematics":
        placed = np.concatenate(views)
        moved = np.concatenate([c.apply(v) for c, v in zip(corrections, views, strict=True)])
        back = Pose.from_matrix(_kabsch(moved, placed))
        corrections = [back @ c for c in corrections]
    return ViewRegistration(corrections, rms, pairs, runs)


def _crop(points: np.ndarray, region: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    points = points[np.all(np.isfinite(points), axis=1)]
    if region is None:
        return points
    low, high = (np.asarray(c, np.float64) for c in region)
    return points[np.all((points >= low) & (points <= high), axis=1)]


def _subsample(points: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    if len(points) <= count:
        return points
    return points[np.sort(rng.choice(len(points), size=int(count), replace=False))]


def _reference(points: np.ndarray, neighbours: int, limit: int, rng: np.random.Generator):  # noqa: ANN202
    """k-d tree of the reference (sub-sampled to ``limit``) and its PCA normals."""
    from scipy.spatial import cKDTree

    ref = _subsample(points, limit, rng)
    tree = cKDTree(ref)
    _, index = tree.query(ref, k=min(neighbours, len(ref)))
    local = ref[index] - ref[index].mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", local, local))
    return tree, vectors[:, :, 0]  # the direction of least spread


def _apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _icp(source, tree, normals, max_distance, min_distance, iterations):  # noqa: ANN001, ANN202
    """Point-to-plane ICP of ``source`` onto the reference: (4x4 motion, RMS, pairs, its),
    or None when fewer than :data:`MIN_PAIRS` points have a reference point within reach."""
    from scipy.spatial.transform import Rotation

    motion = np.eye(4)
    ref = tree.data
    rms, kept, done = 0.0, 0, 0
    for done in range(1, int(iterations) + 1):  # noqa: B007 - the count is reported
        moved = _apply(motion, source)
        distance, index = tree.query(moved, k=1, distance_upper_bound=max_distance)
        ok = np.isfinite(distance)
        if ok.sum() < MIN_PAIRS:
            return None
        limit = float(np.clip(3.0 * np.median(distance[ok]), min_distance, max_distance))
        ok &= distance <= limit
        p, q, n = moved[ok], ref[index[ok]], normals[index[ok]]
        centre = p.mean(axis=0)
        a = np.hstack([np.cross(p - centre, n), n])
        b = -np.einsum("ij,ij->i", p - q, n)
        step, *_ = np.linalg.lstsq(a, b, rcond=None)
        update = np.eye(4)
        update[:3, :3] = Rotation.from_rotvec(step[:3]).as_matrix()
        update[:3, 3] = centre + step[3:] - update[:3, :3] @ centre
        motion = update @ motion
        residual = np.einsum("ij,ij->i", _apply(update, p) - q, n)
        rms, kept = float(np.sqrt(np.mean(residual**2))), int(ok.sum())
        if np.abs(step).max() < 1e-9:
            break
    return motion, rms, kept, done


def _kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """4x4 rigid motion taking ``source`` points onto their ``target`` points (least squares)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = np.linalg.svd((source - cs).T @ (target - ct))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = ct - rotation @ cs
    return out
