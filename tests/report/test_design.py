"""Reports of the design runs (:mod:`virtus.report.design`): ``virtus acceptance``,
``virtus predict`` and ``virtus design``; what each shows and what a changed run gets."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from tests.report.conftest import copy_run
from tests.report.test_runs import _mark_running, _refused
from virtus.report import build_page, write_report
from virtus.report.html import format_value


def _figures(run_dir) -> list[str]:
    page, _ = build_page(run_dir)
    return page.figures


def test_acceptance_shows_the_verdict_and_each_figure_per_position(acceptance_run) -> None:
    page, info = build_page(acceptance_run)
    assert info.kind == "acceptance" and info.command == "acceptance"
    for name in ("p-f", "p-s", "sd", "f"):
        assert f"fig-acceptance-figure-{name}" in page.figures
    html = page.render()
    data = json.loads((acceptance_run / "acceptance.json").read_text())
    assert "Result: PASSED; shortened (--positions)" in html
    for figure in ("P_F", "P_S", "SD", "F"):  # the table carries the run's own maxima
        assert format_value(data["maxima"][figure]["value_mm"]) in html


def test_an_acceptance_without_its_maxima_is_refused(acceptance_run, tmp_path, capsys) -> None:
    run = copy_run(acceptance_run, tmp_path)
    data = json.loads((run / "acceptance.json").read_text())
    del data["maxima"]
    (run / "acceptance.json").write_text(json.dumps(data))
    assert "acceptance result without maxima" in _refused(run, capsys)


def test_predict_draws_every_sigma_map(predict_run) -> None:
    figures = _figures(predict_run)
    assert {"fig-prediction-sigma-u-p", "fig-prediction-sigma-depth",
            "fig-prediction-sigma-point", "fig-prediction-mask"} <= set(figures)  # fmt: skip


def test_a_sigma_map_of_another_size_is_refused(predict_run, tmp_path, capsys) -> None:
    run = copy_run(predict_run, tmp_path)
    np.save(run / "sigma_depth.npy", np.zeros((5, 5)))
    assert "sigma_depth" in _refused(run, capsys)


def test_design_shows_the_sweeps_figures_and_table(design_run, tmp_path) -> None:
    report = write_report(design_run, tmp_path / "design.html")
    assert report.kind == "design"
    drawn = sorted(p.stem for p in (design_run / "figures").glob("*.png"))
    ids = [f"fig-design-figures-sweep-{re.sub('[^a-z0-9]+', '-', stem)}" for stem in drawn]
    assert drawn and set(ids) <= set(report.figures)
    assert "variants" in report.path.read_text()


@pytest.mark.parametrize("fixture", ["acceptance_run", "predict_run", "design_run"])
def test_half_finished_design_runs_are_refused(fixture, request, tmp_path, capsys) -> None:
    run = copy_run(request.getfixturevalue(fixture), tmp_path)
    command = _mark_running(run)
    assert f"half-finished `virtus {command}` run" in _refused(run, capsys)
