"""Sim-to-real: does training on a realistic virtual sensor help a single-shot phase network
on a real bench? The phase head (:mod:`virtus.learn`) trained on virtus data of one real
lab's rig, once with the sensor and projector fitted to that lab's capture and once with
ideal ones, evaluated on the lab's real capture against its own multi-step phase.

The real bench: github.com/kimthyung/3D_Reconstruction_with_Fringe_pattern (commit
561120b, ``3D_reconstruction/data00/p00``: 52 BMPs, 1936 x 1464, 8 bit, a 7 x 21
white-on-black circle board at ~320 mm, a DLP LightCrafter 4500; the lab's OpenCV
calibration). It has **no licence**: nothing of it is committed; ``prepare`` writes a
compact derived copy into a git-ignored folder for one's own runs. Its projector is 126 mm
below the camera and 6 mm beside it, so depth comes from the **horizontal** fringes
(``direction: h``; ``examples/datasets/sim2real/lightcrafter_lab_h.yaml``): at 320 mm,
``v_p`` moves 0.85 projector px per mm of depth at the image centre, ``u_p`` 0.05 (and
not at all on one column near the left edge).

Two steps::

    # 1. here (CPU, ~10 s): the compact capture (26 frames binned 4 x 4: 484 x 366, 1.5 MB
    #    of PNG), its rig, and the light fitted to it (virtus twin --fit's fit)
    PYTHONPATH=src python benchmarks/bench_sim2real.py prepare \\
        /work/.mirror/kimthyung+3D_Reconstruction_with_Fringe_pattern/repo --out .gpu-work/real

    # 2. on one GPU (or a tiny CPU check with the defaults: ~3 min on 2 cores): stores,
    #    training, evaluation
    PYTHONPATH=src python benchmarks/bench_sim2real.py run .gpu-work/real --out .gpu-work/s2r \\
        --num 640 --steps 1500 --base-channels 32 --batch-size 8 --workers 12 \\
        --loader-workers 8 --json sim2real.json

``run`` (a) generates one store per variant on the lab's rig and sequence
(``examples/datasets/sim2real/lab.yaml``: one to two matte objects at 0.25-0.33 m before a
tilted plane at 0.30-0.42 m, the board's standoff; the same scenes in every store):
``realistic`` (the sensor and projector ``prepare`` fitted to the capture -- exposure, gain
and noise, blur, vignetting, fall-off; the imx174 + lightcrafter presets where the fit
failed) and ``ideal`` (the ideal presets: noise-free, auto exposure); optionally
``ideal-exposed`` (noise-free at the fitted exposure: brightness apart from noise and
optics; on this capture the ideal and fitted inputs' levels differ little, mean 0.12
against 0.09 of full scale, so it is left out by default); (b) trains the phase head
(``direction: h``) on each with the same seed and the same number of optimiser steps; (c)
evaluates each on its own store's test split and on the real capture
(:func:`virtus.learn.evaluate_captures`: phase RMSE and depth MAE against the capture's
18-step + Gray-code reconstruction); (d) prints the table. Every step resumes: rerun the
same command after a kill.

The real capture is a flat board (white circles on black): "depth MAE" there is against the
capture's own multi-step depth over its valid pixels, not against a ground truth.
Not a test: numbers depend on the machine (quote them with it and the sizes).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "examples" / "datasets" / "sim2real"
#: The dataset configuration template (rig, sensor and projector are filled in by ``run``).
TEMPLATE = HERE / "lab.yaml"
#: The horizontal half of the lab's sequence: the frames the compact capture keeps.
SEQUENCE = HERE / "lightcrafter_lab_h.yaml"
#: The real frames of SEQUENCE, in its order: phase 0-17, Gray 18-22, black 23-24, white 51.
REAL_FRAMES = (*range(25), 51)
#: The lab's camera (px).
FULL_SIZE = (1936, 1464)
#: Variants: (sensor, projector) choices, resolved by :func:`_devices`.
VARIANTS = ("realistic", "ideal", "ideal-exposed")


# -- prepare (runs here, on the real capture) ------------------------------------------------


def _bin(frame: np.ndarray, factor: int) -> np.ndarray:
    """Mean of ``factor x factor`` blocks (pixel edges kept: ``Intrinsics.scaled(1/factor)``),
    rounded back to uint8."""
    h, w = frame.shape
    blocks = frame.reshape(h // factor, factor, w // factor, factor).astype(np.float64)
    return np.clip(np.rint(blocks.mean(axis=(1, 3))), 0, 255).astype(np.uint8)


def _circles(capture, factor: int) -> np.ndarray:
    """The board's white circles (``bench_twin_real.white_circles``), eroded off their
    blurred edges: the one-albedo pixels the light is fitted on."""
    from scipy import ndimage

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_twin_real import white_circles

    circles, _ = white_circles(capture, factor)
    return ndimage.binary_erosion(circles, iterations=max(1, 5 // factor))


def _write_yaml(path: Path, data: dict, what: str) -> None:
    import yaml

    path.write_text(f"# {what}\n" + yaml.safe_dump(data, sort_keys=False))


def _fit(capture, rig, factor: int, fit_dir: Path) -> str | None:
    """Fit the light to ``capture`` (:func:`virtus.twin.photometric.fit_photometry`, what
    ``virtus twin --fit`` runs) on the board's white circles; write ``fit_dir/sensor.yaml``,
    ``projector.yaml``, ``ideal_exposed.yaml`` and ``photometric.json``. The error's text
    where it fails (``run`` then uses the presets)."""
    import virtus.twin.photometric as photometric
    from virtus.sensor.camera import Sensor

    fit_dir.mkdir(exist_ok=True)
    # The normals' smoothing is in camera px: the same 2 full-size px on the binned image,
    # or the binned circles (~12 px) leave no pixel with full support.
    smooth = photometric.NORMAL_SMOOTH_PX
    photometric.NORMAL_SMOOTH_PX = smooth / factor
    try:
        fit = photometric.fit_photometry(
            [capture], rig, prior_sensor=Sensor(bit_depth=8), regions=[_circles(capture, factor)]
        )
    except Exception as error:  # noqa: BLE001 - any failure: run falls back to presets
        return f"{type(error).__name__}: {error}"
    finally:
        photometric.NORMAL_SMOOTH_PX = smooth
    _write_yaml(fit_dir / "sensor.yaml", fit.sensor.to_dict(), "camera fitted to the capture")
    _write_yaml(
        fit_dir / "projector.yaml", fit.projector.to_dict(), "projector fitted to the capture"
    )
    exposed = {"name": "ideal-exposed", "bit_depth": 8, "exposure": fit.sensor.exposure}
    _write_yaml(fit_dir / "ideal_exposed.yaml", exposed, "noise-free, at the fitted exposure")
    (fit_dir / "photometric.json").write_text(json.dumps(fit.to_dict(), indent=1, default=float))
    return None


def prepare(source: Path, out: Path, factor: int) -> dict:
    """The compact capture ``out/capture`` (REAL_FRAMES binned by ``factor``), its rig
    ``out/rig.json`` and the fitted light ``out/fit/`` (module docstring). Idempotent:
    what exists is kept."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_twin_real import COMMIT, stage
    from bench_twin_real import SEQUENCE as FULL_SEQUENCE
    from PIL import Image

    from virtus.calib.io import load_calibration_report
    from virtus.capture.capture import Capture
    from virtus.geometry.devices import Camera, Rig
    from virtus.io.images import read_image
    from virtus.patterns import load_sequence_file
    from virtus.pipeline.capture import import_images

    if FULL_SIZE[0] % factor or FULL_SIZE[1] % factor:
        raise SystemExit(f"--bin {factor}: must divide {FULL_SIZE[0]} and {FULL_SIZE[1]}")
    out.mkdir(parents=True, exist_ok=True)
    capture_dir, rig_file, fit_dir = out / "capture", out / "rig.json", out / "fit"
    report: dict = {
        "source": f"kimthyung/3D_Reconstruction_with_Fringe_pattern@{COMMIT[:7]} (no licence: "
        "not for redistribution)",
        "frames": list(REAL_FRAMES),
        "bin": factor,
    }
    done = (capture_dir / "capture.json").is_file() and (fit_dir / "sensor.yaml").is_file()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        images, calibration = stage(source, work) if not done else (None, None)
        if not (capture_dir / "capture.json").is_file():
            binned = work / "binned"
            binned.mkdir()
            for i, index in enumerate(REAL_FRAMES):
                frame = read_image(images / f"{index:02d}.bmp")
                Image.fromarray(_bin(frame, factor)).save(binned / f"{i:02d}.png")
            full, _ = load_sequence_file(FULL_SEQUENCE)
            rig, _ = load_calibration_report(
                calibration, units="mm", camera_size=FULL_SIZE,
                projector_size=(full.width, full.height),
            )  # fmt: skip
            rig = Rig(Camera(rig.camera.intrinsics.scaled(1 / factor)), rig.projector, rig.proj2cam)
            rig.save_json(rig_file)
            import_images(binned, SEQUENCE, rig_file, capture_dir)
        if not (fit_dir / "sensor.yaml").is_file():
            # The fit triangulates with both directions: all 52 frames, binned alike (kept
            # only in this temporary folder).
            every = work / "every"
            every.mkdir()
            for index in range(52):
                frame = read_image(images / f"{index:02d}.bmp")
                Image.fromarray(_bin(frame, factor)).save(every / f"{index:02d}.png")
            both = import_images(every, FULL_SEQUENCE, rig_file, work / "both").capture
            report["fit_error"] = _fit(both, Rig.load_json(rig_file), factor, fit_dir)
    capture = Capture.load(capture_dir)
    report["camera_size"] = [capture.frames.shape[2], capture.frames.shape[1]]
    if (fit_dir / "photometric.json").is_file():
        fitted = json.loads((fit_dir / "photometric.json").read_text())
        report["fit"] = {
            "sensor": fitted["sensor"],
            "projector": fitted["projector"],
            "ambient": fitted["ambient"],
            "notes": fitted.get("notes", []),
        }
    decoded = capture.decode()
    report["reference_valid_fraction"] = float(decoded.mask_h.mean())
    report["bytes"] = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    (out / "SOURCE.json").write_text(json.dumps(report, indent=1, default=float))
    return report


