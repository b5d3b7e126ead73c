"""FPP-ML-Bench export (virtus.data.mlbench): their layout and keys, pairs by stem, metric
depth in millimetres, per-sample calibration that re-triangulates, byte reproducibility,
splits by object, and bad input through the CLI (one line, exit 2, nothing written)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from tests.data.test_dataset import run_cli, tiny_config
from virtus.data import DatasetStore, generate, load_config
from virtus.data.mlbench import MLBENCH_VARIANTS, export_fpp_ml_bench, input_frame_index
from virtus.errors import InputError


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("mlbench")
    config = tiny_config(folder, num_samples=8, planes={"count": [1, 1]})
    generate(load_config(config), folder / "store")
    return folder / "store"


def digests(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != "export.json"
    }


def test_layout_pairs_and_values_read_as_their_loader_does(store, tmp_path) -> None:
    from PIL import Image
    from scipy.io import loadmat

    summary = export_fpp_ml_bench(store, tmp_path / "out")
    samples = DatasetStore.open(store).samples()
    assert sum(summary["samples"].values()) == len(samples)
    for variant in MLBENCH_VARIANTS:
        root = tmp_path / "out" / f"training_data_depth{variant}"
        for split in ("train", "val", "test"):
            fringes = sorted(p.stem for p in (root / split / "fringe").glob("*.png"))
            depths = sorted(p.stem for p in (root / split / "depth").glob("*.mat"))
            assert fringes == depths  # pairs by stem, as their dataset.py pairs them
            assert len(fringes) == summary["samples"].get(split, 0)
    s = DatasetStore.open(store)
    for index, meta in samples.items():
        stem, split = f"{index:06d}", meta["split"]
        root = tmp_path / "out" / "training_data_depth_raw" / split
        depth = loadmat(root / "depth" / f"{stem}.mat")["depth"]  # their key
        fringe = np.array(Image.open(root / "fringe" / f"{stem}.png").convert("L"))
        data = s.read_sample(index, ("frames", "depth"))
        truth = data["depth"]
        assert depth.dtype == np.float32 and depth.shape == truth.shape
        has = np.isfinite(truth)
        np.testing.assert_array_equal(depth[~has], 0.0)  # their mask is depth > 0
        np.testing.assert_allclose(depth[has], truth[has] * 1000.0, rtol=1e-6)
        assert 900 < np.median(depth[has]) < 1500  # millimetres, not metres
        frame = input_frame_index(meta)
        assert meta["sequence"]["frames"][frame]["kind"] == "phase"
        np.testing.assert_array_equal(fringe, data["frames"][frame])
        calibration = json.loads(
            (tmp_path / "out" / "calibration" / split / f"{stem}.json").read_text()
        )
        assert calibration["rig"] == meta["rig"] and calibration["input_frame"]["index"] == frame
        assert calibration["input_frame"]["period_px"] == 16.0


def test_export_is_reproducible_and_variants_share_files(store, tmp_path) -> None:
    export_fpp_ml_bench(store, tmp_path / "a")
    export_fpp_ml_bench(store, tmp_path / "b", variants=("_raw",))
    a, b = digests(tmp_path / "a"), digests(tmp_path / "b")
    assert {k: v for k, v in a.items() if k in b} == b
    raw = {k.split("/", 1)[1]: v for k, v in a.items() if k.startswith("training_data_depth_raw/")}
    glob = {
        k.split("/", 1)[1]: v
        for k, v in a.items()
        if k.startswith("training_data_depth_global_normalized/")
    }
    assert raw == glob and raw


def test_splits_are_by_object(store) -> None:
    owner: dict[str, str] = {}
    for meta in DatasetStore.open(store).samples().values():
        for obj in meta["objects"]:
            if obj["type"] != "plane":
                assert owner.setdefault(obj["key"], meta["split"]) == meta["split"]


def test_input_frame_rules(store) -> None:
    meta = next(iter(DatasetStore.open(store).samples().values()))
    assert input_frame_index(meta, 3) == 3
    with pytest.raises(InputError, match="frame"):
        input_frame_index(meta, meta["n_frames"])
    only_h = dict(meta, sequence=dict(meta["sequence"], frames=[
        f for f in meta["sequence"]["frames"] if f.get("direction") != "v"
    ]))  # fmt: skip
    with pytest.raises(InputError, match="vertical phase"):
        input_frame_index(only_h)


def test_cli_export_and_bad_input(store, tmp_path, capsys) -> None:
    out = tmp_path / "cli"
    code, text, _ = run_cli(["dataset", "export", "--format", "fpp-ml-bench", store, out], capsys)
    assert code == 0 and "fpp-ml-bench" in text
    assert (out / "training_data_depth_individual_normalized" / "train" / "fringe").is_dir()
    # again into the same folder: refused, nothing changed
    before = digests(out)
    code, _, err = run_cli(["dataset", "export", "--format", "fpp-ml-bench", store, out], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "earlier export" in err
    assert digests(out) == before
    # a frame the sequence lacks: one line, exit 2, nothing written
    fresh = tmp_path / "fresh"
    args = ["dataset", "export", "--format", "fpp-ml-bench", "--frame", "99", store, fresh]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "frame" in err and len(err.strip().splitlines()) == 1
    assert not fresh.exists()
    code, _, err = run_cli(["dataset", "export", "--format", "fpp-ml-bench", store], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
