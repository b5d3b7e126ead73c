"""Where the render stage of ``virtus calibrate`` spends a pose: the board's scene, the
Mitsuba scene, trace, exposure, synthesis, the decode on the device, the decode to the
host, the white frame, and the kernels each new pose compiles.

The calibration renders every pose through ``_rendered_view`` (the board's scene, then
``Scanner.decoded_view``); on a GPU the frames are decoded on the device. Here that device
path is taken on any variant (``--variant llvm_ad_rgb`` runs it on the CPU, as the tests
do), for ``--poses`` of the paper's poses with the default rig (``--scale`` resamples
camera and projector for a quick look):

* **per pose** (poses after the first, median): the wall time of ``_rendered_view`` as the
  calibration calls it (nothing synchronised), and the JIT kernels each pose compiled
  (not in Dr.Jit's in-memory cache: compiled, or loaded from its disk cache; a kernel
  whose source bakes in a per-pose value compiles again for every pose; none should
  after the first);
* **stages** (the same poses again, each stage timed alone with the device synchronised
  before and after, so launches no longer overlap host work): what each costs;
* with ``--observers N``, the per-pose wall time again while N threads observe a rendered
  pose over and over (``observe_arrays``, as the calibration's observer threads do beside
  the render loop): how much the observation slows the render stage down (GIL, cores,
  memory bandwidth).

**Old against new** (``--baseline DIR --rounds N``): the same run of this checkout and of
another source tree (``DIR/src``, e.g. ``git archive <commit> src | tar -x -C DIR``), each
in its own process, alternated N times, so machine load hits both alike.

    PYTHONPATH=src python benchmarks/bench_calibrate_render.py [--variant cuda_ad_rgb]
        [--poses 18] [--scale 1] [--spp 4] [--observers 8] [--baseline DIR --rounds 3]
        [--json out.json]

Not a test: numbers depend on the machine and its load (quote them with its description).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

#: ``(module, attribute, stage)``: the functions timed alone (looked up where they are
#: called, so wrapping the attribute times every call of the pose).
STAGES = (
    ("virtus.pipeline.calibrate", "board_scene", "board scene"),
    ("virtus.render.tracing", "load_scene", "Mitsuba scene"),
    ("virtus.render.renderer", "trace_device", "trace (with scene)"),
    ("virtus.render.renderer", "percentile_of_positive", "exposure"),
    ("virtus.render.renderer", "synthesize_on_device", "synthesis + sensor"),
    ("virtus.render.jit.decode", "decode_on_device", "decode (lazy)"),
    ("virtus.render.jit.decode:DeviceDecode", "to_host", "decode to host"),
    ("virtus.render.jit.tracing:DeviceFrames", "frame", "white frame"),
)


def setup(args: argparse.Namespace) -> tuple[Any, Any, list[Any], np.ndarray]:
    """The scanner (the device path forced), board, poses and texture of the run."""
    from virtus.calib.board import board_from_spec
    from virtus.calib.poses import pose_set
    from virtus.calib.scene import board_texture
    from virtus.geometry.devices import Camera, Projector, Rig, default_rig
    from virtus.render import RenderSettings
    from virtus.render.backend import choose_variant
    from virtus.scanner import Scanner

    rig = default_rig()
    if args.scale != 1.0:
        rig = Rig(
            Camera(rig.camera.intrinsics.scaled(args.scale)),
            Projector(rig.projector.intrinsics.scaled(args.scale)),
            rig.proj2cam,
        )
    variant = choose_variant(args.variant)
    scanner = Scanner(rig=rig, render=RenderSettings(spp=args.spp, variant=variant))
    # The calibration takes the device path on a GPU only; here on every variant.
    type(scanner).renders_on_gpu = property(lambda self: True)  # type: ignore[assignment]
    board = board_from_spec(args.board)
    poses = pose_set("paper", rig, board)[: args.poses]
    texture = np.array(board_texture(board), dtype=np.float64)
    texture.setflags(write=False)  # as the calibration keeps it
    return scanner, board, poses, texture


def _resolve(spec: str) -> Any:
    import importlib

    module, _, attribute = spec.partition(":")
    owner = importlib.import_module(module)
    return getattr(owner, attribute) if attribute else owner


def instrument(times: dict[str, float], dr: Any) -> None:
    """Wrap every stage of :data:`STAGES`: the device synchronised before and after,
    seconds summed into ``times``."""
    for owner_spec, name, stage in STAGES:
        owner = _resolve(owner_spec)
        original = getattr(owner, name)

        def timed(*a: Any, _f: Any = original, _stage: str = stage, **k: Any) -> Any:
            dr.sync_thread()
            start = time.perf_counter()
            result = _f(*a, **k)
            dr.sync_thread()
            times[_stage] += time.perf_counter() - start
            return result

        # On a class the wrapper is a plain function, so it binds as the method did.
        setattr(owner, name, functools.wraps(original)(timed))


def profile(args: argparse.Namespace) -> dict[str, Any]:
    """One run in this process (this source tree)."""
    from virtus.pipeline import calibrate
    from virtus.render.backend import mitsuba

    scanner, board, poses, texture = setup(args)
    _, dr, variant = mitsuba(scanner.render.variant)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    walls, compiled = [], []
    for index, pose in enumerate(poses):
        dr.kernel_history()  # clears it
        start = time.perf_counter()
        calibrate._rendered_view(scanner, board, pose, texture, index)
        dr.sync_thread()
        walls.append(time.perf_counter() - start)
        history = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
        # Not in the in-memory cache: compiled, or loaded from Dr.Jit's disk cache.
        compiled.append(sum(k["cache_disk"] or not k["cache_hit"] for k in history))
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    beside = _beside_observers(args.observers, scanner, board, poses, texture, dr)
    times: dict[str, float] = defaultdict(float)
    instrument(times, dr)
    synced = []
    for index, pose in enumerate(poses[1:], start=1):
        start = time.perf_counter()
        calibrate._rendered_view(scanner, board, pose, texture, index)
        dr.sync_thread()
        synced.append(time.perf_counter() - start)
    count = max(len(poses) - 1, 1)
    return {
        "variant": variant,
        "camera": list(scanner.rig.camera.intrinsics.size),
        "spp": scanner.render.spp,
        "poses": len(poses),
        "first_pose_s": walls[0],
        "pose_s": statistics.median(walls[1:]) if len(walls) > 1 else walls[0],
        "kernels_compiled_per_pose": compiled,
        "synced_pose_s": sum(synced) / count,
        "stages_s": {stage: times[stage] / count for _, _, stage in STAGES},
        "observers": args.observers,
        "pose_beside_observers_s": beside,
    }


def _beside_observers(
    count: int, scanner: Any, board: Any, poses: list[Any], texture: np.ndarray, dr: Any
) -> float | None:
    """Median wall time (s) of a pose (poses after the first, nothing synchronised but the
    end) while ``count`` threads observe the first pose's view over and over; None for 0."""
    if count <= 0:
        return None
    import threading

    from virtus.calib.observe import observe_arrays
    from virtus.pipeline import calibrate

    view = calibrate._rendered_view(scanner, board, poses[0], texture, 0)
    stop = threading.Event()

    def observe() -> None:
        while not stop.is_set():
            observe_arrays(*view, board, poses[0].name)

    threads = [threading.Thread(target=observe, daemon=True) for _ in range(count)]
    for thread in threads:
        thread.start()
    walls = []
    try:
        for index, pose in enumerate(poses[1:], start=1):
            start = time.perf_counter()
            calibrate._rendered_view(scanner, board, pose, texture, index)
            dr.sync_thread()
            walls.append(time.perf_counter() - start)
    finally:
        stop.set()
        for thread in threads:
            thread.join()
    return statistics.median(walls)


