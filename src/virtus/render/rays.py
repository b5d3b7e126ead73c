"""Camera ray directions: the stratified sub-pixel offsets of a pixel's supersamples, and
every pixel's centre and supersample rays for a camera, cached and laid out as the kernels
read them (:mod:`virtus.render.tracing` and its device twin :mod:`virtus.render.jit.tracing`).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.geometry.optics import Intrinsics

__all__ = ["ROW_ALIGN", "aligned_rows", "camera_rays", "sample_offsets"]


def sample_offsets(spp: int) -> np.ndarray:
    """(spp, 2) float64 stratified sub-pixel offsets ``(du, dv)`` whose centroid is 0.

    ``spp`` must be a perfect square s * s: an s x s grid at ``(i + 0.5) / s - 0.5`` px.
    """
    spp = positive_int("spp", spp)
    side = math.isqrt(spp)
    if side * side != spp:
        raise InputError("spp", "a perfect square (1, 4, 9, 16, ...)", spp)
    grid = (np.arange(side) + 0.5) / side - 0.5
    dv, du = np.meshgrid(grid, grid, indexing="ij")
    return np.stack([du.ravel(), dv.ravel()], axis=1)


#: Byte alignment of each row of the ray arrays that kernels read in place. On LLVM, Dr.Jit
#: maps a numpy array's memory (no copy) and compiles its loads as aligned only when the
#: address is a multiple of the vector's size (128 bytes: 16 float64 lanes), so where numpy's
#: allocator happened to put the rays decided the kernel's source: a new pose, whose rays
#: were copied anew, could compile the kernel again (a test caught it in CI).
ROW_ALIGN = 128


def aligned_rows(values: np.ndarray) -> np.ndarray:
    """A read-only copy of (R, N) ``values`` whose rows each start at a multiple of
    :data:`ROW_ALIGN` bytes."""
    rows, n = values.shape
    itemsize = values.dtype.itemsize
    stride = -(-n * itemsize // ROW_ALIGN) * ROW_ALIGN
    buffer = np.empty(rows * stride + ROW_ALIGN, np.uint8)
    offset = -buffer.ctypes.data % ROW_ALIGN
    out = np.ndarray((rows, n), values.dtype, buffer, offset, (stride, itemsize))
    out[...] = values
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=2)
def camera_rays(intrinsics: Intrinsics, spp: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit ray directions in the camera frame, cached (datasets render many poses with one
    camera): centre rays (3, P) float64, and supersample rays (3, P * spp) float32 (rows x,
    y, z; pixel-major order), each row :data:`ROW_ALIGN`-byte aligned."""
    grid = intrinsics.pixel_grid().reshape(-1, 2)
    centre = aligned_rows(intrinsics.unproject(grid).T)
    pixels = (grid[:, None, :] + sample_offsets(spp)[None, :, :]).reshape(-1, 2)
    samples = aligned_rows(intrinsics.unproject(pixels).T.astype(np.float32))
    return centre, samples
