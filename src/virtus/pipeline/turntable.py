"""Multi-view turntable scanning merged in the object frame, evaluated by C2M.

The object stands on a virtual turntable whose axis is vertical -- parallel to the camera's
y axis (image down) -- and passes through the object's centre. View ``k`` of ``N`` turns it
by ``theta_k = 2 pi k / N``:

    object2cam_k = Pose(R_y(theta_k) @ R_0, c)       (c: the object's centre, camera frame)

Each view is scanned like :func:`virtus.pipeline.scan.scan` (capture, decode, triangulate),
its points are mapped back into the object frame by the known turntable pose
(``X_obj = object2cam_k^-1 X_cam``), optionally refined by ICP against the mesh, and all views
are concatenated into one cloud. The merged cloud is then compared with the mesh by C2M
(after a global ICP, as for a single view).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive_int
from virtus.devices import Rig
from virtus.errors import InputError, VirtusError
from virtus.jsonio import write_json
from virtus.metrology import C2MResult, MeshIndex, cloud_to_mesh, icp_to_mesh
from virtus.pipeline.scan import ScanSettings, scan
from virtus.pipeline.scenes import FREEFORM_CENTRE_M
from virtus.ply import write_ply
from virtus.scanner import Scanner
from virtus.transforms import Pose

__all__ = ["TurntableResult", "turntable_poses", "turntable_scan"]

#: Points farther than this (m) from the object's bounding box (in the object frame) are not
#: the object (background, table) and are not merged.
_BOX_MARGIN_M = 0.003
#: ICP pair rejection for per-view refinement and the global registration (m).
_ICP_MAX_DISTANCE_M = 0.002
#: Most turntable views (one per degree): each view is a whole capture on disk.
MAX_VIEWS = 360


def turntable_poses(n_views: int, start: Pose | None = None) -> list[Pose]:
    """``object2cam`` of each view: turns of ``2 pi k / n_views`` about the vertical axis.

    Parameters
    ----------
    n_views : number of views (>= 1).
    start : object2cam of view 0; the turntable axis (parallel to the camera's y axis)
        passes through its translation, the object's origin. Default: no rotation, origin at
        :data:`~virtus.pipeline.scenes.FREEFORM_CENTRE_M`.
    """
    n = positive_int("n_views", n_views)
    start = start or Pose(np.eye(3), FREEFORM_CENTRE_M)
    c = start.t
    r0 = start.R
    poses = []
    for k in range(n):
        theta = 2.0 * np.pi * k / n
        turn = Pose.from_euler("y", theta, degrees=False).R
        poses.append(Pose(turn @ r0, c))
    return poses


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


def turntable_scan(
    mesh_path: str | Path,
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
) -> TurntableResult:
    """Scan a mesh object from ``n_views`` turntable angles and merge the views.

    Parameters
    ----------
    mesh_path : the object's mesh file (STL/OBJ/PLY); its frame is the object frame.
    out_dir : directory; view ``k`` goes to ``out_dir/view_k``, the merged cloud to
        ``out_dir/merged.ply`` and the report to ``out_dir/turntable.json``.
    n_views : number of turntable angles.
    scale_to_m : metres per mesh-file unit.
    start : object2cam of view 0 (see :func:`turntable_poses`).
    scanner : the virtual scanner (default: the paper's system).
    calibration : rig or calibration file to triangulate with (default: the scanner's rig).
    settings : scan settings.
    refine : refine each view's known pose by ICP against the mesh before merging.
    overwrite : replace existing captures.
    """
    import trimesh

    from virtus.scene import MeshObject, Scene

    settings = settings or ScanSettings()
    scanner = scanner or Scanner()
    n_views = positive_int("n_views", n_views)
    if n_views > MAX_VIEWS:
        raise InputError("n_views", f"at most {MAX_VIEWS} turntable views", n_views)
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    mesh = trimesh.load(mesh_path, force="mesh", process=False)
    mesh.apply_scale(scale_to_m)
    index = MeshIndex(mesh)
    low, high = mesh.bounds[0] - _BOX_MARGIN_M, mesh.bounds[1] + _BOX_MARGIN_M

    poses = turntable_poses(n_views, start)
    clouds, counts, refinements = [], [], []
    timing = {"scan_s": 0.0, "merge_s": 0.0}
    for k, object2cam in enumerate(poses):
        start = time.perf_counter()
        placed = MeshObject(path=Path(mesh_path), scale_to_m=scale_to_m, pose=object2cam)
        scene = Scene(objects=(placed,))
        result = scan(
            scene,
            root / f"view_{k}",
            scanner=scanner,
            calibration=calibration,
            settings=settings,
            overwrite=overwrite,
        )
        timing["scan_s"] += time.perf_counter() - start
        start = time.perf_counter()
        points = object2cam.inverse().apply(result.reconstruction.cloud())
        points = points[np.all((points >= low) & (points <= high), axis=1)]
        refinement = (0.0, 0.0)
        if refine and len(points) >= 6:
            fit = icp_to_mesh(points, index, max_distance=_ICP_MAX_DISTANCE_M)
            points = fit.cloud2mesh.apply(points)
            refinement = (fit.cloud2mesh.angle_deg, float(np.linalg.norm(fit.cloud2mesh.t)) * 1e3)
        clouds.append(points)
        counts.append(int(len(points)))
        refinements.append(refinement)
        timing["merge_s"] += time.perf_counter() - start
    merged = np.concatenate(clouds)
    if len(merged) == 0:
        raise VirtusError("turntable: no view saw the object")

    start = time.perf_counter()
    c2m = cloud_to_mesh(merged, index, max_distance=_ICP_MAX_DISTANCE_M)
    timing["evaluate_s"] = time.perf_counter() - start
    ply = write_ply(
        root / "merged.ply",
        merged,
        frame="object",
        comments=(f"virtus turntable, {n_views} views merged in the object frame",),
    )
    result = TurntableResult(merged, counts, poses, refinements, c2m, ply, timing)
    report = result.to_dict()
    report["settings"] = settings.to_dict()
    report["scanner"] = scanner.to_dict()
    report["refine"] = refine
    report["mesh"] = str(mesh_path)
    write_json(root / "turntable.json", report)
    return result