# -- run (GPU or a tiny CPU check) -----------------------------------------------------------


def _devices(real: Path, variant: str) -> tuple[list[str], list[str]]:
    """(sensor, projector) choices of a variant; the fitted files where ``prepare`` wrote
    them, else imx174 + lightcrafter (and the ideal sensor for ``ideal-exposed``)."""
    fit = real.resolve() / "fit"
    fitted = (fit / "sensor.yaml").is_file()
    if variant == "ideal":
        return ["ideal"], ["ideal"]
    if variant == "ideal-exposed":
        return [str(fit / "ideal_exposed.yaml") if fitted else "ideal"], ["ideal"]
    if fitted:
        return [str(fit / "sensor.yaml")], [str(fit / "projector.yaml")]
    return ["imx174"], ["lightcrafter"]


def dataset_config(real: Path, variant: str, num: int):
    """The template with the real rig, the variant's devices and ``num`` samples."""
    from virtus.data import DatasetConfig
    from virtus.io.safeio import read_yaml

    data = read_yaml(TEMPLATE, "dataset config", expect=dict)
    sensors, projectors = _devices(real, variant)
    data.update(
        num_samples=num,
        sensor=sensors,
        projector=projectors,
        rig={**data.get("rig", {}), "file": str((real / "rig.json").resolve())},
    )
    return DatasetConfig.from_dict(data, base_dir=TEMPLATE.parent)


