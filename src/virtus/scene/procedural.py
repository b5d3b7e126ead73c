"""Procedural test objects shipped with virtus (no downloads).

:func:`freeform_object` builds a deterministic free-form, genus-0 mesh of about 10 cm: a
"bumpy star" made by displacing a subdivided icosphere along its radii,

    r(d) = R0 * (1 + a_lobe * sum_i exp((d . l_i - 1) / w_i^2)
                  + a_wave * sum_j sin(k_j . d + phi_j)),

with a few broad lobes (directions ``l_i``, widths ``w_i``) that give it a figurine-like
silhouette with concave saddles between them, and low-amplitude waves (wave vectors
``k_j``) for mid-frequency relief. Every direction keeps a positive radius, so the surface
is star-shaped about the origin, closed, and free of self-intersections. The parameters
are drawn from a seeded generator, so one seed is always the same mesh.

Units: metres; the object is centred on its bounding-box centre at the origin.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from virtus.checks import as_rng, positive, positive_int
from virtus.errors import InputError

if TYPE_CHECKING:
    import trimesh

__all__ = ["FREEFORM_SEED", "freeform_object", "write_freeform_object"]

#: Seed of the object shipped as "the" free-form test object.
FREEFORM_SEED = 7

_LOBES = 6
_WAVES = 9
_LOBE_AMPLITUDE = 0.7
_WAVE_AMPLITUDE = 0.04


def freeform_object(
    size_m: float = 0.1,
    subdivisions: int = 6,
    seed: int = FREEFORM_SEED,
) -> trimesh.Trimesh:
    """The free-form test object.

    Parameters
    ----------
    size_m : largest bounding-box extent, metres.
    subdivisions : icosphere subdivisions; 6 gives 81,920 faces (40,962 vertices), 7 gives
        327,680 faces.
    seed : shape seed (the default is the shipped object).

    Returns
    -------
    trimesh.Trimesh, watertight, outward-facing normals, metres, bounding box centred on the
    origin.
    """
    size = positive("size_m", size_m)
    subdivisions = positive_int("subdivisions", subdivisions)
    if subdivisions > 8:
        raise InputError("subdivisions", "at most 8 (1.3 M faces)", subdivisions)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise InputError("seed", "an integer", seed)
    import trimesh  # here: importing it (and networkx) costs every ``virtus.scene`` user ~0.6 s

    rng = as_rng(int(seed))
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    d = np.asarray(sphere.vertices, dtype=np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    lobes = rng.normal(size=(_LOBES, 3))
    lobes /= np.linalg.norm(lobes, axis=1, keepdims=True)
    widths = rng.uniform(0.3, 0.5, size=_LOBES)
    heights = rng.uniform(0.6, 1.0, size=_LOBES)
    waves = rng.normal(size=(_WAVES, 3))
    waves *= (rng.uniform(5.0, 11.0, size=_WAVES) / np.linalg.norm(waves, axis=1))[:, None]
    phases = rng.uniform(0, 2 * np.pi, size=_WAVES)

    lobe = (heights * np.exp((d @ lobes.T - 1.0) / widths**2)).sum(axis=1)
    wave = np.sin(d @ waves.T + phases).sum(axis=1) / np.sqrt(_WAVES)
    radius = 1.0 + _LOBE_AMPLITUDE * lobe + _WAVE_AMPLITUDE * wave
    # Positive by construction (lobes >= 0, |wave term| <= 0.04 * 3): star-shaped surface.
    vertices = d * radius[:, None]
    mesh = trimesh.Trimesh(vertices=vertices, faces=np.asarray(sphere.faces), process=False)
    lo, hi = mesh.bounds
    mesh.apply_translation(-(lo + hi) / 2)
    mesh.apply_scale(size / float(np.max(hi - lo)))
    return mesh


def write_freeform_object(
    path: str | os.PathLike[str],
    size_m: float = 0.1,
    subdivisions: int = 6,
    seed: int = FREEFORM_SEED,
) -> Path:
    """Write :func:`freeform_object` to ``path``; the format follows the suffix.

    Parameters
    ----------
    path : ``.stl`` (binary STL) or ``.ply`` (binary PLY); coordinates in metres.
    size_m, subdivisions, seed : see :func:`freeform_object`.

    Returns
    -------
    The path written (parent directories are created).
    """
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in (".stl", ".ply"):
        raise InputError("path", "a file name ending in .stl or .ply", str(target))
    mesh = freeform_object(size_m, subdivisions, seed)
    target.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(target, file_type=suffix[1:])
    return target
