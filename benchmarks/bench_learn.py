"""Learning-based fringe analysis on virtus data: the UNet baseline and the phase head,
trained on the same virtus store, evaluated on held-out objects and on the flat-plane test,
printed beside the published numbers (FPP-ML-Bench's UNet 14.54 mm, PhiCalNet 4.46 mm object
MAE).

Steps (each timed): generate the training store (examples/datasets/fpp_ml_bench.yaml: the
paper's rig, one matte object at 1.5-2.1 m before a plane, splits by object) and the
flat-plane store (fpp_ml_bench_flat.yaml), train ``unet`` and ``phase``
(examples/learn/*.yaml, sized by the options), evaluate both on the test split and the
flat-plane store. Stores and runs are reused when they exist (rerun to resume).

    PYTHONPATH=src python benchmarks/bench_learn.py --out /tmp/bench-learn          # tiny CPU
    PYTHONPATH=src python benchmarks/bench_learn.py --out /tmp/bench-learn --num 640 \\
        --flat 32 --scale 0.5 --epochs 20 --base-channels 64 --batch-size 8 \\
        --workers 12 --loader-workers 8 --json learn.json                           # one GPU

Add ``--realistic-config fpp_ml_bench_realistic.yaml --captures DIR...`` to train the phase
head on realistic sensors as well and compare both on imported real captures.

The CPU default (--scale 0.125: a 120 x 120 camera, 24 samples, 8-channel UNet, 3 epochs)
checks the whole path in a few minutes; its numbers mean nothing. Published numbers are on
960 x 960 images with ~10,000 training images: compare only runs of that size, and say the
size (``--scale``, ``--num``, epochs) with every number. Not a test: numbers depend on the
machine (quote them with its description).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _store(config: Path, out: Path, num: int, scale: float, workers: int) -> float:
    """Generate (or complete) the store of ``config`` (relative: examples/datasets/)."""
    from virtus.data import generate, load_config

    dataset = load_config(ROOT / "examples" / "datasets" / config)  # an absolute path wins
    dataset = dataclasses.replace(dataset, camera_scale=scale)
    start = time.perf_counter()
    generate(dataset, out, num=num, workers=workers)
    return time.perf_counter() - start


def _train(model: str, args: argparse.Namespace, store: Path, run: Path) -> tuple[dict, float]:
    from virtus.learn import TrainConfig, train

    config = TrainConfig.from_dict(
        {
            "model": model,
            "base_channels": args.base_channels,
            "levels": args.levels,
            "epochs": args.epochs,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "checkpoint_every": 50,
            "workers": args.loader_workers,
            "seed": 0,
        }
    )
    start = time.perf_counter()
    train(config, store, run, resume=True, device=args.device)
    return config.to_dict(), time.perf_counter() - start


def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add = parser.add_argument
    add("--out", type=Path, required=True, help="folder for stores and runs")
    add("--num", type=int, default=24, help="training store samples")
    add("--flat", type=int, default=4, help="flat-plane store samples")
    add("--scale", type=float, default=0.125, help="camera scale (1: 960 px)")
    add("--epochs", type=int, default=3)
    add("--base-channels", type=int, default=8)
    add("--levels", type=int, default=4)
    add("--batch-size", type=int, default=2)
    add("--lr", type=float, default=1e-4)
    add("--workers", type=int, default=1, help="dataset generation workers")
    add("--loader-workers", type=int, default=0, help="DataLoader workers")
    add("--device", default=None, help="torch device (default: cuda if any)")
    add("--only", nargs="*", default=["unet", "phase"])
    add(
        "--train-config",
        type=Path,
        default=Path("fpp_ml_bench.yaml"),
        help="dataset config of the training store (relative: examples/datasets/)",
    )
    add(
        "--realistic-config",
        type=Path,
        default=None,
        help="also train the phase head on this store (e.g. fpp_ml_bench_realistic.yaml)",
    )
    add(
        "--captures",
        type=Path,
        nargs="*",
        default=[],
        help="capture directories (virtus import) every run is evaluated on, against their "
        "own multi-step phase",
    )
    add("--json", type=Path, default=None)
    return parser.parse_args()


def _fmt(value: float | None, width: int) -> str:
    return f"{value:{width}.3f}" if value is not None else f"{'-':>{width}}"


def _print(results: dict, args: argparse.Namespace, device: str, timings: dict) -> None:
    from virtus.learn.metrics import PUBLISHED_OBJECT_MAE_MM

    print(
        f"\nvirtus.learn benchmark on {device}; camera scale {args.scale}, {args.num} "
        f"samples, {args.epochs} epochs, UNet width {args.base_channels}"
    )
    print(
        f"{'model':16} {'object MAE mm':>14} {'published':>10} {'bg MAE mm':>10} "
        f"{'phase RMSE rad':>15} {'order err':>10} {'flat MAE mm':>12} {'flat RMS mm':>12}"
    )
    for name, r in results.items():
        t, f = r["test"], r["flat"]
        published = PUBLISHED_OBJECT_MAE_MM[r["config"]["model"]]
        print(
            f"{name:16} {_fmt(t['object_mae_mm'], 14)} {published:10.2f} "
            f"{_fmt(t['background_mae_mm'], 10)} {_fmt(t['phase_rmse_rad'], 15)} "
            f"{_fmt(t['order_error_rate'], 10)} {_fmt(f['background_mae_mm'], 12)} "
            f"{_fmt(f['flat_rms_mm'], 12)}"
        )
    if "unet" in results and "phase" in results:
        u = results["unet"]["flat"]["background_mae_mm"]
        p = results["phase"]["flat"]["background_mae_mm"]
        if u and p:
            print(f"flat-plane test: the phase head's MAE is {u / p:.1f}x lower than the UNet's")
    for name, r in results.items():
        if "test_decode" in r:
            d = r["test_decode"]
            print(
                f"{name}, unwrapped to the branch nearest its sample's own decode: object MAE "
                f"{_fmt(d['object_mae_mm'], 8)} mm, order errors {_fmt(d['order_error_rate'], 6)}, "
                f"at the wrap {_fmt(d['wrap_mae_mm'], 8)} mm"
            )
        if "captures" in r:
            c = r["captures"]
            print(
                f"captures, {name}: phase RMSE {_fmt(c['phase_rmse_rad'], 6)} rad, depth MAE "
                f"{_fmt(c['object_mae_mm'], 8)} mm, order errors "
                f"{_fmt(c['order_error_rate'], 6)} (reference: their multi-step phase)"
            )
    print("timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items()))


def main() -> None:
    args = _arguments()
    import torch

    from virtus.learn import evaluate, evaluate_captures

    args.out.mkdir(parents=True, exist_ok=True)
    store, flat = args.out / "train.zarr", args.out / "flat.zarr"
    timings = {
        "generate_train_s": _store(args.train_config, store, args.num, args.scale, args.workers),
        "generate_flat_s": _store(
            Path("fpp_ml_bench_flat.yaml"), flat, args.flat, args.scale, args.workers
        ),
    }
    runs = [(model, model, store) for model in args.only]
    if args.realistic_config is not None:
        realistic = args.out / "realistic.zarr"
        timings["generate_realistic_s"] = _store(
            args.realistic_config, realistic, args.num, args.scale, args.workers
        )
        runs.append(("phase-realistic", "phase", realistic))
    results = {}
    for name, model, train_store in runs:
        run = args.out / f"run-{name}"
        config, timings[f"train_{name}_s"] = _train(model, args, train_store, run)
        results[name] = {
            "config": config,
            "test": evaluate(run, train_store, "test", device=args.device),
            "flat": evaluate(run, flat, None, device=args.device),
        }
        if model == "phase":
            results[name]["test_decode"] = evaluate(
                run, train_store, "test", device=args.device, unwrap="decode"
            )
        if args.captures:
            results[name]["captures"] = evaluate_captures(run, args.captures, device=args.device)
    device = torch.cuda.get_device_name(0) if torch.cuda.is_available() else platform.platform()
    _print(results, args, device, timings)
    if args.json:
        summary = {
            "device": device,
            "args": {k: str(v) for k, v in vars(args).items()},
            "timings_s": timings,
            "results": results,
        }
        args.json.write_text(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
