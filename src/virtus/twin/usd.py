"""USD stages in and out: rigs (camera, projector) and scenes for NVIDIA Isaac Sim.

Needs ``usd-core`` (``pip install 'virtus-fpp[usd]'``); without it every function raises
:class:`MissingDependency`, one line saying so. Nothing else in virtus imports ``pxr``.

Writing (:func:`export_usd`): a stage with ``metersPerUnit`` stated (1 or 0.01, ...), up
axis Z and Isaac's world (the camera at the origin looking along +X, +Z up;
:mod:`virtus.twin.parameters`)::

    /World                       Xform (default prim); virtus:ambient
    /World/Rig/Camera            UsdGeom.Camera: focalLength, apertures and offsets in tenths
                                 of a scene unit (virtus.geometry.isaac), clippingRange;
                                 OmniLensDistortionOpenCvPinholeAPI (omni:lensdistortion:*,
                                 pixels, float); virtus:opencv:K (matrix3d),
                                 virtus:opencv:dist (double[]), virtus:opencv:imageSize
    /World/Rig/Projector         UsdLux.RectLight + ShapingAPI: width and height (scene units)
                                 of the projected image at 1 m, inputs:texture:file (the
                                 pattern, mirrored left-right: see RECTLIGHT_MIRROR),
                                 bool isProjector = true; virtus:opencv:* as the camera
    /World/Objects/<name>        UsdGeom.Sphere | Cube (size 1, scaled) | Mesh (planes: the
                                 unit square scaled; meshes: the file's vertices, scale_to_m
                                 in the transform), xformOp:transform (matrix4d), a bound
    /World/Looks/<name>          UsdShade.Material with a UsdPreviewSurface (diffuseColor,
                                 roughness, metallic, ior; a UsdUVTexture for boards)

USD stores lens values, points and colours as 32-bit floats; the ``virtus:opencv:*``
attributes keep the calibration in double precision, and geometry goes through double
transforms (unit shapes, scales in the matrix) so a round trip keeps metres to 1e-9.
Material values read from float attributes are rounded to 7 significant digits (0.8 stays
0.8), ``specular`` (through ``ior``) to 5. ``specular`` (Disney, F0 = 0.08 s) is written
as UsdPreviewSurface's ``ior``: ``ior = (1 + sqrt(F0)) / (1 - sqrt(F0))`` (0.5 -> 1.5,
USD's default).

Reading (:func:`read_usd`, :func:`load_usd_scene`): meshes, spheres and cubes with their
world transforms and UsdPreviewSurface base colour (grey = mean of RGB), roughness,
metallic (>= 0.5: a metal) and ior; the camera (prefers ``virtus:opencv:*``, then the
Omniverse lens attributes, then the pinhole attributes) and its pose; the projector light.
Scenes are returned in the stage camera's OpenCV frame (virtus's world = camera frame), so
``virtus scan --scene stage.usda`` sees what the stage's camera sees. Mesh prims are
written as PLY files (their float32 points unchanged, a uniform scale kept in
``scale_to_m``) into ``<stage>_meshes/`` next to the stage, since scene meshes are files.
"""

from __future__ import annotations

import contextlib
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import positive
from virtus.errors import InputError, MissingDependency, VirtusError
from virtus.geometry.devices import Camera, Projector, Rig
from virtus.geometry.isaac import CV_TO_USD_CAMERA, intrinsics_from_isaac, usd_camera_params
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.twin.parameters import (
    DEFAULT_PIXEL_SIZE_M,
    DIST_NAMES,
    OPENCV_PINHOLE,
    camera_world_pose,
    lens_distortion_attributes,
    prim_transform,
    twin_parameters,
)

__all__ = [
    "CAMERA",
    "PROJECTOR",
    "USD_MISSING",
    "USD_SUFFIXES",
    "UsdContents",
    "export_usd",
    "is_usd_path",
    "load_usd_scene",
    "read_usd",
    "require_usd",
    "usd_camera_intrinsics",
]

