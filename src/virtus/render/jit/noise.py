"""The sensor's counter-based noise streams on Dr.Jit arrays (the device twin of
:func:`virtus.sensor.camera.standard_normal`).

Same definition (:data:`virtus.sensor.camera.NOISE_STREAM`): per frame a 64-bit key from
:func:`virtus.sensor.camera.stream_key`, the pcg4d hash (:func:`virtus.sensor.camera.pcg4d`, which
runs
unchanged on ``UInt32`` arrays) of ``(pixel, k0, k1, 0)``, Box-Muller. Keys are computed on
the host (a few Python integers per frame) and gathered by frame inside the synthesis
kernel (in its frame loop, or per lane of a lane per frame and pixel), so one kernel draws
the noise of every frame of a pose.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from virtus.sensor.camera import Sensor
from virtus.sensor.noise import UNIFORM_SCALE, pcg4d, stream_key


def frame_keys(mi: Any, seed: int, frames: np.ndarray) -> tuple[Any, Any]:
    """``(k0, k1)`` UInt32 arrays of the streams of ``frames`` (sequence indices)."""
    keys = np.array([stream_key(seed, int(f)) for f in frames], dtype=np.uint32).reshape(-1, 2)
    return mi.UInt32(keys[:, 0]), mi.UInt32(keys[:, 1])


def standard_normal_jit(mi: Any, dr: Any, k0: Any, k1: Any, pixel: Any) -> Any:
    """Float standard normals at ``pixel`` (UInt32 row-major pixel indices) of the streams
    whose keys are ``k0, k1`` (UInt32, one per lane or broadcast)."""
    zero = dr.zeros(mi.UInt32, dr.width(pixel))
    a, b, _, _ = pcg4d(mi.UInt32(pixel), k0 + zero, k1 + zero, zero)
    u1 = mi.Float((a >> 8) + 1) * UNIFORM_SCALE
    u2 = mi.Float(b >> 8) * UNIFORM_SCALE
    return dr.sqrt(-2.0 * dr.log(u1)) * dr.cos(2.0 * dr.pi * u2)


@functools.lru_cache(maxsize=4)
def pixel_patterns(variant: str, sensor: Sensor, n_pixels: int) -> tuple[Any, Any]:
    """The sensor's PRNU and DSNU maps as Float (P,) device arrays indexed by row-major pixel,
    or None where the sensor has none (uploaded once per sensor and size)."""
    from virtus.render.backend import mitsuba

    mi, _, _ = mitsuba(variant)
    return tuple(None if m is None else mi.Float(m) for m in sensor.fixed_patterns(n_pixels))  # type: ignore[return-value]
