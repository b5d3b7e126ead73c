"""Link shapes: capsules for self-collision, triangle meshes for the rendered scene.

A :class:`Capsule` is the set of points within ``radius`` metres of the segment ``p0``-``p1``
given in its link's frame. Capsules are what the self-collision check uses (exact
segment-to-segment distances); their triangle meshes (or a URDF's own meshes) are what the
renderer sees, so the arm occludes and shadows the scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from virtus.errors import InputError

__all__ = ["Capsule", "capsule_mesh", "segment_distances"]


@dataclass(frozen=True)
class Capsule:
    """A capsule fixed to a link.

    Attributes
    ----------
    link : the link's name.
    p0, p1 : (3,) float64 segment ends, metres, link frame.
    radius : metres (> 0).
    """

    link: str
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float

    def __post_init__(self) -> None:
        if not self.radius > 0:
            raise InputError(f"capsule on {self.link} radius", "a positive radius (m)", self.radius)

    def ends_world(self, link2world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment ends ``(..., 3)`` in the frame ``link2world`` (..., 4, 4) maps into."""
        R, t = link2world[..., :3, :3], link2world[..., :3, 3]  # noqa: N806
        return R @ np.asarray(self.p0) + t, R @ np.asarray(self.p1) + t


def capsule_mesh(capsule: Capsule, link2world: np.ndarray, sections: int = 12):  # noqa: ANN201
    """A watertight :class:`trimesh.Trimesh` of ``capsule`` placed by ``link2world`` (4, 4)."""
    import trimesh

    p0, p1 = (np.asarray(p, dtype=np.float64) for p in (capsule.p0, capsule.p1))
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    mesh = trimesh.creation.capsule(
        height=length, radius=capsule.radius, count=[sections, sections]
    )
    place = np.eye(4)
    if length > 0:
        place[:3, :3] = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], axis / length)[:3, :3]
    place[:3, 3] = (p0 + p1) / 2.0
    mesh.apply_transform(np.asarray(link2world) @ place)
    return mesh


def segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Shortest distances between segments ``a0``-``a1`` and ``b0``-``b1``, (...,) metres.

    All inputs (..., 3) broadcast together; degenerate (zero-length) segments are points.
    The closest-point parameters are clamped to the segments as in Ericson, *Real-Time
    Collision Detection* (2005), 5.1.9.
    """
    d1 = a1 - a0
    d2 = b1 - b0
    r = a0 - b0
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    tiny = 1e-18
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip((b * f - c * e) / np.maximum(denom, tiny), 0.0, 1.0), 0.0)
    t = np.where(e > tiny, (b * s + f) / np.maximum(e, tiny), 0.0)
    # t outside [0, 1]: clamp it and recompute s for the clamped t.
    s = np.where(t < 0.0, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), s)
    s = np.where(t > 1.0, np.clip((b - c) / np.maximum(a, tiny), 0.0, 1.0), s)
    s = np.where(a > tiny, s, 0.0)
    t = np.clip(t, 0.0, 1.0)
    closest = (a0 + s[..., None] * d1) - (b0 + t[..., None] * d2)
    return np.linalg.norm(closest, axis=-1)