#: The one line printed when usd-core is missing.
USD_MISSING = "USD support needs usd-core: pip install 'virtus-fpp[usd]'"
#: Stage file suffixes read as USD.
USD_SUFFIXES = (".usda", ".usdc", ".usd")
#: Omniverse's applied schema for OpenCV pinhole cameras with distortion.
LENS_API = "OmniLensDistortionOpenCvPinholeAPI"
#: Isaac's RectLight puts the texture's first column at the light's +X edge (DESIGN.md
#: section 10: "texture min is at (+X, +Y)"); seen from the projector (looking along -Z,
#: +Y up) +X is on the right, so the pattern is written mirrored left-right for its pixel
#: (0, 0) to light the top-left of the projector's field, as OpenCV's u_p = v_p = 0.
RECTLIGHT_MIRROR = True
#: Prim paths written by :func:`export_usd`.
WORLD, CAMERA, PROJECTOR = "/World", "/World/Rig/Camera", "/World/Rig/Projector"
OBJECTS, LOOKS = "/World/Objects", "/World/Looks"
#: Clipping range of the camera, metres.
CLIPPING_M = (0.01, 1000.0)


def require_usd() -> Any:
    """The ``pxr`` package, or :class:`MissingDependency` with :data:`USD_MISSING`."""
    try:
        import pxr
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade  # noqa: F401
    except ImportError:
        raise MissingDependency(USD_MISSING) from None
    return pxr


def is_usd_path(path: str | Path) -> bool:
    """True for a ``.usda``/``.usdc``/``.usd`` file name."""
    return Path(path).suffix.lower() in USD_SUFFIXES


# -- small conversions --------------------------------------------------------------------


def _gf_matrix(pose_or_matrix: Pose | np.ndarray) -> Any:
    from pxr import Gf

    m = pose_or_matrix.matrix if isinstance(pose_or_matrix, Pose) else pose_or_matrix
    return Gf.Matrix4d(np.asarray(m, dtype=np.float64).T.tolist())  # Gf: row vectors


def _np_matrix(gf_matrix: Any) -> np.ndarray:
    return np.array(gf_matrix, dtype=np.float64).T


def _world_matrix(prim: Any) -> np.ndarray:
    """(4, 4) prim-local -> stage world transform (scene units, column vectors)."""
    from pxr import Usd, UsdGeom

    xformable = UsdGeom.Xformable(prim)
    return _np_matrix(xformable.ComputeLocalToWorldTransform(Usd.TimeCode.Default()))


def _f32(value: float) -> float:
    """A value read from a 32-bit float attribute, rounded to 7 significant digits."""
    return float(f"{float(value):.7g}")


def _ior(specular: float) -> float:
    f0 = 0.08 * specular
    return (1 + np.sqrt(f0)) / (1 - np.sqrt(f0))


def _specular(ior: float) -> float:
    f0 = ((ior - 1) / (ior + 1)) ** 2
    return float(np.clip(f0 / 0.08, 0.0, 1.0))


def _split_scale(matrix: np.ndarray, where: str) -> tuple[Pose, np.ndarray]:
    """(rotation + translation, per-axis scale) of a (4, 4) transform without shear."""
    linear = matrix[:3, :3]
    scale = np.linalg.norm(linear, axis=0)
    if (scale <= 0).any():
        raise InputError(where, "a transform with non-zero scale", scale.tolist())
    rotation = linear / scale
    if np.linalg.det(rotation) < 0:
        scale[2], rotation[:, 2] = -scale[2], -rotation[:, 2]
    if np.max(np.abs(rotation.T @ rotation - np.eye(3))) > 1e-9:
        raise InputError(where, "a transform without shear", matrix.tolist())
    return Pose(rotation, matrix[:3, 3]), scale


# -- writing --------------------------------------------------------------------------------


def _set_opencv(prim: Any, intrinsics: Intrinsics) -> None:
    from pxr import Gf, Sdf

    prim.CreateAttribute("virtus:opencv:K", Sdf.ValueTypeNames.Matrix3d).Set(
        Gf.Matrix3d(intrinsics.K.tolist())
    )
    prim.CreateAttribute("virtus:opencv:dist", Sdf.ValueTypeNames.DoubleArray).Set(
        [float(d) for d in intrinsics.dist]
    )
    prim.CreateAttribute("virtus:opencv:imageSize", Sdf.ValueTypeNames.Int2).Set(
        Gf.Vec2i(intrinsics.width, intrinsics.height)
    )


