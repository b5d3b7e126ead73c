"""Multi-view turntable scanning merged in the object frame, evaluated by C2M.

The object stands on a virtual turntable whose axis is vertical -- parallel to the camera's
y axis (image down) -- and passes through the object's centre. View ``k`` of ``N`` turns it
by ``theta_k = 2 pi k / N``:

    object2cam_k = Pose(R_y(theta_k) @ R_0, c)       (c: the object's centre, camera frame)

(:func:`virtus.geometry.trajectories.turntable_poses`).

Each view is scanned like :func:`virtus.pipeline.scan.scan` (capture, decode, triangulate),
its points are mapped back into the object frame by the known turntable pose
(``X_obj = object2cam_k^-1 X_cam``), optionally refined by ICP against the mesh, and all views
are concatenated into one cloud. The merged cloud is then compared with the mesh by C2M
(after a global ICP, as for a single view).

Output directory (owned by the run through :func:`virtus.io.runs.claim_run`, command
``turntable``)::

    OUT/run.json, OUT/.virtus.lock   the run record and lock (see virtus.io.runs)
    OUT/view_<k>/               view k: a scan directory (capture, decoded/, points.ply, ...)
    OUT/view_<k>/view.npz       view k's result, written when the view is finished:
                                points (N, 3) float64 object frame, metres (after the box
                                crop and the optional ICP refinement), object2cam (4, 4),
                                refinement (2,) deg and mm, episode (the run's config digest)
    OUT/freeform.stl            the built-in free-form object's mesh (when it is scanned)
    OUT/merged.ply              the merged cloud, object frame, metres
    OUT/turntable.json          the report (views, counts, C2M in mm, settings)

**Resumable**: ``resume=True`` (``virtus scan --turntable N --resume``) keeps every finished
view (its ``view.npz`` must belong to this run's configuration) and, for the view that was
in progress, a complete capture; only the rest is rendered.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive, positive_int
from virtus.errors import InputError, VirtusError
from virtus.geometry.devices import Rig
from virtus.geometry.trajectories import turntable_poses
from virtus.geometry.transforms import Pose
from virtus.io.ply import write_ply
from virtus.io.runs import RunDirectory, claim_run, config_digest
from virtus.io.safeio import load_npz
from virtus.metrology import C2MResult, MeshIndex, cloud_to_mesh, icp_to_mesh
from virtus.pipeline.scan import ScanSettings, calibration_rig, scan_into
from virtus.scanner import Scanner

__all__ = [
    "MAX_VIEWS",
    "TurntableResult",
    "check_views",
    "turntable_object",
    "turntable_scan",
    "turntable_scan_scene",
]

#: Points farther than this (m) from the object's bounding box (in the object frame) are not
#: the object (background, table) and are not merged.
_BOX_MARGIN_M = 0.003
#: ICP pair rejection for per-view refinement and the global registration (m).
_ICP_MAX_DISTANCE_M = 0.002
#: Most turntable views (one per degree): each view is a whole capture on disk.
MAX_VIEWS = 360
#: The job's name in ``run.json``.
COMMAND = "turntable"
#: A finished view's result file, inside its directory.
VIEW_FILE = "view.npz"
#: Files of the job (an earlier run's when found without a ``run.json``).
LAYOUT = ("turntable.json", "merged.ply", "view_*/" + VIEW_FILE, "view_*/capture.json")


@dataclass(frozen=True, eq=False)
class TurntableResult:
    """Outcome of :func:`turntable_scan`.

    Attributes
    ----------
    merged : (N, 3) float64 merged cloud in the object frame, metres.
    view_counts : points contributed by each view.
    object2cam : the turntable pose of each view.
    refinements_deg_mm : per view, (rotation deg, translation mm) of the ICP refinement
        applied after the known pose (zeros when refinement is off).
    c2m : C2M of the merged cloud against the mesh (object frame).
    ply_path : the merged cloud, PLY, object frame.
    timing_s : seconds (scan, merge, evaluate).
    """

    merged: np.ndarray
    view_counts: list[int]
    object2cam: list[Pose]
    refinements_deg_mm: list[tuple[float, float]]
    c2m: C2MResult
    ply_path: Path
    timing_s: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: views, point counts, object2cam poses (metres), ICP
        refinements (deg, mm), the merged cloud's C2M summary (mm) and timings (s)."""
        return {
            "n_views": len(self.view_counts),
            "view_counts": self.view_counts,
            "n_points": int(self.merged.shape[0]),
            "object2cam": [p.to_dict() for p in self.object2cam],
            "refinement_deg_mm": [list(r) for r in self.refinements_deg_mm],
            "c2m": self.c2m.to_dict(),
            "timing_s": self.timing_s,
        }


