"""Decode speed on the device (:func:`virtus.render.jit.decode.decode_on_device`) vs the host.

Run: ``PYTHONPATH=src python benchmarks/bench_decode_jit.py`` (``VIRTUS_MITSUBA_VARIANT=
cuda_ad_rgb`` or ``llvm_ad_rgb`` to choose the device; default: CUDA if it works). Decodes
the paper's default 52-frame sequence from 960 x 960 uint8 frames uploaded once: on the
device with the result kept there (``dr.eval``), on the device with the result brought back
(``to_host``), and on the host (``PatternSequence.decode``, neighbour check off as the
default sequence has it off), each the best of a few runs after one warm-up (kernel
compilation), in frames decoded per second (frames of the sequence / seconds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_patterns_decode import ideal_frames

from virtus.patterns import default_sequence
from virtus.render.backend import mitsuba
from virtus.render.jit.decode import decode_on_device, frames_to_device


def best_of(function, repeats: int) -> float:
    """Seconds of the fastest of ``repeats`` calls, after one untimed warm-up call."""
    function()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=960, help="camera px per side")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    mi, dr, variant = mitsuba()
    sequence = default_sequence()
    height = width = args.size
    frames = ideal_frames(sequence, height, width, seed=0)
    on_device = frames_to_device(frames, variant)
    dr.eval(on_device)
    dr.sync_thread()
    count = len(sequence)

    def kept(precision: str):
        def run() -> None:
            result = decode_on_device(on_device, sequence, height, width, precision=precision)
            dr.eval(*result.arrays())
            dr.sync_thread()

        return run

    def to_host(precision: str):
        def run() -> None:
            decode_on_device(on_device, sequence, height, width, precision=precision).to_host(
                sequence
            )

        return run

    host = sequence.decode(frames, neighbour_check=False)
    device = decode_on_device(on_device, sequence, height, width).to_host(sequence)
    differ = int(np.count_nonzero(host.mask != device.mask))
    valid = host.mask & device.mask
    error = np.abs(device.proj_uv[valid] - host.proj_uv[valid])

    print(f"variant {variant}; {count} frames of {height} x {width} uint8 (best of {args.repeats})")
    print(f"agreement: {differ} mask pixels differ, max |proj_uv difference| {error.max():.2e} px")
    print(f"{'decode':<34} {'seconds':>9} {'frames/s':>10}")
    rows = []
    for precision in ("float64", "float32"):
        rows.append((f"device {precision}, kept (dr.eval)", best_of(kept(precision), args.repeats)))
        rows.append((f"device {precision}, to_host", best_of(to_host(precision), args.repeats)))
    host_s = best_of(lambda: sequence.decode(frames, neighbour_check=False), args.repeats)
    rows.append(("host PatternSequence.decode", host_s))
    for name, seconds in rows:
        print(f"{name:<34} {seconds:>9.4f} {count / seconds:>10.1f}")


if __name__ == "__main__":
    main()
