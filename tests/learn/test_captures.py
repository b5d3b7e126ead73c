"""A trained model on captures against their own multi-step phase (virtus.learn.captures),
and captures it cannot read (one line, exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from tests.data.test_dataset import run_cli  # noqa: E402
from tests.learn.conftest import render_capture  # noqa: E402
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
    code, out, _ = run_cli(["learn", "eval", phase_run, "--captures", capture, "--json"], capsys)
    assert code == 0 and json.loads(out)["samples"] == 1


def test_a_capture_without_the_input_frame_is_refused(phase_run, tmp_path, capsys) -> None:
    capture = render_capture(tmp_path / "h", directions=("h",))
    code, _, err = run_cli(["learn", "eval", phase_run, "--captures", capture], capsys)
    assert code == 2 and "input frame" in err and len(err.strip().splitlines()) == 1
