"""Where one pose's time goes, on each backend: the stages, and Dr.Jit's compile vs launch vs run.

For one pose of the default scene (or the 328k-face free-form object) rendered with the
default rig, in one run:

* **stages of a warm pose** (the same pose again, every kernel cached), each timed alone
  with the device synchronised, median of ``--repeats``: scene load, trace, the auto
  exposure's percentile, synthesis + sensor, frames to the host, ground truth to the host,
  and the whole ``render_device`` (frames/s into device memory); on CPU variants also the
  host path of ``render()`` (trace, exposure, sparse synthesis + sensor);
* **Dr.Jit's account of each stage** (``dr.kernel_history()`` of one more run): launches,
  JIT kernels, kernels compiled (not in the in-memory or on-disk cache), IR generation,
  compilation (LLVM / PTX + OptiX) and execution milliseconds;
* **new poses**: ``--poses`` camera poses never rendered before (small turns about the
  object, as a calibration's or a dataset's poses differ), each with its wall time and the
  kernels it compiled. A kernel whose source bakes in a per-pose value compiles again for
  every pose; none should after the first;
* with ``--agreement``, one noisy capture on this backend and on ``llvm_ad_rgb``, decoded:
  phase RMS difference and fringe orders (the CPU-GPU check).

    PYTHONPATH=src python benchmarks/bench_profile.py [--variant llvm_ad_rgb] [--scene default]
        [--size 960] [--spp 4] [--lookup nearest] [--repeats 5] [--poses 6] [--json out.json]

**Old against new** (``--baseline DIR --rounds N``): the same profile of this checkout and of
another virtus source tree (``DIR/src``, e.g. ``git archive <commit> src | tar -x -C DIR``),
each in its own process, alternated N times on the same machine; prints each stage's range
for both and the per-round ratios (baseline / this checkout), so machine load hits both alike.

On a GPU: ``--variant cuda_ad_rgb`` (the default when CUDA works). ``--size`` crops the
camera around its centre (the same pixel footprint, fewer pixels) for a quick look.
Not a test: numbers depend on the machine and its load (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import virtus
from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render, render_device, synthesize, trace
from virtus.render.backend import mitsuba
from virtus.render.jit.synthesis import synthesize_on_device
from virtus.render.jit.tracing import percentile_of_positive, trace_device
from virtus.render.tracing import prepare_pass
from virtus.scene.model import default_scene
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import ProjectorModel


def cropped_rig(size: int) -> Rig:
    """The default rig, its camera cropped to ``size`` x ``size`` px around the centre."""
    rig = default_rig()
    k = rig.camera.intrinsics
    if size >= k.width:
        return rig
    camera = Intrinsics(k.fx, k.fy, k.cx - (k.width - size) / 2, k.cy - (k.height - size) / 2,
                        size, size)  # fmt: skip
    return Rig(Camera(camera), rig.projector, rig.proj2cam)


def build_scene(name: str, folder: Path) -> Any:
    """The default scene, or the free-form object of 327,680 faces (icosphere subdivided 7
    times) at 1 m before the same wall."""
    if name == "default":
        return default_scene()
    from virtus.scene.model import MeshObject, Scene
    from virtus.scene.procedural import write_freeform_object

    path = write_freeform_object(folder / "freeform.stl", subdivisions=7)
    # As a user's file: older than the 2 s for which the loader does not trust a file's
    # time stamp (render.mitsuba_scene._RECENT_S), so poses reuse the loaded mesh.
    past = time.time() - 60.0
    os.utime(path, (past, past))
    return Scene(
        objects=(MeshObject(path=path, scale_to_m=1.0, pose=Pose(np.eye(3), (0.0, 0.0, 1.0))),),
        background=default_scene().background,
    )


def kernel_account(history: list[dict]) -> dict[str, float]:
    """Launches, JIT kernels, kernels compiled, and codegen / compile / run milliseconds of
    a ``dr.kernel_history()``."""
    import drjit as dr

    jit = [k for k in history if k["type"] == dr.KernelType.JIT]
    compiled = [k for k in jit if not k.get("cache_hit") and not k.get("cache_disk")]
    return {
        "launches": len(history),
        "jit_kernels": len(jit),
        "compiled": len(compiled),
        "from_disk_cache": sum(1 for k in jit if k.get("cache_disk") and not k.get("cache_hit")),
        "codegen_ms": sum(k.get("codegen_time", 0.0) for k in jit),
        "compile_ms": sum(k.get("backend_time", 0.0) for k in jit),
        "run_ms": sum(k.get("execution_time", 0.0) for k in history),
    }


def profiled(dr: Any, function: Any) -> tuple[Any, dict[str, float]]:
    """``function()`` with its kernel account (the device synchronised at the end)."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.kernel_history_clear()
        result = function()
        dr.sync_thread()
        history = dr.kernel_history()
    return result, kernel_account(history)


