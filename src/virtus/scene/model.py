"""Scene description: objects, materials, a background plane and ambient light (YAML I/O).

A :class:`Scene` is a validated, renderer-independent description; :mod:`virtus.render` turns
it into a Mitsuba scene. Conventions:

* Lengths in metres. Every object carries an ``object2world`` pose (``X_world = R X_obj + t``);
  the world frame is the camera frame unless the renderer is given another ``cam2world``.
* Albedos and textures are linear diffuse reflectances in [0, 1] (not sRGB-encoded).
* A texture image is indexed ``[row, col]``; on a plane its columns run along the local +x
  axis, its rows along local +y, and its centre sits at the local origin.
* Radiometric units are relative: the projector's full-on white gives a Lambertian surface of
  albedo 1, facing it at 1 m on its axis, a radiance of 1. ``Scene.ambient`` is the level of a
  uniform ambient light in the same units (ambient radiance = ambient x diffuse albedo).
* ``Scene.lights`` are light sources with shadows and interreflections, in the same units:
  rectangular area lights (a Lambertian emitter of radiance L on its front, local +z, side:
  a facing surface close to a large panel gets irradiance pi L) and an environment of
  constant radiance L from every direction (an unoccluded Lambertian surface of albedo rho
  then has radiance rho L, the same as ``ambient = L``).

Bounds (each refusal is an :class:`~virtus.errors.InputError` naming the key or file):
every number finite; lengths (radii, sizes, centres, translations, mesh vertices in the
world) within :data:`MAX_LENGTH_M`; the YAML file read through :mod:`virtus.io.safeio`
(size, UTF-8, aliases, depth); mesh files at most :data:`MAX_MESH_BYTES`, of the size
their header says (a truncated STL or PLY is refused: :mod:`virtus.scene.meshfiles`), with
finite vertices, valid face indices, no degenerate (zero-area) faces; textures at most
:data:`MAX_TEXTURE_BYTES`.

YAML example (unknown keys are rejected with an error naming the key)::

    ambient: 0.02
    lights:
      - type: area
        size_m: [0.5, 0.5]
        radiance: 2.0
        pose: {euler_deg: [-90, 0, 0], t: [0, -0.6, 1.0]}   # above, facing down (+y)
      - type: environment
        radiance: 0.05
    objects:
      - type: sphere
        radius_m: 0.1
        center_m: [0, 0, 1.0]
        material: {albedo: 0.8, roughness: 0.95, specular: 0.15}
      - type: mesh
        path: part.stl          # relative to the YAML file
        scale_to_m: 0.001       # the file is in millimetres
        pose: {euler_deg: [0, 30, 0], t: [0, 0, 1.1]}
    background:
      type: plane
      size_m: [2, 2]
      pose: {R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]], t: [0, 0, 1.3]}
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_serializer,
    field_validator,
    model_validator,
)

from virtus.errors import InputError, VirtusError
from virtus.geometry.transforms import Pose
from virtus.io.safeio import check_file, is_file, load_npy, read_yaml
from virtus.scene.meshfiles import check_mesh_file, load_mesh_file

#: Largest length or coordinate a scene may hold, metres (1 km). Bench FPP scenes span
#: metres; Mitsuba traces in float32, whose spacing at 1 km is already 0.06 mm, so larger
#: values (a sphere of radius 1e300, a size in millimetres given as metres x 1e6) are
#: mistakes that would render as garbage.
MAX_LENGTH_M = 1000.0
#: Largest ambient level, relative to the projector's white: 1000x drowns the fringes by
#: three orders of magnitude; larger values are mistakes.
MAX_AMBIENT = 1000.0
#: Largest mesh file read (bytes): a 10-million-face binary STL is 500 MB; trimesh needs
#: several times the file size in memory.
MAX_MESH_BYTES = 512 * 2**20
#: Largest texture file read (bytes), images and .npy alike: 1 GiB holds an 11k x 11k
#: float64 texture; boards and albedo maps need a few thousand pixels across.
MAX_TEXTURE_BYTES = 2**30
#: File suffixes trimesh reads for :class:`MeshObject`.
MESH_SUFFIXES = (".stl", ".obj", ".ply")
#: Image suffixes accepted as textures (read with OpenCV) besides ``.npy`` float arrays.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr")
#: Scene keys that hold file paths (resolved against, or made relative to, a folder).
_PATH_KEYS = ("path", "texture", "albedo")
#: (8, 3) float64: the corners of the cube [-1, 1]^3.
_CORNER_SIGNS = np.array(np.meshgrid(*([[-1.0, 1.0]] * 3), indexing="ij")).reshape(3, -1).T
#: Raised when in-memory textures would have to be written without an asset folder.
_NO_ASSET_DIR = (
    "an in-memory texture cannot be written to a scene file without an asset folder; "
    "use Scene.to_yaml(path) or Scene.to_dict(asset_dir=...)"
)

__all__ = [
    "MAX_AMBIENT",
    "MAX_LENGTH_M",
    "MAX_MESH_BYTES",
    "MAX_TEXTURE_BYTES",
    "BoxObject",
    "Material",
    "MeshObject",
    "PlaneObject",
    "Scene",
    "SceneObject",
    "SphereObject",
    "TexturedPlaneObject",
    "AreaLight",
    "EnvironmentLight",
    "default_scene",
    "load_scene",
    "load_texture",
    "unchangeable_image",
]


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def _error_from_validation(error: ValidationError, prefix: str) -> InputError:
    """Turn pydantic's first error into one :class:`InputError` line naming the key."""
    first = error.errors()[0]
    # Drop the union tags and model names pydantic inserts into the location.
    parts = [str(part) for part in first["loc"] if str(part) not in _LOC_NOISE]
    loc = ".".join([prefix, *parts])
    got = first.get("input")
    if isinstance(got, np.ndarray):
        got = f"an array of shape {got.shape}"
    if first["type"] == "extra_forbidden":  # (a key named like a union tag leaves no part)
        key = parts[-1] if parts else str(first["loc"][-1]) if first["loc"] else ""
        return InputError(loc, "no such key (unknown keys are rejected)", f"key {key!r}")
    if first["type"] == "missing":
        return InputError(loc, "this required key", "nothing")
    if first["type"] in ("union_tag_invalid", "union_tag_not_found"):
        kinds = "sphere, plane, box, mesh, textured_plane"
        kind = got.get("type") if isinstance(got, Mapping) else got
        return InputError(f"{loc}.type", f"an object type ({kinds})", kind)
    cause = (first.get("ctx") or {}).get("error")
    if isinstance(cause, InputError):
        # Our own validators (and nested models) already phrased "expected ..., got ...";
        # keep their words and join the key paths without repeating a part.
        if parts and cause.name.startswith(f"{parts[-1]} "):  # "path <file>": kept whole
            name = ".".join([prefix, *parts]) + cause.name.removeprefix(parts[-1])
            return InputError(name, cause.expected, cause.got)
        inner = [part for part in cause.name.split(".") if part not in _LOC_NOISE]
        if parts and inner and parts[-1] == inner[0]:
            inner = inner[1:]
        return InputError(".".join([prefix, *parts, *inner]), cause.expected, cause.got)
    message = first["msg"].removeprefix("Value error, ").removeprefix("Input should be ")
    return InputError(loc, message, got)


