"""Training runs (virtus.learn.training) on a tiny store: the loss falls, a run killed at a
chosen step and resumed ends with the same weights as an uninterrupted one, metrics JSON
beside the checkpoint, and bad input through ``virtus learn`` (one line, exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")

from tests.data.test_dataset import run_cli  # noqa: E402
from tests.learn.conftest import TINY_NET  # noqa: E402
from virtus.learn.config import TrainConfig  # noqa: E402
from virtus.learn.training import CHECKPOINT, evaluate, load_model, train  # noqa: E402


class Killed(Exception):
    """Stands for a kill at a deterministic step (after that step's checkpoint, if any)."""


def config(model: str, **changes) -> TrainConfig:
    return TrainConfig.from_dict({"model": model, **TINY_NET, **changes})


def weights(run: Path) -> dict:
    return torch.load(run / CHECKPOINT, weights_only=False)["model"]


@pytest.mark.parametrize("model", ["unet", "phase"])
def test_loss_falls_and_metrics_are_written(learn_store, tmp_path, model) -> None:
    metrics = train(config(model, epochs=3), learn_store, tmp_path / "run")
    history = json.loads((tmp_path / "run" / "history.json").read_text())
    assert len(history) == 3
    assert history[-1]["train_loss"] < 0.8 * history[0]["train_loss"]
    assert history[-1]["val_loss"] < history[0]["val_loss"]
    saved = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert saved == json.loads(json.dumps(metrics))
    test = saved["test"]
    assert test["samples"] > 0 and test["object_mae_mm"] > 0 and test["valid_share"] > 0.5
    if model == "phase":
        assert 0 < test["phase_rmse_rad"] < 2.0 and 0 <= test["order_error_rate"] <= 1
    else:
        assert test["phase_rmse_rad"] is None


def test_resume_after_a_kill_gives_the_same_weights(learn_store, tmp_path) -> None:
    # the phase model: its loss runs the calibration layer too (the UNet's is a subset)
    settings = config("phase", epochs=2, checkpoint_every=2)
    train(settings, learn_store, tmp_path / "whole")

    def kill(step: int) -> None:
        if step == 5:  # step 4 was checkpointed, step 5 is lost with the process
            raise Killed

    with pytest.raises(Killed):
        train(settings, learn_store, tmp_path / "killed", on_step=kill)
    saved = torch.load(tmp_path / "killed" / CHECKPOINT, weights_only=False)
    assert saved["state"]["step"] == 4
    at_kill = saved["model"]
    train(settings, learn_store, tmp_path / "killed", resume=True)
    whole, resumed = weights(tmp_path / "whole"), weights(tmp_path / "killed")
    assert whole.keys() == resumed.keys()
    for name in whole:
        assert torch.equal(whole[name], resumed[name]), name
    for name in ("history.json", "metrics.json"):
        assert (tmp_path / "whole" / name).read_text() == (tmp_path / "killed" / name).read_text()
    # the resumed run went on from step 4 (equal weights there would be a test of nothing)
    assert any(not torch.equal(whole[n], at_kill[n]) for n in whole)


def test_evaluate_on_a_store_and_bad_checkpoints(learn_store, tmp_path, capsys) -> None:
    run = tmp_path / "run"
    train(config("unet", epochs=1), learn_store, run)
    summary = evaluate(run, learn_store, "val")
    on_disk = json.loads((run / "evaluations" / f"{learn_store.name}-val.json").read_text())
    assert on_disk["samples"] == summary["samples"] > 0
    code, out, _ = run_cli(["learn", "eval", run, "--store", learn_store, "--json"], capsys)
    assert code == 0 and json.loads(out)["samples"] == 12
    # a checkpoint of another architecture: the weights do not fit what it names
    saved = torch.load(run / CHECKPOINT, weights_only=False)
    saved["config"]["base_channels"] = 8
    saved["architecture"]["base_channels"] = 8
    torch.save(saved, run / CHECKPOINT)
    code, _, err = run_cli(["learn", "eval", run, "--store", learn_store], capsys)
    assert code == 2 and "another architecture" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(Exception, match="another architecture"):
        load_model(run)
    (run / CHECKPOINT).write_bytes(b"not a checkpoint")
    code, _, err = run_cli(["learn", "eval", run, "--store", learn_store], capsys)
    assert code == 2 and "checkpoint" in err and len(err.strip().splitlines()) == 1


def test_cli_train_and_bad_input(learn_store, horizontal_store, tmp_path, capsys) -> None:
    cfg = tmp_path / "unet.yaml"
    cfg.write_text(yaml.safe_dump({"model": "unet", **TINY_NET, "epochs": 1}))
    out = tmp_path / "run"
    code, text, _ = run_cli(["learn", "train", "--config", cfg, "--store", learn_store,
                             "--out", out], capsys)  # fmt: skip
    assert code == 0 and "object_mae_mm" in text and (out / CHECKPOINT).is_file()
    # a store without the labels the phase model needs (no vertical fringes): one line, exit 2
    phase = tmp_path / "phase.yaml"
    phase.write_text(yaml.safe_dump({"model": "phase", **TINY_NET, "input_frame": 0}))
    args = [
        "learn",
        "train",
        "--config",
        phase,
        "--store",
        horizontal_store,
        "--out",
        tmp_path / "p",
    ]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "labels" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p").exists()
    # a frame the sequences lack, an unknown key, no --store/--captures
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"model": "unet", "input_frame": 999}))
    args = ["learn", "train", "--config", bad, "--store", learn_store, "--out", tmp_path / "b"]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "frame" in err and len(err.strip().splitlines()) == 1
    bad.write_text(yaml.safe_dump({"model": "unet", "learning_rate": 1}))
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "learning_rate" in err
    code, _, err = run_cli(["learn", "eval", out], capsys)
    assert code == 2 and "--store/--captures" in err


