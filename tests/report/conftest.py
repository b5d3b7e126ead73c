"""Tiny runs of every kind the report covers, made once per test session through the
command line (``--no-report``: each test writes the reports it checks).

Sizes are cut to keep the whole report suite within about a minute on two cores: a
160 x 160 px camera (the paper's rig resampled), one supersample, a four-pose calibration,
one ablation cell, a four-sample dataset store of 64 x 48 px; the design, robot, learning
and twin runs of the same sizes their own command tests use.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
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


# -- the design, robot, learning and twin runs (issue 19 follow-ups) -----------------------


@pytest.fixture(scope="session")
def predict_run(tmp_path_factory) -> Path:
    """``virtus predict`` of the sphere scene with an 80 x 80 px camera."""
    folder = tmp_path_factory.mktemp("runs")
    small_rig(1 / 12).save_json(folder / "rig80.json")
    out = folder / "predict"
    run_cli(["predict", "--scene", "sphere", "--rig", folder / "rig80.json", "--spp", "1",
             "--sensor", "imx174", "--out", out, "--quiet"])  # fmt: skip
    return out


@pytest.fixture(scope="session")
def design_run(tmp_path_factory) -> Path:
    """``virtus design`` of two step counts on a 24-sample grid."""
    out = tmp_path_factory.mktemp("runs") / "design"
    run_cli(["design", "--vary", "steps=4,16", "--grid", "24", "--out", out, "--quiet"])
    return out


@pytest.fixture(scope="session")
def acceptance_run(tmp_path_factory) -> Path:
    """``virtus acceptance`` shortened to one position per artefact (true rig, 240 px)."""
    from virtus.geometry.devices import Camera, Rig, default_rig

    folder = tmp_path_factory.mktemp("runs")
    rig = default_rig()
    small = Rig(Camera(rig.camera.intrinsics.scaled(0.25)), rig.projector, rig.proj2cam)
    small.save_json(folder / "rig240.json")
    out = folder / "acceptance"
    run_cli(["acceptance", "--rig", folder / "rig240.json", "--out", out, "--true-rig",
             "--positions", "1", "--lookup", "bilinear", "--limits", "P_F=5,P_S=1,SD=1,F=1",
             "--no-report", "--quiet"])  # fmt: skip
    return out


@pytest.fixture(scope="session")
def robot_scan_run(tmp_path_factory) -> Path:
    """``virtus robot-scan`` of one view of the free-form object from the example Panda's
    wrist (64 x 64 px camera; the robot-scan command test's configuration)."""
    from tests.cli.test_robot_scan_cmd import EXAMPLES, VIEW_Q

    folder = tmp_path_factory.mktemp("runs")
    small_rig(1 / 15).save_json(folder / "rig64.json")
    text = (EXAMPLES / "panda_wrist.yaml").read_text()
    (folder / "robot.yaml").write_text(text.replace("rig: null", f"rig: {folder / 'rig64.json'}"))
    (folder / "trajectory.json").write_text(json.dumps({"q": [VIEW_Q]}))
    out = folder / "robot"
    run_cli(["robot-scan", "--robot", folder / "robot.yaml", "--trajectory",
             folder / "trajectory.json", "--spp", "1", "--out", out, "--no-report",
             "--quiet"])  # fmt: skip
    return out


@pytest.fixture(scope="session")
def learn_store_small(tmp_path_factory) -> Path:
    """Six samples (64 x 48 px), vertical fringes, train/val/test."""
    from tests.data.test_dataset import vertical_store

    splits = {"train": 0.5, "val": 0.17, "test": 0.33}
    return vertical_store(tmp_path_factory.mktemp("learn"), 6, splits)


@pytest.fixture(scope="session")
def learn_run(tmp_path_factory, learn_store_small) -> Path:
    """``virtus learn train`` of a tiny UNet for one epoch, then ``virtus learn eval`` on the
    whole store (which saves the first samples' depth maps)."""
    pytest.importorskip("torch")
    import torch
    import yaml

    torch.set_num_threads(1)  # tiny networks: more threads only slow a shared machine
    folder = tmp_path_factory.mktemp("runs")
    (folder / "unet.yaml").write_text(yaml.safe_dump(
        {"model": "unet", "base_channels": 4, "levels": 2, "batch_size": 2, "lr": 1e-3,
         "epochs": 1}))  # fmt: skip
    out = folder / "learn"
    run_cli(["learn", "train", "--config", folder / "unet.yaml", "--store", learn_store_small,
             "--out", out, "--quiet"])  # fmt: skip
    run_cli(["learn", "eval", out, "--store", learn_store_small, "--no-report", "--quiet"])
    return out


@pytest.fixture(scope="session")
def twin_run(tmp_path_factory) -> Path:
    """``virtus twin --validate`` of two rendered 4x7 board poses (240 x 240 px camera),
    the board placed from both devices (the rig file has no poses)."""
    from tests.pipeline.test_calibrate_captures import scaled_rig
    from virtus.calib.board import board_from_spec
    from virtus.calib.poses import pose_set
    from virtus.calib.scene import BOARD_BLUR_M, BOARD_TEXEL_M, board_scene
    from virtus.render import RenderSettings
    from virtus.scanner import Scanner

    folder = tmp_path_factory.mktemp("runs")
    rig, board = scaled_rig(0.25), board_from_spec("4x7")
    scanner = Scanner(rig=rig, render=RenderSettings(spp=1))
    texture = board.texture(pixel_size_m=BOARD_TEXEL_M, blur_m=BOARD_BLUR_M)
    for index, pose in enumerate(pose_set("random:2", rig, board, np.random.default_rng(7))):
        capture = scanner.capture(board_scene(board, pose, texture), rng=50 + index)
        capture.save(folder / "captures" / pose.name)
    rig.save_json(folder / "calib.json")
    out = folder / "twin"
    run_cli(["twin", folder / "calib.json", "--out", out, "--validate", folder / "captures",
             "--board", "4x7", "--quiet"])  # fmt: skip
    return out


def copy_run(run_dir: Path, tmp_path: Path) -> Path:
    """A private copy of a session run, for tests that damage it."""
    return Path(shutil.copytree(run_dir, tmp_path / run_dir.name))
