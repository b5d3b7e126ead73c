"""The example scenes shipped in examples/ load and render."""

from __future__ import annotations

from pathlib import Path

import pytest

from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.patterns import default_sequence
from virtus.render import render
from virtus.scene.model import load_scene

EXAMPLES = sorted((Path(__file__).parent.parent / "examples").glob("*.yaml"))


def test_there_are_examples():
    assert EXAMPLES


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_scene_renders(path):
    scene = load_scene(path)
    rig = default_rig()
    small = Rig(Camera(rig.camera.intrinsics.scaled(0.25)), rig.projector, rig.proj2cam)
    projector = rig.projector.intrinsics
    rendering = render(small, scene, default_sequence(projector.width, projector.height))
    # Most of the view is a lit surface (objects in front of the wall), none of it empty.
    assert rendering.gt.mask_hit.all()
    assert rendering.gt.mask.mean() > 0.8
