"""Speed of the main job, ``virtus demo``, against the issue's 120 s budget (2 CPU cores).

Runs the command as a user would (a fresh process: imports, Mitsuba start-up, 18-pose
calibration, sphere capture, reconstruction, fit, files), then reports the stages of that
run from its ``metrics.json`` side by side with their shares, and the accuracy it reached.

    PYTHONPATH=src python benchmarks/bench_demo.py [--json out.json]

Not a test: numbers depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The issue's budget for the whole demo on 2 CPU cores, seconds.
BUDGET_S = 120.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        command = [sys.executable, "-m", "virtus", "demo", "--out", str(out)]
        start = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        metrics = json.loads((out / "metrics.json").read_text())

    timing = metrics["timing"]
    stages = {
        "calibration (18 poses x 52 frames)": timing["calibration_s"],
        "sphere scan (render + decode + triangulate + files)": timing["scan_s"],
        "sphere fit": timing["fit_s"],
        "reference fit with the true rig": timing["reference_s"],
    }
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs"
    print(f"virtus demo on {machine}")
    print(f"  wall time of the command: {wall:7.1f} s  ({wall / BUDGET_S:.0%} of {BUDGET_S:.0f} s)")
    print(f"  library total (metrics):  {timing['total_s']:7.1f} s")
    print(f"  start-up (imports, Mitsuba) and metrics.json: {wall - timing['total_s']:.1f} s")
    for name, seconds in stages.items():
        print(f"    {name:52s} {seconds:6.1f} s  {seconds / timing['total_s']:5.1%}")
    sphere = metrics["sphere"]
    print(
        f"  radius error {sphere['radius_error_mm']:+.4f} mm, "
        f"inliers {sphere['inlier_ratio']:.2%}, fit RMS {sphere['fit_rms_mm']:.3f} mm"
    )
    if args.json is not None:
        report = {"wall_s": wall, "budget_s": BUDGET_S, "stages_s": stages, "machine": machine,
                  "sphere": {k: v for k, v in sphere.items() if k != "radial_error_histogram_mm"},
                  "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}  # fmt: skip
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