def _prefix(class_name: str) -> str:
    return "scene" if class_name == "Scene" else class_name


class _Model(BaseModel):
    """Frozen pydantic model whose validation errors are :class:`InputError` lines."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, arbitrary_types_allowed=True, allow_inf_nan=False
    )
    #: Field names that may be given positionally, in order.
    _positional: ClassVar[tuple[str, ...]] = ()

    def __init__(self, *args: Any, **data: Any) -> None:
        if len(args) > len(self._positional):
            raise InputError(
                type(self).__name__,
                f"at most {len(self._positional)} positional arguments {self._positional}",
                f"{len(args)}",
            )
        for key, value in zip(self._positional, args, strict=False):
            if key in data:
                raise InputError(key, "one value", "both a positional and a keyword value")
            data[key] = value
        try:
            super().__init__(**data)
        except ValidationError as error:
            raise _error_from_validation(error, _prefix(type(self).__name__)) from None


def _as_pose(value: Any) -> Pose:
    """Accept a Pose, ``{R, t}``, ``{euler_deg, t[, seq]}`` or a 4x4 matrix; the translation
    must lie within :data:`MAX_LENGTH_M`."""
    pose = _parse_pose(value)
    if np.abs(pose.t).max() > MAX_LENGTH_M:
        raise InputError("pose.t", f"coordinates within +-{MAX_LENGTH_M:g} m", pose.t.tolist())
    return pose


def _parse_pose(value: Any) -> Pose:
    if isinstance(value, Pose):
        return value
    if isinstance(value, Mapping):
        keys = set(value)
        if keys <= {"R", "t"} and "R" in keys:
            return Pose.from_dict({"R": value["R"], "t": value.get("t", (0.0, 0.0, 0.0))})
        if keys <= {"euler_deg", "t", "seq"} and "euler_deg" in keys:
            return Pose.from_euler(
                str(value.get("seq", "xyz")),
                value["euler_deg"],
                degrees=True,
                t=value.get("t", (0.0, 0.0, 0.0)),
            )
        if keys == {"t"}:
            return Pose(np.eye(3), value["t"])
        raise InputError(
            "pose", "{R: 3x3, t: [x, y, z]} or {euler_deg: [a, b, c], t: [x, y, z]}", dict(value)
        )
    return Pose.from_matrix(value)


def _as_vector(name: str, value: Any, length: int, *, positive_entries: bool) -> tuple:
    """``length`` finite lengths in metres, each within :data:`MAX_LENGTH_M` (and > 0 when
    ``positive_entries``)."""
    try:
        array = np.asarray(value, dtype=np.float64) if not isinstance(value, str) else None
    except (TypeError, ValueError, OverflowError):
        array = None
    if array is None or array.shape != (length,) or not np.all(np.isfinite(array)):
        raise InputError(name, f"{length} finite numbers", value)
    if positive_entries and np.any(array <= 0):
        raise InputError(name, f"{length} positive numbers (metres)", value)
    if np.any(np.abs(array) > MAX_LENGTH_M):
        raise InputError(name, f"lengths within {MAX_LENGTH_M:g} m", value)
    return tuple(float(x) for x in array)


def unchangeable_image(value: Any) -> bool:
    """True for a read-only array that owns its data: nothing can change it while it stays
    read-only (a view could change through its base; a writeable array through itself).
    Images kept so are shared by the scenes built from them and by the renderer's caches."""
    return isinstance(value, np.ndarray) and not value.flags.writeable and value.flags.owndata


