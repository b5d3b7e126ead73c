"""Renderer speed: one pass for all frames vs Mitsuba's projector emitter, one render per frame.

Renders the paper's 52-frame sequence of the default scene (100 mm sphere at 1 m before a
wall) with the default rig (960 x 960 camera, 4 spp) two ways in one run, prints frames/s of
each, their ratio, the mean absolute difference between the two images of each frame, and,
separately, what writing the capture to disk costs.

    PYTHONPATH=src python benchmarks/bench_render.py [--repeats 5] [--json out.json]

Not a test: numbers depend on the machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from virtus.capture.groundtruth import ARRAY_NAMES as GT_NAMES
from virtus.geometry.devices import default_rig
from virtus.io.images import write_frames
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render, synthesize, trace
from virtus.render.jit.synthesis import synthesize_digital
from virtus.render.reference import ReferenceRenderer
from virtus.scene.model import default_scene
from virtus.sensor.camera import Sensor
from virtus.sensor.projector import ProjectorModel


def timed(function, repeats: int) -> tuple[list[float], object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return times, result


def synced(dr, function):  # noqa: ANN001, ANN201
    """``function`` whose timing includes the device work it queued."""

    def run():  # noqa: ANN202
        result = function()
        dr.sync_thread()
        return result

    return run


def device_section(rig, scene, sequence, args, mitsuba_fps) -> dict:  # noqa: ANN001
    """The device-resident path: frames/s into device memory, decoded, to the host, written
    to Zarr, with its stage split; ratios against per-frame Mitsuba measured above."""
    from virtus.render.backend import mitsuba
    from virtus.render.jit.synthesis import synthesize_on_device
    from virtus.render.jit.tracing import percentile_of_positive, trace_device
    from virtus.render.renderer import render_device
    from virtus.render.tracing import prepare_pass

    n_frames = len(sequence)
    _, dr, _ = mitsuba()
    projector, sensor = ProjectorModel(pixel=args.lookup), Sensor()
    options = {"spp": args.spp}
    settings = RenderSettings(spp=args.spp)
    repeats = max(args.repeats, 10)
    out: dict[str, object] = {}

    def render_to_device():
        return render_device(rig, scene, sequence, settings, projector=projector, sensor=sensor)

    warm = synced(dr, render_to_device)()
    times, _ = timed(synced(dr, render_to_device), repeats)
    out["render_to_device_s"] = statistics.median(times)
    out["frames_per_s_into_device_memory"] = n_frames / statistics.median(times)
    stages = {
        "scene_load": lambda: prepare_pass(rig, scene, **options),
        "trace": lambda: trace_device(rig, scene, **options),
        "exposure": lambda: percentile_of_positive(warm.trace.white(), 99.0),
        "synthesis_and_sensor": lambda: synthesize_on_device(
            warm.trace, sequence, projector, sensor, warm.exposure, 0, rig.projector.intrinsics
        ),
        "frames_to_host": lambda: warm.frames.numpy(),
        "ground_truth_to_host": lambda: warm.trace.ground_truth(),
    }
    out["stage_s"] = {
        name: statistics.median(timed(synced(dr, f), repeats)[0]) for name, f in stages.items()
    }
    host_times, _ = timed(synced(dr, lambda: render_to_device().to_rendering()), repeats)
    out["frames_per_s_to_host_with_ground_truth"] = n_frames / statistics.median(host_times)
    fastest = max(mitsuba_fps.values())
    out["mitsuba_frames_per_s"] = fastest
    out["speedup_vs_fastest_mitsuba"] = out["frames_per_s_into_device_memory"] / fastest
    try:
        from virtus.render.jit.decode import decode_on_device
    except ImportError:
        decode_on_device = None
    if decode_on_device is not None:
        data = warm.frames.data
        height, width = rig.camera.height, rig.camera.width
        for precision in ("float32", "float64"):

            def decode(precision: str = precision) -> None:
                result = decode_on_device(data, sequence, height, width, precision=precision)
                dr.eval(*result.arrays())

            synced(dr, decode)()
            decode_times, _ = timed(synced(dr, decode), repeats)
            out[f"frames_per_s_decoded_{precision}"] = n_frames / statistics.median(decode_times)
        out["frames_per_s_decoded"] = out["frames_per_s_decoded_float32"]
        start = time.perf_counter()
        sequence.decode(warm.frames.numpy())
        out["frames_per_s_decoded_host"] = n_frames / (time.perf_counter() - start)
    out["zarr"] = zarr_write(warm.frames.numpy(), repeats=3)
    return out


def zarr_write(frames: np.ndarray, repeats: int) -> dict:
    """Frames/s of writing one pose's frames into a local Zarr v3 array (one chunk per
    frame, LZ4 through Blosc at level 1), median of ``repeats`` writes."""
    try:
        import zarr
        from zarr.codecs import BloscCodec
    except ImportError:
        return {"skipped": "zarr is not installed"}
    times = []
    with tempfile.TemporaryDirectory() as folder:
        for k in range(repeats):
            start = time.perf_counter()
            array = zarr.create_array(
                Path(folder) / f"frames{k}.zarr", shape=frames.shape, dtype=frames.dtype,
                chunks=(1, *frames.shape[1:]),
                compressors=BloscCodec(cname="lz4", clevel=1, shuffle="bitshuffle"),
            )  # fmt: skip
            array[:] = frames
            times.append(time.perf_counter() - start)
        disk = sum(p.stat().st_size for p in Path(folder, "frames0.zarr").rglob("*"))
    return {"frames_per_s": len(frames) / statistics.median(times), "mb": disk / 1e6}


def print_device_section(device: dict, n_frames: int) -> None:
    stages = ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in device["stage_s"].items())
    print(
        f"device-resident:       {device['frames_per_s_into_device_memory']:7.0f} frames/s into "
        f"device memory ({device['render_to_device_s'] * 1e3:.1f} ms per {n_frames}-frame pose; "
        f"{device['speedup_vs_fastest_mitsuba']:.1f} x per-frame Mitsuba)"
    )
    print(f"  stages (each timed alone): {stages}")
    print(
        f"  to the host with ground truth: "
        f"{device['frames_per_s_to_host_with_ground_truth']:.0f} frames/s"
    )
    if "frames_per_s_decoded" in device:
        print(
            f"  decoded on the device: {device['frames_per_s_decoded_float32']:.0f} frames/s "
            f"float32, {device['frames_per_s_decoded_float64']:.0f} float64 "
            f"(host decoder: {device['frames_per_s_decoded_host']:.0f} frames/s)"
        )
    zarr = device["zarr"]
    if "frames_per_s" in zarr:
        print(f"  written to Zarr (lz4): {zarr['frames_per_s']:.0f} frames/s, {zarr['mb']:.1f} MB")
    else:
        print(f"  Zarr: {zarr['skipped']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of our renderer")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--lookup", default="nearest", choices=["nearest", "bilinear"])
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    parser.add_argument(
        "--device",
        action="store_true",
        help="also run the device-resident section on a CPU variant (always on CUDA)",
    )
    args = parser.parse_args()

    rig, scene, sequence = default_rig(), default_scene(), default_sequence()
    n_frames = len(sequence)
    load_before = os.getloadavg()[0]
    report: dict[str, object] = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"{platform.system()}",
        "frames": n_frames,
        "camera_px": [rig.camera.width, rig.camera.height],
        "spp": args.spp,
        "lookup": args.lookup,
    }

    # ---- ours: one pass, all frames, into memory (uint8) ----
    def ours():
        settings = RenderSettings(spp=args.spp)
        return render(rig, scene, sequence, settings, projector=ProjectorModel(pixel=args.lookup))

    warm = ours()  # compiles Dr.Jit kernels, caches camera rays
    report["variant"] = warm.variant
    times, _ = timed(ours, args.repeats)
    # Stage split of one more run.
    start = time.perf_counter()
    traced = trace(rig, scene, spp=args.spp)
    traced_s = time.perf_counter() - start
    sensor = Sensor()
    exposure = sensor.exposure_for(traced.white)
    start = time.perf_counter()
    if traced.variant.startswith("cuda"):  # what render() does for CUDA variants
        synthesize_digital(traced, sequence, args.lookup, sensor, exposure)
    else:
        synthesize(
            traced,
            sequence,
            args.lookup,
            transform=lambda b, f, p: sensor.digitize(b, exposure),
            dtype=np.uint8,
        )
    synth_s = time.perf_counter() - start
    report["ours_s"] = {
        "best": min(times),
        "median": statistics.median(times),
        "trace": traced_s,
        "synthesis_and_sensor": synth_s,
    }
    ours_fps = n_frames / statistics.median(times)
    report["ours_frames_per_s"] = ours_fps

    # ---- Mitsuba: projector emitter, one render per frame, same spp ----
    # "lean": direct integrator with the one emitter sample only (the fastest correct
    # setting); "default": Mitsuba's direct integrator defaults (also one BSDF sample,
    # which cannot hit a point light).
    mitsuba_fps: dict[str, float] = {}
    reference = None
    renderers = {
        name: ReferenceRenderer(
            rig, scene, spp=args.spp, lookup=args.lookup, bsdf_samples=bsdf_samples
        )
        for name, bsdf_samples in (("lean", 0), ("default", 1))
    }
    # Each setting twice, alternating: the first series in a process runs slower.
    for name in [*renderers, *renderers]:
        mitsuba = renderers[name]
        mitsuba.render_frames(sequence, [0, 1])  # warm-up (kernel compilation)
        images, frame_s = [], []
        for index in range(n_frames):
            start = time.perf_counter()
            images.append(mitsuba.render_image(sequence.image(index), seed=index))
            frame_s.append(time.perf_counter() - start)
        # Median frame time: robust to other load on the machine, like our median run.
        mitsuba_fps[name] = max(mitsuba_fps.get(name, 0.0), 1.0 / statistics.median(frame_s))
        reference = np.stack(images) if reference is None else reference
    report["mitsuba_frames_per_s"] = mitsuba_fps
    report["speedup"] = {name: ours_fps / fps for name, fps in mitsuba_fps.items()}
    report["speedup_vs_fastest_mitsuba"] = ours_fps / max(mitsuba_fps.values())

    # ---- agreement on the same frames (radiance, before the sensor) ----
    radiance = synthesize(traced, sequence, args.lookup)
    relative = [
        float(np.abs(radiance[i] - reference[i]).mean() / reference[i].mean())
        for i in range(n_frames)
        if reference[i].mean() > 0
    ]
    report["mad_rel_jittered"] = {"mean": float(np.mean(relative)), "max": float(np.max(relative))}
    same_points = ReferenceRenderer(rig, scene, spp=args.spp, lookup=args.lookup, jitter=False)
    check = [0, 25, 50]
    unjittered = same_points.render_frames(sequence, check)
    report["mad_rel_same_sample_positions"] = max(
        float(np.abs(radiance[i] - unjittered[k]).mean() / unjittered[k].mean())
        for k, i in enumerate(check)
    )

    # ---- writing a capture: PNG frames and ground-truth arrays ----
    with tempfile.TemporaryDirectory() as folder:
        png = {}
        for level in (0, 1, 3):
            start = time.perf_counter()
            paths = write_frames(Path(folder) / f"png{level}", warm.frames, compression=level)
            png[level] = {
                "s": time.perf_counter() - start,
                "mb": sum(p.stat().st_size for p in paths) / 1e6,
            }
        start = time.perf_counter()
        arrays = warm.gt.arrays()
        for name in GT_NAMES:
            np.save(Path(folder) / f"{name}.npy", arrays[name])
        gt_s = time.perf_counter() - start
    report["png_write"] = png
    report["gt_write_s"] = gt_s

    if args.device or report["variant"].startswith("cuda"):
        report["device"] = device_section(rig, scene, sequence, args, mitsuba_fps)

    report["load_average_1min"] = [load_before, os.getloadavg()[0]]
    print(f"machine: {report['machine']}; Mitsuba variant {report['variant']}")
    print(f"load average (1 min) before/after: {load_before:.2f} / {os.getloadavg()[0]:.2f}")
    print(
        f"{n_frames} frames, {rig.camera.width} x {rig.camera.height} px, {args.spp} spp, "
        f"{args.lookup} lookup"
    )
    print(
        f"virtus (one pass):     {ours_fps:7.1f} frames/s  (median {statistics.median(times):.3f} s"
        f", best {min(times):.3f} s; trace {traced_s:.3f} s + synthesis/sensor {synth_s:.3f} s)"
    )
    for name, fps in mitsuba_fps.items():
        print(
            f"Mitsuba, one render per frame ({name}): {fps:.2f} frames/s; "
            f"virtus is {ours_fps / fps:.1f} x faster"
        )
    print(f"speed-up over the faster Mitsuba setting: {report['speedup_vs_fastest_mitsuba']:.1f} x")
    print(
        f"mean |difference| / mean radiance, Mitsuba jittered sampler: "
        f"mean {report['mad_rel_jittered']['mean']:.4f}, "
        f"max {report['mad_rel_jittered']['max']:.4f}"
        f"; same sample positions: {report['mad_rel_same_sample_positions']:.1e}"
    )
    for level, info in png.items():
        print(
            f"write PNG (level {level}):  {info['s']:.2f} s for {n_frames} frames, "
            f"{info['mb']:.1f} MB ({n_frames / info['s']:.0f} frames/s)"
        )
    print(f"write ground truth:    {gt_s:.2f} s ({len(GT_NAMES)} .npy arrays)")
    if "device" in report:
        print_device_section(report["device"], n_frames)
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
