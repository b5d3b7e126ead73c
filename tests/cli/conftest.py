"""Fixtures of the command-line tests."""

from __future__ import annotations

import json

import pytest

from virtus.cli import main


@pytest.fixture(scope="session")
def tiny(tmp_path_factory):
    """A folder with a tiny rig (rig.json: 64 x 64 camera), a capture of the built-in sphere
    made with it (cap/, read only: copy it to change it) and its sequence (seq.json)."""
    from tests.support import small_rig

    root = tmp_path_factory.mktemp("tiny")
    small_rig(1 / 15).save_json(root / "rig.json")
    cap = root / "cap"
    with pytest.raises(SystemExit) as exit_info:
        main(["capture", "--scene", "sphere", "--rig", str(root / "rig.json"), "--spp", "1",
              "--out", str(cap), "--quiet"])  # fmt: skip
    assert exit_info.value.code == 0
    sequence = json.loads((cap / "capture.json").read_text())["sequence"]
    (root / "seq.json").write_text(json.dumps(sequence))
    return root


@pytest.fixture
def emitted(monkeypatch) -> list:
    """The plain data of every summary the CLI emits during the test, in order (the table
    is printed 400 columns wide, so that no cell wraps and paths stay whole)."""
    from virtus.cli import output as printing

    monkeypatch.setenv("COLUMNS", "400")
    seen = []
    emit = printing.Output.emit

    def spy(self, summary):  # noqa: ANN001, ANN202
        seen.append(printing.plain(summary.data))
        return emit(self, summary)

    monkeypatch.setattr(printing.Output, "emit", spy)
    return seen
