"""The counter-based random streams of the sensor noise, defined once for host and device.

Randomness is counter-based (:data:`NOISE_STREAM`): the standard normal of pixel ``p`` in
frame ``f`` is a pure function of ``(seed, f, p)``. The pair ``(seed, f)`` is mixed into a
64-bit key ``(k0, k1)`` by SplitMix64 (Steele et al. 2014); the integer hash pcg4d
(Jarzynski & Olano, "Hash Functions for GPU Rendering", JCGT 2020) of ``(p, k0, k1, 0)``
gives two uniform 24-bit numbers, and Box-Muller turns them into one normal. Integer hashing
is exact on every backend, so the same formula runs here in numpy and on the device in
Dr.Jit (``virtus.render.jit.noise``): a frame's noise never depends on how the work is
split into blocks, threads or kernels, and the same seed gives the same bytes. Between
backends only the float32 ``log``/``cos`` may differ by an ulp, which moves a digital
number only when the value sits within that ulp of a rounding edge.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.errors import InputError

__all__ = [
    "LEGACY_NOISE_STREAMS",
    "MAX_SEED",
    "NOISE_STREAM",
    "PCG_INCREMENT",
    "PCG_MULTIPLIER",
    "UNIFORM_SCALE",
    "as_seed",
    "pcg4d",
    "standard_normal",
    "stream_key",
]

#: Largest seed (seeds are non-negative 63-bit integers, so they survive JSON and C longs).
MAX_SEED = (1 << 63) - 1
#: Description of the noise stream, recorded with every capture.
NOISE_STREAM = "pcg4d(p, splitmix64(seed, frame)) + box-muller, float32"
#: Streams of earlier versions: a capture that names one still loads (its frames are what
#: they are); re-rendering it draws the current stream.
LEGACY_NOISE_STREAMS = ("philox4x64(SeedSequence([seed, frame, pixel // 16384]))",)
#: pcg4d's linear congruential step (Numerical Recipes' constants, as in the paper).
PCG_MULTIPLIER = 1664525
PCG_INCREMENT = 1013904223
#: Uniforms keep 24 bits (exact in float32): u1 in (0, 1], u2 in [0, 1).
_UNIFORM_SHIFT = 8
UNIFORM_SCALE = 2.0**-24
_MASK64 = (1 << 64) - 1


def as_seed(rng: np.random.Generator | int | None) -> int:
    """The integer seed of the counter-based streams from the project's ``rng`` argument.

    An int is used as it is (``0 <= seed <= MAX_SEED``); ``None`` is seed 0 (captures are
    reproducible by default); a Generator draws one seed, so a seeded Generator still gives
    reproducible captures.
    """
    if isinstance(rng, np.random.Generator):
        return int(rng.integers(0, MAX_SEED, endpoint=True))
    if rng is None:
        return 0
    if isinstance(rng, bool) or not isinstance(rng, int | np.integer):
        raise InputError("seed", "a non-negative integer, a numpy Generator or None", rng)
    if not 0 <= int(rng) <= MAX_SEED:
        raise InputError("seed", f"an integer in 0..{MAX_SEED}", rng)
    return int(rng)


def _splitmix64(value: int) -> int:
    """SplitMix64's output function on a 64-bit integer (Python ints, exact)."""
    value = (value + 0x9E3779B97F4A7C15) & _MASK64
    value = ((value ^ (value >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    value = ((value ^ (value >> 27)) * 0x94D049BB133111EB) & _MASK64
    return value ^ (value >> 31)


def stream_key(seed: int, frame: int) -> tuple[int, int]:
    """The 64-bit key ``(k0, k1)`` (two uint32) of frame ``frame``'s stream under ``seed``."""
    key = _splitmix64(_splitmix64(int(seed) & _MASK64) ^ (int(frame) & _MASK64))
    return key & 0xFFFFFFFF, key >> 32


def pcg4d(x: Any, y: Any, z: Any, w: Any) -> tuple[Any, Any, Any, Any]:
    """The pcg4d hash of four uint32 arrays (numpy ``uint32`` or Dr.Jit ``UInt32``: only
    wrapping integer arithmetic, shifts and xor, so both give the same bits)."""
    x = x * PCG_MULTIPLIER + PCG_INCREMENT
    y = y * PCG_MULTIPLIER + PCG_INCREMENT
    z = z * PCG_MULTIPLIER + PCG_INCREMENT
    w = w * PCG_MULTIPLIER + PCG_INCREMENT
    x += y * w
    y += z * x
    z += x * y
    w += y * z
    x ^= x >> 16
    y ^= y >> 16
    z ^= z >> 16
    w ^= w >> 16
    x += y * w
    y += z * x
    z += x * y
    w += y * z
    return x, y, z, w


def standard_normal(seed: int, frame: int, pixels: slice) -> np.ndarray:
    """(stop - start,) float32 standard normals of frame ``frame`` at the row-major pixel
    indices ``pixels`` (a slice with step 1), identical however the pixels are split."""
    start, stop = pixels.start or 0, pixels.stop
    k0, k1 = stream_key(seed, frame)
    p = np.arange(start, stop, dtype=np.uint32)
    a, b, _, _ = pcg4d(p, np.full_like(p, k0), np.full_like(p, k1), np.zeros_like(p))
    u1 = ((a >> _UNIFORM_SHIFT) + np.uint32(1)).astype(np.float32) * np.float32(UNIFORM_SCALE)
    u2 = (b >> _UNIFORM_SHIFT).astype(np.float32) * np.float32(UNIFORM_SCALE)
    radius = np.sqrt(np.float32(-2.0) * np.log(u1))
    return radius * np.cos(np.float32(2.0 * np.pi) * u2)
