"""Tiny runs of every kind the report covers, made once per test session through the
command line (``--no-report``: each test writes the reports it checks).

Sizes are cut to keep the whole report suite within about a minute on two cores: a
160 x 160 px camera (the paper's rig resampled), one supersample, a four-pose calibration,
one ablation cell, a four-sample dataset store of 64 x 48 px.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.support import small_rig
from virtus.cli import main


def run_cli(argv: list[str]) -> None:
    """Run ``virtus ARGV`` in-process; fail the test on a non-zero exit."""
    with pytest.raises(SystemExit) as done:
        main([str(a) for a in argv])
    assert done.value.code == 0, f"virtus {' '.join(map(str, argv))} exited {done.value.code}"


@pytest.fixture(scope="session")
def rig_file(tmp_path_factory) -> Path:
    return small_rig().save_json(tmp_path_factory.mktemp("rig") / "rig160.json")


@pytest.fixture(scope="session")
def scan_run(tmp_path_factory, rig_file) -> Path:
    """``virtus scan`` of the paper's sphere scene (single view)."""
    out = tmp_path_factory.mktemp("runs") / "scan"
    run_cli(["scan", "--rig", rig_file, "--spp", "1", "--out", out, "--no-report", "--quiet"])
    return out


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory, rig_file) -> Path:
    """``virtus demo`` at 160 x 160 px (18 poses, one supersample)."""
    out = tmp_path_factory.mktemp("runs") / "demo"
    run_cli(["demo", "--rig", rig_file, "--spp", "1", "--out", out, "--no-report", "--quiet"])
    return out


@pytest.fixture(scope="session")
def calibrate_run(tmp_path_factory, rig_file) -> Path:
    """A rendered ``virtus calibrate`` of four random poses of a 4x7 board."""
    out = tmp_path_factory.mktemp("runs") / "calibrate"
    run_cli(["calibrate", "--rig", rig_file, "--spp", "1", "--poses", "random:4",
             "--board", "4x7", "--out", out, "--no-report", "--quiet"])  # fmt: skip
    return out


@pytest.fixture(scope="session")
def ablation_run(tmp_path_factory, rig_file) -> Path:
    """``virtus ablation`` of two cells (matte and metal, dark, ideal)."""
    out = tmp_path_factory.mktemp("runs") / "ablation"
    run_cli(["ablation", "--rig", rig_file, "--spp", "1", "--materials", "matte,metal",
             "--ambient", "dark", "--realism", "ideal", "--out", out, "--no-report",
             "--quiet"])  # fmt: skip
    return out


@pytest.fixture(scope="session")
def dataset_run(tmp_path_factory) -> Path:
    """A four-sample training store (the dataset tests' tiny configuration)."""
    from tests.data.test_dataset import tiny_config

    folder = tmp_path_factory.mktemp("dataset")
    config = tiny_config(folder, num_samples=4)
    out = folder / "store"
    run_cli(["dataset", "generate", "--config", config, "--out", out, "--workers", "1"])
    return out


@pytest.fixture
def scan_copy(scan_run, tmp_path) -> Path:
    """A private copy of the scan run, for tests that damage it."""
    return Path(shutil.copytree(scan_run, tmp_path / "scan"))
