"""Speed of a whole virtual calibration: ``virtus calibrate`` (18 poses x 52 frames = 936).

Runs the command as a user would (a fresh process: imports, Mitsuba start-up, capture,
calibration, files) and reports its wall time against the issue's 60 s budget, then the
library call twice in this process: the first compiles the kernels (and starts the
observation workers), the second is the warm time (the GPU issue's "excluding interpreter
and JIT start-up"), with the stages of the warm run (render + decode, detect + fit summed
over the worker processes, calibration) and frames/s.

Then, same process, alternating and repeated (``--repeat``): the whole library call with
the observation of before issue 25 (one ``cv2.findHomography`` RANSAC fit per circle and
the wrapped phase on a float64 copy of the whole stack) against today's (one batched fit
for all circles, a blocked wrapped phase), both observing in this process so that the
patch reaches them, with the calibration's RMS to 4 decimals; and the parts of one pose
(host decode, wrapped phase of one phase set, local homographies, whole observation) on
the first ``--parts-poses`` poses rendered on the host, with how far the old and new
projector points are apart.

    PYTHONPATH=src python benchmarks/bench_calibrate.py [--board 7x13] [--repeat 3]
        [--parts-poses 3] [--skip-cli] [--json out.json]

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
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

#: The issue's budget for the whole run on 2 CPU cores, seconds.
BUDGET_S = 60.0


def run_cli(board: str, out: Path) -> float:
    """Wall time (s) of ``virtus calibrate`` in a fresh Python process."""
    command = [sys.executable, "-m", "virtus", "calibrate", "--board", board, "--out", str(out)]
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def wrapped_phase_before(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``virtus.patterns.phase.wrapped_phase`` as it was before issue 25 (one product on a
    float64 copy of the whole stack, then whole-image temporaries), for the comparison."""
    stack = np.asarray(frames)
    steps = stack.shape[0]
    shifts = 2.0 * np.pi * np.arange(1, steps + 1) / steps
    weights = np.stack([np.ones(steps), np.cos(shifts), np.sin(shifts)])
    sums = weights @ stack.reshape(steps, -1).astype(np.float64, copy=False)
    phase = np.arctan2(-sums[2], sums[1])
    phase[phase >= np.pi] -= 2.0 * np.pi
    background = sums[0] / steps
    modulation = (2.0 / steps) * np.hypot(sums[1], sums[2])
    shape = stack.shape[1:]
    return phase.reshape(shape), background.reshape(shape), modulation.reshape(shape)


@contextmanager
def observation(kind: str) -> Iterator[None]:
    """Run the block with the ``"old"`` (per-circle cv2, whole-stack phase) or ``"new"``
    observation and host decode (patched in this process only)."""
    from virtus.calib import observe, projector
    from virtus.patterns import phase

    saved = (observe.local_homographies, phase.wrapped_phase)
    if kind == "old":
        observe.local_homographies = projector.local_homographies_per_circle
        phase.wrapped_phase = wrapped_phase_before
    try:
        yield
    finally:
        observe.local_homographies, phase.wrapped_phase = saved


def spread(values: list[float]) -> str:
    """``min-max`` of timings in seconds, as ms when short."""
    lo, hi = min(values), max(values)
    return f"{lo * 1e3:.1f}-{hi * 1e3:.1f} ms" if hi < 1.0 else f"{lo:.2f}-{hi:.2f} s"


def compare_totals(board: str, repeat: int) -> dict[str, Any]:
    """The library call with the old and the new observation, alternating, ``repeat``
    times each, observing in this process: wall, stages and RMS per run."""
    from virtus.pipeline.calibrate import calibrate_rig
    from virtus.scanner import Scanner

    runs: dict[str, list[dict[str, Any]]] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(repeat):
            for kind in ("old", "new"):
                with observation(kind):
                    start = time.perf_counter()
                    result = calibrate_rig(
                        Scanner(), board=board, out_dir=Path(tmp) / f"{kind}{index}", processes=0
                    )
                    wall = time.perf_counter() - start
                runs[kind].append({"s": wall, "stages_s": result.timing_s, "rms_px": result.rms_px})
    print(f"\nold vs new observation, same process, {repeat} runs each (observed in this process)")
    print(f"{'':<26} {'old':>17} {'new':>17} {'old/new':>9}")
    keys = [("library total", None), *[(k, k) for k in ("render_s", "observe_s", "calibrate_s")]]
    for label, key in keys:
        old = [r["s"] if key is None else r["stages_s"][key] for r in runs["old"]]
        new = [r["s"] if key is None else r["stages_s"][key] for r in runs["new"]]
        ratio = f"{min(old) / max(new):.2f}-{max(old) / min(new):.2f}"
        print(f"{label:<26} {spread(old):>17} {spread(new):>17} {ratio:>9}")
    rms = {kind: {k: round(v, 4) for k, v in runs[kind][0]["rms_px"].items()} for kind in runs}
    print(f"rms px old: {json.dumps(rms['old'])}\nrms px new: {json.dumps(rms['new'])}")
    print("same calibration to 4 decimals:", rms["old"] == rms["new"])
    return runs


