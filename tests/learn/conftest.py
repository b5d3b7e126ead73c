"""Tiny stores and captures for the virtus.learn tests (64 x 48 camera, ~40 ms a sample)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.data.test_dataset import tiny_config, tiny_rig, vertical_store
from virtus.data import generate, load_config

try:  # one intra-op thread: the tiny networks gain nothing from more, and on a shared
    # 2-core machine spinning worker threads slow every step several times over
    import torch

    torch.set_num_threads(1)
except ImportError:
    pass

#: A tiny UNet: 4 channels, 2 levels (~5k parameters), fast enough for several steps on CPU.
TINY_NET = {"base_channels": 4, "levels": 2, "batch_size": 2, "lr": 1e-3}


@pytest.fixture(scope="session")
def learn_store(tmp_path_factory) -> Path:
    """12 samples of a sphere before a plane, vertical fringes only; train/val/test by object."""
    splits = {"train": 0.6, "val": 0.2, "test": 0.2}
    return vertical_store(tmp_path_factory.mktemp("learn-store"), 12, splits)


@pytest.fixture(scope="session")
def horizontal_store(tmp_path_factory) -> Path:
    """A store of horizontal fringes only: no vertical phase labels for the phase model."""
    folder = tmp_path_factory.mktemp("learn-h")
    config = tiny_config(
        folder, num_samples=3,
        fringes={"codings": ["gray"], "steps": [4], "periods": [16], "directions": ["h"]},
    )  # fmt: skip
    generate(load_config(config), folder / "store")
    return folder / "store"


def render_capture(folder: Path, directions: tuple[str, ...] = ("v",)) -> Path:
    """A rendered capture (sphere before a plane) of the tiny rig, saved to ``folder``."""
    from tests.support import sphere_and_plane
    from virtus.patterns.catalog import build_sequence
    from virtus.render.settings import RenderSettings
    from virtus.scanner import Scanner

    rig = tiny_rig()
    proj = rig.projector.intrinsics
    sequence = build_sequence(
        proj.width, proj.height, periods=16, steps=4, gray_bits=5, directions=directions
    )
    scanner = Scanner(rig=rig, sequence=sequence, render=RenderSettings(spp=1))
    capture = scanner.capture(sphere_and_plane(), rng=1)
    capture.save(folder)
    return folder


@pytest.fixture(scope="session")
def phase_run(learn_store, tmp_path_factory) -> Path:
    """A phase model trained one epoch on :func:`learn_store`."""
    from virtus.learn.config import TrainConfig
    from virtus.learn.training import train

    run = tmp_path_factory.mktemp("phase-run") / "run"
    train(TrainConfig.from_dict({"model": "phase", **TINY_NET, "epochs": 1}), learn_store, run)
    return run


#: The benchmarks folder (not a package): bench_sim2real is tested as a module.
BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def bench_sim2real():
    """``benchmarks/bench_sim2real.py`` imported as a module."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import bench_sim2real as module
    finally:
        sys.path.remove(str(BENCHMARKS))
    return module
