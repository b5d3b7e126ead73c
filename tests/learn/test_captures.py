"""A trained model on captures against their own multi-step phase (virtus.learn.captures),
and captures it cannot read (one line, exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from tests.data.test_dataset import run_cli  # noqa: E402
from tests.learn.conftest import render_capture  # noqa: E402
from virtus.errors import InputError  # noqa: E402
from virtus.learn.captures import evaluate_captures  # noqa: E402


def test_phase_model_on_a_capture(phase_run, tmp_path, capsys) -> None:
    capture = render_capture(tmp_path / "cap")
    summary = evaluate_captures(phase_run, [capture])
    assert summary["samples"] == 1 and summary["reference"].startswith("multi-step")
    # every reference pixel is compared: depth against the capture's own decode, in mm
    assert summary["valid_share"] > 0.9 and summary["object_mae_mm"] > 0
    assert 0 < summary["phase_rmse_rad"] <= np.pi
    on_disk = json.loads((phase_run / "evaluations" / "captures.json").read_text())
    assert on_disk["phase_rmse_rad"] == summary["phase_rmse_rad"]
    # its depth maps beside the metrics: predicted, multi-step reference, their difference (mm)
    (entry,) = on_disk["maps"]
    maps = np.load(phase_run / "evaluations" / entry["file"])
    predicted, reference, error = maps
    assert maps.shape[0] == 3 and entry["unit"] == "mm" and np.isfinite(reference).mean() > 0.9
    np.testing.assert_allclose(error, predicted - reference, atol=1e-3, equal_nan=True)
    mae = np.nanmean(np.abs(error))
    assert mae == pytest.approx(summary["object_mae_mm"], rel=1e-3)
    code, out, _ = run_cli(["learn", "eval", phase_run, "--captures", capture, "--json"], capsys)
    assert code == 0 and json.loads(out)["samples"] == 1


def test_a_capture_without_the_input_frame_is_refused(phase_run, tmp_path, capsys) -> None:
    capture = render_capture(tmp_path / "h", directions=("h",))
    code, _, err = run_cli(["learn", "eval", phase_run, "--captures", capture], capsys)
    assert code == 2 and "input frame" in err and len(err.strip().splitlines()) == 1


def test_a_horizontal_fringe_model_on_a_horizontal_capture(horizontal_store, tmp_path) -> None:
    """A phase model of ``direction: h`` reads a capture's horizontal fringes and is
    compared with their multi-step phase and the depth it gives."""
    from tests.learn.conftest import TINY_NET
    from virtus.learn.config import TrainConfig
    from virtus.learn.training import train

    config = TrainConfig.from_dict(
        {"model": "phase", "direction": "h", **TINY_NET, "epochs": 1, "max_steps": 1}
    )
    train(config, horizontal_store, tmp_path / "run")
    capture = render_capture(tmp_path / "cap", directions=("h",))
    summary = evaluate_captures(tmp_path / "run", [capture])
    assert summary["samples"] == 1 and summary["valid_share"] > 0.9
    assert 0 < summary["phase_rmse_rad"] <= np.pi and summary["object_mae_mm"] > 0
    with pytest.raises(InputError, match="input frame"):  # no horizontal frame to read
        evaluate_captures(tmp_path / "run", [render_capture(tmp_path / "v")])
