"""Report sections of tables and collections (:mod:`virtus.report.others`): here the twin
validation's difference maps, checked against their checksums, and a twin's run record."""

from __future__ import annotations

import json

import numpy as np

from tests.report.conftest import copy_run
from tests.report.test_runs import _mark_running, _refused
from virtus.report import build_page


def test_the_twins_difference_maps_are_drawn_per_pose(twin_run) -> None:
    page, info = build_page(twin_run)
    assert info.kind == "twin" and info.command == "twin"
    data = json.loads((twin_run / "validation.json").read_text())
    assert len(data["maps"]["files"]) == len(data["per_pose"]) == 2
    for index in range(2):
        for layer in ("white", "fringe", "code", "proj-uv"):
            assert f"fig-twin-maps-pose-{index}-{layer}" in page.figures


def test_a_changed_difference_map_is_refused(twin_run, tmp_path, capsys) -> None:
    run = copy_run(twin_run, tmp_path)
    target = run / "validation_maps" / "pose_002.npy"
    np.save(target, np.zeros_like(np.load(target)))
    assert "pose_002.npy: changed since the validation wrote it" in _refused(run, capsys)


def test_a_validation_without_maps_gets_a_note(twin_run, tmp_path) -> None:
    run = copy_run(twin_run, tmp_path)
    data = json.loads((run / "validation.json").read_text())
    del data["maps"]
    (run / "validation.json").write_text(json.dumps(data))
    assert "stored no difference maps" in build_page(run)[0].render()


def test_a_half_finished_twin_is_refused(twin_run, tmp_path, capsys) -> None:
    run = copy_run(twin_run, tmp_path)
    _mark_running(run)
    assert "half-finished `virtus twin` run (status running)" in _refused(run, capsys)
