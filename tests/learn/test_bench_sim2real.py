"""The sim-to-real benchmark's whole path (benchmarks/bench_sim2real.py ``run``) on CPU at a
tiny size: a rendered stand-in for the prepared real capture (a lab-like rig with the
projector below the camera, the lab's horizontal-fringe sequence), two stores, two phase
heads of the same steps, their metrics on the capture, and a rerun that resumes."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from tests.learn.conftest import bench_sim2real  # noqa: E402


def _prepared(folder: Path, sequence_file: Path) -> Path:
    """What ``prepare`` writes (rig.json, capture/; no fit/: the presets are used), from a
    render: a 64 x 48 camera with about the lab's field of view, a projector 126 mm below
    it tilted 7 degrees up, a sphere before a tilted plane at the board's ~0.32 m."""
    from virtus.geometry.devices import Camera, Projector, Rig
    from virtus.geometry.optics import Intrinsics
    from virtus.geometry.transforms import Pose
    from virtus.patterns import load_sequence_file
    from virtus.render.settings import RenderSettings
    from virtus.scanner import Scanner
    from virtus.scene.model import PlaneObject, Scene, SphereObject

    rig = Rig(
        Camera(Intrinsics(70.4, 70.4, 31.5, 23.5, 64, 48)),
        Projector(Intrinsics(1056.0, 1057.0, 494.0, 562.0, 912, 570)),
        Pose.from_euler("xyz", [7.4, 2.0, 0.0], t=(0.006, 0.126, -0.067)),
    )
    folder.mkdir()
    rig.save_json(folder / "rig.json")
    sequence, _ = load_sequence_file(sequence_file)
    scene = Scene(
        objects=[SphereObject(0.03, (0.0, 0.0, 0.29))],
        background=PlaneObject(
            (1.0, 1.0), Pose.from_euler("xyz", [10.0, 0.0, 0.0], t=(0, 0, 0.33))
        ),
    )
    capture = Scanner(rig=rig, sequence=sequence, render=RenderSettings(spp=1)).capture(
        scene, rng=1
    )
    capture.save(folder / "capture")
    return folder


def test_the_benchmark_runs_and_resumes(tmp_path) -> None:
    bench = bench_sim2real()
    real = _prepared(tmp_path / "real", bench.SEQUENCE)
    args = argparse.Namespace(
        real=real, out=tmp_path / "out", variants=["realistic", "ideal"], num=10, steps=2,
        base_channels=4, levels=2, batch_size=2, lr=1e-3, depth_weight=1.0, workers=1,
        loader_workers=0, device="cpu",
    )  # fmt: skip
    summary = bench.run(args)
    results = summary["results"]
    assert set(results) == {"realistic", "ideal"}
    assert results["realistic"]["devices"] == {"sensor": ["imx174"], "projector": ["lightcrafter"]}
    assert summary["config"]["direction"] == "h" and summary["config"]["max_steps"] == 2
    for result in results.values():
        real_metrics = result["real"]
        assert real_metrics["samples"] == 1 and real_metrics["valid_share"] > 0.5
        assert 0 < real_metrics["phase_rmse_rad"] <= np.pi
        assert np.isfinite(real_metrics["object_mae_mm"])
        assert np.isfinite(result["test"]["phase_rmse_rad"])
    # the two stores differ only by their devices: the same scenes, other pixels
    from virtus.data import FringeDataset

    a = FringeDataset(args.out / "realistic.zarr", None, ("frames", "depth"), tensors=False)
    b = FringeDataset(args.out / "ideal.zarr", None, ("frames", "depth"), tensors=False)
    np.testing.assert_array_equal(a[0]["depth"], b[0]["depth"])
    assert not np.array_equal(a[0]["frames"], b[0]["frames"])
    # a rerun finds every store and run complete: the same numbers
    again = bench.run(args)
    for name in results:
        assert again["results"][name]["real"] == results[name]["real"]