def _write_camera(stage: Any, intrinsics: Intrinsics, prim2world: Pose, mpu: float, pitch: float):
    from pxr import Gf, Sdf, UsdGeom

    camera = UsdGeom.Camera.Define(stage, CAMERA)
    params = usd_camera_params(intrinsics, pitch, mpu)
    camera.CreateFocalLengthAttr(params.focal_length)
    camera.CreateHorizontalApertureAttr(params.horizontal_aperture)
    camera.CreateVerticalApertureAttr(params.vertical_aperture)
    camera.CreateHorizontalApertureOffsetAttr(params.horizontal_aperture_offset)
    camera.CreateVerticalApertureOffsetAttr(params.vertical_aperture_offset)
    camera.CreateClippingRangeAttr(Gf.Vec2f(CLIPPING_M[0] / mpu, CLIPPING_M[1] / mpu))
    camera.AddTransformOp().Set(_gf_matrix(_scene_units(prim2world, mpu)))
    prim = camera.GetPrim()
    prim.AddAppliedSchema(LENS_API)
    for name, value in lens_distortion_attributes(intrinsics).items():
        if name.endswith(":model"):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Token).Set(value)
        elif name.endswith(":imageSize"):
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Int2).Set(Gf.Vec2i(*value))
        else:
            prim.CreateAttribute(name, Sdf.ValueTypeNames.Float).Set(float(value))
    prim.CreateAttribute("virtus:pixelSize_m", Sdf.ValueTypeNames.Double).Set(pitch)
    _set_opencv(prim, intrinsics)


def _scene_units(pose: Pose, mpu: float) -> np.ndarray:
    m = pose.matrix
    m[:3, 3] /= mpu
    return m


def _write_projector(
    stage: Any, rig: Rig, params: dict[str, Any], prim2world: Pose, mpu: float, texture: Path
) -> None:
    from pxr import Sdf, UsdLux

    light = UsdLux.RectLight.Define(stage, PROJECTOR)
    light.CreateWidthAttr(params["width"])
    light.CreateHeightAttr(params["height"])
    light.CreateTextureFileAttr(Sdf.AssetPath(texture.name))
    light.AddTransformOp().Set(_gf_matrix(_scene_units(prim2world, mpu)))
    prim = light.GetPrim()
    shaping = UsdLux.ShapingAPI.Apply(prim)
    proj = rig.projector.intrinsics
    half = np.degrees(np.arctan(np.hypot(proj.width, proj.height) / (2 * min(proj.fx, proj.fy))))
    shaping.CreateShapingConeAngleAttr(float(half))
    prim.CreateAttribute("isProjector", Sdf.ValueTypeNames.Bool).Set(True)
    _set_opencv(prim, proj)


def _write_texture(path: Path, image: np.ndarray) -> Path:
    import cv2

    image = np.asarray(image)
    if image.dtype.kind == "f":
        image = np.rint(np.clip(image, 0, 1) * 65535).astype(np.uint16)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise VirtusError(f"{path}: could not write the texture")
    return path


def _write_material(stage: Any, name: str, material: Any, texture: str | None) -> Any:
    from pxr import Gf, Sdf, UsdShade

    look = UsdShade.Material.Define(stage, f"{LOOKS}/{name}")
    shader = UsdShade.Shader.Define(stage, f"{LOOKS}/{name}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    albedo = 1.0 if material.is_textured else float(material.albedo)
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(albedo))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(material.roughness)
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(1.0 if material.metal else 0.0)
    shader.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(_ior(material.specular)))
    look.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    if texture is not None:
        reader = UsdShade.Shader.Define(stage, f"{LOOKS}/{name}/st")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
        image = UsdShade.Shader.Define(stage, f"{LOOKS}/{name}/texture")
        image.CreateIdAttr("UsdUVTexture")
        image.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(texture))
        image.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        image.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
            reader.ConnectableAPI(), "result"
        )
        image.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
        shader.GetInput("diffuseColor").ConnectToSource(image.ConnectableAPI(), "rgb")
    return look


def _bind(prim: Any, look: Any) -> None:
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(look)


def _unit_square(stage: Any, path: str, uv: bool) -> Any:
    from pxr import Sdf, UsdGeom

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([(-0.5, -0.5, 0.0), (0.5, -0.5, 0.0), (0.5, 0.5, 0.0), (-0.5, 0.5, 0.0)])
    mesh.CreateFaceVertexCountsAttr([3, 3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 0, 2, 3])
    mesh.CreateDoubleSidedAttr(True)
    if uv:  # texture row 0 (local y = -h/2) is the top of the image: v = 0.5 - y
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
        )
        st.Set([(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)])
    return mesh


