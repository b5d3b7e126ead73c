"""Turn a :class:`virtus.scene.model.Scene` into a Mitsuba scene description.

Shapes are placed in the world frame given by their ``object2world`` poses; every BSDF is
wrapped in ``twosided`` so that planes and open meshes reflect on both sides. Materials map
to Mitsuba BSDFs as documented in :class:`virtus.scene.model.Material`. Scene lights become
Mitsuba emitters: an area light a black ``rectangle`` with an ``area`` emitter (radiance on
its local +z side), the environment a ``constant`` emitter.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.render.backend import mitsuba
from virtus.scene.model import (
    AreaLight,
    BoxObject,
    EnvironmentLight,
    Material,
    MeshObject,
    PlaneObject,
    Scene,
    SphereObject,
    TexturedPlaneObject,
    unchangeable_image,
)

#: Textures made from in-memory images, most recent last: ``(variant, image, copy,
#: texture)``, ``copy`` None for an image nothing can change. A calibration renders one
#: board image in every pose; building its Mitsuba texture (a 2000 x 2000 bitmap) took
#: ~30 ms of a ~40 ms GPU pose.
_TEXTURES: list[tuple[str, np.ndarray, np.ndarray | None, Any]] = []
_TEXTURE_CACHE_SIZE = 2


def _texture(mi: ModuleType, image: np.ndarray) -> Any:
    """The Mitsuba texture of an albedo image, reused while the same unchanged image
    comes back: the same array object, still unchangeable
    (:func:`~virtus.scene.model.unchangeable_image`), or with contents equal to the copy kept
    here (comparing a 2000 x 2000 image took 4-5 ms a pose on 2 CPU cores)."""
    variant = mi.variant()
    for entry in _TEXTURES:
        if entry[0] != variant or entry[1] is not image:
            continue
        # An entry kept without a copy was made while the image could not change.
        copy = entry[2]
        if copy is None if unchangeable_image(image) else np.array_equal(copy, image):
            return entry[3]
    # raw: the values are linear albedos; clamp: no wrap-around at the board's edges.
    bitmap = mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)[..., None])
    texture = mi.load_dict(
        {
            "type": "bitmap",
            "bitmap": bitmap,
            "raw": True,
            "filter_type": "bilinear",
            "wrap_mode": "clamp",
        }
    )
    copy = None if unchangeable_image(image) else np.array(image)
    _TEXTURES.append((variant, image, copy, texture))
    del _TEXTURES[:-_TEXTURE_CACHE_SIZE]
    return texture


def bsdf_dict(mi: ModuleType, material: Material, albedo: np.ndarray | None = None) -> dict:
    """Mitsuba BSDF dict for ``material``; ``albedo`` (H, W) overrides its albedo texture."""
    image = albedo if albedo is not None else material.albedo_image()
    if image is not None:
        colour: Any = _texture(mi, image)
    else:
        colour = {"type": "rgb", "value": [float(material.albedo)] * 3}  # type: ignore[arg-type]
    if material.metal:
        inner = {
            "type": "principled",
            "base_color": colour,
            "metallic": 1.0,
            "roughness": material.roughness,
            "specular": material.specular,
        }
    elif material.specular == 0.0:
        inner = {"type": "diffuse", "reflectance": colour}
    else:
        inner = {
            "type": "principled",
            "base_color": colour,
            "metallic": 0.0,
            "roughness": material.roughness,
            "specular": material.specular,
        }
    return {"type": "twosided", "bsdf": inner}


def _transform(mi: ModuleType, pose: Pose, scale: tuple[float, float, float]) -> Any:
    matrix = pose.matrix @ np.diag([*scale, 1.0])
    return mi.ScalarTransform4f(matrix.tolist())


def _mesh(mi: ModuleType, dr: ModuleType, obj: MeshObject, name: str) -> Any:
    vertices, faces, uv = obj.load()
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf_dict(mi, obj.material))
    mesh = mi.Mesh(
        name,
        vertex_count=len(vertices),
        face_count=len(faces),
        props=props,
        has_vertex_normals=False,
        has_vertex_texcoords=uv is not None,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.Point3f(*vertices.T.astype(np.float32)))
    params["faces"] = dr.ravel(mi.Vector3u(*faces.T.astype(np.uint32)))
    if uv is not None:
        params["vertex_texcoords"] = dr.ravel(mi.Point2f(*uv.T.astype(np.float32)))
    params.update()
    return mesh


def shape_dict(mi: ModuleType, dr: ModuleType, obj: Any, name: str) -> Any:
    """Mitsuba shape (dict or Mesh object) for one scene object."""
    if isinstance(obj, SphereObject):
        return {
            "type": "sphere",
            "center": list(obj.center_m),
            "radius": obj.radius_m,
            "bsdf": bsdf_dict(mi, obj.material),
        }
    if isinstance(obj, TexturedPlaneObject):
        # Mitsuba's rectangle spans [-1, 1]^2 with uv = ((x + 1) / 2, (y + 1) / 2) and bitmap
        # row 0 at v = 0: texture columns along +x and rows along +y, as documented.
        width, height = obj.size_m
        return {
            "type": "rectangle",
            "to_world": _transform(mi, obj.pose, (width / 2, height / 2, 1.0)),
            "bsdf": bsdf_dict(mi, obj.material, albedo=obj.texture_image()),
        }
    if isinstance(obj, PlaneObject):
        width, height = obj.size_m
        return {
            "type": "rectangle",
            "to_world": _transform(mi, obj.pose, (width / 2, height / 2, 1.0)),
            "bsdf": bsdf_dict(mi, obj.material),
        }
    if isinstance(obj, BoxObject):
        x, y, z = obj.size_m
        return {
            "type": "cube",
            "to_world": _transform(mi, obj.pose, (x / 2, y / 2, z / 2)),
            "bsdf": bsdf_dict(mi, obj.material),
        }
    if isinstance(obj, MeshObject):
        return _mesh(mi, dr, obj, name)
    raise InputError(name, "a scene object", type(obj).__name__)


def light_dict(mi: ModuleType, light: AreaLight | EnvironmentLight) -> dict[str, Any]:
    """Mitsuba description of one scene light (an emitting shape, or an emitter)."""
    radiance = {"type": "rgb", "value": [float(light.radiance)] * 3}
    if isinstance(light, EnvironmentLight):
        return {"type": "constant", "radiance": radiance}
    width, height = light.size_m
    return {
        "type": "rectangle",
        "to_world": _transform(mi, light.pose, (width / 2, height / 2, 1.0)),
        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0] * 3}},
        "emitter": {"type": "area", "radiance": radiance},
    }


def scene_dict(mi: ModuleType, dr: ModuleType, scene: Scene) -> dict[str, Any]:
    """Mitsuba ``load_dict`` description of the scene's shapes and lights (no projector, no
    sensor)."""
    result: dict[str, Any] = {"type": "scene"}
    for index, (obj, name) in enumerate(
        zip(scene.all_objects(), scene.object_names(), strict=True)
    ):
        result[f"shape_{index:03d}"] = shape_dict(mi, dr, obj, name)
    for index, light in enumerate(scene.lights):
        result[f"light_{index:03d}"] = light_dict(mi, light)
    return result


def check_in_front(scene: Scene, world2cam: Pose) -> None:
    """Raise :class:`InputError` naming any object that lies entirely behind the camera."""
    for obj, name in zip(scene.all_objects(), scene.object_names(), strict=True):
        z = world2cam.apply(_bounds_world(obj))[:, 2]
        if z.max() <= 0:
            raise InputError(
                f"scene.{name}",
                "an object in front of the camera (z > 0 in the camera frame)",
                f"all of it at z <= {z.max():.3g} m",
            )


#: A file modified less than this long (seconds) before a load is not cached: where file
#: times are coarse, an edit within the same tick would leave its signature unchanged.
_RECENT_S = 2.0


def load_scene(variant: str, scene: Scene) -> Any:
    """The Mitsuba scene of ``scene`` in ``variant``. Poses of one scene (a calibration's
    camera moves, a turntable's views, a dataset's object, a benchmark) reuse the last two
    loaded: its BVH build is ~1.5 ms of a ~10 ms GPU pass, and reading and building a
    328k-face mesh file much more. A scene that reads files (meshes, texture images) is
    reused only while every file keeps its identity, size and modification time (and was
    not modified within :data:`_RECENT_S`), so an edited file is never rendered stale."""
    try:
        signature = _file_signature(scene)
        if signature is not None:
            return _cached_scene(variant, scene, signature)
    except TypeError:  # a scene holding unhashable values is loaded each time
        pass
    mi, dr, _ = mitsuba(variant)
    return mi.load_dict(scene_dict(mi, dr, scene))


def _paths(value: Any) -> Iterator[Path]:
    """Every file a scene (or any model, list or tuple inside it) names."""
    if isinstance(value, Path):
        yield value
    elif isinstance(value, list | tuple):
        for item in value:
            yield from _paths(item)
    else:
        for name in getattr(type(value), "model_fields", None) or ():
            yield from _paths(getattr(value, name))


def reads_files(value: Any) -> bool:
    """True when a scene (or any model, list or tuple inside it) names a file."""
    return next(_paths(value), None) is not None


def _file_signature(scene: Any) -> tuple[tuple[Any, ...], ...] | None:
    """``(path, device, inode, size, mtime_ns, ctime_ns)`` of each file a scene (or object) reads
    (empty for none), or None where a file is missing (the loader says so) or recent."""
    now, signature = time.time(), []
    for path in _paths(scene):
        try:
            st = os.stat(path)
        except OSError:
            return None
        if now - st.st_mtime < _RECENT_S:
            return None
        signature.append(
            (os.path.abspath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns,
             st.st_ctime_ns)
        )  # fmt: skip
    return tuple(signature)


@functools.lru_cache(maxsize=2)
def _cached_scene(variant: str, scene: Scene, signature: tuple[tuple[Any, ...], ...]) -> Any:
    mi, dr, _ = mitsuba(variant)
    return mi.load_dict(scene_dict(mi, dr, scene))


def _bounds_world(obj: Any) -> np.ndarray:
    """``obj.bounds_world()``, kept while the object and its files are unchanged (a mesh's
    bounds read the whole file: 0.15 s a pose for the 328k-face free-form object)."""
    try:
        signature = _file_signature(obj)
        if signature is not None:
            return _cached_bounds(obj, signature)
    except TypeError:  # an unhashable object
        pass
    return obj.bounds_world()


@functools.lru_cache(maxsize=16)
def _cached_bounds(obj: Any, signature: tuple[tuple[Any, ...], ...]) -> np.ndarray:
    bounds = np.array(obj.bounds_world(), dtype=np.float64)
    bounds.setflags(write=False)
    return bounds