def _timed(function: Callable[[], Any], repeat: int) -> tuple[list[float], Any]:
    times, value = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        value = function()
        times.append(time.perf_counter() - start)
    return times, value


def compare_parts(board_spec: str, n_poses: int, repeat: int) -> dict[str, Any]:
    """Per pose, old vs new, alternating: host decode, one phase set's wrapped phase,
    local homographies, whole observation; and the old-new projector point difference."""
    from virtus.calib import observe, projector
    from virtus.calib.board import board_from_spec
    from virtus.calib.detect import find_grid
    from virtus.calib.poses import pose_set
    from virtus.calib.scene import board_scene, board_texture
    from virtus.patterns import phase
    from virtus.scanner import Scanner

    scanner, board = Scanner(), board_from_spec(board_spec)
    texture = board_texture(board)
    kinds = [frame.kind for frame in scanner.sequence.frames]
    first_set = _one_phase_set([i for i, kind in enumerate(kinds) if kind == "phase"])
    times: dict[str, dict[str, list[float]]] = {}
    worst = 0.0
    for index, pose in enumerate(pose_set("paper", scanner.rig, board, 1)[:n_poses]):
        capture = scanner.capture(board_scene(board, pose, texture), rng=index, command=[])
        frames = capture.frames[first_set]
        white = capture.frames[kinds.index("white")] if "white" in kinds else None
        decoded = capture.decode()
        centres = find_grid(decoded.background if white is None else white, board)
        points = {}
        observe_pose = partial(
            observe.observe_arrays, decoded.proj_uv, decoded.background, white, board, "p"
        )
        for _ in range(repeat):
            for kind, fit, wrap in (
                ("old", projector.local_homographies_per_circle, wrapped_phase_before),
                ("new", projector.local_homographies, phase.wrapped_phase),
            ):
                part = times.setdefault(kind, {})
                with observation(kind):
                    part.setdefault("host decode", []).extend(_timed(capture.decode, 1)[0])
                    part.setdefault("observe (all)", []).extend(_timed(observe_pose, 1)[0])
                seconds, _ = _timed(partial(wrap, frames), 1)
                part.setdefault("wrapped phase (1 set)", []).extend(seconds)
                seconds, homographies = _timed(partial(fit, decoded.proj_uv, board, centres), 1)
                part.setdefault("local homographies", []).extend(seconds)
                points[kind] = projector.apply_homographies(homographies, centres)
        worst = max(worst, float(np.nanmax(np.linalg.norm(points["old"] - points["new"], axis=1))))
    print(f"\nparts of one pose, {n_poses} poses x {repeat} repeats, old vs new alternating")
    print(f"{'':<26} {'old':>17} {'new':>17} {'old/new (median)':>17}")
    for name in times["old"]:
        old, new = times["old"][name], times["new"][name]
        ratio = np.median(old) / np.median(new)
        print(f"{name:<26} {spread(old):>17} {spread(new):>17} {ratio:>17.2f}")
    print(f"projector points, old - new: max {worst:.2e} px")
    return {"times_s": times, "max_point_difference_px": worst}


def _one_phase_set(phase_frames: list[int]) -> list[int]:
    """Frame indices of the sequence's first phase set (its first run of phase frames)."""
    run = [phase_frames[0]]
    for index in phase_frames[1:]:
        if index != run[-1] + 1:
            break
        run.append(index)
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--board", default="7x13")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    parser.add_argument("--repeat", type=int, default=3, help="old/new runs each (default 3)")
    parser.add_argument("--parts-poses", type=int, default=3, help="poses timed part by part")
    parser.add_argument("--skip-cli", action="store_true", help="no fresh-process CLI run")
    args = parser.parse_args()
    if not 1 <= args.repeat <= 20 or not 0 <= args.parts_poses <= 18:
        parser.error("--repeat must be in 1..20 and --parts-poses in 0..18")

    from virtus.pipeline.calibrate import calibrate_rig, observe_processes
    from virtus.render.backend import choose_variant
    from virtus.scanner import Scanner

    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs"
    with tempfile.TemporaryDirectory() as tmp:
        cli_s = float("nan") if args.skip_cli else run_cli(args.board, Path(tmp) / "cli")
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
    totals = compare_totals(args.board, args.repeat)
    parts = compare_parts(args.board, args.parts_poses, args.repeat) if args.parts_poses else None
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
                    "old_vs_new_in_process": totals,
                    "old_vs_new_parts": parts,
                },
                indent=2,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
