"""Capsules: exact segment distances, meshes where the capsule is."""

from __future__ import annotations

import numpy as np

from virtus.robot.shapes import Capsule, capsule_mesh, segment_distances


def test_segment_distances_match_dense_sampling() -> None:
    rng = np.random.default_rng(0)
    a0, a1, b0, b1 = (rng.normal(size=(200, 3)) for _ in range(4))
    a1[:20] = a0[:20]  # degenerate segments (points) too
    b1[10:30] = b0[10:30] + 1e-3 * (a1[10:30] - a0[10:30])  # nearly parallel
    exact = segment_distances(a0, a1, b0, b1)
    s = np.linspace(0.0, 1.0, 101)
    pa = a0[:, None] + s[None, :, None] * (a1 - a0)[:, None]
    pb = b0[:, None] + s[None, :, None] * (b1 - b0)[:, None]
    dense = np.linalg.norm(pa[:, :, None] - pb[:, None, :], axis=-1).min(axis=(1, 2))
    assert np.all(exact <= dense + 1e-12)  # never longer than a sampled pair
    assert np.all(dense - exact < 5e-2)  # and within the sampling step of the minimum
    # crossing segments touch; parallel ones offset by 1 are 1 apart
    assert (
        segment_distances(
            np.array([-1.0, 0, 0]),
            np.array([1.0, 0, 0]),
            np.array([0.0, -1, 0]),
            np.array([0.0, 1, 0]),
        )
        == 0.0
    )
    assert (
        segment_distances(
            np.array([0.0, 0, 0]),
            np.array([1.0, 0, 0]),
            np.array([0.0, 1, 0]),
            np.array([1.0, 1, 0]),
        )
        == 1.0
    )


def test_capsule_mesh_is_placed_like_the_capsule() -> None:
    capsule = Capsule("link", (0.0, 0.0, 0.0), (0.2, 0.0, 0.0), 0.05)
    place = np.eye(4)
    place[:3, 3] = (1.0, 2.0, 3.0)
    mesh = capsule_mesh(capsule, place)
    assert mesh.is_watertight
    np.testing.assert_allclose(mesh.bounds, [[0.95, 1.95, 2.95], [1.25, 2.05, 3.05]], atol=1e-3)
    p0, p1 = capsule.ends_world(place)
    np.testing.assert_allclose(p1 - p0, (0.2, 0.0, 0.0))