def median_ms(dr: Any, function: Any, repeats: int) -> tuple[float, float]:
    """Median wall and process CPU milliseconds of ``function()`` (the device synchronised).
    The CPU time of all threads is less sensitive to other jobs on a shared machine: on a
    CPU variant, CPU time / Dr.Jit's thread count estimates the wall time on idle cores."""
    times, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        function()
        dr.sync_thread()
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return 1e3 * statistics.median(times), 1e3 * statistics.median(cpu)


def stage_table(dr: Any, stages: dict[str, Any], repeats: int) -> dict[str, dict[str, float]]:
    """Per stage: median wall and CPU milliseconds, and the kernel account of one more run."""
    out = {}
    for name, function in stages.items():
        function()  # warm: compiles what this stage alone needs
        dr.sync_thread()
        wall, cpu = median_ms(dr, function, repeats)
        _, account = profiled(dr, function)
        out[name] = {"wall_ms": wall, "cpu_ms": cpu, **account}
    return out


def device_stages(rig, scene, sequence, settings, projector, sensor) -> dict[str, Any]:  # noqa: ANN001
    warm = render_device(rig, scene, sequence, settings, projector=projector, sensor=sensor)
    options = {"spp": settings.spp, "variant": settings.variant}
    return {
        "scene_load": lambda: prepare_pass(rig, scene, **options),
        "trace": lambda: trace_device(rig, scene, **options),
        "exposure": lambda: percentile_of_positive(warm.trace.white(), sensor.auto_percentile),
        "synthesis_and_sensor": lambda: synthesize_on_device(
            warm.trace, sequence, projector, sensor, warm.exposure, 0, rig.projector.intrinsics
        ),
        "frames_to_host": lambda: warm.frames.numpy(),
        "ground_truth_to_host": lambda: warm.trace.ground_truth(),
        "render_device": lambda: render_device(
            rig, scene, sequence, settings, projector=projector, sensor=sensor
        ),
    }


def host_stages(rig, scene, sequence, settings, projector, sensor) -> dict[str, Any]:  # noqa: ANN001
    traced = trace(rig, scene, spp=settings.spp, variant=settings.variant)
    exposure = sensor.exposure_for(traced.white)

    def synthesis() -> np.ndarray:
        return synthesize(
            traced, sequence, projector, dtype=sensor.dtype,
            transform=lambda b, f, p: sensor.digitize(b, exposure, frames=f, pixels=p),
        )  # fmt: skip

    return {
        "trace": lambda: trace(rig, scene, spp=settings.spp, variant=settings.variant),
        "exposure": lambda: sensor.exposure_for(traced.white),
        "synthesis_and_sensor": synthesis,
        "render": lambda: render(
            rig, scene, sequence, settings, projector=projector, sensor=sensor, synthesis="sparse"
        ),
    }


def new_poses(render_pose: Any, dr: Any, count: int) -> list[dict[str, float]]:
    """``render_pose(cam2world)`` for ``count`` camera poses never rendered before (turns of
    up to 2 deg about the object 1 m ahead; a random start so no cache knows them)."""
    rng = random.Random()
    out = []
    for _ in range(count):
        angles = [rng.uniform(-2.0, 2.0) for _ in range(3)]
        turn = Pose.from_euler("xyz", angles)
        about = Pose(np.eye(3), (0.0, 0.0, 1.0))  # the object's centre
        cam2world = about @ turn @ about.inverse()
        start = time.perf_counter()
        _, account = profiled(dr, lambda c=cam2world: render_pose(c))
        out.append({"wall_ms": 1e3 * (time.perf_counter() - start), **account})
    return out


def mitsuba_frames_per_s(rig, scene, sequence, settings, lookup: str, frames: int) -> float:  # noqa: ANN001
    """Frames/s of Mitsuba's own ``projector`` emitter, one render per frame (the lean
    setting of ``bench_render.py``: one emitter sample, no BSDF sample), median frame."""
    from virtus.render.reference import ReferenceRenderer

    reference = ReferenceRenderer(
        rig, scene, spp=settings.spp, lookup=lookup, bsdf_samples=0, variant=settings.variant
    )
    reference.render_frames(sequence, [0, 1])  # warm-up (kernel compilation)
    times = []
    for index in range(frames):
        start = time.perf_counter()
        reference.render_image(sequence.image(index), seed=index)
        times.append(time.perf_counter() - start)
    return 1.0 / statistics.median(times)


