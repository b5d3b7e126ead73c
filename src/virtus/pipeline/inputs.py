"""The one scene resolver of the jobs: a built-in name, a scene YAML file or a USD stage.

Dispatch by format sits here, above the formats, so :mod:`virtus.scene` (YAML) and
:mod:`virtus.twin.usd` (USD) never import each other:

* ``sphere`` / ``freeform`` -- :func:`virtus.scene.builtin.builtin_scene` (assets written into
  the run's directory);
* ``*.yaml`` / ``*.yml`` and any other suffix -- :func:`virtus.scene.model.load_scene`;
* ``*.usda`` / ``*.usdc`` / ``*.usd`` -- :func:`virtus.twin.usd.load_usd_scene` (needs
  ``usd-core``): meshes, transforms, materials and camera pose, the objects expressed in the
  stage camera's frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from virtus.errors import InputError
from virtus.scene.builtin import BUILTIN_SCENES, builtin_scene
from virtus.scene.model import Scene
from virtus.scene.model import load_scene as load_scene_yaml

__all__ = ["USD_SUFFIXES", "load_scene", "resolve_scene"]

#: Suffixes read as USD stages (case-insensitive).
USD_SUFFIXES = (".usda", ".usdc", ".usd")


def load_scene(path: str | Path) -> Scene:
    """A scene file: a USD stage by its suffix (:data:`USD_SUFFIXES`), else scene YAML."""
    if Path(path).suffix.lower() in USD_SUFFIXES:
        from virtus.twin.usd import load_usd_scene

        return load_usd_scene(path)
    return load_scene_yaml(path)


def resolve_scene(spec: str | Path, directory: str | Path) -> Any:
    """A scene from a file path or a built-in name (assets of built-ins go to ``directory``)."""
    text = str(spec)
    if text in BUILTIN_SCENES and not Path(text).is_file():
        return builtin_scene(text, directory)
    if not Path(text).is_file():
        raise InputError(
            "scene", f"an existing scene YAML file or one of {', '.join(BUILTIN_SCENES)}", text
        )
    return load_scene(text)