def _train_config(args: argparse.Namespace):
    from virtus.learn import TrainConfig

    return TrainConfig.from_dict(
        {
            "model": "phase",
            "direction": "h",
            "base_channels": args.base_channels,
            "levels": args.levels,
            "epochs": 100_000,  # max_steps decides: every variant takes the same steps
            "max_steps": args.steps,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "depth_range_m": 0.05,  # depth L1 in units of 5 cm (the scenes' depth span)
            "depth_weight": args.depth_weight,
            "checkpoint_every": 100,
            "workers": args.loader_workers,
            "seed": 0,
        }
    )


def _progress(message: str) -> None:
    """One line at once (a run cut off at a time limit still shows how far it got)."""
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def run(args: argparse.Namespace) -> dict:
    from virtus.data import generate
    from virtus.learn import evaluate, evaluate_captures, train

    real = args.real
    if not (real / "capture" / "capture.json").is_file() or not (real / "rig.json").is_file():
        raise SystemExit(f"{real}: no prepared capture (run `prepare` first)")
    args.out.mkdir(parents=True, exist_ok=True)
    config = _train_config(args)
    results, timings = {}, {}
    for variant in args.variants:
        store, run_dir = args.out / f"{variant}.zarr", args.out / f"run-{variant}"
        _progress(f"{variant}: generating {args.num} samples into {store}")
        start = time.perf_counter()
        generate(dataset_config(real, variant, args.num), store, workers=args.workers)
        timings[f"generate_{variant}_s"] = time.perf_counter() - start
        _progress(f"{variant}: generated in {timings[f'generate_{variant}_s']:.0f} s; training")
        start = time.perf_counter()

        def step_done(step: int, variant: str = variant) -> None:
            if step % 100 == 0:
                _progress(f"{variant}: step {step} of {args.steps}")

        train(config, store, run_dir, resume=True, device=args.device, on_step=step_done)
        timings[f"train_{variant}_s"] = time.perf_counter() - start
        _progress(f"{variant}: trained in {timings[f'train_{variant}_s']:.0f} s; evaluating")
        results[variant] = {
            "devices": dict(zip(("sensor", "projector"), _devices(real, variant), strict=True)),
            "test": evaluate(run_dir, store, "test", device=args.device),
            "real": evaluate_captures(run_dir, [real / "capture"], device=args.device),
        }
    return {"config": config.to_dict(), "results": results, "timings_s": timings}


