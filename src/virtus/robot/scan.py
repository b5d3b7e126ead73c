"""The robot scan job (``virtus robot-scan``): views from the arm, merged by its kinematics.

For each configuration of a trajectory (a file, or a plan of N views by
:func:`virtus.robot.planning.plan_views`) the job renders the scene with the robot's links
in it and the rig at ``cam2world = base2world @ FK(q) @ cam2link``, decodes and
reconstructs the view (the scan job's :func:`virtus.pipeline.scan.scan_into`, resumable per
view), and maps the view's cloud into the world with the **reported** joint values
``q + noise`` (``joint_noise_rad``: one normal draw per joint and view, seeded, clipped to
the limits -- encoder and joint-offset errors of the arm). The clouds are merged and, by
default, registered **view to view** (``icp="views"``: point-to-plane ICP of each view onto
the merged cloud so far, :mod:`virtus.robot.registration`; what a real scan without a mesh
can do); ``icp="mesh"`` registers each view onto the scene's meshes instead (the registration
``virtus evaluate`` uses: an evaluation aid, it needs the truth), ``icp="none"`` skips it.
The merged clouds are measured against the scene's meshes: C2M **without** any
registration (kinematics alone), and after the ICP; coverage is the share of surface
samples with a merged point within ``coverage_radius_m``. ``progress`` receives one line
per stage (planning, each view, merge, ICP, C2M, coverage) with the seconds since the start.

Run directory (owned by the run, :func:`virtus.io.runs.claim_run`, command ``robot-scan``):

==========================  =====================================================
``trajectory.json``         the joint values scanned (:mod:`virtus.robot.planning`)
``views/NNN/``              one scan directory per view (capture, decoded,
                            reconstruction, ``points.ply`` in the camera frame); its
                            ``capture.json`` provenance holds the robot record
                            (``q`` rendered, ``q_reported``, poses)
``robot/view_NNN.stl``      the robot's links at that view (world frame, metres)
``merged.ply``              merged cloud, world frame, metres, kinematics alone
``merged_icp.ply``          merged cloud after the ICP (unless ``icp="none"``)
``robot_scan.json``         per-view poses and counts, C2M (mm) and coverage
==========================  =====================================================

Built-in scene ``freeform``: the free-form object (0.1 m) with its centre at
:data:`FREEFORM_CENTRE_M` in the world, 5 cm above a floor plane at z = 0 (so the floor's
points stay out of the object's box); the robot file places the robot in that world.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.robot.capture import scene_with_robot
from virtus.robot.config import RobotSetup
from virtus.robot.planning import (
    MAX_VIEWS,
    CoverageSettings,
    load_trajectory,
    plan_views,
    save_trajectory,
    surface_samples,
    view_coverage,
)

__all__ = [
    "COMMAND",
    "FREEFORM_CENTRE_M",
    "ICP_MODES",
    "MergedViews",
    "RobotScanResult",
    "merge_views",
    "reported_joints",
    "robot_scan",
]

COMMAND = "robot-scan"
#: The free-form object's centre in the robot scan's built-in world (metres, z up).
FREEFORM_CENTRE_M = (0.5, 0.0, 0.1)
TRAJECTORY_JSON = "trajectory.json"
RESULT_JSON = "robot_scan.json"
MERGED_PLY = "merged.ply"
MERGED_ICP_PLY = "merged_icp.ply"
LAYOUT = (
    TRAJECTORY_JSON,
    RESULT_JSON,
    MERGED_PLY,
    MERGED_ICP_PLY,
    "views/*",
    "views/*/*",
    "views/*/*/*",
    "robot/*",
    "freeform.stl",
)
#: Surface samples of the coverage measure (a share's sampling error <= 0.5 %).
COVERAGE_SAMPLES = 10_000
#: Registration modes: view to view (no mesh needed), each view onto the mesh, none.
ICP_MODES = ("views", "mesh", "none")
#: The working volume registered by view-to-view ICP: the meshes' box grown by this (m).
REGION_MARGIN_M = 0.01
#: Most merged points measured by C2M: beyond it, a seeded sample of the points in the
#: working volume (the same indices before and after the ICP; MAE's sampling error ~0.3 %).
C2M_POINTS = 100_000
#: Largest joint noise accepted (rad): beyond it the views do not overlap any more.
MAX_JOINT_NOISE_RAD = 0.1


@dataclass
class RobotScanResult:
    """Outcome of :func:`robot_scan`: the run directory, the record written to
    ``robot_scan.json``, the merged clouds (world frame, metres), each view's scan result
    and the scene's meshes (for :func:`merge_views` with other joint errors)."""

    directory: Path
    record: dict[str, Any]
    merged: np.ndarray
    merged_icp: np.ndarray | None = None
    views: list[Any] = field(default_factory=list)
    meshes: list[Any] = field(default_factory=list)
    """The scene's meshes (world frame) the C2M is measured against."""