def _ms(values: list[float]) -> str:
    low, high = min(values) * 1e3, max(values) * 1e3
    return f"{low:.1f}" if abs(high - low) < 0.05 else f"{low:.1f}-{high:.1f}"


def report(runs: dict[str, list[dict[str, Any]]]) -> None:
    names = list(runs)
    first = runs[names[0]][0]
    print(
        f"{platform.node()} ({os.cpu_count()} CPUs), {first['variant']}, camera "
        f"{first['camera'][0]}x{first['camera'][1]}, {first['spp']} spp, {first['poses']} "
        f"poses; ms a pose (range over {len(runs[names[0]])} run(s))"
    )
    print(f"  {'':28s}" + "".join(f"{n:>18s}" for n in names))
    rows = [("pose (as calibrate)", "pose_s"), ("first pose", "first_pose_s")]
    rows.append(("pose, stages synced", "synced_pose_s"))
    if first["observers"] > 0:
        rows.insert(1, (f"pose, {first['observers']} observing", "pose_beside_observers_s"))
    for label, key in rows:
        print(f"  {label:28s}" + "".join(f"{_ms([r[key] for r in runs[n]]):>18s}" for n in names))
    for _, _, stage in STAGES:
        cells = "".join(f"{_ms([r['stages_s'][stage] for r in runs[n]]):>18s}" for n in names)
        print(f"    {stage:26s}{cells}")
    for name in names:
        compiled = runs[name][-1]["kernels_compiled_per_pose"]
        print(f"  kernels compiled or loaded from disk per pose ({name}): {compiled}")


