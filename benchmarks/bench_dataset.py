"""Dataset generation speed: images written per second into a Zarr store, split by stage.

Generates ``--samples`` samples of a training configuration on the paper's rig (960 x 960
camera, the paper's 52-frame sequence, 1 spp, ideal sensor and projector, one sphere or box
before a plane) with :func:`virtus.data.generate` in this process, then reports in one run:

* images/s written (frames of all samples / wall time of the generation), and samples/s;
* the per-stage split summed over the samples: render (trace + synthesis of every frame),
  labels (ground truth -> phase, order, numerator/denominator, masks, object ids), write
  (Zarr shard encoding + file I/O), with compression timed alone on the same arrays
  (the rest of write is I/O and Zarr overhead);
* for context, the renderer alone on the same scenes (``Scanner.capture``, frames/s): the
  ceiling a dataset run can reach on this machine.

    PYTHONPATH=src python benchmarks/bench_dataset.py [--samples 8] [--json out.json]

Not a test: numbers depend on the machine and its load (quote them with its description).
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
import yaml

from virtus.data import DatasetStore, generate, load_config
from virtus.data.sampling import Randomiser


def config_file(folder: Path, samples: int, shard: int, codec: str, dtype: str) -> Path:
    data = {
        "mode": "training",
        "seed": 0,
        "num_samples": samples,
        "fringes": {"codings": ["gray"], "steps": [18], "periods": [18]},
        "objects": {
            "sources": [
                {"type": "sphere", "radius_m": [0.05, 0.1], "instances": 32},
                {"type": "box", "size_m": [0.05, 0.12], "instances": 32},
            ]
        },
        "planes": {"count": [1, 1]},
        "storage": {"shard_samples": shard, "codec": codec, "level": 1, "label_dtype": dtype},
    }
    path = folder / "bench.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def compression_seconds(store: DatasetStore, codec: str, level: int, samples: int) -> float:
    """Seconds to compress ``samples`` samples' arrays with the store's codec alone."""
    from numcodecs import Blosc, Zstd

    if codec == "none":
        return 0.0
    compressor = (
        Zstd(level=level)
        if codec == "zstd"
        else Blosc(cname=codec.removeprefix("blosc-"), clevel=level, shuffle=Blosc.SHUFFLE)
    )
    arrays = store.read_sample(0)
    start = time.perf_counter()
    for array in arrays.values():
        compressor.encode(np.ascontiguousarray(array))
    return (time.perf_counter() - start) * samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--shard", type=int, default=4, help="samples per shard")
    parser.add_argument(
        "--codec", default="blosc-zstd", choices=["blosc-zstd", "blosc-lz4", "zstd", "none"]
    )
    parser.add_argument("--label-dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    args = parser.parse_args()

    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        config = load_config(
            config_file(folder, args.samples, args.shard, args.codec, args.label_dtype)
        )
        # The renderer alone on the same samples (warm-up: the first kernel compilation).
        randomiser = Randomiser(config, folder / "assets")
        spec = randomiser.sample(0)
        spec.scanner.capture(spec.scene, rng=spec.capture_seed).frames  # noqa: B018
        start = time.perf_counter()
        frames = 0
        for index in range(args.samples):
            spec = randomiser.sample(index)
            frames += len(spec.scanner.capture(spec.scene, rng=spec.capture_seed).frames)
        render_only_s = time.perf_counter() - start

        store_path = folder / "store"
        report = generate(config, store_path, workers=args.workers)
        store = DatasetStore.open(store_path)
        written = args.samples * len(spec.scanner.sequence)
        compress_s = compression_seconds(store, args.codec, 1, args.samples)
        disk = sum(p.stat().st_size for p in store_path.rglob("*") if p.is_file())
        raw = args.samples * sum(a.nbytes for a in store.layout)

    stages = dict(report.timing_s)
    stages["compression"] = compress_s
    stages["io_and_zarr"] = max(stages["write"] - compress_s, 0.0)
    result = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"{platform.system()}",
        "load_average_before": load_before,
        "image_px": "960x960",
        "frames_per_sample": len(spec.scanner.sequence),
        "samples": args.samples,
        "workers": args.workers,
        "codec": args.codec,
        "label_dtype": args.label_dtype,
        "images_per_s": written / report.seconds,
        "samples_per_s": args.samples / report.seconds,
        "seconds": report.seconds,
        "stage_s": stages,
        "stage_share": {k: v / report.seconds for k, v in stages.items() if k != "write"},
        "renderer_only_images_per_s": frames / render_only_s,
        "bytes_raw": raw,
        "bytes_on_disk": disk,
        "paper_images_per_s": 3.1,
        "target_images_per_s": 150.0,
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
