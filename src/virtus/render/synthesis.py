"""Synthesise every frame of a pattern sequence from one tracing pass.

Light transport is linear in the projected pattern, and each frame varies along one
projector axis only, so a frame's radiance at camera pixel p is

    L_f(p) = sum_s w_s(p) * profile_f(c_s(p)) + L_ambient(p),

with ``w_s`` the white-projector radiance of sample (tap) s and ``c_s`` its projector
column (``u_p``, frames of direction "v") or row (``v_p``, direction "h"). For all frames of
one direction this is one sparse (pixels x projector columns) matrix times a dense
(columns x frames) profile matrix.

The profile of a frame is the light the projector emits
(:meth:`virtus.sensor.projector.ProjectorModel.emitted_profile`: pre-compensation, response, black
level); the projector's fall-off scales each tap's weight. Pixel models
(:class:`virtus.sensor.projector.Lookup`):

* ``"nearest"``: the DMD pixel containing the point, ``floor(c + 0.5)`` (pixel j covers
  [j - 0.5, j + 0.5)); this is the physical staircase of a DMD.
* ``"bilinear"``: linear interpolation between projector pixel centres, clamped to the edge
  pixels' values in the outer half pixel.
* ``"psf"``: linear interpolation in the profile spread by the pixel aperture and lens PSF,
  tabulated at several points per pixel (:meth:`~virtus.sensor.projector.ProjectorModel.spread`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import scipy.sparse

from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.render.tracing import Trace
from virtus.sensor.projector import Lookup, ProjectorModel

#: The projector pixel models (:class:`virtus.sensor.projector.Lookup`).
LOOKUPS = tuple(member.value for member in Lookup)
#: Pixels per block of the sparse product: (block x frames) float32 fits in L2 cache.
_BLOCK_PIXELS = 1 << 14


def lookup_matrix(
    coordinate: np.ndarray, weight: np.ndarray, length: int, lookup: str = "nearest"
) -> scipy.sparse.csr_array:
    """Sparse (P, length) float32 matrix mapping a 1-D pattern profile to pixel radiance.

    Parameters
    ----------
    coordinate : (P, S) float32 projector coordinate (u_p or v_p, pixels) of each sample.
    weight : (P, S) float32 radiance weight of each sample (0 = no contribution).
    length : projector width (for u_p) or height (for v_p) in pixels.
    lookup : ``"nearest"`` or ``"bilinear"`` (see the module docstring; the ``psf`` model
        reads its table bilinearly).

    Every sample keeps its entries (S per row for nearest, 2 S for bilinear), zero weights
    included: a fixed row length needs no compaction pass and costs little in the product.
    """
    if lookup not in (Lookup.nearest, Lookup.bilinear):
        raise InputError("lookup", '"nearest" or "bilinear"', lookup)
    n_pixels, n_samples = coordinate.shape
    c = coordinate.reshape(-1)
    w = weight.reshape(-1).astype(np.float32, copy=False)
    if lookup == "nearest":
        columns = np.floor(c + np.float32(0.5)).astype(np.int32)
        np.clip(columns, 0, length - 1, out=columns)  # float32 rounding at the last edge
        data = w
    else:
        x = np.clip(c, np.float32(0.0), np.float32(length - 1))
        left = np.floor(x).astype(np.int32)
        np.minimum(left, max(length - 2, 0), out=left)
        frac = x - left
        # Interleave (left, right) per sample so each row's entries stay together.
        columns = np.empty(2 * c.size, dtype=np.int32)
        columns[0::2] = left
        columns[1::2] = np.minimum(left + 1, length - 1)
        data = np.empty(2 * c.size, dtype=np.float32)
        data[1::2] = w * frac
        data[0::2] = w - data[1::2]
    per_row = data.size // n_pixels
    index_dtype = np.int32 if data.size < 2**31 else np.int64
    indptr = np.arange(0, data.size + 1, per_row, dtype=index_dtype)
    matrix = scipy.sparse.csr_array((n_pixels, length), dtype=np.float32)
    # Assign the CSR arrays directly: the constructor would re-check and copy them.
    matrix.data, matrix.indices, matrix.indptr = (
        data,
        columns.astype(index_dtype, copy=False),
        indptr,
    )
    return matrix


def _threads() -> int:
    """CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def frame_groups(sequence: Any) -> dict[str | None, list[int]]:
    """Frame indices by direction: ``{"v": [...], "h": [...], None: [uniform frames]}``."""
    groups: dict[str | None, list[int]] = {"v": [], "h": [], None: []}
    for index, frame in enumerate(sequence.frames):
        direction = getattr(frame, "direction", None)
        if direction not in groups:
            raise InputError(f"sequence.frames[{index}].direction", '"v", "h" or None', direction)
        groups[direction].append(index)
    return groups


