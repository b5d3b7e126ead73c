"""Robots from a URDF file, read with yourdfpy (``pip install 'virtus-fpp[robot]'``).

Mesh paths are resolved by :func:`resolve_mesh_path`, never guessed:

* ``package://NAME/rest`` -> ``DIR/rest`` for a mapping ``NAME=DIR`` given by the caller
  (``--package-path NAME=DIR`` on the command line, ``package_paths: {NAME: DIR}`` in a robot
  file; a relative DIR is relative to the robot file). An unknown NAME is an error naming
  the mapping to add.
* ``file:///abs/path`` -> that path; any other relative path -> relative to the URDF's folder.

Every mesh of every link (visual and collision) must resolve to an existing file: a missing
mesh is an :class:`~virtus.errors.InputError` naming the link and the path (yourdfpy itself
skips meshes it cannot open without a word). Joints: ``revolute``, ``continuous``,
``prismatic`` and ``fixed``; ``floating`` and ``planar`` are refused. Collision capsules are
fitted to each link's collision shapes (their bounding box in the link frame: the longest
side is the segment, the larger half of the other two the radius) -- conservative, coarse.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError, MissingDependency
from virtus.robot.chain import Joint, KinematicTree
from virtus.robot.model import Robot
from virtus.robot.shapes import Capsule

__all__ = ["load_urdf", "parse_package_paths", "resolve_mesh_path"]

#: Largest URDF read (bytes): a robot description is text of some hundred kilobytes.
MAX_URDF_BYTES = 16 * 1024 * 1024
_KINDS = {
    "revolute": "revolute",
    "continuous": "revolute",
    "prismatic": "prismatic",
    "fixed": "fixed",
}


def parse_package_paths(items: list[str] | None, base: Path | None = None) -> dict[str, Path]:
    """``["NAME=DIR", ...]`` -> ``{NAME: DIR}`` (relative DIRs against ``base``)."""
    out: dict[str, Path] = {}
    for item in items or []:
        name, sep, folder = str(item).partition("=")
        if not sep or not name or not folder:
            raise InputError("--package-path", "NAME=DIR", item)
        path = Path(folder).expanduser()
        if base is not None and not path.is_absolute():
            path = base / path
        if not path.is_dir():
            raise InputError(f"--package-path {name}", "an existing directory", str(path))
        out[name] = path
    return out


def resolve_mesh_path(
    filename: str, urdf_dir: Path, package_paths: Mapping[str, Path], *, link: str = "?"
) -> Path:
    """The file a URDF mesh ``filename`` names (see the module docs); it must exist."""
    if filename.startswith("package://"):
        name, _, rest = filename[len("package://") :].partition("/")
        if name not in package_paths:
            raise InputError(
                f"link {link} mesh {filename}",
                f"a package path for '{name}' (--package-path {name}=DIR)",
                f"known: {sorted(package_paths) or 'none'}",
            )
        path = Path(package_paths[name]) / rest
    elif filename.startswith("file://"):
        path = Path(filename[len("file://") :])
    else:
        path = Path(filename)
        if not path.is_absolute():
            path = urdf_dir / path
    if not path.is_file():
        raise InputError(f"link {link} mesh {filename}", "an existing mesh file", str(path))
    return path


def load_urdf(path: str | Path, package_paths: Mapping[str, Path] | None = None) -> Robot:
    """A :class:`Robot` from the URDF at ``path`` (every mesh checked; see module docs)."""
    try:
        import yourdfpy
    except ImportError:
        raise MissingDependency(
            "reading a URDF needs yourdfpy: pip install 'virtus-fpp[robot]'"
        ) from None
    urdf_path = Path(path).expanduser()
    if not urdf_path.is_file():
        raise InputError("robot", "an existing URDF file", str(urdf_path))
    if urdf_path.stat().st_size > MAX_URDF_BYTES:
        raise InputError("robot", f"a URDF of at most {MAX_URDF_BYTES} bytes", str(urdf_path))
    packages = dict(package_paths or {})
    try:
        model = yourdfpy.URDF.load(str(urdf_path), load_meshes=False, build_scene_graph=False)
    except Exception as error:  # noqa: BLE001 - lxml/yourdfpy raise many kinds on bad XML
        raise InputError("robot", "a readable URDF", f"{urdf_path}: {error}") from None
    files: dict[tuple[str, str, int], Path] = {}
    for name, link in model.link_map.items():
        for kind in ("visuals", "collisions"):
            for k, element in enumerate(getattr(link, kind) or []):
                mesh = element.geometry.mesh if element.geometry is not None else None
                if mesh is not None:
                    files[(name, kind, k)] = resolve_mesh_path(
                        mesh.filename, urdf_path.parent, packages, link=name
                    )
    tree = KinematicTree(model.robot.name or urdf_path.stem, _joints(model))

    def visuals() -> dict[str, list[Any]]:
        return {
            name: _shapes(
                name,
                link.visuals or link.collisions or [],
                "visuals" if link.visuals else "collisions",
                files,
            )
            for name, link in model.link_map.items()
        }

    capsules = []
    for name, link in model.link_map.items():
        meshes = _shapes(name, link.collisions or [], "collisions", files)
        if meshes:
            capsules.append(_fit_capsule(name, meshes))
    source = {"urdf": str(urdf_path), "package_paths": {k: str(v) for k, v in packages.items()}}
    return Robot(tree, tuple(capsules), visuals, source)


def _joints(model: Any) -> list[Joint]:
    joints = []
    for name, joint in model.joint_map.items():
        kind = _KINDS.get(joint.type)
        if kind is None:
            raise InputError(f"joint {name}", f"a joint of type {sorted(_KINDS)}", joint.type)
        origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, np.float64)
        axis = np.array([1.0, 0.0, 0.0]) if joint.axis is None else np.asarray(joint.axis)
        lower, upper = -np.inf, np.inf
        if joint.type in ("revolute", "prismatic"):
            limit = joint.limit
            if limit is None or limit.lower is None or limit.upper is None:
                raise InputError(f"joint {name}", "a <limit lower upper>", "none")
            lower, upper = float(limit.lower), float(limit.upper)
        joints.append(Joint(name, kind, joint.parent, joint.child, origin, axis, lower, upper))
    return joints


def _shapes(link: str, elements: list[Any], kind: str, files: dict) -> list[Any]:
    """The link's shapes as trimesh meshes in the link frame."""
    import trimesh

    out = []
    for k, element in enumerate(elements):
        geometry = element.geometry
        if geometry is None:
            continue
        if geometry.box is not None:
            mesh = trimesh.creation.box(extents=np.asarray(geometry.box.size, np.float64))
        elif geometry.cylinder is not None:
            mesh = trimesh.creation.cylinder(
                radius=geometry.cylinder.radius, height=geometry.cylinder.length, sections=16
            )
        elif geometry.sphere is not None:
            mesh = trimesh.creation.icosphere(subdivisions=2, radius=geometry.sphere.radius)
        elif geometry.mesh is not None:
            mesh = _load_mesh(link, files[(link, kind, k)])
            if geometry.mesh.scale is not None:
                mesh.apply_scale(np.broadcast_to(np.asarray(geometry.mesh.scale, float), 3))
        else:
            continue
        if element.origin is not None:
            mesh.apply_transform(np.asarray(element.origin, np.float64))
        out.append(mesh)
    return out


def _load_mesh(link: str, path: Path) -> Any:
    import trimesh

    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as error:  # noqa: BLE001 - trimesh raises many kinds on bad files
        raise InputError(f"link {link} mesh", "a readable mesh file", f"{path}: {error}") from None
    if len(getattr(mesh, "faces", ())) == 0:
        raise InputError(f"link {link} mesh", "a mesh with triangles", str(path))
    return mesh


def _fit_capsule(link: str, meshes: list[Any]) -> Capsule:
    points = np.concatenate([np.asarray(m.vertices) for m in meshes])
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = (low + high) / 2.0, (high - low) / 2.0
    axis = int(np.argmax(half))
    radius = float(max(np.delete(half, axis).max(), 1e-3))
    offset = np.zeros(3)
    offset[axis] = max(half[axis] - radius, 0.0)
    return Capsule(link, tuple(centre - offset), tuple(centre + offset), radius)
