"""The procedural free-form test object."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

from tests.tolerances import FLOAT64_EXACT, MESH_FILE_REL
from virtus.errors import InputError
from virtus.scene.procedural import freeform_object, write_freeform_object


def test_default_object_is_a_closed_10cm_free_form_surface():
    mesh = freeform_object()
    assert 50_000 <= len(mesh.faces) <= 200_000
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0  # outward normals
    assert max(mesh.extents) == pytest.approx(0.1, rel=FLOAT64_EXACT)
    assert np.allclose(mesh.bounds.mean(axis=0), 0.0, atol=FLOAT64_EXACT)
    # Free-form: far from a sphere (radii vary widely) and curved everywhere differently.
    radii = np.linalg.norm(mesh.vertices - mesh.centroid, axis=1)
    assert radii.max() / radii.min() > 1.5
    assert mesh.is_volume


def test_object_is_deterministic_and_seed_dependent():
    a, b = freeform_object(subdivisions=3), freeform_object(subdivisions=3)
    assert np.array_equal(a.vertices, b.vertices)
    other = freeform_object(subdivisions=3, seed=1)
    assert not np.allclose(a.vertices, other.vertices)


@pytest.mark.parametrize("suffix", [".stl", ".ply"])
def test_write_and_reload(tmp_path: Path, suffix: str):
    path = write_freeform_object(tmp_path / "sub" / f"blob{suffix}", size_m=0.08, subdivisions=3)
    mesh = trimesh.load(path, force="mesh")
    assert len(mesh.faces) == 1280
    assert max(mesh.extents) == pytest.approx(0.08, rel=MESH_FILE_REL)


def test_bad_arguments(tmp_path: Path):
    with pytest.raises(InputError, match="path"):
        write_freeform_object(tmp_path / "blob.obj")
    with pytest.raises(InputError, match="size_m"):
        freeform_object(size_m=0)
    with pytest.raises(InputError, match="subdivisions"):
        freeform_object(subdivisions=9)