def _as_unit_image(name: str, value: Any) -> np.ndarray:
    """A (H, W) float64 array in [0, 1], read-only: a copy, unless ``value`` already is a
    float64 :func:`unchangeable_image`, so scenes built from one image share it (and the
    renderer's texture made from it)."""
    reusable = unchangeable_image(value) and value.dtype == np.float64
    try:
        array = value if reusable else np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # a mapping, ragged rows, text
        raise InputError(name, "a (H, W) array of numbers in [0, 1]", value) from None
    if array.ndim != 2 or min(array.shape) < 1:
        raise InputError(name, "a (H, W) array", f"shape {array.shape}")
    if not np.all(np.isfinite(array)) or array.min() < 0 or array.max() > 1:
        raise InputError(
            name, "values in [0, 1]", f"range [{np.nanmin(array):.4g}, {np.nanmax(array):.4g}]"
        )
    if not reusable:
        array.setflags(write=False)
    return array


def _as_image_or_path(name: str, value: Any) -> Path | np.ndarray:
    if isinstance(value, str | Path):
        path = Path(value).expanduser()
        if path.suffix.lower() not in (*IMAGE_SUFFIXES, ".npy"):
            raise InputError(
                name, f"an image file ({', '.join(IMAGE_SUFFIXES)}) or .npy", str(path)
            )
        if not is_file(path):
            raise InputError(name, "an existing texture file", str(path))
        return path
    return _as_unit_image(name, value)


def load_texture(path: str | Path) -> np.ndarray:
    """Read a texture file as a (H, W) float64 albedo array in [0, 1].

    8/16-bit images are divided by 255/65535; colour images are converted to grey (OpenCV's
    luma weights); float images (``.exr``, ``.tif``, ``.npy``) must already be in [0, 1].
    """
    path = check_file(path, "texture", max_bytes=MAX_TEXTURE_BYTES, kind="texture file")
    if path.suffix.lower() == ".npy":
        return _as_unit_image(
            str(path), load_npy(path, "texture", max_bytes=MAX_TEXTURE_BYTES, shape=(None, None))
        )
    import cv2

    from virtus.io.images import IMAGE_SUFFIXES as CHECKED
    from virtus.io.images import check_image_size, image_size, quiet_codecs

    try:  # a PNG, TIFF or BMP header (told by its bytes) is checked before decoding
        width, height = image_size(path)
    except InputError:
        if path.suffix.lower() in CHECKED:
            raise
    else:
        check_image_size(path, width, height)
    with quiet_codecs():
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(str(path), "an image OpenCV can read", "an unreadable file")
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    if np.issubdtype(image.dtype, np.integer):
        image = image.astype(np.float64) / np.iinfo(image.dtype).max
    return _as_unit_image(str(path), image)


