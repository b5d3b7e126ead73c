"""The uncertainty model against Monte Carlo over the issue's whole matrix, and the speed of a
12-variant prediction-only design sweep.

1. **Model vs Monte Carlo**: a tilted plane and a sphere (24 mm, filling most of the field)
   at 1 m, N = 3, 4, 18 steps, periods 18 and 36 px, the shot-noise-limited 12-bit sensor
   (``ideal12``: the ``ideal`` preset is noise-free, so re-renders would not differ),
   ``imx174`` and ``webcam``; the paper's rig with its camera cropped to ``--size`` px (the
   paper's pixel footprint). For each case, the predicted sigma of ``u_p`` and of depth
   against the standard deviation over ``--draws`` noisy re-renders
   (:func:`virtus.design.montecarlo.monte_carlo`): the ratio measured / predicted at the
   median pixel and at the raw 95th percentile, and whether the issue's bounds (10 % median,
   20 % raw 95th percentile) hold; with the ratio of the 90-99th percentile band pooled
   (no sampling bias) as an extra column. The raw 95th percentile includes the draws' own
   sampling inflation, printed for the draw count (1.08 for the default 200 draws, 1.21 for
   30: :func:`virtus.design.montecarlo.p95_sampling_inflation`).
2. **Design sweep**: ``virtus design`` with 12 variants (steps 3, 4, 9, 18 x period 12, 18,
   36 px), prediction only, ``--grid`` camera samples a side, timed with ``--workers``.

    PYTHONPATH=src python benchmarks/bench_uncertainty.py [--draws 200] [--size 48]
        [--grid 64] [--workers 1] [--json out.json]

Runs on the CPU (Mitsuba's LLVM variant) by default; with ``VIRTUS_MITSUBA_VARIANT=cuda_ad_rgb``
the traces run on the GPU (the noise and decode stay on the host). Not a test: the times
depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from virtus.design import monte_carlo, run_design
from virtus.design.montecarlo import DEFAULT_DRAWS, p95_sampling_inflation
from virtus.patterns import build_sequence
from virtus.render.settings import RenderSettings
from virtus.scanner import Scanner
from virtus.sensor import SENSOR_PRESETS, Sensor

ROOT = Path(__file__).resolve().parents[1]

SENSORS = {
    "ideal12": Sensor(name="ideal12", bit_depth=12, system_gain_dn_per_e=4095 / 20000),
    "imx174": SENSOR_PRESETS["imx174"],
    "webcam": SENSOR_PRESETS["webcam"],
}


def model_vs_monte_carlo(draws: int, size: int) -> list[dict]:
    sys.path.insert(0, str(ROOT))  # the test suite's scenes and rig: the same cases
    from tests.support import cropped_rig, uncertainty_scenes

    rows = []
    rig = cropped_rig(size)
    header = f"{'scene':<7}{'sensor':<9}{'N':>3}{'T':>4}  " + " ".join(
        f"{q + ' ' + s:>15}" for q in ("u_p", "depth") for s in ("median", "p95", "p95 pooled")
    )
    print(
        f"raw 95th percentile: sampling spread alone lifts it to "
        f"{p95_sampling_inflation(draws):.3f} on a constant sigma ({draws} draws)"
    )
    print(header + f"{'ok':>5}{'orders':>8}")
    for scene_name, scene in uncertainty_scenes().items():
        for sensor_name, sensor in SENSORS.items():
            for steps in (3, 4, 18):
                for period in (18.0, 36.0):
                    sequence = build_sequence(912, 1140, periods=period, steps=steps,
                                              gray_bits=7, directions=("v",))  # fmt: skip
                    scanner = Scanner(rig=rig, sequence=sequence, sensor=sensor,
                                      render=RenderSettings(spp=4))  # fmt: skip
                    result = monte_carlo(scanner, scene, draws)
                    row = {"scene": scene_name, "sensor": sensor_name, "steps": steps,
                           "period_px": period, "order_errors": result.order_errors}  # fmt: skip
                    cells = []
                    ok = True
                    for quantity in ("u_p", "depth"):
                        ratios = result.ratios(quantity)
                        row[quantity] = ratios
                        row[f"{quantity}_predicted_median"] = float(
                            np.median(result.predicted[quantity])
                        )
                        ok &= abs(ratios["median"] - 1) <= 0.1
                        ok &= abs(ratios["p95_raw"] - 1) <= 0.2
                        cells += [ratios["median"], ratios["p95_raw"], ratios["p95_pooled"]]
                    row["within_bounds"] = bool(ok)
                    rows.append(row)
                    print(f"{scene_name:<7}{sensor_name:<9}{steps:>3}{period:>4.0f}  "
                          + " ".join(f"{c:>15.3f}" for c in cells)
                          + f"{'yes' if ok else 'NO':>5}{result.order_errors:>8.2%}",
                          flush=True)  # fmt: skip
    return rows


def sweep_timing(grid: int, workers: int) -> dict:
    vary = ["steps=3,4,9,18", "period_px=12,18,36"]
    base = Scanner(sensor=SENSOR_PRESETS["imx174"])
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        rows = run_design(out, base, vary=vary, grid=grid, workers=workers)
        seconds = time.perf_counter() - start
    print(f"\ndesign sweep: {len(rows)} variants, grid {grid}, workers {workers}: "
          f"{seconds:.1f} s ({seconds / len(rows):.2f} s a variant)")  # fmt: skip
    for row in rows:
        print(f"  steps {row['steps']:>2} period {row['period_px']:>4.0f} px: depth sigma "
              f"median {row['sigma_depth_um_median']:7.2f} um, p95 "
              f"{row['sigma_depth_um_p95']:7.2f} um")  # fmt: skip
    return {"variants": len(rows), "grid": grid, "workers": workers, "seconds": seconds,
            "rows": rows}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=DEFAULT_DRAWS,
                        help="noisy re-renders per case")  # fmt: skip
    parser.add_argument("--size", type=int, default=48, help="camera px a side (cropped)")
    parser.add_argument("--grid", type=int, default=64, help="sweep camera samples a side")
    parser.add_argument("--workers", type=int, default=1, help="sweep worker processes")
    parser.add_argument("--skip-matrix", action="store_true", help="only the sweep timing")
    parser.add_argument("--json", help="write the results to this JSON file")
    args = parser.parse_args()
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs"
    variant = os.environ.get("VIRTUS_MITSUBA_VARIANT", "auto")
    print(f"{machine}; Mitsuba variant {variant}; {args.draws} draws, {args.size} px\n")
    start = time.perf_counter()
    matrix = [] if args.skip_matrix else model_vs_monte_carlo(args.draws, args.size)
    if matrix:
        held = sum(r["within_bounds"] for r in matrix)
        print(f"\n{held}/{len(matrix)} cases within the bounds "
              f"({time.perf_counter() - start:.1f} s)")  # fmt: skip
    timing = sweep_timing(args.grid, args.workers)
    if args.json:
        with open(args.json, "w") as file:
            json.dump({"machine": machine, "matrix": matrix, "sweep": timing}, file, indent=1)


if __name__ == "__main__":
    main()
