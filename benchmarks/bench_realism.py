"""Renderer speed with realism on: ideal (direct light, pinholes) vs each effect alone.

Renders the paper's 52-frame sequence of the default scene (100 mm sphere at 1 m before a
wall) with the default rig (960 x 960 camera) in one run, once per configuration:

* ``ideal``: 1 bounce, pinholes, 4 spp (4 taps per pixel);
* ``bounces 2`` / ``bounces 3``: interreflections (8 / 12 taps per pixel);
* ``projector defocus``: a thin-lens projector, 10 mm aperture focused at 1.15 m, with
  ``--aperture-samples`` (default 8) aperture samples per vertex (4 x 8 = 32 taps per pixel);
* ``camera DOF``: a thin-lens camera, 10 mm aperture focused at 1.15 m, 16 spp (its aperture
  is sampled by the camera supersamples; 16 taps per pixel).

For each it prints the trace time, the synthesis time of all frames (float radiance, sparse
host path), frames/s of both together, and the slowdown against ``ideal``.

    PYTHONPATH=src python benchmarks/bench_realism.py [--repeats 1] [--json out.json]

Not a test: numbers depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from virtus.geometry.devices import default_rig
from virtus.geometry.optics import ThinLens
from virtus.patterns import default_sequence
from virtus.render import synthesize, trace
from virtus.scene.model import default_scene


def configurations(aperture_samples: int) -> dict[str, dict]:
    """Name -> ``trace`` keyword arguments of each configuration."""
    lens = ThinLens(aperture_m=0.01, focus_distance_m=1.15)
    return {
        "ideal": {"spp": 4},
        "bounces 2": {"spp": 4, "bounces": 2},
        "bounces 3": {"spp": 4, "bounces": 3},
        "projector defocus": {
            "spp": 4,
            "projector_lens": lens,
            "aperture_samples": aperture_samples,
        },
        "camera DOF": {"spp": 16, "camera_lens": lens},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1, help="timed runs per configuration")
    parser.add_argument("--aperture-samples", type=int, default=8)
    parser.add_argument("--lookup", default="nearest", choices=["nearest", "bilinear"])
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    args = parser.parse_args()

    rig, scene, sequence = default_rig(), default_scene(), default_sequence()
    n_frames = len(sequence)
    trace(rig, scene, spp=4)  # compile the kernels and fill the camera-ray cache once
    rows = []
    for name, options in configurations(args.aperture_samples).items():
        best = None
        for _ in range(args.repeats):
            start = time.perf_counter()
            traced = trace(rig, scene, **options)
            traced_s = time.perf_counter() - start
            start = time.perf_counter()
            synthesize(traced, sequence, args.lookup)
            synth_s = time.perf_counter() - start
            if best is None or traced_s + synth_s < best[0] + best[1]:
                best = (traced_s, synth_s, traced.weight.shape[1])
            del traced
        traced_s, synth_s, taps = best
        rows.append(
            {
                "config": name,
                "taps_per_pixel": taps,
                "trace_s": traced_s,
                "synthesis_s": synth_s,
                "frames_per_s": n_frames / (traced_s + synth_s),
            }
        )
    ideal = rows[0]["frames_per_s"]
    machine = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}"
    )
    print(f"{machine}; {rig.camera.width} x {rig.camera.height} px, {n_frames} frames, "
          f"{args.lookup} lookup")  # fmt: skip
    header = ("config", "taps/px", "trace s", "synth s", "frames/s", "vs ideal")
    print(f"{header[0]:<18} " + " ".join(f"{h:>8}" for h in header[1:]))
    for row in rows:
        row["slowdown"] = ideal / row["frames_per_s"]
        print(
            f"{row['config']:<18} {row['taps_per_pixel']:>8d} {row['trace_s']:>8.2f} "
            f"{row['synthesis_s']:>8.2f} {row['frames_per_s']:>8.1f} {row['slowdown']:>7.2f}x"
        )
    if args.json:
        args.json.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