def projector_groups(sequence: Any, projector: ProjectorModel) -> dict[str | None, list[int]]:
    """:func:`frame_groups` for synthesis: with the ``psf`` pixel model the uniform frames
    join a fringe direction (as constant profiles), since a lit DMD shows its pixel
    structure too (dark gaps with a fill factor below 1)."""
    groups = frame_groups(sequence)
    if projector.pixel == Lookup.psf and groups[None]:
        carrier = "v" if groups["v"] or not groups["h"] else "h"
        groups[carrier] = sorted(groups[carrier] + groups[None])
        groups[None] = []
    return groups


def as_projector(projector: ProjectorModel | str) -> ProjectorModel:
    """A :class:`ProjectorModel`, or the ideal one with the pixel model ``projector`` names."""
    if isinstance(projector, ProjectorModel):
        return projector
    return ProjectorModel(pixel=projector)  # type: ignore[arg-type]


def emitted_profiles(
    projector: ProjectorModel, sequence: Any, indices: list[int], length: int
) -> np.ndarray:
    """(length * R, F) float32 table of the light the frames emit along their axis (R = the
    pixel model's supersampling, 1 for nearest and bilinear)."""
    columns = []
    for index in indices:
        profile = projector.emitted_profile(sequence, index)
        if sequence.frames[index].direction is None:
            profile = np.full(length, profile.reshape(-1)[0])
        if profile.shape != (length,):
            raise InputError(
                f"sequence.profile({index})",
                f"shape ({length},) for this projector",
                f"shape {profile.shape}",
            )
        columns.append(profile)
    return projector.spread(np.stack(columns, axis=1)).astype(np.float32)


def tap_weights(trace: Any, projector: ProjectorModel, intrinsics: Any | None) -> Any:
    """Tap weights with the projector's fall-off applied: (P, S) float32 of a host
    :class:`Trace`, or the Float (P * S,) of a device trace
    (:class:`virtus.render.jit.tracing.DeviceTrace`; the fall-off is plain arithmetic)."""
    if projector.falloff == "none":
        return trace.weight
    if intrinsics is None:
        raise InputError("projector_intrinsics", "the projector's intrinsics for a fall-off", None)
    return trace.weight * projector.falloff_factor(trace.u_p, trace.v_p, intrinsics)