def _write_object(
    stage: Any, name: str, obj: Any, scene2world: Pose, mpu: float, assets: Path, role: str
) -> None:
    from pxr import Sdf, UsdGeom

    from virtus.scene.meshfiles import load_mesh_file
    from virtus.scene.model import (
        BoxObject,
        MeshObject,
        PlaneObject,
        SphereObject,
        TexturedPlaneObject,
    )

    path = f"{OBJECTS}/{name}"
    texture = None
    if isinstance(obj, SphereObject):
        prim = UsdGeom.Sphere.Define(stage, path)
        prim.CreateRadiusAttr(obj.radius_m / mpu)
        pose, scale = Pose(np.eye(3), obj.center_m), np.ones(3)
    elif isinstance(obj, BoxObject):
        prim = UsdGeom.Cube.Define(stage, path)
        prim.CreateSizeAttr(1.0)
        pose, scale = obj.pose, np.asarray(obj.size_m) / mpu
    elif isinstance(obj, PlaneObject | TexturedPlaneObject):
        textured = isinstance(obj, TexturedPlaneObject)
        prim = _unit_square(stage, path, textured)
        pose, scale = obj.pose, np.array([*obj.size_m, 1.0]) / np.array([mpu, mpu, 1.0])
        if textured:
            if isinstance(obj.texture, Path):
                texture = str(obj.texture.resolve())
            else:
                file = _write_texture(assets / f"{name}.png", obj.texture)
                texture = f"{assets.name}/{file.name}"
    elif isinstance(obj, MeshObject):
        mesh = load_mesh_file(obj.path)  # checked against its header (a truncated file)
        prim = UsdGeom.Mesh.Define(stage, path)
        points = np.asarray(mesh.vertices, dtype=np.float32)
        prim.CreatePointsAttr(points.tolist())
        faces = np.asarray(mesh.faces, dtype=np.int64)
        prim.CreateFaceVertexCountsAttr([3] * len(faces))
        prim.CreateFaceVertexIndicesAttr(faces.ravel().tolist())
        prim.CreateDoubleSidedAttr(True)
        pose, scale = obj.pose, np.full(3, obj.scale_to_m / mpu)
    else:
        raise InputError(f"scene object {name}", "a sphere, box, plane or mesh", type(obj))
    world = scene2world @ pose
    matrix = world.matrix
    matrix[:3, 3] /= mpu
    matrix[:3, :3] = matrix[:3, :3] * scale
    prim.AddTransformOp().Set(_gf_matrix(matrix))
    usd_prim = prim.GetPrim()
    usd_prim.CreateAttribute("virtus:type", Sdf.ValueTypeNames.String).Set(obj.type)
    usd_prim.CreateAttribute("virtus:role", Sdf.ValueTypeNames.String).Set(role)
    _bind(usd_prim, _write_material(stage, name, obj.material, texture))