def cpu_gpu_agreement(rig, scene, sequence, spp: int, variant: str) -> dict[str, Any]:  # noqa: ANN001
    """The same noisy capture (``imx174`` sensor, ``lightcrafter`` projector, seed 0) rendered
    on the device path of ``variant`` and of its CPU twin ``llvm_ad_rgb``, both decoded on the
    host: RMS difference of the absolute phases (rad) where both are valid, the share of those
    pixels whose fringe order differs, and the share of pixels valid in one only."""
    from virtus.sensor.camera import SENSOR_PRESETS
    from virtus.sensor.projector import PROJECTOR_PRESETS

    decoded = {}
    for name in (variant, "llvm_ad_rgb"):
        rendering = render(
            rig, scene, sequence, RenderSettings(spp=spp, variant=name), synthesis="jit",
            projector=PROJECTOR_PRESETS["lightcrafter"], sensor=SENSOR_PRESETS["imx174"], rng=0,
        )  # fmt: skip
        decoded[name] = sequence.decode(rendering.frames)
    a, b = decoded[variant], decoded["llvm_ad_rgb"]
    out: dict[str, Any] = {"variants": [variant, "llvm_ad_rgb"]}
    for direction in ("v", "h"):
        phase_a, phase_b = getattr(a, f"phase_{direction}"), getattr(b, f"phase_{direction}")
        both = getattr(a, f"mask_{direction}") & getattr(b, f"mask_{direction}")
        order_a = np.floor(phase_a[both] / (2 * np.pi))
        order_b = np.floor(phase_b[both] / (2 * np.pi))
        difference = phase_a[both] - phase_b[both]
        out[direction] = {
            "phase_rms_difference_rad": float(np.sqrt(np.mean(difference**2))),
            "fringe_orders_differing": float(np.mean(order_a != order_b)),
            "valid_in_one_only": float(np.mean(getattr(a, f"mask_{direction}")
                                               ^ getattr(b, f"mask_{direction}"))),
        }  # fmt: skip
    return out


def print_agreement(agreement: dict[str, Any]) -> None:
    print(f"{agreement['variants'][0]} vs {agreement['variants'][1]}, one noisy capture:")
    for direction in ("v", "h"):
        row = agreement[direction]
        print(f"  phase_{direction}: RMS difference {row['phase_rms_difference_rad']:.2e} rad, "
              f"fringe orders differing {row['fringe_orders_differing']:.2%}, valid in one "
              f"only {row['valid_in_one_only']:.3%}")  # fmt: skip


def summarise_poses(poses: list[dict[str, float]]) -> dict[str, float]:
    later = poses[1:] or poses
    return {
        "first_wall_ms": poses[0]["wall_ms"],
        "first_compiled": poses[0]["compiled"],
        "later_wall_ms_median": statistics.median(p["wall_ms"] for p in later),
        "later_compiled_total": sum(p["compiled"] for p in later),
        "later_compile_ms_median": statistics.median(p["compile_ms"] for p in later),
    }


def print_table(title: str, table: dict[str, dict[str, float]]) -> None:
    print(title)
    print(f"  {'stage':24s} {'wall ms':>9s} {'cpu ms':>8s} {'launches':>9s} {'jit':>4s} "
          f"{'compiled':>9s} {'codegen ms':>11s} {'compile ms':>11s} {'run ms':>8s}")  # fmt: skip
    for name, row in table.items():
        print(f"  {name:24s} {row['wall_ms']:9.2f} {row['cpu_ms']:8.1f} {row['launches']:9d} "
              f"{row['jit_kernels']:4d} "
              f"{row['compiled']:9d} {row['codegen_ms']:11.2f} {row['compile_ms']:11.1f} "
              f"{row['run_ms']:8.2f}")  # fmt: skip


def print_poses(title: str, poses: list[dict[str, float]]) -> None:
    walls = ", ".join(f"{p['wall_ms']:.0f}" for p in poses)
    compiled = ", ".join(f"{p['compiled']}" for p in poses)
    compile_ms = ", ".join(f"{p['compile_ms']:.0f}" for p in poses)
    print(
        f"{title}\n  wall ms: {walls}\n  kernels compiled: {compiled}\n  compile ms: {compile_ms}"
    )