# --------------------------------------------------------------------------------------------
# materials
# --------------------------------------------------------------------------------------------


class Material(_Model):
    """Surface reflectance.

    The renderer maps it to a Mitsuba BSDF: ``metal`` -> a principled BSDF with
    ``metallic = 1`` (albedo = specular reflectance colour); ``specular == 0`` -> an ideal
    Lambertian (``diffuse``); otherwise a principled (Disney) BSDF with this base colour,
    roughness and specular. All surfaces reflect on both sides.
    """

    _positional: ClassVar[tuple[str, ...]] = ("albedo", "roughness", "specular", "metal")

    albedo: float | Path | np.ndarray = 0.8
    """Diffuse albedo in [0, 1]: a constant, an image/.npy file, or an in-memory (H, W) array
    (texture mapped with the shape's uv coordinates)."""
    roughness: float = Field(0.95, ge=0.0, le=1.0)
    """Perceptual roughness in [0, 1] (the paper's matte default: 0.95)."""
    specular: float = Field(0.15, ge=0.0, le=1.0)
    """Specular reflection strength in [0, 1] (the paper's default: 0.15)."""
    metal: bool = False
    """A conductor: no diffuse lobe, the albedo tints the specular reflection."""

    @field_validator("albedo", mode="before")
    @classmethod
    def _check_albedo(cls, value: Any) -> Any:
        if isinstance(value, bool):
            raise InputError("albedo", "a number in [0, 1], a texture path or an array", value)
        if isinstance(value, int | float | np.floating | np.integer):
            value = float(value)
            if not 0.0 <= value <= 1.0:
                raise InputError("albedo", "a number in [0, 1]", value)
            return value
        return _as_image_or_path("albedo", value)

    @property
    def is_textured(self) -> bool:
        """True when the albedo is an image rather than a constant."""
        return not isinstance(self.albedo, float)

    def albedo_image(self) -> np.ndarray | None:
        """The albedo texture as a (H, W) float64 array in [0, 1], or None for a constant."""
        if isinstance(self.albedo, float):
            return None
        if isinstance(self.albedo, Path):
            return load_texture(self.albedo)
        return self.albedo

    @field_serializer("albedo")
    def _dump_albedo(self, value: Any) -> Any:
        return _dump_image_or_path(value)


#: Set by :meth:`Scene.to_dict` while it writes in-memory arrays to an asset folder.
_ASSET_WRITER: list[Any] = []


def _dump_image_or_path(value: Any) -> Any:
    if isinstance(value, float):
        return value
    if isinstance(value, Path):
        return str(value)
    if not _ASSET_WRITER:
        raise VirtusError(_NO_ASSET_DIR)
    return _ASSET_WRITER[-1](value)


# --------------------------------------------------------------------------------------------
# objects
# --------------------------------------------------------------------------------------------


class _Posed(_Model):
    pose: Pose = Field(default_factory=Pose.identity)
    """object2world: maps object-local points (metres) to the world (= camera) frame."""

    @field_validator("pose", mode="before")
    @classmethod
    def _check_pose(cls, value: Any) -> Pose:
        return _as_pose(value)

    @field_serializer("pose")
    def _dump_pose(self, value: Pose) -> dict[str, Any]:
        return value.to_dict()

    def _corners_world(self, half: np.ndarray) -> np.ndarray:
        """(8, 3) world-frame corners of the local box [-half, half], metres."""
        return self.pose.apply(_CORNER_SIGNS * half)