def export_usd(
    path: str | Path,
    *,
    scene: Any = None,
    rig: Rig | None = None,
    cam2world: Pose | None = None,
    meters_per_unit: float = 1.0,
    pixel_size_m: float = DEFAULT_PIXEL_SIZE_M,
    pattern: np.ndarray | None = None,
) -> Path:
    """Write a scene and/or a rig as a USD stage for Isaac Sim (layout: module docstring).

    Parameters
    ----------
    path : the stage file (``.usda`` text, ``.usdc``/``.usd`` binary).
    scene : a :class:`virtus.scene.model.Scene` (its world frame: the camera frame unless
        ``cam2world`` says otherwise) or None.
    rig : the rig whose camera and projector are written (None: no devices; the stage's
        world still puts the camera frame at the origin looking along +X).
    cam2world : the camera's pose in the scene's world (default identity).
    meters_per_unit : the stage's ``metersPerUnit``.
    pixel_size_m : pixel pitch of the USD camera (:mod:`virtus.geometry.isaac`), metres.
    pattern : (H_p, W_p) image the projector shows (uint8/uint16 or floats in [0, 1]);
        default: full white. Written beside the stage, mirrored (:data:`RECTLIGHT_MIRROR`).

    Returns
    -------
    The stage's path.
    """
    require_usd()
    from pxr import Sdf, Usd, UsdGeom

    if scene is None and rig is None:
        raise InputError("export_usd", "a scene, a rig or both", None)
    path = Path(path)
    if not is_usd_path(path):
        raise InputError("out", f"a USD file ({', '.join(USD_SUFFIXES)})", str(path))
    meters_per_unit = positive("meters_per_unit", meters_per_unit)
    if scene is not None:  # every mesh file is checked before anything is written
        from virtus.scene.meshfiles import check_mesh_file

        for obj in (*scene.objects, scene.background):
            if getattr(obj, "type", None) == "mesh":
                check_mesh_file(obj.path)
    path.parent.mkdir(parents=True, exist_ok=True)
    assets = path.parent / f"{path.stem}_assets"
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    world = UsdGeom.Xform.Define(stage, WORLD)
    stage.SetDefaultPrim(world.GetPrim())
    cam_in_isaac = camera_world_pose()
    scene2world = cam_in_isaac @ (cam2world or Pose.identity()).inverse()
    if rig is not None:
        params = twin_parameters(rig, pixel_size_m=pixel_size_m, meters_per_unit=meters_per_unit)
        UsdGeom.Scope.Define(stage, "/World/Rig")
        _write_camera(
            stage, rig.camera.intrinsics, prim_transform(cam_in_isaac), meters_per_unit,
            pixel_size_m,
        )  # fmt: skip
        proj = rig.projector.intrinsics
        image = np.full((proj.height, proj.width), 255, np.uint8) if pattern is None else pattern
        if np.shape(image) != (proj.height, proj.width):
            raise InputError(
                "pattern", f"a {proj.width}x{proj.height} px image", f"shape {np.shape(image)}"
            )
        image = np.asarray(image)[:, ::-1] if RECTLIGHT_MIRROR else np.asarray(image)
        texture = _write_texture(path.parent / f"{path.stem}_projector.png", image)
        _write_projector(
            stage, rig, params["projector"]["rect_light"],
            prim_transform(cam_in_isaac @ rig.proj2cam), meters_per_unit, texture,
        )  # fmt: skip
    if scene is not None:
        world.GetPrim().CreateAttribute("virtus:ambient", Sdf.ValueTypeNames.Double).Set(
            float(scene.ambient)
        )
        if scene.lights:
            warnings.warn("export_usd: scene lights are not written to USD", stacklevel=2)
        UsdGeom.Scope.Define(stage, OBJECTS)
        UsdGeom.Scope.Define(stage, LOOKS)
        for index, obj in enumerate(scene.objects):
            _write_object(
                stage, f"object_{index:03d}", obj, scene2world, meters_per_unit, assets, "object"
            )
        if scene.background is not None:
            _write_object(
                stage, "background", scene.background, scene2world, meters_per_unit, assets,
                "background",
            )  # fmt: skip
    if not stage.GetRootLayer().Export(str(path)):
        raise VirtusError(f"{path}: could not write the stage")
    return path


# -- reading --------------------------------------------------------------------------------


@dataclass(frozen=True)
class UsdContents:
    """What :func:`read_usd` found in a stage.

    Attributes
    ----------
    scene : the objects as a :class:`virtus.scene.model.Scene` in the camera's OpenCV frame (the
        stage's world frame, in metres, if it has no camera); None without objects.
    camera : the camera's intrinsics, or None (no camera, or no image size known).
    cam2stage : the camera's OpenCV frame -> the stage's world, metres (None without one).
    rig : camera + projector (``proj2cam``) when the stage has both, else None.
    meters_per_unit : the stage's ``metersPerUnit``.
    """

    scene: Any
    camera: Intrinsics | None
    cam2stage: Pose | None
    rig: Rig | None
    meters_per_unit: float


def _opencv_attrs(prim: Any) -> Intrinsics | None:
    k = prim.GetAttribute("virtus:opencv:K")
    if not k or not k.HasAuthoredValue():
        return None
    K = np.array(k.Get(), dtype=np.float64)  # noqa: N806
    dist = prim.GetAttribute("virtus:opencv:dist").Get() or []
    width, height = prim.GetAttribute("virtus:opencv:imageSize").Get()
    return Intrinsics.from_opencv(K, list(dist), int(width), int(height))