def child_arguments(argv: list[str]) -> list[str]:
    """``argv`` without the options that only the parent uses."""
    out, skip = [], False
    for item in argv:
        if skip:
            skip = False
            continue
        if item in ("--baseline", "--rounds", "--json"):
            skip = True
            continue
        if item.startswith(("--baseline=", "--rounds=", "--json=")):
            continue
        out.append(item)
    return out


def compare(argv: list[str], baseline: Path, rounds: int) -> dict[str, list[dict[str, Any]]]:
    """This checkout and ``baseline`` alternately, each in its own process."""
    here = Path(__file__).resolve().parents[1]
    runs: dict[str, list[dict[str, Any]]] = {"this checkout": [], "baseline": []}
    for _ in range(rounds):
        for name, tree in (("this checkout", here), ("baseline", baseline.resolve())):
            env = dict(os.environ)
            rest = env.get("PYTHONPATH", "")
            env["PYTHONPATH"] = str(tree / "src") + (os.pathsep + rest if rest else "")
            command = [sys.executable, str(Path(__file__).resolve()), *argv, "--child"]
            output = subprocess.run(command, env=env, check=True, capture_output=True, text=True)
            runs[name].append(json.loads(output.stdout.strip().splitlines()[-1]))
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variant", default=None, help="Mitsuba variant (default: auto)")
    parser.add_argument("--board", default="7x13")
    parser.add_argument("--poses", type=int, default=6, help="paper poses (at most 18)")
    parser.add_argument("--scale", type=float, default=1.0, help="resample camera, projector")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--observers", type=int, default=0, help="observing threads beside")
    parser.add_argument("--baseline", type=Path, metavar="DIR", help="a tree holding src/virtus")
    parser.add_argument("--rounds", type=int, default=3, help="alternations with --baseline")
    parser.add_argument("--json", type=Path, help="write the runs here")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if not 2 <= args.poses <= 18:
        parser.error("--poses: 2..18")
    if not 0 <= args.observers <= 64:
        parser.error("--observers: 0..64")
    if args.child:
        print(json.dumps(profile(args)))
        return
    if args.baseline is not None:
        if not (args.baseline / "src" / "virtus").is_dir():
            parser.error(f"--baseline: expected a folder holding src/virtus, got {args.baseline}")
        runs = compare(child_arguments(sys.argv[1:]), args.baseline, max(args.rounds, 1))
    else:
        runs = {"this checkout": [profile(args)]}
    report(runs)
    if args.json is not None:
        args.json.write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()
