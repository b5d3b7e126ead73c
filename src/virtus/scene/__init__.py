"""Validated, renderer-independent scenes (YAML); USD scenes are read by
:mod:`virtus.pipeline.inputs`.

* :mod:`~virtus.scene.model` -- ``Scene``: objects, materials, background, ambient light.
* :mod:`~virtus.scene.presets` -- named materials and ambient levels.
* :mod:`~virtus.scene.builtin` -- built-in scenes by name (sphere, freeform).
* :mod:`~virtus.scene.procedural` -- procedural test objects (the free-form mesh).
"""

from virtus.scene.builtin import (
    BUILTIN_SCENES,
    FREEFORM_CENTRE_M,
    builtin_scene,
    freeform_scene,
)
from virtus.scene.model import (
    MAX_AMBIENT,
    MAX_LENGTH_M,
    MAX_MESH_BYTES,
    MAX_TEXTURE_BYTES,
    AreaLight,
    BoxObject,
    EnvironmentLight,
    Material,
    MeshObject,
    PlaneObject,
    Scene,
    SceneObject,
    SphereObject,
    TexturedPlaneObject,
    default_scene,
    load_scene,
    load_texture,
)
from virtus.scene.presets import AMBIENTS, MATERIALS, sphere_scene
from virtus.scene.procedural import (
    FREEFORM_SEED,
    freeform_object,
    write_freeform_object,
)

__all__ = [
    "AMBIENTS",
    "AreaLight",
    "BUILTIN_SCENES",
    "BoxObject",
    "EnvironmentLight",
    "FREEFORM_CENTRE_M",
    "FREEFORM_SEED",
    "MATERIALS",
    "MAX_AMBIENT",
    "MAX_LENGTH_M",
    "MAX_MESH_BYTES",
    "MAX_TEXTURE_BYTES",
    "Material",
    "MeshObject",
    "PlaneObject",
    "Scene",
    "SceneObject",
    "SphereObject",
    "TexturedPlaneObject",
    "builtin_scene",
    "default_scene",
    "freeform_object",
    "freeform_scene",
    "load_scene",
    "load_texture",
    "sphere_scene",
    "write_freeform_object",
]