def synthesize(
    trace: Trace,
    sequence: Any,
    projector: ProjectorModel | str = "nearest",
    *,
    transform: Callable[[np.ndarray, np.ndarray, slice], np.ndarray] | None = None,
    dtype: Any = np.float32,
    threads: int | None = None,
    block_pixels: int = _BLOCK_PIXELS,
    projector_intrinsics: Any | None = None,
) -> np.ndarray:
    """Every frame of ``sequence`` from one trace.

    Parameters
    ----------
    trace : the tracing pass of this pose.
    sequence : a pattern sequence (``virtus.patterns``): ``frames[i].direction`` in
        {"v", "h", None} and ``profile(i)`` -> (L,) values in [0, 1] along the varying axis
        (L = projector width for "v", height for "h", 1 for uniform frames).
    projector : the projector model (:class:`virtus.sensor.projector.ProjectorModel`), or just a
        pixel model name for an otherwise ideal projector (``"nearest"``: DMD pixels).
    transform : optional pointwise function ``transform(block, frames, pixels)`` applied to
        each block of radiance before it is stored (e.g. a sensor's digitisation), where
        ``block`` is (len(frames), n) float32, ``frames`` the block's frame indices in the
        sequence and ``pixels`` its slice of the row-major pixel index. Fusing it here avoids
        materialising the float radiance of all frames. Blocks are processed concurrently
        and in no fixed order: a random transform (noise) must draw from generators derived
        from ``frames`` and ``pixels`` to stay deterministic.
    dtype : dtype of the result (that of ``transform``'s output).
    threads : worker threads (default: the CPUs this process may use).
    block_pixels : pixels per block of the sparse product (the result does not depend on it).
    projector_intrinsics : the projector's intrinsics (needed for a fall-off).

    Returns
    -------
    (F, H, W) frames in sequence order: radiance (float32, same units as ``trace.weight``),
    or ``transform`` of it.
    """
    projector = as_projector(projector)
    threads = _threads() if threads is None else positive_int("threads", threads)
    block_pixels = positive_int("block_pixels", block_pixels)
    n_frames = len(sequence.frames)
    if n_frames == 0:
        raise InputError("sequence", "at least one frame", "an empty sequence")
    height, width = trace.height, trace.width
    n_pixels = height * width
    transform = transform or (lambda block, frames, pixels: block)
    ambient = trace.ambient if np.any(trace.ambient) else None
    out = np.empty((n_frames, n_pixels), dtype=dtype)
    groups = projector_groups(sequence, projector)
    lengths = {"v": trace.projector_width, "h": trace.projector_height}
    coordinates = {"v": trace.u_p, "h": trace.v_p}
    directions = [d for d in ("v", "h") if groups[d]]
    profiles = {d: emitted_profiles(projector, sequence, groups[d], lengths[d]) for d in directions}
    weight = tap_weights(trace, projector, projector_intrinsics)
    read = Lookup.bilinear if projector.pixel == Lookup.psf else projector.pixel
    table = projector.supersampling

    def matrix(direction: str) -> scipy.sparse.csr_array:
        position = (
            projector.table_coordinate(coordinates[direction])
            if table > 1
            else (coordinates[direction])
        )
        return lookup_matrix(position, weight, lengths[direction] * table, read)

    # Both directions' matrices are built at once (numpy releases the GIL).
    with ThreadPoolExecutor(max_workers=min(2, threads)) as pool:
        matrices = dict(zip(directions, pool.map(matrix, directions), strict=True))
    for direction in directions:
        _fill_direction(
            out,
            groups[direction],
            matrices[direction],
            profiles[direction],
            ambient,
            transform,
            threads,
            block_pixels,
        )
    if groups[None]:
        white = trace.direct if weight is trace.weight else weight.sum(axis=1)
        for index in groups[None]:
            level = projector.emitted_profile(sequence, index).astype(np.float32).reshape(-1)
            if level.shape != (1,):
                raise InputError(f"sequence.profile({index})", "shape (1,)", level.shape)
            frame = white * level[0]
            if ambient is not None:
                frame += ambient
            out[index] = transform(frame[None, :], np.array([index]), slice(0, n_pixels))[0]
    return out.reshape(n_frames, height, width)


def _fill_direction(
    out: np.ndarray,
    rows: list[int],
    matrix: scipy.sparse.csr_array,
    profiles: np.ndarray,
    ambient: np.ndarray | None,
    transform: Callable[[np.ndarray, np.ndarray, slice], np.ndarray],
    threads: int,
    block_pixels: int,
) -> None:
    """``out[rows] = transform((matrix @ profiles).T + ambient)``, by pixel blocks: the
    transposed (frames, pixels) write stays in cache (a whole-image transpose would cost
    more than the sparse product itself), and blocks run on a thread pool (scipy's sparse
    product and numpy's ufuncs release the GIL)."""
    n_pixels = matrix.shape[0]
    index = np.asarray(rows)
    target = out[index[0] : index[-1] + 1] if np.all(np.diff(index) == 1) else None

    def block_of_frames(start: int) -> None:
        stop = min(start + block_pixels, n_pixels)
        block = (matrix[start:stop] @ profiles).T
        if ambient is not None:
            block = block + ambient[None, start:stop]
        block = transform(block, index, slice(start, stop))
        if target is not None:
            target[:, start:stop] = block
        else:
            out[index, start:stop] = block

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(block_of_frames, range(0, n_pixels, block_pixels)))
