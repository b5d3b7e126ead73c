"""Built-in scenes by name, for ``virtus scan --scene NAME`` and the demo.

* ``sphere``: the paper's experiment, :func:`virtus.scene.model.default_scene` (a matte sphere of
  radius 100 mm at 1 m, background plane at 1.3 m).
* ``freeform``: the procedural free-form object (:func:`virtus.scene.procedural.freeform_object`,
  about 10 cm) centred 1 m in front of the camera, same background. Its mesh is written as
  ``freeform.stl`` (metres) into the given directory, which the scene references.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.geometry.transforms import Pose

__all__ = [
    "BUILTIN_SCENES",
    "FREEFORM_CENTRE_M",
    "builtin_scene",
    "freeform_scene",
]

BUILTIN_SCENES = ("sphere", "freeform")
#: Where the free-form object sits in the camera frame (metres): on the camera axis at the
#: rig's 1 m working distance.
FREEFORM_CENTRE_M = (0.0, 0.0, 1.0)
#: A 2 m x 2 m background plane at z = 1.3 m, as in the sphere scene.
_BACKGROUND_Z_M = 1.3


def freeform_scene(
    directory: str | Path,
    object2world: Pose | None = None,
    *,
    background: bool = True,
) -> Any:
    """The free-form object in a scene; writes ``directory/freeform.stl``.

    Parameters
    ----------
    directory : where the mesh file goes (created).
    object2world : placement of the object (its frame: centred on its bounding box, metres);
        default: a translation to :data:`FREEFORM_CENTRE_M`.
    background : add the background plane at z = 1.3 m.
    """
    from virtus.scene.model import MeshObject, PlaneObject, Scene
    from virtus.scene.procedural import write_freeform_object

    folder = Path(directory)
    path = folder / "freeform.stl"
    if not path.is_file():
        write_freeform_object(path)
    pose = object2world or Pose(np.eye(3), FREEFORM_CENTRE_M)
    back = PlaneObject(size_m=(2.0, 2.0), pose=Pose(np.eye(3), (0.0, 0.0, _BACKGROUND_Z_M)))
    return Scene(
        objects=(MeshObject(path=path, scale_to_m=1.0, pose=pose),),
        background=back if background else None,
    )


def builtin_scene(name: str, directory: str | Path) -> Any:
    """A built-in scene by name (:data:`BUILTIN_SCENES`); assets go to ``directory``."""
    from virtus.scene.model import default_scene

    if name == "sphere":
        return default_scene()
    if name == "freeform":
        return freeform_scene(directory)
    raise InputError("scene", f"a YAML file or one of {', '.join(BUILTIN_SCENES)}", name)