class _Rectangle(_Posed):
    """Base of the flat objects: ``size_m = (width, height)`` in the local z = 0 plane,
    centred at the local origin (subclasses declare the field, so dumps keep their order)."""

    @field_validator("size_m", mode="before", check_fields=False)
    @classmethod
    def _check_size(cls, value: Any) -> tuple:
        return _as_vector("size_m", value, 2, positive_entries=True)

    def bounds_world(self) -> np.ndarray:
        """(8, 3) float64 world-frame corners (the 4 corners, twice), metres."""
        width, height = self.size_m  # type: ignore[attr-defined]
        return self._corners_world(np.array([width / 2, height / 2, 0.0]))


class SphereObject(_Model):
    """A sphere of radius ``radius_m`` centred at ``center_m`` (world frame, metres)."""

    _positional: ClassVar[tuple[str, ...]] = ("radius_m", "center_m", "material")
    type: Literal["sphere"] = "sphere"
    radius_m: float = Field(gt=0.0, le=MAX_LENGTH_M)
    """Radius in metres, in (0, :data:`MAX_LENGTH_M`]."""
    center_m: tuple[float, float, float]
    """Centre (x, y, z) in metres, world frame."""
    material: Material = Field(default_factory=Material)

    @field_validator("center_m", mode="before")
    @classmethod
    def _check_center(cls, value: Any) -> tuple:
        return _as_vector("center_m", value, 3, positive_entries=False)

    def bounds_world(self) -> np.ndarray:
        """(8, 3) float64 corners of a world-frame box enclosing the object, metres."""
        return np.asarray(self.center_m) + self.radius_m * _CORNER_SIGNS


class PlaneObject(_Rectangle):
    """A rectangle ``size_m = (width, height)`` in its local z = 0 plane, centred at the
    local origin (width along local x); reflects on both sides."""

    _positional: ClassVar[tuple[str, ...]] = ("size_m", "pose", "material")
    type: Literal["plane"] = "plane"
    size_m: tuple[float, float]
    """(width along local x, height along local y) in metres."""
    material: Material = Field(default_factory=Material)


class BoxObject(_Posed):
    """A box with edge lengths ``size_m = (x, y, z)`` centred at the local origin."""

    _positional: ClassVar[tuple[str, ...]] = ("size_m", "pose", "material")
    type: Literal["box"] = "box"
    size_m: tuple[float, float, float]
    """Edge lengths along local x, y, z in metres."""
    material: Material = Field(default_factory=Material)

    @field_validator("size_m", mode="before")
    @classmethod
    def _check_size(cls, value: Any) -> tuple:
        return _as_vector("size_m", value, 3, positive_entries=True)

    def bounds_world(self) -> np.ndarray:
        """(8, 3) float64 world-frame corners, metres."""
        return self._corners_world(np.asarray(self.size_m) / 2)


