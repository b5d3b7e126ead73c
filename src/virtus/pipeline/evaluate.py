"""Evaluate a scan: cloud-to-mesh distance against the scene's meshes after ICP.

For every mesh object of the scene, the points inside its bounding box (grown by
``margin_m``) are registered to the mesh by point-to-plane ICP, starting from the scene's
pose of the mesh (the cloud is in the camera frame, the mesh placed there by the scene), and
their signed distances to the surface are summarised (MAE, RMSE, histogram). This is the
paper's C2M figure: the ICP takes out a global rigid misplacement (e.g. from calibrated
extrinsics), the distances measure the shape.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.capture import scandir as layout
from virtus.capture.scandir import check_points_current
from virtus.checks import as_points, positive
from virtus.errors import VirtusError
from virtus.geometry.transforms import Pose
from virtus.io.ply import read_ply
from virtus.io.runs import directory_lock, file_digest, write_json_atomic
from virtus.metrology import C2MResult, cloud_to_mesh

__all__ = ["MeshEvaluation", "evaluate_points", "evaluate_scan", "scene_meshes"]

#: Bounding-box margin (m) around a mesh for the points that belong to it.
MARGIN_M = 0.003
#: ICP ignores pairs farther apart than this (m): background and gross outliers.
ICP_MAX_DISTANCE_M = 0.002


@dataclass(frozen=True, eq=False)
class MeshEvaluation:
    """C2M of the points near one mesh.

    Attributes
    ----------
    name : the object's name in the scene (``objects[i]``) and its file.
    n_points : points inside the grown bounding box (all of them are measured).
    c2m : distances, statistics and the ICP result.
    """

    name: str
    path: str
    n_points: int
    c2m: C2MResult

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: object name, mesh file, point count and the C2M summary (mm)."""
        out = {"object": self.name, "mesh": self.path, "n_points": self.n_points}
        out.update(self.c2m.to_dict())
        return out


def scene_meshes(scene: Any, world2cam: Pose | None = None) -> list[tuple[str, str, Any]]:
    """The mesh objects of a scene as ``(name, file, trimesh.Trimesh in the camera frame)``."""
    import trimesh

    from virtus.scene.model import MeshObject

    out = []
    for name, obj in zip(scene.object_names(), scene.all_objects(), strict=True):
        if isinstance(obj, MeshObject):
            vertices, faces, _ = obj.load()
            if world2cam is not None:
                vertices = world2cam.apply(vertices)
            mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
            out.append((name, str(obj.path), mesh))
    return out


def evaluate_points(
    points: object,
    meshes: list[tuple[str, str, Any]],
    *,
    margin_m: float = MARGIN_M,
    register: bool = True,
    max_distance: float = ICP_MAX_DISTANCE_M,
) -> list[MeshEvaluation]:
    """C2M of a cloud against meshes in the same frame.

    Parameters
    ----------
    points : (N, 3) float, metres, the meshes' frame (camera frame for a scan).
    meshes : ``(name, file, trimesh.Trimesh)`` as from :func:`scene_meshes`.
    margin_m : points within the mesh's bounding box grown by this are its points.
    register : refine the placement by ICP before measuring.
    max_distance : ICP pair rejection distance, metres.
    """
    pts = as_points("points", points, 3)
    margin = positive("margin_m", margin_m)
    if not meshes:
        raise VirtusError("evaluate: no mesh to compare with")
    results = []
    for name, path, mesh in meshes:
        low, high = mesh.bounds[0] - margin, mesh.bounds[1] + margin
        inside = np.all((pts >= low) & (pts <= high), axis=1)
        if inside.sum() < 6:
            raise VirtusError(
                f"evaluate: only {int(inside.sum())} points near {name} ({path}); "
                "is it in the camera's view?"
            )
        c2m = cloud_to_mesh(pts[inside], mesh, register=register, max_distance=max_distance)
        results.append(MeshEvaluation(name, path, int(inside.sum()), c2m))
    return results


def evaluate_scan(
    scan_dir: str | Path,
    ply_path: str | Path | None = None,
    *,
    register: bool = True,
    save: bool = True,
) -> list[MeshEvaluation]:
    """C2M of a scan directory's point cloud against its scene's meshes.

    Parameters
    ----------
    scan_dir : directory from ``virtus scan`` (capture + ``points.ply``).
    ply_path : the cloud to evaluate (default ``scan_dir/points.ply``, which must be the
        latest reconstruction of the frames the directory holds:
        :func:`virtus.capture.scandir.check_points_current`); metres, camera frame.
    register : ICP before measuring.
    save : write ``scan_dir/evaluation.json`` (with the cloud's SHA-256, ``cloud_sha256``,
        which ties it to the cloud it measured), holding the directory's lock.

    Raises
    ------
    VirtusError
        The scene has no mesh object; the PLY is missing, not a PLY, empty or stale; the
        directory is in use by another run.
    """
    from virtus.capture.capture import Capture

    directory = Path(scan_dir)
    capture = Capture.load(directory)
    if capture.scene is None:
        raise VirtusError(f"evaluate: {directory}/capture.json holds no scene to compare with")
    meshes = scene_meshes(capture.scene)
    if not meshes:
        kinds = ", ".join(getattr(o, "type", type(o).__name__) for o in capture.scene.all_objects())
        raise VirtusError(
            f"evaluate: the scene of {directory} has no mesh object to compare with "
            f"(it has: {kinds}); C2M needs a mesh (for spheres use the sphere fit of `virtus demo`)"
        )
    default = directory / layout.POINTS_PLY
    source = Path(ply_path) if ply_path is not None else default
    if not source.is_file():
        raise VirtusError(f"evaluate: no point cloud at {source} (run `virtus reconstruct` first)")
    lock = directory_lock(directory) if save else contextlib.nullcontext()
    with lock:
        if source.resolve() == default.resolve():
            digest = check_points_current(capture, source)
        else:
            digest = file_digest(source)
        cloud = read_ply(source)
        if len(cloud) == 0:
            raise VirtusError(f"evaluate: {source} holds no points")
        if cloud.units not in (None, "m"):
            raise VirtusError(f"evaluate: {source} states units {cloud.units!r}; expected metres")
        results = evaluate_points(cloud.points, meshes, register=register)
        if save:
            report = {
                "units": "mm",
                "cloud": str(source),
                "cloud_sha256": digest,
                "meshes": [r.to_dict() for r in results],
            }
            write_json_atomic(directory / layout.EVALUATION_JSON, report, allow_nan=True)
    return results
