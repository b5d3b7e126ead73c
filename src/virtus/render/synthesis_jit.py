"""Frame synthesis on Dr.Jit arrays: the same model as :mod:`virtus.render.synthesis`,
run where Mitsuba runs (on the GPU with ``cuda_ad_rgb``).

Per frame, each supersample gathers its pattern value from the frame's 1-D profile, the
weighted samples of a pixel are summed (``block_sum``) and the sensor digitises the result
on the device; only the digital frames come back to the host. On a GPU this removes the
host-side sparse products that otherwise dominate; on the CPU the sparse path is faster.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.errors import InputError
from virtus.projection import Lookup, ProjectorModel
from virtus.render.backend import mitsuba
from virtus.render.synthesis import (
    as_projector,
    emitted_profiles,
    projector_groups,
    tap_weights,
)
from virtus.render.tracing import Trace
from virtus.sensor import Sensor


def synthesize_digital(
    trace: Trace,
    sequence: Any,
    projector: ProjectorModel | str,
    sensor: Sensor,
    exposure: float,
    seed: int = 0,
    projector_intrinsics: Any | None = None,
) -> np.ndarray:
    """Digital frames (F, H, W) of ``sequence`` from ``trace``, synthesised with Dr.Jit in the
    variant that traced it; same result as :func:`virtus.render.synthesis.synthesize`
    followed by ``sensor.digitize`` (up to float32 rounding at exact half levels). A noisy
    sensor digitises each frame on the host from the counter-based streams of ``seed``, so
    its noise is the same as on the CPU path.
    """
    projector = as_projector(projector)
    mi, dr, _ = mitsuba(trace.variant)
    n_frames = len(sequence.frames)
    n_pixels, spp = trace.weight.shape
    groups = projector_groups(sequence, projector)
    weight = mi.Float(tap_weights(trace, projector, projector_intrinsics).reshape(-1))
    table = projector.supersampling
    read = Lookup.bilinear if projector.pixel == Lookup.psf else projector.pixel
    ambient = mi.Float(trace.ambient) if np.any(trace.ambient) else None
    lengths = {"v": trace.projector_width, "h": trace.projector_height}
    out = np.empty((n_frames, n_pixels), dtype=sensor.dtype)

    def finish(index: int, radiance: Any) -> None:
        if ambient is not None:
            radiance = radiance + ambient
        if sensor.noisy:
            host = np.asarray(radiance.numpy(), dtype=np.float32)[None, :]
            out[index] = sensor.digitize(
                host, exposure, seed=seed, frames=np.array([index]), pixels=slice(0, n_pixels)
            )[0]
            return
        digital = sensor.digitize_jit(radiance, exposure, dr)
        out[index] = (mi.UInt8(digital) if sensor.bit_depth == 8 else mi.UInt32(digital)).numpy()

    for direction, coordinate in (("v", trace.u_p), ("h", trace.v_p)):
        if not groups[direction]:
            continue
        length = lengths[direction] * table
        if table > 1:
            coordinate = projector.table_coordinate(coordinate)
        c = mi.Float(np.ascontiguousarray(coordinate, dtype=np.float32).reshape(-1))
        if read == Lookup.nearest:
            taps = [(mi.UInt32(dr.clip(dr.floor(c + 0.5), 0, length - 1)), weight)]
        else:
            x = dr.clip(c, 0.0, float(length - 1))
            left = dr.minimum(dr.floor(x), float(max(length - 2, 0)))
            frac = x - left
            right = dr.minimum(left + 1.0, float(length - 1))
            taps = [(mi.UInt32(left), weight * (1.0 - frac)), (mi.UInt32(right), weight * frac)]
        for column, tap_weight in taps:
            dr.eval(column, tap_weight)
        profiles = emitted_profiles(projector, sequence, groups[direction], lengths[direction])
        for k, index in enumerate(groups[direction]):
            profile = mi.Float(np.ascontiguousarray(profiles[:, k]))
            values = sum(dr.gather(mi.Float, profile, col) * w for col, w in taps)
            finish(index, dr.block_sum(values, spp))
    if groups[None]:
        direct = dr.block_sum(weight, spp)
        for index in groups[None]:
            level = projector.emitted_profile(sequence, index).astype(np.float32).reshape(-1)
            if level.shape != (1,):
                raise InputError(f"sequence.profile({index})", "shape (1,)", level.shape)
            finish(index, direct * float(level[0]))
    return out.reshape(n_frames, trace.height, trace.width)
