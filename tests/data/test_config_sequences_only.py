"""``fringes.codings: []`` with sequence files: samples show only those sequences (a real
bench's own patterns, e.g. examples/datasets/sim2real/lab.yaml); without files an empty
list is refused."""

from __future__ import annotations

import json

import pytest

from tests.data.test_dataset import tiny_config, tiny_rig
from virtus.data import DatasetConfig, load_config
from virtus.data.sampling import candidate_sequences
from virtus.errors import InputError


def _sequence_file(folder) -> str:
    """A 4-step horizontal-fringe sequence for the tiny rig's projector."""
    from virtus.patterns.catalog import build_sequence

    proj = tiny_rig().projector.intrinsics
    sequence = build_sequence(
        proj.width, proj.height, periods=16, steps=4, gray_bits=5, directions=("h",)
    )
    path = folder / "h.json"
    path.write_text(json.dumps(sequence.to_dict()))
    return str(path)


def test_only_the_sequence_files_are_drawn(tmp_path) -> None:
    files = [_sequence_file(tmp_path)]
    config = load_config(tiny_config(tmp_path, fringes={"codings": [], "sequences": files}))
    assert config.fringes.codings == ()
    assert DatasetConfig.from_dict(config.to_dict()) == config  # a store's record reads back
    names = [name for name, _ in candidate_sequences(config, tiny_rig())]
    assert names == ["h.json"]


def test_no_coding_and_no_file_is_refused(tmp_path) -> None:
    with pytest.raises(InputError, match="fringes.codings"):
        load_config(tiny_config(tmp_path, fringes={"codings": []}))