def child_arguments(argv: list[str]) -> list[str]:
    """``argv`` without the options that only the comparing parent reads."""
    parent = ("--baseline", "--rounds", "--json")
    out, skip = [], False
    for item in argv:
        if skip:
            skip = False
        elif item in parent:
            skip = True
        elif not item.startswith(tuple(f"{o}=" for o in parent)):
            out.append(item)
    return out


def run_profile(source: Path, argv: list[str], out: Path) -> dict[str, Any]:
    """This benchmark's report with the virtus of ``source`` (a tree holding ``src/``), run
    in a fresh process."""
    # ``source`` first; the rest of PYTHONPATH (packages installed to a folder) stays
    paths = [str((source / "src").resolve()), os.environ.get("PYTHONPATH", "")]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in paths if p))
    command = [sys.executable, __file__, *argv, "--json", str(out)]
    subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL)
    report = json.loads(out.read_text())
    if not report["virtus"].startswith(str(source.resolve())):
        raise SystemExit(f"the run for {source} imported virtus from {report['virtus']}")
    return report


def compare(argv: list[str], baseline: Path, rounds: int) -> None:
    """Profile this checkout and ``baseline`` alternately, ``rounds`` times each, and print
    every device stage's range for both and the per-round ratios."""
    here = Path(__file__).resolve().parents[1]
    runs: dict[str, list[dict[str, Any]]] = {"new": [], "baseline": []}
    plain = [a for a in argv if a != "--agreement"]  # the CPU-GPU check: once, this checkout
    with tempfile.TemporaryDirectory() as folder:
        for k in range(rounds):
            for name, source in (("new", here), ("baseline", baseline)):
                first_run = k == 0 and name == "new" and len(plain) < len(argv)
                arguments = [*plain, "--agreement"] if first_run else plain
                path = Path(folder) / f"{name}{k}.json"
                runs[name].append(run_profile(source, arguments, path))
                print(f"round {k + 1}/{rounds}: {name} done", flush=True)
    first = runs["new"][0]
    print(
        f"machine: {first['machine']}; {first['variant']}; {first['scene']} scene, "
        f"{first['frames']} frames, {first['camera_px'][0]} px, {first['spp']} spp, "
        f"{first['lookup']}; {rounds} rounds alternated, median of each run's repeats"
    )
    for measure in ("wall_ms", "cpu_ms"):
        print(f"  {measure:24s} {'this checkout':>16s} {'baseline':>16s} {'baseline/this':>14s}")
        for stage in first["device_stages"]:
            new = [r["device_stages"][stage][measure] for r in runs["new"]]
            old = [r["device_stages"][stage][measure] for r in runs["baseline"]]
            print(f"  {stage:24s} {span(new, '7.1f'):>16s} {span(old, '7.1f'):>16s} "
                  f"{span(ratios(old, new), '.2f'):>14s}")  # fmt: skip
    key = "frames_per_s_into_device_memory"
    new, old = ([r[key] for r in runs[n]] for n in ("new", "baseline"))
    print(
        f"  frames/s into device memory: this checkout {span(new, '.0f')}, baseline "
        f"{span(old, '.0f')} (x {span(ratios(new, old), '.2f')} per round)"
    )
    if "cpu_gpu_agreement" in first:
        print_agreement(first["cpu_gpu_agreement"])
    if "mitsuba_frames_per_s" in first:
        mitsuba = [r["mitsuba_frames_per_s"] for r in runs["new"]]
        print(
            f"  per-frame Mitsuba in this checkout's runs: {span(mitsuba, '.1f')} frames/s "
            f"(this checkout x {span(ratios(new, mitsuba), '.1f')} per run)"
        )


def span(values: list[float], spec: str) -> str:
    """``min-max`` of ``values`` formatted with ``spec``."""
    return f"{min(values):{spec}}-{max(values):{spec}}" if values else "-"