def _lens_attrs(prim: Any) -> Intrinsics | None:
    model = prim.GetAttribute("omni:lensdistortion:model")
    if not model or model.Get() != OPENCV_PINHOLE:
        return None
    prefix = f"omni:lensdistortion:{OPENCV_PINHOLE}"

    def get(name: str, default: float = 0.0) -> float:
        attribute = prim.GetAttribute(f"{prefix}:{name}")
        return float(attribute.Get()) if attribute and attribute.HasAuthoredValue() else default

    width, height = prim.GetAttribute(f"{prefix}:imageSize").Get()
    K = [[get("fx"), 0.0, get("cx")], [0.0, get("fy"), get("cy")], [0.0, 0.0, 1.0]]  # noqa: N806
    return Intrinsics.from_opencv(K, [get(n) for n in DIST_NAMES], int(width), int(height))


def usd_camera_intrinsics(prim: Any, image_size: tuple[int, int] | None = None) -> Intrinsics:
    """Intrinsics of a ``UsdGeom.Camera`` prim.

    In order of preference: ``virtus:opencv:*`` (double precision), Omniverse's
    OpenCV-pinhole lens attributes, the USD pinhole attributes (needs ``image_size``
    ``(width, height)`` px, or the lens API's ``imageSize``).
    """
    exact = _opencv_attrs(prim)
    if exact is not None:
        return exact
    lens = _lens_attrs(prim)
    if lens is not None:
        return lens
    if image_size is None:
        raise InputError(
            f"camera {prim.GetPath()}", "an image size (virtus:opencv or lens attributes)", None
        )
    from pxr import UsdGeom

    camera = UsdGeom.Camera(prim)
    return intrinsics_from_isaac(
        camera.GetFocalLengthAttr().Get(),
        camera.GetHorizontalApertureAttr().Get(),
        image_size[0],
        image_size[1],
        camera.GetVerticalApertureAttr().Get(),
        camera.GetHorizontalApertureOffsetAttr().Get(),
        camera.GetVerticalApertureOffsetAttr().Get(),
    )


def _device2stage(prim: Any, mpu: float) -> Pose:
    """OpenCV device frame -> stage world, metres, of a camera or light prim."""
    from pxr import Usd, UsdGeom

    matrix = _np_matrix(
        UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    )
    pose, scale = _split_scale(matrix, f"transform of {prim.GetPath()}")
    if np.max(np.abs(scale - 1.0)) > 1e-9:
        raise InputError(f"transform of {prim.GetPath()}", "no scale on a device", scale.tolist())
    return Pose(pose.R @ CV_TO_USD_CAMERA, pose.t * mpu)


def _material(prim: Any) -> tuple[dict[str, Any], str | None]:
    """Material keys and texture file (resolved) of a prim's bound UsdPreviewSurface."""
    from pxr import UsdShade

    look, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    if not look:
        return {}, None
    source = look.ComputeSurfaceSource()
    shader = source[0] if source and source[0] else None
    if shader is None or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        return {}, None
    out: dict[str, Any] = {}
    texture = None
    colour = shader.GetInput("diffuseColor")
    if colour:
        connected = colour.GetConnectedSources()[0] if colour.HasConnectedSource() else []
        if connected:
            image = UsdShade.Shader(connected[0].source.GetPrim())
            file = image.GetInput("file")
            asset = file.Get() if file else None
            if asset is not None:
                texture = asset.resolvedPath or asset.path
        elif colour.Get() is not None:
            out["albedo"] = _f32(np.mean(list(colour.Get())))
    for key, name in (("roughness", "roughness"), ("metallic", "metal"), ("ior", "specular")):
        value = shader.GetInput(key)
        if value and value.Get() is not None:
            v = _f32(value.Get())
            out[name] = v >= 0.5 if key == "metallic" else _specular(v) if key == "ior" else v
    if "specular" in out:  # ior (float32) -> specular carries ~1e-6: keep 5 digits
        out["specular"] = float(f"{out['specular']:.5g}")
    return out, texture


def _mesh_arrays(prim: Any) -> tuple[np.ndarray, np.ndarray]:
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(prim)
    points = np.array(mesh.GetPointsAttr().Get(), dtype=np.float64).reshape(-1, 3)
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
    faces, start = [], 0
    for count in counts:  # fan triangulation of polygons
        polygon = indices[start : start + count]
        faces += [(polygon[0], polygon[k], polygon[k + 1]) for k in range(1, count - 1)]
        start += count
    return points, np.array(faces, dtype=np.int64).reshape(-1, 3)


