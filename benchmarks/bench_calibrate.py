"""Speed of a whole virtual calibration: ``virtus calibrate`` (18 poses x 52 frames = 936).

Runs the command as a user would (a fresh process: imports, Mitsuba start-up, capture,
calibration, files) and reports its wall time against the issue's 60 s budget, then the
library call twice in this process: the first compiles the kernels (and starts the
observation threads), the second is the warm time (the GPU issue's "excluding interpreter
and JIT start-up"), with the stages of the warm run (render + decode, detect + fit summed
over the worker processes, calibration) and frames/s.

Then, same process, alternating and repeated (``--repeat``): the whole library call as it
was before the second round of issue 25 ("old": centroids refined circle by circle, poses
observed in spawned worker processes on hosts of 4+ CPUs and here on smaller ones, whole
frames decoded on the host) against today's ("new": every circle's centroid window in one
batch, poses observed in threads of this process, only the board's window decoded on the
host, and where a GPU renders, the circles' centroids and local homographies computed on
it) and, there, today's observing on the host alone ("on host"), with the stages, the CPU
seconds, the calibration's RMS to 4 decimals and whether ``calibration.json`` is
byte-identical. Then the parts of one pose, old vs new (host decode of the whole frame;
"frame/window": today's decode of the whole frame against that of the board's window;
wrapped phase of one phase set; refined centroids and local homographies (and, where a
GPU renders, both on it); whole observation; "old" is before issue 25 there: one
``cv2.findHomography`` RANSAC fit per circle, the wrapped phase on a float64 copy of the
whole stack, per-circle centroids) on the first ``--parts-poses`` poses rendered on the
host, with how far the old and new projector points and centroids are apart. Last, the
observation alone of ``--observer-poses`` poses rendered and decoded once: here, in 2, 4,
... threads and in spawned processes, and where a GPU renders in threads that observe on
it (how observation scales with the host's cores, without the renderer beside it).

    PYTHONPATH=src python benchmarks/bench_calibrate.py [--board 7x13] [--repeat 3]
        [--parts-poses 3] [--observer-poses 18] [--skip-cli] [--json out.json]

The library calls run with glibc's malloc as the ``virtus`` command sets it
(:mod:`virtus.allocator`); ``--malloc default`` keeps glibc's defaults for them (the timed
``virtus calibrate`` process always sets it: pair ``--malloc default`` with ``--skip-cli``).

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
from contextlib import contextmanager, nullcontext
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
    """Run the block with the ``"old"`` (per-circle cv2 homographies, whole-stack phase,
    per-circle centroids: before issue 25) or ``"new"`` observation and host decode
    (patched in this process only)."""
    from virtus.calib import detect, observe, projector
    from virtus.patterns import phase

    saved = (observe.local_homographies, phase.wrapped_phase, detect._centroids)
    if kind == "old":
        observe.local_homographies = partial(_on_host, projector.local_homographies_per_circle)
        phase.wrapped_phase = wrapped_phase_before
        detect._centroids = detect._centroids_per_circle
    try:
        yield
    finally:
        observe.local_homographies, phase.wrapped_phase, detect._centroids = saved


def _on_host(fit: Callable, *arguments: Any, device: str | None = None, **options: Any) -> Any:
    """``fit`` (a fit of the host alone) called as ``local_homographies``, whatever the
    device asked for."""
    return fit(*arguments, **options)


def processes_before() -> int:
    """Worker processes the calibration observed in by default before the second round of
    issue 25: one per CPU beyond the renderer's, at most 8; none below 4 CPUs."""
    cpus = os.cpu_count() or 1
    return 0 if cpus < 4 else min(8, cpus - 1)


def observe_timed_before(*arguments: Any, **options: Any) -> Any:
    """``virtus.calib.observers.observe_timed`` with the per-circle centroids (in a worker
    process too: spawned workers import this script, so the patch reaches them)."""
    from virtus.calib import detect, observers

    detect._centroids = detect._centroids_per_circle
    return observers.observe_timed(*arguments, **options)


@contextmanager
def calibration_before() -> Iterator[int]:
    """The library call of before the second round (per-circle centroids, observed in
    :func:`processes_before` processes, the whole frames decoded on the host); yields its
    ``processes`` argument."""
    from virtus.calib import detect
    from virtus.pipeline import calibrate

    saved = (calibrate.observe_timed, detect._centroids, calibrate.board_window)
    calibrate.observe_timed = observe_timed_before
    detect._centroids = detect._centroids_per_circle
    calibrate.board_window = lambda *arguments: None  # the whole frame decoded
    try:
        yield processes_before()
    finally:
        calibrate.observe_timed, detect._centroids, calibrate.board_window = saved