def check_views(n_views: object) -> int:
    """``n_views`` as an int in 1..:data:`MAX_VIEWS`, else :class:`InputError`."""
    n = positive_int("turntable views (--turntable)", n_views)
    if n > MAX_VIEWS:
        raise InputError("turntable views (--turntable)", f"at most {MAX_VIEWS} views", n)
    return n


def turntable_scan(
    mesh_path: str | Path | None,
    out_dir: str | Path,
    *,
    n_views: int = 8,
    scale_to_m: float = 1.0,
    start: Pose | None = None,
    scanner: Scanner | None = None,
    calibration: str | Path | Rig | None = None,
    settings: ScanSettings | None = None,
    refine: bool = False,
    overwrite: bool = False,
    resume: bool = False,
) -> TurntableResult:
    """Scan a mesh object from ``n_views`` turntable angles and merge the views.

    Parameters
    ----------
    mesh_path : the object's mesh file (STL/OBJ/PLY); its frame is the object frame. None:
        the built-in free-form object (:func:`virtus.scene.procedural.freeform_object`, metres),
        written as ``out_dir/freeform.stl``.
    out_dir : directory owned by the run (layout in the module docstring).
    n_views : number of turntable angles, 1..:data:`MAX_VIEWS`.
    scale_to_m : metres per mesh-file unit.
    start : object2cam of view 0 (see :func:`virtus.geometry.trajectories.turntable_poses`).
    scanner : the virtual scanner (default: the paper's system).
    calibration : rig or calibration file to triangulate with (default: the scanner's rig).
    settings : scan settings.
    refine : refine each view's known pose by ICP against the mesh before merging.
    overwrite : remove an earlier run's files first.
    resume : continue the run in ``out_dir``: finished views are kept.

    Raises
    ------
    InputError, VirtusError : bad arguments, an unreadable mesh or calibration, a capture
        over the memory budget (all before anything is written); ``out_dir`` in use or
        holding another run's files; no view that saw the object.
    """
    from virtus.scene.model import MeshObject, Scene

    settings = settings or ScanSettings()
    scanner = scanner or Scanner()
    n_views = check_views(n_views)
    scale = positive("scale_to_m", scale_to_m)
    used = calibration_rig(calibration, scanner)
    poses = turntable_poses(n_views, start)
    if mesh_path is None:
        from virtus.scene.procedural import freeform_object

        built = freeform_object()
        vertices, faces = np.asarray(built.vertices), np.asarray(built.faces)
        scanner.check()
    else:
        with np.errstate(all="ignore"):  # a far-off mesh is refused by name, not warned about
            vertices, faces, _ = MeshObject(path=Path(mesh_path), scale_to_m=scale).load()
        first = MeshObject(path=Path(mesh_path), scale_to_m=scale, pose=poses[0])
        scanner.check(Scene(objects=(first,)))
    config = {
        "mesh": "freeform" if mesh_path is None else str(mesh_path),
        "n_views": n_views,
        "scale_to_m": scale,
        "start": poses[0].to_dict(),
        "scanner": scanner.to_dict(),
        "calibration": None if calibration is None else used.to_dict(),
        "settings": settings.to_dict(),
        "refine": bool(refine),
    }
    inputs = {} if mesh_path is None else {"mesh": mesh_path}
    with claim_run(
        out_dir, COMMAND, config, inputs=inputs, layout=LAYOUT, overwrite=overwrite,
        resume=resume,
    ) as run:  # fmt: skip
        if mesh_path is None:
            run.own("freeform.stl")
            mesh_path = run.file("freeform.stl")
            run.write("freeform.stl", lambda tmp: built.export(tmp, file_type="stl"))
        import trimesh

        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
        return _run_views(run, config, mesh, Path(mesh_path), scale, poses, scanner, used,
                          settings, refine)  # fmt: skip


def turntable_object(scene: Any) -> tuple[Path | None, float, Pose]:
    """The object a turntable scan of ``scene`` turns: ``(mesh_path, scale_to_m, start)``
    for :func:`turntable_scan`.

    ``scene`` is the name of a built-in scene or a :class:`~virtus.scene.model.Scene`. The
    built-in ``"freeform"`` is the free-form object (``mesh_path`` None, written into the
    run's directory) at :data:`virtus.scene.builtin.FREEFORM_CENTRE_M`; a scene must hold
    exactly one mesh object (its file, scale and pose), else :class:`InputError`.
    """
    from virtus.scene.builtin import FREEFORM_CENTRE_M
    from virtus.scene.model import MeshObject

    if scene == "freeform":  # the built-in object, written into OUT by the run
        return None, 1.0, Pose(np.eye(3), FREEFORM_CENTRE_M)
    objects = [] if isinstance(scene, str) else list(scene.objects)
    meshes = [o for o in objects if isinstance(o, MeshObject)]
    if len(meshes) != 1:
        raise InputError("scene", "exactly one mesh object for a turntable scan", f"{len(meshes)}")
    return meshes[0].path, meshes[0].scale_to_m, meshes[0].pose


