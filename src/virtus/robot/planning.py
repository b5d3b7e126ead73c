"""View planning for fringe projection from a robot: coverage, greedy selection, trajectories.

A surface point counts as **covered** by a view only when (DESIGN 13)

* the camera sees it: in front of the camera, inside its image, the segment from the point
  to the camera's centre free of any surface (the object, the rest of the scene and the
  robot's own links at that configuration), at an incidence angle (between the surface
  normal and the direction to the camera) of at most ``max_incidence_deg``;
* the projector lights it: the same four tests for the projector;
* its camera depth is within the rig's depth of field ``depth_range_m``.

Visibility is ray casting (Mitsuba's ``ray_test``, :class:`Occluders`), not rendering: a
view of a few thousand sample points costs milliseconds; the projector's rays are cast
only for the points the camera sees in focus. Candidate views lie on a sphere cap around
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

from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.geometry.transforms import Pose
from virtus.io.runs import write_json_atomic
from virtus.io.safeio import check_keys, read_json
from virtus.robot.config import RobotSetup
from virtus.robot.ik import Unreachable

__all__ = [
    "TRAJECTORY_FORMAT",
    "CoverageSettings",
    "Occluders",
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
    occluders: Occluders | None,
    settings: CoverageSettings,
    among: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(visible mask, depth along the device's axis) of ``points`` from one device; only
    the points of ``among`` (bool mask) are ray cast (the others are reported unseen)."""
    local = device2world.inverse().apply(points)
    depth = local[:, 2]
    ok = depth > 1e-6
    if among is not None:
        ok &= among
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
        origins = points[index] + normals[index] * settings.offset_m
        blocked = occluders.blocked(
            origins, direction[index], distance[index] - 2 * settings.offset_m
        )
        ok[index[blocked]] = False
    return ok, depth


class Occluders:
    """Surfaces that block rays: trimesh meshes (world, metres) in one Mitsuba scene, cast
    with ``ray_test`` (the renderer's own ray tracer, CPU or GPU, :func:`virtus.render.
    backend.mitsuba`). trimesh's own casting needs Embree (``embreex``) to be fast; through
    ``rtree`` a ray costs ~0.5 ms (measured on 2 CPU cores against the free-form object:
    planning 48 candidates took 88 s through rtree, 16 s through Embree)."""

    def __init__(self, meshes: list[Any]) -> None:
        from virtus.render.backend import mitsuba

        mi, dr, _ = mitsuba()
        self._mi, self._dr = mi, dr
        shapes: dict[str, Any] = {"type": "scene"}
        for k, mesh in enumerate(m for m in meshes if m is not None and len(m.faces)):
            vertices = np.asarray(mesh.vertices, dtype=np.float32)
            faces = np.asarray(mesh.faces, dtype=np.uint32)
            shape = mi.Mesh(f"occluder_{k}", vertex_count=len(vertices),
                            face_count=len(faces), has_vertex_normals=False)  # fmt: skip
            params = mi.traverse(shape)
            params["vertex_positions"] = dr.ravel(mi.Point3f(*vertices.T))
            params["faces"] = dr.ravel(mi.Vector3u(*faces.T))
            params.update()
            shapes[f"occluder_{k}"] = shape
        self._scene = mi.load_dict(shapes)

    def blocked(
        self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray
    ) -> np.ndarray:
        """(N,) bool: whether a surface lies on each segment ``origin + t direction``,
        ``0 < t < length`` (unit directions, metres)."""
        mi = self._mi
        if not len(origins):
            return np.zeros(0, dtype=bool)
        ray = mi.Ray3f(
            mi.Point3f(*np.asarray(origins, np.float32).T),
            mi.Vector3f(*np.asarray(directions, np.float32).T),
        )
        ray.maxt = mi.Float(np.maximum(np.asarray(lengths, np.float32), 0.0))
        return np.asarray(self._scene.ray_test(ray), dtype=bool)


def _as_occluders(occluders: Any) -> Occluders | None:
    if occluders is None or isinstance(occluders, Occluders):
        return occluders
    return Occluders(list(occluders) if isinstance(occluders, list | tuple) else [occluders])


def view_coverage(
    rig: Rig,
    cam2world: Pose,
    points: np.ndarray,
    normals: np.ndarray,
    occluders: Any,
    settings: CoverageSettings | None = None,
) -> np.ndarray:
    """(N,) bool: the points (world, metres) that the view ``cam2world`` measures (seen by
    the camera, lit by the projector, in focus; see the module docs). ``occluders``: a
    trimesh of every surface in the world (the object included), a list of such meshes,
    an :class:`Occluders` of them, or None."""
    settings = settings or CoverageSettings()
    occluders = _as_occluders(occluders)
    proj2world = cam2world @ rig.proj2cam
    near, far = settings.depth_range_m
    local_depth = cam2world.inverse().apply(points)[:, 2]
    in_focus = (local_depth >= near) & (local_depth <= far)
    # the camera's rays first, the projector's only for what the camera sees in focus
    cam_ok, depth = _sees(
        cam2world.t, cam2world, rig.camera.intrinsics, points, normals, occluders, settings,
        in_focus,
    )  # fmt: skip
    proj_ok, _ = _sees(
        proj2world.t, proj2world, rig.projector.intrinsics, points, normals, occluders,
        settings, cam_ok,
    )  # fmt: skip
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
        occluders = Occluders([*scene_parts, *setup.scene_meshes(q)])
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
