"""The full virtual VDI/VDE 2634-2 acceptance test (10 spheres, 7 ball bars, 6 planes) of the
paper's scanner, in the settings the tests check in miniature, side by side:

* ``true-nearest``: ideal sensor, sharp DMD pixels, the true rig (the staircase alone);
* ``true-bilinear``: ideal sensor, projector pixels blurred over ~1 px, the true rig;
* ``calibrated``: ideal sensor, DMD pixels, the rig from a virtual calibration (the default);
* ``imx174``: the IMX174 sensor, DMD pixels, a virtual calibration;
* ``scale+1%``: ``true-bilinear`` reconstructed with a baseline 1 % long (SD ~ 1 % of the bar).

Reports each figure's largest magnitude (mm) and the wall time of each run. The renderer
takes CUDA where it works, else the CPU; ``--scale 0.25`` makes a quick CPU run (240 px
camera), ``--positions N`` a shortened one.

    PYTHONPATH=src python benchmarks/bench_acceptance.py [--scale 1] [--positions N]
        [--only NAME ...] [--json out.json]

Not a test: numbers depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np


def scanners(scale: float) -> dict[str, tuple[object, object]]:
    """name -> (scanner, calibration) of each setting."""
    from virtus.geometry.devices import Camera, Rig, default_rig
    from virtus.geometry.transforms import Pose
    from virtus.scanner import Scanner
    from virtus.sensor import Lookup, load_projector, load_sensor

    rig = default_rig()
    rig = Rig(Camera(rig.camera.intrinsics.scaled(scale)), rig.projector, rig.proj2cam)
    dmd = Scanner(rig=rig)
    blurred = dmd.with_(projector=load_projector("ideal").with_(pixel=Lookup.bilinear))
    long = Rig(rig.camera, rig.projector, Pose(rig.proj2cam.R, 1.01 * np.asarray(rig.proj2cam.t)))
    return {
        "true-nearest": (dmd, "true"),
        "true-bilinear": (blurred, "true"),
        "calibrated": (dmd, "virtual"),
        "imx174": (dmd.with_(sensor=load_sensor("imx174")), "virtual"),
        "scale+1%": (blurred, long),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0, help="camera resampling factor")
    parser.add_argument("--positions", type=int, default=None)
    parser.add_argument("--only", nargs="*", default=None, help="settings to run")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()

    from virtus.design import acceptance_test
    from virtus.render.backend import choose_variant

    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs"
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (scanner, calibration) in scanners(args.scale).items():
            if args.only and name not in args.only:
                continue
            start = time.perf_counter()
            result = acceptance_test(
                scanner,
                Path(tmp) / name.replace("%", "pct"),
                calibration=calibration,
                positions=args.positions,
            )
            seconds = time.perf_counter() - start
            maxima = {k: v["value_mm"] for k, v in result.summary["maxima"].items()}
            length = result.summary["artefacts"]["bar_length_mm"]
            rows[name] = {"seconds": seconds, "max_mm": maxima, "bar_length_mm": length}
            figures = "  ".join(f"{k} {v:+.4f}" for k, v in maxima.items())
            print(f"{name:14s} {seconds:7.1f} s  {figures}", flush=True)
    report = {
        "machine": machine,
        "variant": choose_variant(None),
        "camera_scale": args.scale,
        "positions": args.positions,
        "runs": rows,
    }
    print(json.dumps(report, indent=1))
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