def _read_object(prim: Any, stage2scene: Pose, mpu: float, mesh_dir: Path) -> tuple[Any, str]:
    import trimesh
    from pxr import Usd, UsdGeom

    from virtus.scene.model import (
        BoxObject,
        Material,
        MeshObject,
        PlaneObject,
        SphereObject,
        TexturedPlaneObject,
    )

    where = str(prim.GetPath())
    matrix = _np_matrix(
        UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    )
    pose, scale = _split_scale(matrix, f"transform of {where}")
    pose = stage2scene @ Pose(pose.R, pose.t * mpu)
    keys, texture = _material(prim)
    kind = prim.GetAttribute("virtus:type").Get() if prim.HasAttribute("virtus:type") else None
    role = prim.GetAttribute("virtus:role").Get() if prim.HasAttribute("virtus:role") else "object"
    if prim.IsA(UsdGeom.Sphere):
        if np.ptp(scale) > 1e-9 * scale.max():
            raise InputError(f"sphere {where}", "a uniform scale", scale.tolist())
        radius = UsdGeom.Sphere(prim).GetRadiusAttr().Get() * scale[0] * mpu
        return SphereObject(radius, tuple(pose.t), Material(**keys)), role
    if prim.IsA(UsdGeom.Cube):
        size = UsdGeom.Cube(prim).GetSizeAttr().Get() * scale * mpu
        return BoxObject(tuple(size), pose, Material(**keys)), role
    points, faces = _mesh_arrays(prim)
    if kind in ("plane", "textured_plane"):
        size = (scale[0] * mpu, scale[1] * mpu)
        if kind == "textured_plane" and texture:
            keys.pop("albedo", None)
            return TexturedPlaneObject(size, texture, pose, Material(albedo=1.0, **keys)), role
        return PlaneObject(size, pose, Material(**keys)), role
    mesh_dir.mkdir(parents=True, exist_ok=True)
    file = mesh_dir / f"{prim.GetName()}.ply"
    # PLY files hold float32 vertices: keep USD's float32 points as they are and a uniform
    # scale in scale_to_m (exact); a non-uniform scale is applied to the points.
    uniform = np.ptp(scale) <= 1e-12 * scale.max()
    vertices = points if uniform else points * scale
    trimesh.Trimesh(vertices, faces, process=False).export(file)
    return MeshObject(file, (scale[0] if uniform else 1.0) * mpu, pose, Material(**keys)), role


def _error_text(error: Any) -> str:
    """``str(error)`` of a pxr error or diagnostic; one whose text is not UTF-8 (bytes of a
    damaged file quoted in it) cannot be a str, and is named by its type instead."""
    try:
        return str(error)
    except UnicodeError:
        return f"{type(error).__name__} (its message is not UTF-8 text: a damaged file?)"


def _composition_problem(error: Any) -> tuple[str, str]:
    """``(what, why)`` of a composition error (``Pcp.Error*``): ``("reference @asset@ of
    </Prim>", "not found")``, or USD's own words for other kinds."""
    text = " ".join(_error_text(error).split()).removesuffix("; skipping.").rstrip(".")
    found = re.match(r"Could not load sublayer (@[^@]*@) of layer (@[^@]*@)", text)
    if found:
        return f"sublayer {found[1]} of {found[2]}", "not found"
    found = re.match(
        r"(?:In <[^>]*>: )?Could not open asset (@[^@]*@) for (\w+) introduced by (.*)", text
    )
    if found:
        prim = re.search(r"<[^>]*>$", found[3])
        return f"{found[2]} {found[1]} of {prim[0] if prim else found[3]}", "not found"
    return text, "a composition error"


def _open_stage(path: Path) -> Any:
    """The stage of ``path``, composed: every sublayer, reference and payload found.

    Raises
    ------
    InputError : usd-core cannot open it, a composition error (the missing sublayer,
        reference or payload named; USD's own warnings about it are not repeated), or a
        ``metersPerUnit`` that is not a positive number.
    """
    from pxr import Tf, Usd, UsdGeom

    trap = getattr(Tf, "DiagnosticTrap", None)
    try:
        with trap() if trap is not None else contextlib.nullcontext() as caught:
            stage = Usd.Stage.Open(str(path))
            errors = list(stage.GetCompositionErrors()) if stage is not None else []
            if errors and caught is not None:
                caught.Clear()  # one line below says it
    except Exception as error:  # pxr raises Tf errors of its own types
        raise InputError(
            f"stage {path}", "a USD stage usd-core can open", _error_text(error)
        ) from None
    if stage is None:
        raise InputError(f"stage {path}", "a USD stage usd-core can open", "nothing")
    if errors:
        what, why = _composition_problem(errors[0])
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        raise InputError(
            f"stage {path}: {what}{more}", "every sublayer, reference and payload found", why
        )
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    if not np.isfinite(mpu) or mpu <= 0:
        raise InputError(f"stage {path} metersPerUnit", "a positive number of metres", mpu)
    return stage