def ratios(numerators: list[float], denominators: list[float]) -> list[float]:
    """Pairwise ratios (pairs with a zero denominator left out)."""
    return [n / d for n, d in zip(numerators, denominators, strict=True) if d > 0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", default=None, help="Mitsuba variant (default: automatic)")
    parser.add_argument("--scene", default="default", choices=["default", "freeform"])
    parser.add_argument("--size", type=int, default=960, help="camera crop, px (default 960)")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--lookup", default="nearest", choices=["nearest", "bilinear"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--poses", type=int, default=6, help="new poses rendered (>= 2)")
    parser.add_argument(
        "--mitsuba", type=int, default=0, metavar="N",
        help="also time N frames of Mitsuba's projector emitter, one render per frame",
    )  # fmt: skip
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    parser.add_argument("--no-host", action="store_true", help="skip the host path of render()")
    parser.add_argument(
        "--agreement", action="store_true",
        help="also render one noisy capture here and on llvm_ad_rgb and compare their decoding",
    )  # fmt: skip
    parser.add_argument(
        "--baseline", type=Path, metavar="DIR",
        help="also profile the virtus in DIR/src, alternating with this checkout (see above)",
    )  # fmt: skip
    parser.add_argument("--rounds", type=int, default=3, help="alternations with --baseline")
    args = parser.parse_args()
    if args.baseline is not None:
        if not (args.baseline / "src" / "virtus").is_dir():
            parser.error(f"--baseline: expected a folder holding src/virtus, got {args.baseline}")
        compare(child_arguments(sys.argv[1:]), args.baseline, max(args.rounds, 1))
        return

    _, dr, variant = mitsuba(args.variant)
    rig, sequence = cropped_rig(args.size), default_sequence()
    settings = RenderSettings(spp=args.spp, variant=variant)
    projector, sensor = ProjectorModel(pixel=args.lookup), Sensor()
    n_frames = len(sequence)
    report: dict[str, Any] = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "variant": variant, "scene": args.scene, "frames": n_frames,
        "camera_px": [rig.camera.width, rig.camera.height], "spp": args.spp,
        "lookup": args.lookup, "load_average_1min": [os.getloadavg()[0]],
        "virtus": str(Path(virtus.__file__).resolve()),
    }  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        scene = build_scene(args.scene, Path(folder))
        models = (rig, scene, sequence, settings, projector, sensor)
        device = stage_table(dr, device_stages(*models), args.repeats)
        report["device_stages"] = device
        report["frames_per_s_into_device_memory"] = (
            n_frames / device["render_device"]["wall_ms"] * 1e3
        )

        def device_pose(cam2world: Pose) -> Any:
            return render_device(rig, scene, sequence, settings, projector=projector,
                                 sensor=sensor, cam2world=cam2world)  # fmt: skip

        report["device_new_poses"] = new_poses(device_pose, dr, max(args.poses, 2))
        if args.mitsuba > 0:
            fps = mitsuba_frames_per_s(rig, scene, sequence, settings, args.lookup, args.mitsuba)
            report["mitsuba_frames_per_s"] = fps
        if not variant.startswith("cuda") and not args.no_host:
            host = stage_table(dr, host_stages(*models), args.repeats)
            report["host_stages"] = host
            report["frames_per_s_render"] = n_frames / host["render"]["wall_ms"] * 1e3

            def host_pose(cam2world: Pose) -> Any:
                return render(rig, scene, sequence, settings, projector=projector,
                              sensor=sensor, cam2world=cam2world, synthesis="sparse")  # fmt: skip

            report["host_new_poses"] = new_poses(host_pose, dr, max(args.poses, 2))
        if args.agreement:
            agreement = cpu_gpu_agreement(rig, scene, sequence, args.spp, variant)
            report["cpu_gpu_agreement"] = agreement
    report["load_average_1min"].append(os.getloadavg()[0])
    for key in ("device_new_poses", "host_new_poses"):
        if key in report:
            report[key.replace("new_poses", "poses_summary")] = summarise_poses(report[key])

    print(f"machine: {report['machine']}; {variant}; load average {report['load_average_1min']}")
    print(
        f"{args.scene} scene, {n_frames} frames, {args.size} x {args.size} px, {args.spp} spp, "
        f"{args.lookup}; stages: median of {args.repeats} (ms), Dr.Jit's account of one run"
    )
    print_table("device-resident path (render_device):", device)
    print(f"  -> {report['frames_per_s_into_device_memory']:.0f} frames/s into device memory")
    if "mitsuba_frames_per_s" in report:
        ratio = report["frames_per_s_into_device_memory"] / report["mitsuba_frames_per_s"]
        print(
            f"  Mitsuba's projector emitter, one render per frame: "
            f"{report['mitsuba_frames_per_s']:.1f} frames/s (render_device {ratio:.1f} x)"
        )
    if "host_stages" in report:
        print_table("host path (render(), sparse synthesis on the CPU):", report["host_stages"])
        print(f"  -> {report['frames_per_s_render']:.0f} frames/s")
    print_poses("new poses, render_device:", report["device_new_poses"])
    if "host_new_poses" in report:
        print_poses("new poses, render():", report["host_new_poses"])
    if "cpu_gpu_agreement" in report:
        print_agreement(report["cpu_gpu_agreement"])
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
