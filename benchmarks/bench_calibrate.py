"""Speed of a whole virtual calibration: ``virtus calibrate`` (18 poses x 52 frames = 936).

Runs the command as a user would (a fresh process: imports, Mitsuba start-up, capture,
calibration, files) and reports its wall time against the issue's 60 s budget, then the
library call twice in this process: the first compiles the kernels (and starts the
observation workers), the second is the warm time (the GPU issue's "excluding interpreter
and JIT start-up"), with the stages of the warm run (render + decode, detect + fit summed
over the worker processes, calibration) and frames/s.

    PYTHONPATH=src python benchmarks/bench_calibrate.py [--board 7x13] [--json out.json]

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

#: The issue's budget for the whole run on 2 CPU cores, seconds.
BUDGET_S = 60.0


def run_cli(board: str, out: Path) -> float:
    """Wall time (s) of ``virtus calibrate`` in a fresh Python process."""
    command = [sys.executable, "-m", "virtus", "calibrate", "--board", board, "--out", str(out)]
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--board", default="7x13")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()

    from virtus.pipeline.calibrate import calibrate_rig, observe_processes
    from virtus.render.backend import choose_variant
    from virtus.scanner import Scanner

    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs"
    with tempfile.TemporaryDirectory() as tmp:
        cli_s = run_cli(args.board, Path(tmp) / "cli")
        start = time.perf_counter()
        calibrate_rig(Scanner(), board=args.board, out_dir=Path(tmp) / "first")
        first_s = time.perf_counter() - start
        start = time.perf_counter()
        result = calibrate_rig(Scanner(), board=args.board, out_dir=Path(tmp) / "lib")
        library_s = time.perf_counter() - start
    timing = result.timing_s  # run-dependent, so not in calibration.json (see timing.json)
    frames = result.settings["n_poses"] * result.settings["frames_per_pose"]
    workers = observe_processes()
    print(
        f"virtual calibration, board {args.board}, {frames} frames ({machine}), variant "
        f"{choose_variant()}, observed in {workers or 'this'} process{'es' if workers else ''}"
    )
    print(f"first library call (compiles kernels, starts workers): {first_s:.2f} s")
    print(f"{'stage (warm call)':<28} {'s':>7} {'share':>7} {'frames/s':>9}")
    for name, key in (
        ("render (+ decode on a GPU)", "render_s"),
        ("detect + decode + fit", "observe_s"),
        ("calibrate", "calibrate_s"),
    ):
        print(
            f"{name:<28} {timing[key]:>7.2f} {timing[key] / library_s:>7.1%} "
            f"{frames / timing[key]:>9.1f}"
        )
    print(f"{'library total':<28} {library_s:>7.2f} {1:>7.1%} {frames / library_s:>9.1f}")
    print(
        f"{'virtus calibrate (CLI)':<28} {cli_s:>7.2f} {cli_s / BUDGET_S:>7.1%} of the "
        f"{BUDGET_S:.0f} s budget"
    )
    print(f"rms px: {json.dumps({k: round(v, 4) for k, v in result.rms_px.items()})}")
    if args.json is not None:
        args.json.write_text(
            json.dumps(
                {
                    "machine": machine,
                    "board": args.board,
                    "frames": frames,
                    "cli_s": cli_s,
                    "library_first_s": first_s,
                    "library_s": library_s,
                    "observe_processes": workers,
                    "stages_s": timing,
                    "budget_s": BUDGET_S,
                    "rms_px": result.rms_px,
                },
                indent=2,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