def test_loader_workers_give_the_same_weights(learn_store, tmp_path) -> None:
    # batches are fixed by (seed, epoch) before any worker reads them
    train(config("unet", epochs=1), learn_store, tmp_path / "here")
    train(config("unet", epochs=1, workers=2), learn_store, tmp_path / "workers")
    here, there = weights(tmp_path / "here"), weights(tmp_path / "workers")
    assert all(torch.equal(here[n], there[n]) for n in here)


def test_phase_evaluation_with_decoded_orders(phase_run, learn_store, capsys) -> None:
    label = evaluate(phase_run, learn_store, "test")
    decoded = evaluate(phase_run, learn_store, "test", unwrap="decode")
    assert decoded["unwrap"] == "decode" and (phase_run / "evaluations").is_dir()
    assert decoded["phase_rmse_rad"] == label["phase_rmse_rad"]  # the network is the same
    # the stored order takes a predicted phase just across the wrap to the wrong period;
    # the branch nearest the decode (within ~0.2 rad of the truth) only one off by > ~pi
    assert decoded["order_error_rate"] <= label["order_error_rate"]
    assert decoded["valid_share"] > 0.5
    args = ["learn", "eval", phase_run, "--store", learn_store, "--unwrap", "guess"]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "unwrap" in err and len(err.strip().splitlines()) == 1


def test_evaluate_saves_the_first_samples_depth_maps(learn_store, tmp_path) -> None:
    """``evaluate`` keeps the predicted, true and error depth of its first samples (for the
    run's report), each listed in the evaluation JSON with its checksum."""
    from virtus.io.runs import file_digest
    from virtus.learn.training import MAP_LAYERS, MAP_SAMPLES

    run = tmp_path / "run"
    train(config("unet", epochs=1), learn_store, run)
    summary = evaluate(run, learn_store, None, name="all")
    assert len(summary["maps"]) == MAP_SAMPLES
    for entry in summary["maps"]:
        file = run / "evaluations" / entry["file"]
        assert entry["layers"] == list(MAP_LAYERS) and file_digest(file) == entry["sha256"]
        predicted, true, error = np.load(file).astype(np.float64)
        assert np.isfinite(true).mean() > 0.5  # a sphere before a plane: mostly surface
        assert np.array_equal(np.isnan(error), np.isnan(true) | np.isnan(predicted))
        assert np.array_equal(np.isnan(predicted), np.isnan(true) | np.isnan(predicted))
        finite = np.isfinite(error)
        assert np.allclose(error[finite], predicted[finite] - true[finite], atol=1e-3)  # mm
        assert 100 < np.nanmedian(true) < 5000  # millimetres, not metres
    on_disk = json.loads((run / "evaluations" / "all.json").read_text())
    assert on_disk["maps"] == summary["maps"]