class MeshObject(_Posed):
    """A triangle mesh from an STL, OBJ or PLY file (read with trimesh).

    Vertices are multiplied by ``scale_to_m`` (e.g. 0.001 for a file in millimetres) and then
    mapped by ``pose``. Faces are shaded flat (the file's geometry is the truth).
    """

    _positional: ClassVar[tuple[str, ...]] = ("path", "scale_to_m", "pose", "material")
    type: Literal["mesh"] = "mesh"
    path: Path
    """Mesh file (.stl, .obj, .ply); relative paths in YAML are relative to the YAML file."""
    scale_to_m: float = Field(1.0, gt=0.0)
    """Metres per file unit."""
    material: Material = Field(default_factory=Material)

    @field_validator("path", mode="before")
    @classmethod
    def _check_path(cls, value: Any) -> Path:
        if not isinstance(value, str | Path):
            raise InputError("path", "a mesh file path", value)
        path = Path(value).expanduser()
        if path.suffix.lower() not in MESH_SUFFIXES:
            raise InputError("path", f"a mesh file ({', '.join(MESH_SUFFIXES)})", str(path))
        if not is_file(path):
            raise InputError("path", "an existing mesh file", str(path))
        try:
            check_file(path, "mesh", max_bytes=MAX_MESH_BYTES, kind="mesh file")
        except InputError as error:  # too large: keep the key as the name, the path as got
            raise InputError("path", error.expected, f"{path} ({error.got})") from None
        try:
            check_mesh_file(path)  # its header against its size (a truncated file)
        except InputError as error:  # the key, then the file in full (not cut as a got)
            raise InputError(f"path {path}", error.expected, error.got) from None
        return path

    @field_serializer("path")
    def _dump_path(self, value: Path) -> str:
        return str(value)

    def load(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Read the mesh in world coordinates.

        Returns
        -------
        vertices : (V, 3) float64, metres, world frame.
        faces : (F, 3) int64 vertex indices.
        uv : (V, 2) float64 texture coordinates, or None when the file has none.
        """
        path = check_file(self.path, "mesh", max_bytes=MAX_MESH_BYTES, kind="mesh file")
        mesh = load_mesh_file(path)  # checked against its header first (scene.meshfiles)
        try:  # what trimesh made of a damaged file may not be (N, 3) numbers
            vertices = np.asarray(getattr(mesh, "vertices", ()), dtype=np.float64).reshape(-1, 3)
            faces = np.asarray(getattr(mesh, "faces", ()), dtype=np.int64).reshape(-1, 3)
            uv = getattr(getattr(mesh, "visual", None), "uv", None)
            uv = None if uv is None or len(uv) != len(vertices) else np.asarray(uv, np.float64)
        except (ValueError, TypeError, OverflowError) as error:
            raise InputError(
                f"mesh {path}", "vertices of 3 coordinates and triangle faces", str(error)
            ) from None
        _check_mesh(f"mesh {path}", vertices, faces, uv)
        world = self.pose.apply(vertices * self.scale_to_m)
        reach = float(np.abs(world).max())
        if reach > MAX_LENGTH_M:
            raise InputError(
                f"mesh {path}",
                f"vertices within +-{MAX_LENGTH_M:g} m of the world origin (check scale_to_m)",
                f"a vertex {reach:.3g} m away",
            )
        return world, faces, uv

    def bounds_world(self) -> np.ndarray:
        """(8, 3) float64 corners of the world-frame bounding box of the vertices, metres."""
        vertices = self.load()[0]
        low, high = vertices.min(axis=0), vertices.max(axis=0)
        return low + (_CORNER_SIGNS + 1.0) / 2.0 * (high - low)


def _check_mesh(label: str, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None) -> None:
    """Refuse a mesh that cannot be rendered or measured faithfully.

    Parameters
    ----------
    label : ``"mesh <path>"`` for messages.
    vertices : (V, 3) float64, file units.
    faces : (F, 3) int64 vertex indices.
    uv : (V, 2) float64 texture coordinates, or None.

    Raises
    ------
    InputError
        No triangles; non-finite vertex or uv coordinates; face indices outside
        ``[0, V)``; zero total area; or degenerate faces (zero area, e.g. a vertex index
        repeated: they have no normal and break point-to-mesh distances).
    """
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(label, "a mesh with triangles", "an empty mesh")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputError(
            label, "finite vertex coordinates", f"{int(bad.sum())} non-finite (first #{first})"
        )
    if uv is not None and not np.isfinite(uv).all():
        raise InputError(label, "finite texture coordinates", "non-finite uv")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(
            label,
            f"face indices in [0, {len(vertices)})",
            f"indices {int(faces.min())}..{int(faces.max())}",
        )
    corners = vertices[faces]
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    if not areas.sum() > 0:
        raise InputError(label, "a surface with area", "zero total area")
    degenerate = areas == 0  # includes every face that repeats a vertex index
    if degenerate.any():
        first = int(np.flatnonzero(degenerate)[0])
        raise InputError(
            label,
            "no degenerate faces (with trimesh: mesh.update_faces(mesh.nondegenerate_faces()))",
            f"{int(degenerate.sum())} of {len(faces)} faces with zero area (first #{first})",
        )


class TexturedPlaneObject(_Rectangle):
    """A flat board with an albedo texture (e.g. a calibration target).

    The plane is the local z = 0 plane, ``size_m = (width, height)`` centred at the local
    origin; texture columns run along local +x and rows along local +y, so texture pixel
    ``[row, col]`` of an (H, W) texture is centred at local
    ``x = (col + 0.5) * width / W - width / 2``, ``y = (row + 0.5) * height / H - height / 2``.
    The effective albedo is ``material.albedo * texture`` (the default material has albedo 1,
    so the texture values are the albedo); it reflects on both sides. ``pose`` is board2world.
    """

    _positional: ClassVar[tuple[str, ...]] = ("size_m", "texture", "pose", "material")
    type: Literal["textured_plane"] = "textured_plane"
    size_m: tuple[float, float]
    """(width along local x, height along local y) in metres."""
    texture: Path | np.ndarray
    """Albedo texture: an image/.npy file or an in-memory (H, W) float array in [0, 1]."""
    material: Material = Field(default_factory=lambda: Material(albedo=1.0))

    @field_validator("texture", mode="before")
    @classmethod
    def _check_texture(cls, value: Any) -> Any:
        return _as_image_or_path("texture", value)

    @field_validator("material")
    @classmethod
    def _check_material(cls, value: Material) -> Material:
        if value.is_textured:
            raise InputError(
                "material.albedo", "a constant (the board's texture is its albedo)", "a texture"
            )
        return value

    @field_serializer("texture")
    def _dump_texture(self, value: Any) -> Any:
        return _dump_image_or_path(value)

    def texture_image(self) -> np.ndarray:
        """(H, W) float64 albedo in [0, 1]: the texture times the material's albedo."""
        image = load_texture(self.texture) if isinstance(self.texture, Path) else self.texture
        albedo = float(self.material.albedo)  # type: ignore[arg-type]
        # The texture itself (read-only) when unscaled: the renderer reuses its texture.
        return image if albedo == 1.0 else image * albedo  # type: ignore[return-value]


# --------------------------------------------------------------------------------------------
# lights
# --------------------------------------------------------------------------------------------


class AreaLight(_Rectangle):
    """A rectangle ``size_m = (width, height)`` in its local z = 0 plane that emits a uniform
    radiance from its front (local +z) side. It is a black object too: it hides what is
    behind it and casts shadows."""

    _positional: ClassVar[tuple[str, ...]] = ("size_m", "pose", "radiance")
    type: Literal["area"] = "area"
    size_m: tuple[float, float]
    """(width along local x, height along local y) in metres."""
    radiance: float = Field(gt=0.0, le=MAX_AMBIENT)
    """Emitted radiance, relative to the projector's white (see the module docstring)."""


class EnvironmentLight(_Model):
    """Light of constant radiance arriving from every direction (an overcast sky, a lit room)
    that the scene's objects occlude."""

    _positional: ClassVar[tuple[str, ...]] = ("radiance",)
    type: Literal["environment"] = "environment"
    radiance: float = Field(gt=0.0, le=MAX_AMBIENT)
    """Radiance from every direction, relative to the projector's white."""


SceneLight = Annotated[AreaLight | EnvironmentLight, Field(discriminator="type")]


#: Location parts pydantic adds for unions and nested models (not keys of the YAML).
_LOC_NOISE = {
    "sphere", "plane", "box", "mesh", "textured_plane", "SphereObject", "PlaneObject",
    "BoxObject", "MeshObject", "TexturedPlaneObject", "Material", "area", "environment",
    "AreaLight", "EnvironmentLight",
}  # fmt: skip

SceneObject = Annotated[
    SphereObject | PlaneObject | BoxObject | MeshObject | TexturedPlaneObject,
    Field(discriminator="type"),
]


# --------------------------------------------------------------------------------------------
# scene
# --------------------------------------------------------------------------------------------


class Scene(_Model):
    """Objects to measure, an optional background plane and a uniform ambient light."""

    _positional: ClassVar[tuple[str, ...]] = ("objects", "background", "ambient")
    objects: tuple[SceneObject, ...] = ()
    """The objects (world frame = camera frame unless the renderer says otherwise)."""
    background: PlaneObject | None = None
    """A plane behind the objects (or None)."""
    ambient: float = Field(0.0, ge=0.0, le=MAX_AMBIENT)
    """Uniform ambient light level, relative to the projector's white (see module docs), in
    [0, :data:`MAX_AMBIENT`]."""
    lights: tuple[SceneLight, ...] = ()
    """Area lights and at most one environment (shadows and interreflections included)."""

    @model_validator(mode="after")
    def _not_empty(self) -> Scene:
        if not self.objects and self.background is None:
            raise InputError("objects", "at least one object or a background", "an empty scene")
        environments = sum(isinstance(light, EnvironmentLight) for light in self.lights)
        if environments > 1:
            raise InputError("lights", "at most one environment light", environments)
        return self

    def all_objects(self) -> list[Any]:
        """The objects followed by the background (if any)."""
        return [*self.objects, *([self.background] if self.background is not None else [])]

    def object_names(self) -> list[str]:
        """Names used in messages: ``objects[i]`` and ``background``."""
        names = [f"objects[{i}]" for i in range(len(self.objects))]
        return names + (["background"] if self.background is not None else [])

    def _has_arrays(self) -> bool:
        for obj in self.all_objects():
            if isinstance(obj.material.albedo, np.ndarray):
                return True
            if isinstance(getattr(obj, "texture", None), np.ndarray):
                return True
        return False

    # -- I/O -------------------------------------------------------------------------------

    def to_dict(
        self, asset_dir: str | Path | None = None, relative_to: str | Path | None = None
    ) -> dict[str, Any]:
        """JSON/YAML-ready dict. In-memory texture arrays are written as ``.npy`` files into
        ``asset_dir`` (named ``texture_<k>.npy``) and referenced by their paths; without an
        ``asset_dir`` such arrays raise :class:`VirtusError`. With ``relative_to``, file
        paths inside that folder are written relative to it (the folder can be moved)."""
        counter = [0]

        def write(array: np.ndarray) -> str:
            folder = Path(asset_dir)  # type: ignore[arg-type]
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f"texture_{counter[0]}.npy"
            counter[0] += 1
            np.save(path, np.asarray(array, dtype=np.float64))
            return str(path)

        if asset_dir is None and self._has_arrays():
            raise VirtusError(_NO_ASSET_DIR)
        if asset_dir is not None:
            _ASSET_WRITER.append(write)
        try:
            data = self.model_dump(mode="python")
        finally:
            if asset_dir is not None:
                _ASSET_WRITER.pop()
        return data if relative_to is None else _relative_paths(data, Path(relative_to))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: str | Path | None = None) -> Scene:
        """Build a scene from a dict (as read from YAML); relative file paths are resolved
        against ``base_dir``."""
        if not isinstance(data, Mapping):
            raise InputError("scene", "a mapping of scene keys", type(data).__name__)
        odd = [key for key in data if not isinstance(key, str)]
        if odd:  # YAML keys may be numbers or lists; keyword arguments must be names
            raise InputError("scene", "keys that are names", f"key {odd[0]!r}")
        if base_dir is not None:
            data = _resolve_paths(data, Path(base_dir))
        return cls(**dict(data))

    def to_yaml(self, path: str | Path) -> Path:
        """Write the scene as YAML; in-memory textures go to ``<stem>_assets/`` beside it,
        referenced by paths relative to the YAML file."""
        path = Path(path)
        assets = path.parent / f"{path.stem}_assets"
        data = self.to_dict(asset_dir=assets, relative_to=path.parent)
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        return path


