"""View planning for fringe projection from a robot: coverage, greedy selection, trajectories.

A surface point counts as **covered** by a view only when (DESIGN 13)

* the camera sees it: in front of the camera, inside its image, the segment from the point
  to the camera's centre free of any surface (the object, the rest of the scene and the
  robot's own links at that configuration), at an incidence angle (between the surface
  normal and the direction to the camera) of at most ``max_incidence_deg``;
* the projector lights it: the same four tests for the projector;
* its camera depth is within the rig's depth of field ``depth_range_m``.

Visibility is ray casting with trimesh (Embree when installed), not rendering: a view of a
few thousand sample points costs milliseconds. Candidate views lie on a sphere cap around
the object at the working distance, looking at its centre; each is kept only when inverse
kinematics reaches it without self-collision and with every link clear of the scene's
bounding boxes' floor (links above ``floor_z_m``). Greedy maximum coverage then picks views
one at a time, each adding the most uncovered points (within ``1 - 1/e`` of the best set of
that size). The denominator of the coverage is the points some candidate view covers (the
*measurable* surface): points no reachable view can measure are reported apart.

A trajectory file (JSON, :func:`save_trajectory`) holds the joint names, units and one row
of joint values per view, plus each view's ``cam2world`` for reference.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, MissingDependency
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.runs import write_json_atomic
from virtus.io.safeio import check_keys, read_json
from virtus.robot.config import RobotSetup
from virtus.robot.ik import Unreachable

__all__ = [
    "TRAJECTORY_FORMAT",
    "CoverageSettings",
    "ViewPlan",
    "candidate_views",
    "load_trajectory",
    "plan_views",
    "save_trajectory",
    "surface_samples",
    "view_coverage",
]

TRAJECTORY_FORMAT = "virtus.trajectory/1"
#: Most views a trajectory file or a plan may hold.
MAX_VIEWS = 10_000


@dataclass(frozen=True)
class CoverageSettings:
    """What counts as measured (see the module docs)."""

    max_incidence_deg: float = 70.0
    """Largest angle between the surface normal and the direction to either device."""
    depth_range_m: tuple[float, float] = (0.8, 1.2)
    """Camera depths in focus (the rig's depth of field), metres."""
    offset_m: float = 1e-4
    """Rays start this far off the surface (metres) so they do not hit their own face."""

    def __post_init__(self) -> None:
        if not 0 < self.max_incidence_deg < 90:
            raise InputError("max_incidence_deg", "an angle in (0, 90) deg", self.max_incidence_deg)
        low, high = self.depth_range_m
        if not 0 < low < high:
            raise InputError("depth_range_m", "0 < near < far (m)", self.depth_range_m)


def surface_samples(mesh: Any, count: int, rng: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``count`` area-uniform points (N, 3) and their unit normals (N, 3) on ``mesh``
    (trimesh, metres), seeded."""
    import trimesh

    if not 1 <= int(count) <= 1_000_000:
        raise InputError("samples", "1 to 1,000,000 points", count)
    points, faces = trimesh.sample.sample_surface(mesh, int(count), seed=int(rng))
    return np.asarray(points, np.float64), np.asarray(mesh.face_normals[faces], np.float64)


def _sees(
    centre: np.ndarray,
    device2world: Pose,
    intrinsics: Any,
    points: np.ndarray,
    normals: np.ndarray,
    occluders: Any,
    settings: CoverageSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """(visible mask, depth along the device's axis) of ``points`` from one device."""
    local = device2world.inverse().apply(points)
    depth = local[:, 2]
    ok = depth > 1e-6
    pixels = intrinsics.project(np.where(ok[:, None], local, [0.0, 0.0, 1.0]))
    width, height = intrinsics.size
    ok &= (pixels[:, 0] >= -0.5) & (pixels[:, 0] <= width - 0.5)
    ok &= (pixels[:, 1] >= -0.5) & (pixels[:, 1] <= height - 0.5)
    to_device = centre - points
    distance = np.linalg.norm(to_device, axis=1)
    direction = to_device / distance[:, None]
    cos_limit = np.cos(np.radians(settings.max_incidence_deg))
    ok &= np.einsum("ij,ij->i", direction, normals) >= cos_limit
    index = np.flatnonzero(ok)
    if index.size and occluders is not None:
        _require_ray_index()
        origins = points[index] + normals[index] * settings.offset_m
        hits, rays = occluders.ray.intersects_location(
            origins, direction[index], multiple_hits=False
        )[:2]
        if len(rays):
            along = np.linalg.norm(hits - origins[rays], axis=1)
            blocked = rays[along < distance[index[rays]] - settings.offset_m]
            ok[index[blocked]] = False
    return ok, depth


def _require_ray_index() -> None:
    """trimesh casts rays through Embree (``embreex``) or an R-tree (``rtree``); with neither
    it fails deep inside with a bare ``ModuleNotFoundError`` (seen on a GPU host)."""
    import importlib.util

    if not any(importlib.util.find_spec(name) for name in ("embreex", "rtree")):
        raise MissingDependency(
            "view planning casts rays with trimesh, which needs rtree or embreex: "
            "pip install 'virtus-fpp[robot]'"
        )


def view_coverage(
    rig: Rig,
    cam2world: Pose,
    points: np.ndarray,
    normals: np.ndarray,
    occluders: Any,
    settings: CoverageSettings | None = None,
) -> np.ndarray:
    """(N,) bool: the points (world, metres) that the view ``cam2world`` measures (seen by
    the camera, lit by the projector, in focus; see the module docs). ``occluders``: one
    trimesh of every surface in the world (the object included), or None."""
    settings = settings or CoverageSettings()
    proj2world = cam2world @ rig.proj2cam
    cam_ok, depth = _sees(
        cam2world.t, cam2world, rig.camera.intrinsics, points, normals, occluders, settings
    )
    proj_ok, _ = _sees(
        proj2world.t, proj2world, rig.projector.intrinsics, points, normals, occluders, settings
    )
    near, far = settings.depth_range_m
    return cam_ok & proj_ok & (depth >= near) & (depth <= far)


def candidate_views(
    centre: object,
    distance_m: float,
    count: int,
    *,
    max_polar_deg: float = 60.0,
    up: object = (0.0, 0.0, 1.0),
) -> list[Pose]:
    """``count`` camera poses on a spherical cap of radius ``distance_m`` around ``centre``
    (world, metres), within ``max_polar_deg`` of ``up``, each looking at ``centre`` (a
    Fibonacci spiral: near-uniform spacing; deterministic)."""
    if not 1 <= int(count) <= MAX_VIEWS:
        raise InputError("candidates", f"1 to {MAX_VIEWS} views", count)
    c = np.asarray(centre, dtype=np.float64)
    z = np.asarray(up, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    cos_min = np.cos(np.radians(max_polar_deg))
    golden = np.pi * (3.0 - np.sqrt(5.0))
    views = []
    for i in range(int(count)):
        cos_t = 1.0 - (i + 0.5) / count * (1.0 - cos_min)
        sin_t = np.sqrt(max(1.0 - cos_t**2, 0.0))
        phi = golden * i
        d = cos_t * z + sin_t * (np.cos(phi) * x + np.sin(phi) * y)
        eye = c + distance_m * d
        # image "down" along -up (the picture upright as the camera circles), x at the pole
        views.append(Pose.look_at(eye, c, image_down=x if sin_t < 1e-9 else -z))
    return views


@dataclass
class ViewPlan:
    """A planned scan: the chosen views and what they cover.

    Attributes
    ----------
    q : (V, dof) joint values, rad/m, in scan order.
    cam2world : the views' camera poses.
    coverage : coverage of the measurable surface after each view (V,), share in [0, 1].
    measurable_share : share of the surface samples any reachable candidate measures.
    candidates, reachable : candidate views tried, and those IK reached collision-free.
    """

    q: np.ndarray
    cam2world: list[Pose]
    coverage: np.ndarray
    measurable_share: float
    candidates: int
    reachable: int
    notes: dict[str, Any] = field(default_factory=dict)


def _floor_clear(setup: RobotSetup, q: np.ndarray, floor_z_m: float) -> bool:
    poses = setup.robot.tree.fk(q)
    base = setup.base2world.matrix
    for capsule in setup.robot.capsules:
        if capsule.link == setup.robot.tree.root:
            continue  # the base stands on its mount
        a, b = capsule.ends_world(base @ poses[capsule.link])
        if min(a[2], b[2]) - capsule.radius < floor_z_m:
            return False
    return True


#: Turns of the camera about its axis tried for a candidate view (deg): coverage does not
#: care which way the picture is up, the arm often does.
ROLLS_DEG = (0.0, 180.0, 90.0, 270.0)


def _reach(
    setup: RobotSetup, view: Pose, rng: int, starts: int, floor: float
) -> tuple[np.ndarray, Pose] | None:
    """(q, cam2world) of the first roll of ``view`` the robot reaches clear of the floor."""
    for roll in ROLLS_DEG:
        cam2world = view @ Pose.from_euler("z", [roll])
        try:
            q = setup.solve_view(cam2world, rng=rng, starts=starts, batch=8, max_iter=80).q
        except Unreachable:
            continue
        if _floor_clear(setup, q, floor):
            return q, cam2world
    return None


def plan_views(
    setup: RobotSetup,
    rig: Rig,
    target: Any,
    views: int,
    *,
    environment: Any = None,
    candidates: int = 48,
    samples: int = 3000,
    settings: CoverageSettings | None = None,
    distance_m: float = 1.0,
    max_polar_deg: float = 60.0,
    floor_z_m: float | None = None,
    ik_starts: int = 8,
    rng: int = 0,
) -> ViewPlan:
    """Plan at most ``views`` views of ``target`` (a trimesh in the world, metres).

    ``environment``: the other surfaces (trimesh, world) that occlude; the robot's links
    at each candidate's configuration occlude too. ``floor_z_m``: lowest world z a link may
    reach (default: the lowest point of target and environment). Deterministic for a seed.
    """
    import trimesh

    if not 1 <= int(views) <= MAX_VIEWS:
        raise InputError("--plan", f"1 to {MAX_VIEWS} views", views)
    settings = settings or CoverageSettings()
    points, normals = surface_samples(target, samples, rng)
    scene_parts = [target] + ([environment] if environment is not None else [])
    floor = (
        float(min(m.bounds[0][2] for m in scene_parts)) if floor_z_m is None else float(floor_z_m)
    )
    centre = target.bounds.mean(axis=0)
    qs, poses, masks = [], [], []
    tried = candidate_views(centre, distance_m, candidates, max_polar_deg=max_polar_deg)
    for k, view in enumerate(tried):
        found = _reach(setup, view, rng + k, ik_starts, floor)
        if found is None:
            continue
        q, cam2world = found
        occluders = trimesh.util.concatenate([*scene_parts, *setup.scene_meshes(q)])
        qs.append(q)
        poses.append(cam2world)
        masks.append(view_coverage(rig, cam2world, points, normals, occluders, settings))
    if not masks:
        raise InputError("plan", "at least one candidate view the robot reaches", "none")
    covered_by = np.array(masks)
    measurable = covered_by.any(axis=0)
    chosen: list[int] = []
    covered = np.zeros(len(points), dtype=bool)
    shares = []
    for _ in range(min(int(views), len(masks))):
        gain = (covered_by & ~covered).sum(axis=1)
        gain[chosen] = -1
        best = int(np.argmax(gain))
        if gain[best] <= 0:
            break
        chosen.append(best)
        covered |= covered_by[best]
        shares.append(covered.sum() / max(measurable.sum(), 1))
    return ViewPlan(
        q=np.array([qs[i] for i in chosen]),
        cam2world=[poses[i] for i in chosen],
        coverage=np.array(shares),
        measurable_share=float(measurable.mean()),
        candidates=len(tried),
        reachable=len(masks),
    )


def save_trajectory(path: str | Path, setup: RobotSetup, q: np.ndarray) -> Path:
    """Write a trajectory file (see the module docs) for the joint values ``q`` (V, dof)."""
    values = setup.robot.tree.check_q(np.atleast_2d(q), "trajectory")
    data = {
        "format": TRAJECTORY_FORMAT,
        "units": "rad (revolute), m (prismatic); cam2world in m",
        "robot": setup.robot.tree.name,
        "joint_names": list(setup.robot.tree.joint_names),
        "q": values.tolist(),
        "cam2world": [setup.cam2world(v).to_dict() for v in values],
    }
    return write_json_atomic(path, data)


def load_trajectory(path: str | Path, setup: RobotSetup) -> np.ndarray:
    """The joint values (V, dof) of a trajectory file, checked against ``setup``'s robot:
    joint count (and names, when given) and limits."""
    data = read_json(path, "trajectory", expect=dict)
    check_keys(data, ("format", "units", "robot", "joint_names", "q", "cam2world"), "trajectory")
    if data.get("format", TRAJECTORY_FORMAT) != TRAJECTORY_FORMAT:
        raise InputError("trajectory format", TRAJECTORY_FORMAT, data.get("format"))
    tree = setup.robot.tree
    names = data.get("joint_names")
    if names is not None and list(names) != list(tree.joint_names):
        raise InputError("trajectory joint_names", f"{list(tree.joint_names)}", names)
    rows = data.get("q")
    if not isinstance(rows, list) or not rows or len(rows) > MAX_VIEWS:
        raise InputError("trajectory q", f"1 to {MAX_VIEWS} rows of joint values", rows)
    for i, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != tree.dof:
            got = len(row) if isinstance(row, list) else row
            raise InputError(f"trajectory q[{i}]", f"{tree.dof} joint values", got)
    return tree.check_q(np.array(rows, dtype=np.float64), "trajectory q")