def turntable_scan_scene(
    scene: Any,
    out_dir: str | Path,
    *,
    n_views: int = 8,
    scanner: Scanner | None = None,
    calibration: str | Path | Rig | None = None,
    settings: ScanSettings | None = None,
    refine: bool = False,
    overwrite: bool = False,
    resume: bool = False,
) -> TurntableResult:
    """:func:`turntable_scan` of the object of ``scene`` (:func:`turntable_object`: a
    built-in scene's name or a scene with one mesh object), turned about the vertical axis
    through its origin, view 0 at its pose in the scene; the other arguments are
    :func:`turntable_scan`'s."""
    mesh_path, scale, start = turntable_object(scene)
    return turntable_scan(
        mesh_path,
        out_dir,
        n_views=n_views,
        scale_to_m=scale,
        start=start,
        scanner=scanner,
        calibration=calibration,
        settings=settings,
        refine=refine,
        overwrite=overwrite,
        resume=resume,
    )


def _run_views(
    run: RunDirectory,
    config: dict[str, Any],
    mesh: Any,
    mesh_path: Path,
    scale: float,
    poses: list[Pose],
    scanner: Scanner,
    rig: Rig,
    settings: ScanSettings,
    refine: bool,
) -> TurntableResult:
    from virtus.scene.model import MeshObject, Scene

    index = MeshIndex(mesh)
    low, high = mesh.bounds[0] - _BOX_MARGIN_M, mesh.bounds[1] + _BOX_MARGIN_M
    episode = config_digest(config)
    clouds, counts, refinements = [], [], []
    timing = {"scan_s": 0.0, "merge_s": 0.0}
    for k, object2cam in enumerate(poses):
        name = f"view_{k}/{VIEW_FILE}"
        run.own(name)
        if run.resumed and run.file(name).is_file():
            points, refinement = _load_view(run.file(name), object2cam, episode)
            run.log(f"reused view {k}")
        else:
            start = time.perf_counter()
            placed = MeshObject(path=mesh_path, scale_to_m=scale, pose=object2cam)
            result = scan_into(run, f"view_{k}", Scene(objects=(placed,)), scanner, rig, settings)
            timing["scan_s"] += time.perf_counter() - start
            start = time.perf_counter()
            points = object2cam.inverse().apply(result.reconstruction.cloud())
            points = points[np.all((points >= low) & (points <= high), axis=1)]
            refinement = (0.0, 0.0)
            if refine and len(points) >= 6:
                fit = icp_to_mesh(points, index, max_distance=_ICP_MAX_DISTANCE_M)
                points = fit.cloud2mesh.apply(points)
                refinement = (
                    fit.cloud2mesh.angle_deg, float(np.linalg.norm(fit.cloud2mesh.t)) * 1e3
                )  # fmt: skip
            timing["merge_s"] += time.perf_counter() - start
            arrays = {
                "points": points,
                "object2cam": object2cam.matrix,
                "refinement": np.array(refinement, dtype=np.float64),
                "episode": np.array(episode),
            }
            run.write(name, lambda tmp, arrays=arrays: np.savez(tmp, **arrays))
            run.log(f"scanned view {k}")
        clouds.append(points)
        counts.append(int(len(points)))
        refinements.append(refinement)
    merged = np.concatenate(clouds)
    if len(merged) == 0:
        raise VirtusError("turntable: no view saw the object")

    start = time.perf_counter()
    c2m = cloud_to_mesh(merged, index, max_distance=_ICP_MAX_DISTANCE_M)
    timing["evaluate_s"] = time.perf_counter() - start
    run.own("merged.ply", "turntable.json")
    ply = run.write(
        "merged.ply",
        lambda tmp: write_ply(
            tmp,
            merged,
            frame="object",
            comments=(f"virtus turntable, {len(poses)} views merged in the object frame",),
        ),
    )
    result = TurntableResult(merged, counts, poses, refinements, c2m, ply, timing)
    report = result.to_dict()
    report["settings"] = settings.to_dict()
    report["scanner"] = scanner.to_dict()
    report["refine"] = refine
    report["mesh"] = str(mesh_path)
    run.write_json("turntable.json", report)
    return result


def _load_view(path: Path, object2cam: Pose, episode: str) -> tuple[np.ndarray, tuple]:
    """A finished view's points and refinement, checked to belong to this run and pose."""
    arrays = load_npz(path, "view file")
    points = arrays.get("points")
    if (
        str(arrays.get("episode", "")) != episode
        or not np.array_equal(arrays.get("object2cam"), object2cam.matrix)
        or points is None
        or points.ndim != 2
        or points.shape[1:] != (3,)
    ):
        raise VirtusError(
            f"{path} was made by another turntable configuration or view; remove it or start "
            "again with --overwrite"
        )
    refinement = tuple(float(x) for x in arrays.get("refinement", (0.0, 0.0)))
    return points.astype(np.float64), refinement
