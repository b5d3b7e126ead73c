"""Named materials and ambient levels: the ablation's tables (``virtus ablation``, the
dataset's ablation mode), and the demo's sphere scene dressed with them.

* :data:`MATERIALS` -- keyword arguments of :class:`virtus.scene.model.Material` by name.
* :data:`AMBIENTS` -- ambient light levels (:attr:`virtus.scene.model.Scene.ambient`) by name.
* :func:`sphere_scene` -- the demo's scene with one of each.
"""

from __future__ import annotations

from typing import Any

__all__ = ["AMBIENTS", "MATERIALS", "sphere_scene"]

#: Sphere materials: (roughness, specular, metal) of :class:`virtus.scene.model.Material`.
MATERIALS: dict[str, dict[str, Any]] = {
    "matte": {"roughness": 0.95, "specular": 0.15},
    "glossy": {"roughness": 0.3, "specular": 0.8},
    "metal": {"roughness": 0.3, "metal": True},
    "reflective": {"roughness": 0.05, "metal": True},
}
#: Ambient light levels (relative radiance: 1 = a white projector on albedo 1 at 1 m).
AMBIENTS = {"dark": 0.0, "ambient": 0.3}


def sphere_scene(material: str, ambient: str) -> Any:
    """The demo's scene (100 mm sphere at 1 m before a wall) with this sphere material and
    ambient level."""
    from virtus.scene.model import Material, Scene, SphereObject, default_scene

    base = default_scene()
    sphere = next(o for o in base.objects if isinstance(o, SphereObject))
    dressed = SphereObject(
        radius_m=sphere.radius_m, center_m=sphere.center_m, material=Material(**MATERIALS[material])
    )
    return Scene(objects=(dressed,), background=base.background, ambient=AMBIENTS[ambient])