def _map_paths(data: Any, function: Any) -> Any:
    if isinstance(data, Mapping):
        return {
            key: (
                function(value)
                if key in _PATH_KEYS and isinstance(value, str)
                else _map_paths(value, function)
            )
            for key, value in data.items()
        }
    if isinstance(data, list | tuple):
        return [_map_paths(item, function) for item in data]
    return data


def _resolve_paths(data: Mapping[str, Any], base: Path) -> dict[str, Any]:
    return _map_paths(data, lambda text: str(base / Path(text).expanduser()))


def _relative_paths(data: Mapping[str, Any], base: Path) -> dict[str, Any]:
    base = base.resolve()

    def relative(text: str) -> str:
        path = Path(text).resolve()
        return str(path.relative_to(base)) if path.is_relative_to(base) else str(path)

    return _map_paths(data, relative)


def load_scene(path: str | Path) -> Scene:
    """Read a scene YAML file (see the module docstring).

    The file is read through :func:`virtus.io.safeio.read_yaml` (size, UTF-8, aliases, depth,
    syntax) and must hold a mapping; unknown keys and values out of bounds raise
    :class:`InputError`. USD stages are read by :func:`virtus.pipeline.inputs.load_scene`,
    which dispatches on the suffix (this floor never imports USD).
    """
    data = read_yaml(path, "scene", expect=dict)
    return Scene.from_dict(data, base_dir=Path(path).parent)


def default_scene() -> Scene:
    """The issue's scene: a matte sphere of radius 100 mm centred 1 m in front of the camera,
    (0, 0, 1) m, and a matte 2 m x 2 m background plane at z = 1.3 m facing the camera."""
    return Scene(
        objects=(SphereObject(radius_m=0.1, center_m=(0.0, 0.0, 1.0)),),
        background=PlaneObject(size_m=(2.0, 2.0), pose=Pose(np.eye(3), (0.0, 0.0, 1.3))),
    )