def _fmt(value: float | None, width: int) -> str:
    return f"{value:{width}.3f}" if value is not None else f"{'-':>{width}}"


def _print(summary: dict, args: argparse.Namespace) -> None:
    print(
        f"\nsim-to-real on {summary['device']}: phase head, {args.num} samples per store, "
        f"{args.steps} steps, batch {args.batch_size}, width {args.base_channels}; real: "
        f"{args.real / 'capture'} (reference: its 18-step + Gray-code phase)"
    )
    print(
        f"{'trained on':14} {'sim phase rad':>13} {'sim obj MAE mm':>15} {'real phase rad':>15} "
        f"{'real MAE mm':>12} {'real RMSE mm':>13} {'real order err':>15}"
    )
    for name, r in summary["results"].items():
        t, c = r["test"], r["real"]
        print(
            f"{name:14} {_fmt(t['phase_rmse_rad'], 13)} {_fmt(t['object_mae_mm'], 15)} "
            f"{_fmt(c['phase_rmse_rad'], 15)} {_fmt(c['object_mae_mm'], 12)} "
            f"{_fmt(c['object_rmse_mm'], 13)} {_fmt(c['order_error_rate'], 15)}"
        )
    print("timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in summary["timings_s"].items()))


def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    p = sub.add_parser("prepare", help="the compact real capture (runs here)")
    p.add_argument("source", type=Path, help="clone or bare git dir of the capture's repo")
    p.add_argument("--out", type=Path, required=True, help="e.g. .gpu-work/real")
    p.add_argument("--bin", type=int, default=4, help="binning factor (4: 484 x 366)")
    r = sub.add_parser("run", help="stores, training and evaluation")
    add = r.add_argument
    add("real", type=Path, help="the folder `prepare` wrote")
    add("--out", type=Path, required=True, help="folder for stores and runs")
    add("--variants", nargs="+", choices=VARIANTS, default=["realistic", "ideal"])
    add("--num", type=int, default=12, help="samples per store")
    add("--steps", type=int, default=4, help="optimiser steps (every variant)")
    add("--base-channels", type=int, default=8)
    add("--levels", type=int, default=4)
    add("--batch-size", type=int, default=2)
    add("--lr", type=float, default=1e-4)
    add("--depth-weight", type=float, default=1.0, help="phase head's depth L1 weight")
    add("--workers", type=int, default=1, help="dataset generation workers")
    add("--loader-workers", type=int, default=0, help="DataLoader workers")
    add("--device", default=None, help="torch device (default: cuda if any)")
    add("--json", type=Path, default=None)
    return parser.parse_args()


def main() -> None:
    args = _arguments()
    if args.step == "prepare":
        print(json.dumps(prepare(args.source, args.out, args.bin), indent=1, default=float))
        return
    import torch

    summary = run(args)
    cuda = torch.cuda.is_available() and args.device in (None, "cuda")
    summary["device"] = torch.cuda.get_device_name(0) if cuda else platform.platform()
    summary["args"] = {k: str(v) for k, v in vars(args).items()}
    _print(summary, args)
    if args.json:
        args.json.write_text(json.dumps(summary, indent=2, default=float))


if __name__ == "__main__":
    main()
