"""The report of a learning run (:mod:`virtus.report.learn`): training, each evaluation and
the depth maps ``virtus learn eval`` saved; a changed map is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.report.conftest import copy_run
from tests.report.test_runs import _mark_running, _refused
from virtus.report import build_page

pytest.importorskip("torch")


def test_training_and_the_evaluations_maps_are_shown(learn_run) -> None:
    page, info = build_page(learn_run)
    assert info.kind == "learn" and info.command == "learn train"
    (evaluation,) = sorted((learn_run / "evaluations").glob("*.json"))
    maps = json.loads(evaluation.read_text())["maps"]
    assert [m["sample"] for m in maps] == [0, 1, 2]
    key = f"fig-evaluation-{evaluation.stem}"
    for entry in maps:
        for layer in ("predicted-depth", "true-depth", "error"):
            assert f"{key}-sample-{entry['sample']}-{layer}" in page.figures
    assert "fig-training-loss" in page.figures


def test_a_changed_map_is_refused(learn_run, tmp_path, capsys) -> None:
    run = copy_run(learn_run, tmp_path)
    (target,) = sorted((run / "evaluations").glob("*/sample_000001.npy"))
    values = np.load(target)
    np.save(target, values + 1.0)  # same shape and dtype, other numbers
    assert "changed since the evaluation wrote it" in _refused(run, capsys)


def test_a_run_without_evaluations_says_how_to_make_one(learn_run, tmp_path) -> None:
    import shutil

    run = copy_run(learn_run, tmp_path)
    shutil.rmtree(run / "evaluations")
    assert "No evaluation yet" in build_page(run)[0].render()


def test_a_half_finished_training_is_refused(learn_run, tmp_path, capsys) -> None:
    run = copy_run(learn_run, tmp_path)
    _mark_running(run)
    assert "half-finished `virtus learn train` run" in _refused(run, capsys)