@contextlib.contextmanager
def _values_of(prim: Any) -> Any:
    """Turn what a malformed attribute value makes numpy, Python or USD raise (a value USD
    could not parse, ``Sdf.UnregisteredValue``; a missing value, ``None``; a wrong shape;
    an xform op USD refuses, ``Tf.ErrorException``) into an :class:`InputError` naming the
    prim."""
    try:
        yield
    except VirtusError:
        raise
    except (TypeError, ValueError, IndexError, KeyError, AttributeError, OverflowError,
            ZeroDivisionError, RuntimeError) as error:  # fmt: skip
        where = f"prim {prim.GetPath()}" if prim is not None else "stage"
        text = _error_text(error).strip()
        got = text.splitlines()[0][:200] if text else type(error).__name__
        expected = "attribute values of the types and shapes USD defines"
        raise InputError(where, expected, got) from None


def read_usd(path: str | Path) -> UsdContents:
    """Read a stage's camera, projector and objects (module docstring).

    Raises
    ------
    MissingDependency : usd-core missing.
    InputError : not a stage, a missing sublayer, reference or payload, a ``metersPerUnit``
        that is not positive, a sheared or mirrored transform, a camera without size.
    """
    require_usd()
    from pxr import UsdGeom, UsdLux

    from virtus.scene.model import Scene

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "no such USD stage", str(path))
    stage = _open_stage(path)
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    prims = list(stage.Traverse())
    cameras = [p for p in prims if p.IsA(UsdGeom.Camera)]
    camera = cam2stage = None
    if cameras:
        with _values_of(cameras[0]):
            cam2stage = _device2stage(cameras[0], mpu)
            try:
                camera = usd_camera_intrinsics(cameras[0])
            except InputError:  # a pinhole camera without image size: its pose still counts
                camera = None
    projectors = [
        p
        for p in prims
        if p.IsA(UsdLux.RectLight) and p.HasAttribute("isProjector")
        and p.GetAttribute("isProjector").Get()
    ]  # fmt: skip
    rig = None
    with _values_of(projectors[0] if projectors else None):
        if camera is not None and projectors and _opencv_attrs(projectors[0]) is not None:
            proj2stage = _device2stage(projectors[0], mpu)
            rig = Rig(
                Camera(camera),
                Projector(_opencv_attrs(projectors[0])),  # type: ignore[arg-type]
                cam2stage.inverse() @ proj2stage,  # type: ignore[union-attr]
            )
    stage2scene = cam2stage.inverse() if cam2stage is not None else Pose.identity()
    mesh_dir = path.parent / f"{path.stem}_meshes"
    objects, background = [], None
    for prim in prims:
        if not (prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Sphere) or prim.IsA(UsdGeom.Cube)):
            if prim.IsA(UsdGeom.Gprim):
                warnings.warn(f"USD: {prim.GetPath()} ({prim.GetTypeName()}) skipped", stacklevel=2)
            continue
        if UsdGeom.Imageable(prim).ComputeVisibility() == UsdGeom.Tokens.invisible:
            continue
        with _values_of(prim):
            obj, role = _read_object(prim, stage2scene, mpu, mesh_dir)
        if role == "background" and background is None:
            background = obj
        else:
            objects.append(obj)
    scene = None
    if objects or background is not None:
        world = stage.GetDefaultPrim()
        ambient = 0.0
        if world and world.HasAttribute("virtus:ambient"):
            with _values_of(world):
                ambient = float(world.GetAttribute("virtus:ambient").Get())
        scene = Scene(objects=tuple(objects), background=background, ambient=ambient)
    return UsdContents(scene, camera, cam2stage, rig, mpu)


def load_usd_scene(path: str | Path) -> Any:
    """The objects of a stage as a :class:`virtus.scene.model.Scene` in its camera's frame."""
    contents = read_usd(path)
    if contents.scene is None:
        raise InputError(f"stage {path}", "meshes, spheres or cubes", "no geometry")
    return contents.scene