def spread(values: list[float]) -> str:
    """``min-max`` of timings in seconds, as ms when short."""
    lo, hi = min(values), max(values)
    return f"{lo * 1e3:.1f}-{hi * 1e3:.1f} ms" if hi < 1.0 else f"{lo:.2f}-{hi:.2f} s"


def cpu_seconds() -> float:
    """CPU seconds of this process (every thread) and of its ended child processes."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


@contextmanager
def observe_on_host() -> Iterator[None]:
    """Today's library call with the centroids and local homographies computed on the host
    even when the poses render on a GPU (as before the third round of issue 25)."""
    from virtus.pipeline import calibrate

    saved = calibrate.observation_device
    calibrate.observation_device = lambda on_gpu: None
    try:
        yield
    finally:
        calibrate.observation_device = saved


def compare_totals(board: str, repeat: int) -> dict[str, Any]:
    """The library call as before the second round of issue 25 ("old"), as now with the
    centroids and local homographies on the host ("on host", only where a GPU renders: there
    they are computed on it) and as now ("new"), alternating, ``repeat`` times each: wall, stages
    and RMS per run, and whether the files agree with the old ones."""
    from virtus.calib.observe import observation_device
    from virtus.pipeline.calibrate import calibrate_rig
    from virtus.scanner import Scanner

    device = observation_device(Scanner().renders_on_gpu)
    kinds = ["old", "on host", "new"] if device is not None else ["old", "new"]
    runs: dict[str, list[dict[str, Any]]] = {kind: [] for kind in kinds}
    same_files = {kind: True for kind in kinds[1:]}
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(repeat):
            for kind in kinds:
                out = Path(tmp) / f"{kind}{index}"
                variant = {"old": calibration_before, "on host": observe_on_host}.get(kind)
                with variant() if variant else nullcontext(None) as processes:
                    start, cpu = time.perf_counter(), cpu_seconds()
                    result = calibrate_rig(Scanner(), board=board, out_dir=out, processes=processes)
                    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
                runs[kind].append(
                    {"s": wall, "cpu_s": cpu, "stages_s": result.timing_s, "rms_px": result.rms_px}
                )
            old_result = (Path(tmp) / f"old{index}" / "calibration.json").read_bytes()
            for kind in kinds[1:]:
                same = (Path(tmp) / f"{kind}{index}" / "calibration.json").read_bytes()
                same_files[kind] &= old_result == same
    before = processes_before()
    print(
        f"\nold (per-circle centroids, observed {f'in {before} processes' if before else 'here'},"
        f" whole frames decoded) vs new (batched centroids, observed in threads, board window"
        f" decoded{f', centroids and homographies on {device}' if device else ''}), {repeat} runs "
        "each, alternating"
    )
    print(f"{'':<30}" + "".join(f" {kind:>17}" for kind in kinds) + f" {'old/new':>9}")
    stages = [(k, k) for k in ("render_s", "observe_s", "calibrate_s")]
    keys = [("library total", "s"), ("CPU s (all threads+workers)", "cpu_s"), *stages]
    for label, key in keys:
        values = {
            kind: [r[key] if key in r else r["stages_s"][key] for r in runs[kind]] for kind in kinds
        }
        old, new = values["old"], values["new"]
        ratio = f"{min(old) / max(new):.2f}-{max(old) / min(new):.2f}"
        name = label if key != "observe_s" else "observe_s (summed, workers)"
        print(f"{name:<30}" + "".join(f" {spread(values[k]):>17}" for k in kinds) + f" {ratio:>9}")
    rms = {kind: {k: round(v, 4) for k, v in runs[kind][0]["rms_px"].items()} for kind in runs}
    for kind in kinds:
        print(f"rms px {kind}: {json.dumps(rms[kind])}")
    print("same calibration to 4 decimals:", all(rms[k] == rms["old"] for k in kinds))
    for kind in kinds[1:]:
        print(f"calibration.json of {kind} byte-identical to old in every pair:", same_files[kind])
    return {**runs, "same_calibration_json": same_files, "observation_device": device}


def _timed(function: Callable[[], Any], repeat: int) -> tuple[list[float], Any]:
    times, value = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        value = function()
        times.append(time.perf_counter() - start)
    return times, value


def compare_parts(board_spec: str, n_poses: int, repeat: int) -> dict[str, Any]:
    """Per pose, old vs new, alternating: host decode, one phase set's wrapped phase,
    refined centroids, local homographies, whole observation; and the old-new projector
    point and centroid differences."""
    from virtus.calib import detect, observe, projector
    from virtus.calib.board import board_from_spec
    from virtus.calib.detect import find_grid
    from virtus.calib.poses import pose_set
    from virtus.calib.scene import board_scene, board_texture, board_window
    from virtus.patterns import phase
    from virtus.scanner import Scanner

    scanner, board = Scanner(), board_from_spec(board_spec)
    texture = board_texture(board)
    kinds = [frame.kind for frame in scanner.sequence.frames]
    first_set = _one_phase_set([i for i, kind in enumerate(kinds) if kind == "phase"])
    times: dict[str, dict[str, list[float]]] = {}
    worst = worst_centroid = device_worst = device_worst_centroid = 0.0
    device = observe.observation_device(scanner.renders_on_gpu)
    device_fit: list[float] = []
    device_centroids: list[float] = []
    for index, pose in enumerate(pose_set("paper", scanner.rig, board, 1)[:n_poses]):
        capture = scanner.capture(board_scene(board, pose, texture), rng=index, command=[])
        frames = capture.frames[first_set]
        white = capture.frames[kinds.index("white")] if "white" in kinds else None
        decoded = capture.decode()
        centres = find_grid(decoded.background if white is None else white, board)
        points, centroids = {}, {}
        window = board_window(scanner.rig.camera.intrinsics, board, pose.board2cam)
        window_frames = capture.frames[:, window[0], window[1]]
        window_decode = partial(
            scanner.sequence.decode, window_frames, full_scale=capture.full_scale
        )
        observe_pose = partial(
            observe.observe_arrays, decoded.proj_uv, decoded.background, white, board, "p"
        )
        for _ in range(repeat):
            for kind, fit, wrap, one_pass in (
                ("old", projector.local_homographies_per_circle, wrapped_phase_before,
                 detect._centroids_per_circle),
                ("new", projector.local_homographies, phase.wrapped_phase, detect._centroids),
            ):  # fmt: skip
                part = times.setdefault(kind, {})
                with observation(kind):
                    part.setdefault("host decode", []).extend(_timed(capture.decode, 1)[0])
                    part.setdefault("observe (all)", []).extend(_timed(observe_pose, 1)[0])
                decode = capture.decode if kind == "old" else window_decode  # today's phase
                seconds, _ = _timed(decode, 1)
                part.setdefault("host decode: frame/window", []).extend(seconds)
                seconds, _ = _timed(partial(wrap, frames), 1)
                part.setdefault("wrapped phase (1 set)", []).extend(seconds)
                seconds, homographies = _timed(partial(fit, decoded.proj_uv, board, centres), 1)
                part.setdefault("local homographies", []).extend(seconds)
                points[kind] = projector.apply_homographies(homographies, centres)
                if kind == "new" and device is not None:
                    on_device = partial(fit, decoded.proj_uv, board, centres, device=device)
                    seconds, homographies = _timed(on_device, 1)
                    device_fit.extend(seconds)
                    moved = projector.apply_homographies(homographies, centres) - points["new"]
                    device_worst = max(device_worst, float(np.nanmax(np.abs(moved))))
                saved, detect._centroids = detect._centroids, one_pass
                try:
                    refine = partial(detect.refine_points, decoded.background, board, centres)
                    seconds, centroids[kind] = _timed(refine, 1)
                finally:
                    detect._centroids = saved
                part.setdefault("refined centroids", []).extend(seconds)
                if kind == "new" and device is not None:
                    seconds, found = _timed(partial(refine, device=device), 1)
                    device_centroids.extend(seconds)
                    moved = np.abs(found - centroids["new"])
                    device_worst_centroid = max(device_worst_centroid, float(np.nanmax(moved)))
        worst = max(worst, float(np.nanmax(np.linalg.norm(points["old"] - points["new"], axis=1))))
        moved = np.linalg.norm(centroids["old"] - centroids["new"], axis=1)
        worst_centroid = max(worst_centroid, float(np.nanmax(moved)))
    print(f"\nparts of one pose, {n_poses} poses x {repeat} repeats, old vs new alternating")
    print(f"{'':<26} {'old':>17} {'new':>17} {'old/new (median)':>17}")
    for name in times["old"]:
        old, new = times["old"][name], times["new"][name]
        ratio = np.median(old) / np.median(new)
        print(f"{name:<26} {spread(old):>17} {spread(new):>17} {ratio:>17.2f}")
    print(f"projector points, old - new: max {worst:.2e} px")
    print(f"refined centroids, old - new: max {worst_centroid:.2e} px")
    if device_fit:
        print(
            f"local homographies on {device}: {spread(device_fit)} (new on the host: "
            f"{spread(times['new']['local homographies'])}), points apart by at most "
            f"{device_worst:.2e} px"
        )
        print(
            f"refined centroids on {device}: {spread(device_centroids)} (new on the host: "
            f"{spread(times['new']['refined centroids'])}), apart by at most "
            f"{device_worst_centroid:.2e} px"
        )
    return {
        "device_fit_s": device_fit,
        "device_centroids_s": device_centroids,
        "times_s": times,
        "max_point_difference_px": worst,
        "max_centroid_difference_px": worst_centroid,
    }


def compare_observers(board_spec: str, n_poses: int, repeat: int) -> dict[str, Any]:
    """Observation alone of ``n_poses`` poses rendered and decoded once (on the device if
    there is one), wall time with each kind of observers: here, threads (2, 4, ... up to
    the CPUs, and the default), and spawned processes as before (start-up included, as
    in a calibration), alternating, ``repeat`` times each; and that they agree."""
    from virtus.calib.board import board_from_spec
    from virtus.calib.observe import observation_device
    from virtus.calib.observers import Observers, observe_timed, observer_pool, observers
    from virtus.calib.poses import pose_set
    from virtus.calib.scene import board_scene, board_texture
    from virtus.scanner import Scanner

    scanner, board = Scanner(), board_from_spec(board_spec)
    texture = board_texture(board)
    views = []
    for index, pose in enumerate(pose_set("paper", scanner.rig, board, 1)[:n_poses]):
        view = scanner.decoded_view(board_scene(board, pose, texture), rng=index)
        views.append((view.decoded.proj_uv, view.decoded.background, view.white, board, pose.name))
    cpus = os.cpu_count() or 1
    kinds: list[tuple[Observers, str | None]] = [(Observers("here", 0), None)]
    kinds += [(Observers("threads", k), None) for k in (2, 4, 8, 16) if k <= cpus]
    kinds += [(observers(None), None)] if (observers(None), None) not in kinds else []
    kinds += [(Observers("processes", max(processes_before(), 2)), None)]
    device = observation_device(scanner.renders_on_gpu)
    if device is not None:  # as a calibration rendered on a GPU observes
        kinds += [(Observers("threads", k), device) for k in (2, 4, 8) if k <= cpus]
    times: dict[str, list[float]] = {}
    reference = None
    for _ in range(repeat):
        for chosen, on in kinds:
            start = time.perf_counter()
            with observer_pool(chosen) as pool:
                jobs = [pool.submit(observe_timed, *view, device=on) for view in views]
                found = [job.result()[0] for job in jobs]
            label = f"{chosen.kind} {chosen.count}" + (f", on {on}" if on else "")
            times.setdefault(label, []).append(time.perf_counter() - start)
            centroids = np.array([obs.cam_centroids for obs in found])
            reference = centroids if reference is None else reference
            if on:  # on the device: the host's centroids to rounding
                agree = np.allclose(centroids, reference, rtol=0, atol=1e-9, equal_nan=True)
            else:
                agree = np.array_equal(centroids, reference, equal_nan=True)
            if not agree:
                raise AssertionError(f"{chosen} observed other centroids")
    print(f"\nobservation alone, {len(views)} decoded poses, {repeat} runs each, alternating")
    base = float(np.median(times["here 0"]))
    for name, values in times.items():
        print(f"{name:<26} {spread(values):>17} {base / np.median(values):>8.2f}x")
    return {"wall_s": times, "poses": len(views)}


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
    parser.add_argument(
        "--observer-poses", type=int, default=18, help="poses of the observers' comparison"
    )
    parser.add_argument(
        "--malloc", choices=["virtus", "default"], default="virtus",
        help="glibc's malloc as the virtus command sets it (virtus.allocator), or its "
        "defaults, for this process's library calls (default: virtus)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.malloc == "virtus":
        from virtus.allocator import keep_freed_memory

        keep_freed_memory()
    if not 1 <= args.repeat <= 20 or not 0 <= args.parts_poses <= 18:
        parser.error("--repeat must be in 1..20 and --parts-poses in 0..18")
    if not 0 <= args.observer_poses <= 18:
        parser.error("--observer-poses must be in 0..18")

    from virtus.calib.observers import observers
    from virtus.pipeline.calibrate import calibrate_rig
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
    workers = observers(None)
    print(
        f"virtual calibration, board {args.board}, {frames} frames ({machine}), variant "
        f"{choose_variant()}, observed in {workers.count} {workers.kind}"
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
    observer_poses, board = args.observer_poses, args.board
    scaling = compare_observers(board, observer_poses, args.repeat) if observer_poses else None
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
                    "observers": [workers.kind, workers.count],
                    "stages_s": timing,
                    "budget_s": BUDGET_S,
                    "rms_px": result.rms_px,
                    "old_vs_new": totals,
                    "old_vs_new_parts": parts,
                    "observation_alone": scaling,
                },
                indent=2,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
