"""Decode speed of pattern sequences on full 960 x 960 camera frames.

Run: ``PYTHONPATH=src python benchmarks/bench_patterns_decode.py``. Prints the best of a few
runs per sequence (uint8 frames, as the renderer's 8-bit sensor writes them) and the time
to encode the projector images, side by side.
"""

from __future__ import annotations

import time

import numpy as np

from virtus.patterns import PatternSequence, default_sequence, heterodyne_sequence


def ideal_frames(sequence: PatternSequence, height: int, width: int, seed: int) -> np.ndarray:
    """8-bit camera frames of a smooth random surface: I = A + B * pattern(u_p, v_p)."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    u = cols * (sequence.width - 1) / (width - 1) + rng.uniform(-0.4, 0.4, (height, width))
    v = rows * (sequence.height - 1) / (height - 1) + rng.uniform(-0.4, 0.4, (height, width))
    frames = np.empty((len(sequence), height, width), dtype=np.uint8)
    for index, frame in enumerate(sequence.frames):
        coordinate = u if frame.direction == "v" else v
        frames[index] = np.rint(40 + 150 * frame.values(coordinate))
    return frames


def best_of(function, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    height = width = 960
    print(f"decode of {height} x {width} uint8 frames (best of 3)")
    print(f"{'sequence':<12} {'frames':>6} {'decode s':>9} {'images() s':>11} {'ratio':>6}")
    reference = None
    for name, sequence in (("default", default_sequence()), ("heterodyne", heterodyne_sequence())):
        frames = ideal_frames(sequence, height, width, seed=0)
        decode_s = best_of(lambda s=sequence, f=frames: s.decode(f))
        encode_s = best_of(sequence.images)
        reference = reference or decode_s
        print(
            f"{name:<12} {len(sequence):>6} {decode_s:>9.3f} {encode_s:>11.3f} "
            f"{decode_s / reference:>6.2f}"
        )


if __name__ == "__main__":
    main()