class _RobotScanner:
    """The scanner, adding the robot record to each capture it makes (what
    :func:`virtus.pipeline.scan.scan_into` calls is ``capture(scene, cam2world=, rng=)``)."""

    def __init__(self, scanner: Any, record: dict[str, Any]) -> None:
        self._scanner = scanner
        self._record = record

    def capture(self, scene: Any, *, cam2world: Pose, rng: int) -> Any:
        captured = self._scanner.capture(scene, cam2world=cam2world, rng=rng)
        return replace(captured, provenance={**captured.provenance, "robot": self._record})


def _builtin_freeform(folder: Path) -> Any:
    from virtus.scene.builtin import freeform_scene
    from virtus.scene.model import PlaneObject

    scene = freeform_scene(folder, Pose(np.eye(3), FREEFORM_CENTRE_M), background=False)
    return scene.model_copy(update={"background": PlaneObject((3.0, 3.0), Pose.identity())})


def _noisy(setup: RobotSetup, q: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    tree = setup.robot.tree
    noise = np.random.default_rng([seed, 21]).normal(scale=sigma, size=q.shape)
    return np.clip(q + noise, tree.lower, tree.upper)


def robot_scan(
    setup: RobotSetup,
    scene: Any,
    out_dir: str | Path,
    *,
    scanner: Any,
    trajectory: str | Path | None = None,
    plan: int | None = None,
    joint_noise_rad: float = 0.0,
    icp: str = "views",
    seed: int = 0,
    coverage: CoverageSettings | None = None,
    coverage_radius_m: float = 1e-3,
    candidates: int = 48,
    overwrite: bool = False,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
) -> RobotScanResult:
    """Scan ``scene`` from the robot (see the module docs).

    Parameters
    ----------
    setup : the robot, its base and the mount (:func:`virtus.robot.config.load_robot_file`).
    scene : a :class:`~virtus.scene.model.Scene` (world frame, z up for the robot), a scene
        file, or ``"freeform"``.
    scanner : the :class:`~virtus.scanner.Scanner` (its rig renders and triangulates).
    trajectory, plan : a trajectory file, or the number of views to plan (exactly one).
    joint_noise_rad : standard deviation of the reported joints' error (rad).
    icp : ``"views"`` (each view onto the merged cloud so far, no mesh needed),
        ``"mesh"`` (each view onto the scene's meshes: an evaluation aid) or ``"none"``.
    seed : seed of the captures, the joint noise and the plan.
    progress : called with one line per stage (planning, each view, merge, ICP, C2M).
    """
    from virtus.io.ply import write_ply
    from virtus.io.runs import claim_run
    from virtus.pipeline.evaluate import scene_meshes
    from virtus.pipeline.inputs import load_scene

    if (trajectory is None) == (plan is None):
        raise InputError("--trajectory/--plan", "exactly one of them", "both or neither")
    if plan is not None and (isinstance(plan, bool) or not 1 <= int(plan) <= MAX_VIEWS):
        raise InputError("--plan", f"1 to {MAX_VIEWS} views", plan)
    if isinstance(candidates, bool) or not 1 <= int(candidates) <= MAX_VIEWS:
        raise InputError("--candidates", f"1 to {MAX_VIEWS} views", candidates)
    if not 0.0 < float(coverage_radius_m) <= 1.0:
        raise InputError("coverage_radius_m", "a radius in (0, 1] m", coverage_radius_m)
    if not 0.0 <= float(joint_noise_rad) <= MAX_JOINT_NOISE_RAD:
        raise InputError("--joint-noise", f"0 to {MAX_JOINT_NOISE_RAD} rad", joint_noise_rad)
    if icp not in ICP_MODES:
        raise InputError("--icp", " or ".join(ICP_MODES), icp)
    say = _progress(progress)
    q_file = None if trajectory is None else load_trajectory(trajectory, setup)
    builtin = isinstance(scene, str) and scene == "freeform" and not Path(scene).is_file()
    if isinstance(scene, str | Path) and not builtin:
        scene = load_scene(scene)
    rig = scanner.rig
    config = {
        "robot": {k: str(v) for k, v in setup.source.items()},
        "scanner": scanner.to_dict(),
        "scene": "freeform" if builtin else _scene_config(scene),
        "trajectory": None if q_file is None else q_file.tolist(),
        "plan": plan,
        "joint_noise_rad": float(joint_noise_rad),
        "icp": icp,
        "seed": int(seed),
        "coverage_radius_m": float(coverage_radius_m),
        "candidates": int(candidates),
    }
    with claim_run(
        out_dir, COMMAND, config, layout=LAYOUT, overwrite=overwrite, resume=resume
    ) as run:
        if builtin:
            run.own("freeform.stl")
            scene = _builtin_freeform(run.path)
        meshes = scene_meshes(scene)
        if not meshes:
            raise InputError("scene", "at least one mesh object to scan", "none")
        import trimesh

        target = trimesh.util.concatenate([m for _, _, m in meshes])
        floor = _floor_mesh(scene)
        say(f"planning: {'trajectory file' if q_file is not None else f'{plan} views'}")
        q_all, plan_record = _trajectory(
            run, setup, rig, target, floor, q_file, plan, candidates, coverage, seed
        )
        say(f"planning: {len(q_all)} views")
        reported = reported_joints(setup, q_all, float(joint_noise_rad), seed)
        views, clouds, views_record, measurable = _scan_views(
            run, setup, scanner, scene, (target, floor), q_all, reported, coverage, seed, say
        )
        merge = merge_views(setup, reported, clouds, meshes, icp=icp, seed=seed, progress=say)
        run.own(MERGED_PLY)
        run.write(MERGED_PLY, lambda p: write_ply(p, merge.merged, frame="world"))
        say("coverage")
        record = {
            "units": "m (poses), mm (C2M)",
            "views": views_record,
            "plan": plan_record,
            "joint_noise_rad": float(joint_noise_rad),
            "icp": icp,
            **merge.record,
            "coverage_kinematics": _coverage(
                target, merge.merged, coverage_radius_m, seed, measurable
            ),
        }
        if merge.merged_icp is not None:
            run.own(MERGED_ICP_PLY)
            run.write(MERGED_ICP_PLY, lambda p: write_ply(p, merge.merged_icp, frame="world"))
            record["coverage_icp"] = _coverage(
                target, merge.merged_icp, coverage_radius_m, seed, measurable
            )
        run.own(RESULT_JSON)
        run.write_json(RESULT_JSON, record, allow_nan=True)
        say(f"done: {run.path / RESULT_JSON}")
        return RobotScanResult(run.path, record, merge.merged, merge.merged_icp, views, meshes)


def _progress(progress: Callable[[str], None] | None) -> Callable[[str], None]:
    """``progress`` with the seconds since the start in front of each line (or a no-op)."""
    if progress is None:
        return lambda _: None
    start = time.perf_counter()
    return lambda line: progress(f"[robot-scan {time.perf_counter() - start:7.1f} s] {line}")


def reported_joints(setup: RobotSetup, q: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """The joint values the arm reports at each view (V, dof): ``q`` plus one normal draw of
    standard deviation ``sigma`` (rad) per joint and view, seeded, clipped to the limits."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    return np.array([_noisy(setup, v, sigma, seed * 100_003 + k) for k, v in enumerate(q)])


@dataclass
class MergedViews:
    """Outcome of :func:`merge_views`: the merged clouds (world, metres) and their record
    (``c2m_kinematics``, and with ICP ``c2m_icp`` and the registration)."""

    merged: np.ndarray
    merged_icp: np.ndarray | None
    record: dict[str, Any]


def merge_views(
    setup: RobotSetup,
    reported: np.ndarray,
    clouds: list[np.ndarray],
    meshes: list[tuple[str, str, Any]],
    *,
    icp: str = "views",
    anchor: str = "kinematics",
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> MergedViews:
    """Map each view's cloud (camera frame, metres) into the world by FK of its
    ``reported`` joints, merge, optionally register (``icp``: see :func:`robot_scan`) and
    measure C2M against ``meshes`` (world frame) before and after.

    View-to-view ICP (:func:`virtus.robot.registration.register_views`) registers the
    points inside the meshes' bounding box grown by :data:`REGION_MARGIN_M` (the working
    volume the scan is planned for; the floor stays out); the meshes serve only that box
    and the C2M measure. C2M measures the points of that box (at most :data:`C2M_POINTS`,
    a sample seeded by ``seed``; ``record["c2m_sample"]``). ``anchor``: where the
    registered cloud lies as a whole (:func:`~virtus.robot.registration.register_views`:
    the kinematic average of the views, or the first view)."""
    from virtus.pipeline.evaluate import evaluate_points

    if icp not in ICP_MODES:
        raise InputError("--icp", " or ".join(ICP_MODES), icp)
    say = progress or (lambda _: None)
    placed = [setup.cam2world(q).apply(c) for q, c in zip(reported, clouds, strict=True)]
    merged = np.concatenate(placed)
    low = np.min([m.bounds[0] for _, _, m in meshes], axis=0) - REGION_MARGIN_M
    high = np.max([m.bounds[1] for _, _, m in meshes], axis=0) + REGION_MARGIN_M
    near = np.flatnonzero(np.all((merged >= low) & (merged <= high), axis=1))
    if len(near) > C2M_POINTS:  # the same points before and after the ICP
        near = np.sort(np.random.default_rng([int(seed), 2105]).choice(near, C2M_POINTS, False))
    say(f"merge: {len(merged):,} points from {len(placed)} views; C2M of {len(near):,} of "
        f"them, kinematics alone")  # fmt: skip
    record: dict[str, Any] = {
        "c2m_sample": {"points_near_meshes": int(len(near)), "limit": C2M_POINTS},
        "c2m_kinematics": [
            e.to_dict() for e in evaluate_points(merged[near], meshes, register=False)
        ],
    }
    if icp == "none":
        return MergedViews(merged, None, record)
    say(f"ICP ({icp})")
    if icp == "views":
        from virtus.robot.registration import register_views

        registration = register_views(placed, region=(low, high), anchor=anchor, seed=seed)
        refined = [c.apply(v) for c, v in zip(registration.corrections, placed, strict=True)]
        record["registration"] = registration.to_dict()
    else:
        refined = []
        for cloud in placed:
            single = evaluate_points(cloud, meshes, register=True)
            refined.append(single[0].c2m.cloud2mesh.apply(cloud))
    merged_icp = np.concatenate(refined)
    say("C2M after ICP")
    after = evaluate_points(merged_icp[near], meshes, register=False)
    record["c2m_icp"] = [e.to_dict() for e in after]
    return MergedViews(merged, merged_icp, record)


def _trajectory(run, setup, rig, target, floor, q_file, plan, candidates, coverage, seed):  # noqa: ANN001, ANN202
    """The joint values to scan (V, dof) and the plan's record: the given trajectory, the
    plan of an interrupted attempt of this run, or a new plan; ``trajectory.json`` saved."""
    kept = run.file(TRAJECTORY_JSON)
    run.own(TRAJECTORY_JSON)
    if q_file is None and run.resumed and kept.is_file():  # the plan of this run
        return load_trajectory(kept, setup), _read_plan(run.file(RESULT_JSON))
    if q_file is not None:
        save_trajectory(kept, setup, q_file)
        return q_file, None
    planned = plan_views(
        setup, rig, target, int(plan), environment=floor, candidates=candidates,
        settings=coverage, rng=seed,
        floor_z_m=None if floor is None else float(floor.bounds[1][2]),
    )  # fmt: skip
    save_trajectory(kept, setup, planned.q)
    record = {
        "coverage_after_each_view": planned.coverage.tolist(),
        "measurable_share": planned.measurable_share,
        "candidates": planned.candidates,
        "reachable": planned.reachable,
    }
    return planned.q, record


def _scan_views(run, setup, scanner, scene, parts, q_all, reported, coverage, seed, say):  # noqa: ANN001, ANN202
    """Capture, decode and reconstruct each view (resumable); each view's cloud in the camera
    frame; the surface samples some view measures."""
    import trimesh

    from virtus.pipeline.scan import ScanSettings, scan_into

    rig = scanner.rig
    target, floor = parts
    settings = ScanSettings(seed=int(seed))
    views, clouds, views_record = [], [], []
    samples, normals = surface_samples(target, COVERAGE_SAMPLES, seed)
    measurable = np.zeros(len(samples), dtype=bool)
    # one ray index for the scene, built once; the robot's links apart (they move)
    still = trimesh.util.concatenate([target, *([floor] if floor is not None else [])])
    for k, q in enumerate(q_all):
        sub = f"views/{k:03d}"
        start = time.perf_counter()
        run.own(f"robot/view_{k:03d}.stl")
        full = scene_with_robot(scene, setup, q, run.file("robot"), f"view_{k:03d}.stl")
        record = setup.capture_record(q)
        record["q_reported"] = reported[k].tolist()
        result = scan_into(run, sub, full, _RobotScanner(scanner, record), rig, settings,
                           cam2world=setup.cam2world(q))  # fmt: skip
        links = trimesh.util.concatenate(setup.scene_meshes(q))
        measurable |= view_coverage(rig, setup.cam2world(q), samples, normals, [still, links],
                                    coverage)  # fmt: skip
        cloud = result.reconstruction.cloud()
        views.append(result)
        clouds.append(cloud)
        views_record.append({"view": sub, "q": record["q"], "q_reported": reported[k].tolist(),
                             "points": int(len(cloud))})  # fmt: skip
        seconds = time.perf_counter() - start
        say(f"view {k + 1}/{len(q_all)}: {len(cloud):,} points, {seconds:.1f} s")
    return views, clouds, views_record, measurable


def _read_plan(path: Path) -> dict[str, Any] | None:
    """The plan record of an earlier attempt's ``robot_scan.json`` (None when absent)."""
    from virtus.io.safeio import read_json

    if not path.is_file():
        return None
    return read_json(path, "robot scan record", expect=dict, allow_nan=True).get("plan")


def _scene_config(scene: Any) -> Any:
    """The scene's description for ``run.json`` (in-memory textures: named only)."""
    from virtus.errors import VirtusError

    try:
        return scene.to_dict()
    except VirtusError:
        return {"objects": [type(o).__name__ for o in scene.all_objects()], "in_memory": True}


def _floor_mesh(scene: Any) -> Any:
    """The scene's background plane as a thin box (occluder for planning), or None."""
    import trimesh

    back = scene.background
    if back is None:
        return None
    width, height = back.size_m
    box = trimesh.creation.box(extents=(width, height, 1e-3))
    box.apply_transform(back.pose.matrix)
    return box


def _coverage(
    target: Any, cloud: np.ndarray, radius_m: float, seed: int, measurable: np.ndarray
) -> dict[str, Any]:
    """Share of surface samples (:data:`COVERAGE_SAMPLES` of ``target``, seeded) with a cloud
    point within ``radius_m``: of all samples, and of the ``measurable`` ones (those some
    scanned view sees and lights, :func:`virtus.robot.planning.view_coverage`)."""
    from scipy.spatial import cKDTree

    points, _ = surface_samples(target, COVERAGE_SAMPLES, seed)
    # only points within radius_m of the target's box can be within radius_m of a sample
    low, high = target.bounds[0] - radius_m, target.bounds[1] + radius_m
    near = cloud[np.all((cloud >= low) & (cloud <= high), axis=1)]
    if not len(near):
        near = np.full((1, 3), np.inf)
    distance, _ = cKDTree(near).query(points, k=1, distance_upper_bound=radius_m)
    hit = np.isfinite(distance)
    return {
        "radius_mm": radius_m * 1e3,
        "samples": len(points),
        "share_of_surface": float(hit.mean()),
        "measurable_share_of_surface": float(measurable.mean()),
        "share_of_measurable": float(hit[measurable].mean()) if measurable.any() else 0.0,
    }
